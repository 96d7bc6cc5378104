//! Stage 4: training to the end of the schedule, with the held-out curve, the splat budget's
//! rounds and checkpoints along the way.

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use splat_core::Splats;
use splat_train::eval::{EvalOptions, evaluate_views};
use splat_train::{BudgetSearch, Trainer, View};

use super::budget::{Budgeting, budget_round};
use super::error::PipelineError;
use super::layout::Layout;
use super::references::References;
use super::schedule::scheduled_config;
use super::{RunOf, STAGES};
use crate::config::Config;
use crate::progress::{Event, Observer};
use crate::report::HeldoutPoint;
use crate::resume::{self, ResumeError, RunState, Schedule, TrainedState};

/// Stage 4: trains from `fresh` splats, or from the run's checkpoint, to the end of the schedule
/// (or finds it trained already), checkpointing as it goes. Returns the splats, the trainer's
/// report and the held-out curve (`eval.every`).
#[allow(clippy::too_many_arguments)]
pub(super) fn train(
    run: &RunOf<'_>,
    fresh: Option<Splats>,
    schedule: &Schedule,
    sh_degree: u32,
    refs: &References,
    cfg: &Config,
    layout: &Layout,
    state: &mut RunState,
    observer: Observer<'_>,
) -> Result<Trained, PipelineError> {
    let (mode, k, out) = (run.mode, run.index, &layout.out);
    let ckpt = resume::checkpoint_path(out, mode);
    observer(Event::Stage {
        index: 4,
        of: STAGES,
        what: format!(
            "training {} iterations{}",
            cfg.training.iterations,
            cfg.training
                .time_budget_s
                .map(|b| format!(" (budget {b:.0} s)"))
                .unwrap_or_default()
        ),
    });
    let tc = scheduled_config(cfg.train_config(mode, sh_degree), schedule);
    if let (Some(steps), Some(d)) = (schedule.densify_steps, tc.densify) {
        observer(Event::Note(format!(
            "densification scaled to ~{steps} steps: from step {} every {} until {}, opacity reset every {}",
            d.start, d.interval, d.stop, d.opacity_reset_interval
        )));
    }
    let mut trainer = match fresh {
        Some(splats) => {
            let mut t = Trainer::new(splats, Arc::clone(&refs.train), tc)?;
            if let Some(pace) = schedule.pace {
                t.start_pace(pace);
            }
            t
        }
        None => Trainer::resume(&ckpt, Arc::clone(&refs.train), tc).map_err(|e| {
            ResumeError::Checkpoint {
                path: ckpt.clone(),
                problem: e.to_string(),
            }
        })?,
    };
    // The curve as far as the checkpoint: points taken after it are taken again.
    let mut probe = HeldoutProbe {
        views: &refs.heldout,
        every: cfg.eval.every,
        options: cfg.eval_options(),
        curve: state
            .modes
            .get(k)
            .map(|m| m.heldout_curve.clone())
            .unwrap_or_default(),
    };
    probe.curve.retain(|p| p.iteration <= trainer.iteration());
    let mut search = state
        .modes
        .get(k)
        .map(|m| m.budget.clone())
        .unwrap_or_default();
    search.plan = schedule.budget;
    let already = state.modes.get(k).and_then(|m| m.trained);
    if already.is_none() {
        search.rewind(trainer.iteration());
    }
    let report = match already {
        Some(t) => {
            observer(Event::Note(format!(
                "trained already ({} steps)",
                trainer.iteration()
            )));
            trainer.report(t.stopped_by_budget)
        }
        None => {
            if trainer.iteration() > 0 {
                observer(Event::Note(format!(
                    "continuing from step {}",
                    trainer.iteration()
                )));
            }
            let every = Duration::from_secs_f64(cfg.output.checkpoint_interval_s);
            let saving = Saving {
                checkpoint: &ckpt,
                every,
                state,
                mode_index: k,
                out,
            };
            let budget = Budgeting {
                search: &mut search,
                config: &cfg.budget,
            };
            let report = train_to_end(&mut trainer, saving, &mut probe, budget, observer)?;
            if let Some(m) = state.modes.get_mut(k) {
                m.trained = Some(TrainedState {
                    stopped_by_budget: report.stopped_by_budget,
                });
            }
            state.save(out)?;
            report
        }
    };
    Ok((trainer.splats().clone(), report, probe.curve, search))
}

/// What stage 4 returns: the splats, the trainer's report, the held-out curve and the splat
/// budget's rounds.
type Trained = (
    Splats,
    splat_train::TrainReport,
    Vec<HeldoutPoint>,
    BudgetSearch,
);

/// Scores the model on the held-out views every `every` steps while it trains.
struct HeldoutProbe<'a> {
    views: &'a [View],
    every: u32,
    options: EvalOptions,
    curve: Vec<HeldoutPoint>,
}

impl HeldoutProbe<'_> {
    /// Adds the point of the trainer's current step when one is due: at step 0, every `every`
    /// steps and at the last step (`last`). A multiple of `every` that a splat budget round
    /// trained past (its two branches train between two calls) is taken at the first step
    /// after the round, so the curve has a point in every `every` steps.
    fn take(&mut self, trainer: &Trainer, elapsed_s: f64, last: bool) -> Result<(), PipelineError> {
        let it = trainer.iteration();
        let previous = self.curve.last().map(|p| p.iteration);
        if self.every == 0 || previous.is_some_and(|p| p >= it) {
            return Ok(());
        }
        let passed = previous.is_some_and(|p| it / self.every > p / self.every);
        if !(it.is_multiple_of(self.every) || last || passed) {
            return Ok(());
        }
        let (metrics, _) = evaluate_views(trainer.splats(), self.views, None, &self.options)?;
        self.curve.push(HeldoutPoint::new(it, elapsed_s, &metrics));
        Ok(())
    }
}

/// Where and how often [`train_to_end`] saves its progress.
struct Saving<'a> {
    checkpoint: &'a Path,
    /// Wall time between checkpoints.
    every: Duration,
    state: &'a mut RunState,
    mode_index: usize,
    out: &'a Path,
}

impl Saving<'_> {
    /// Saves the held-out curve so far in the run state, then the trainer's checkpoint. The
    /// state goes first: a point newer than the checkpoint is dropped and taken again on resume.
    fn save(
        &mut self,
        trainer: &Trainer,
        curve: &[HeldoutPoint],
        search: &BudgetSearch,
    ) -> Result<(), PipelineError> {
        if let Some(m) = self.state.modes.get_mut(self.mode_index) {
            m.heldout_curve = curve.to_vec();
            m.budget = search.clone();
        }
        self.state.save(self.out)?;
        trainer.save_checkpoint(self.checkpoint)?;
        Ok(())
    }
}

/// Runs `trainer` to the end of its schedule one step at a time, reporting progress, taking
/// the held-out curve's points, and checkpointing every `saving.every` of wall time and once
/// more at the end (the later stages resume from that).
///
/// The trainer pauses between two steps to save or score, which changes nothing it computes: a
/// run checkpointed or scored at any moments ends bit-identical to one that never stopped.
fn train_to_end(
    trainer: &mut Trainer,
    mut saving: Saving<'_>,
    probe: &mut HeldoutProbe<'_>,
    mut budget: Budgeting<'_>,
    observer: Observer<'_>,
) -> Result<splat_train::TrainReport, PipelineError> {
    let total = trainer.horizon();
    observer(Event::Begin {
        unit: "steps",
        total: u64::from(total),
        done: u64::from(trainer.iteration()),
    });
    // The held-out curve's scores (`--eval-every`, off by default) are a measurement of the
    // run and stay off its clock, so the curve's time axis is training time, as in `transcode
    // train`; the checkpoints are part of the run, and a time budget pays for them
    // (`Trainer::count_time_between_steps`).
    if trainer.iteration() == 0 {
        probe.take(trainer, 0.0, false)?;
    }
    let mut shown_total = total;
    let mut advance = |p: &splat_train::Progress| {
        if p.total != shown_total {
            shown_total = p.total;
            observer(Event::Total(u64::from(p.total)));
        }
        let message = p
            .step
            .iteration
            .is_multiple_of(25)
            .then(|| format!("PSNR {:.2} dB, {} splats", p.step.psnr, p.step.splats));
        observer(Event::Advance {
            done: u64::from(p.step.iteration),
            message,
        });
    };
    let mut saved_at = Instant::now();
    let report = loop {
        while budget.search.due(trainer.iteration()) {
            // A round trains two branches for many steps and cannot be checkpointed inside it:
            // the state before it is saved, so a run killed during a round resumes at the
            // round's start (it went back to the last timed checkpoint, at the demo's scale
            // often none: the whole run again).
            let t = Instant::now();
            saving.save(trainer, &probe.curve, budget.search)?;
            trainer.count_time_between_steps(t.elapsed().as_secs_f64());
            saved_at = Instant::now();
            budget_round(
                trainer,
                &mut budget,
                probe.views,
                &probe.options,
                &mut advance,
                observer,
            )?;
        }
        let r = trainer.run_until(trainer.iteration() + 1, &mut advance);
        // The horizon as it stands now: under a time budget it is re-estimated every step, and
        // it grows when the steps get faster (a budget round's merge), so the length estimated
        // before the first step would end the schedule early, with budget left.
        let last = r.iterations >= trainer.horizon() || r.stopped_by_budget;
        probe.take(trainer, r.elapsed_s, last)?;
        if last {
            // A time budget that laid the schedule over fewer steps than configured stopped it.
            break trainer.report(r.stopped_by_budget || trainer.budget_binds());
        }
        if saved_at.elapsed() >= saving.every {
            let t = Instant::now();
            saving.save(trainer, &probe.curve, budget.search)?;
            trainer.count_time_between_steps(t.elapsed().as_secs_f64());
            saved_at = Instant::now();
        }
    };
    saving.save(trainer, &probe.curve, budget.search)?;
    observer(Event::End);
    Ok(report)
}
