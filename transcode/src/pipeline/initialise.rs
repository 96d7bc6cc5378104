//! Stage 3: a model's initial splats (merged to the splat budget's start, warm-started, their
//! colours solved) and its schedule, or the checkpoint its training continues from.

use std::time::Instant;

use splat_core::Splats;
use splat_init::{self as init, InitSummary};
use splat_train::eval::evaluate_views;
use splat_train::{BudgetSearch, View, from_unorm16};

use super::error::PipelineError;
use super::input::{Surfaces, load};
use super::layout::{Layout, remove_file_if_present};
use super::references::References;
use super::schedule::plan;
use super::{RunOf, STAGES, WarmStart};
use crate::config::{Config, InitMode};
use crate::progress::{Event, Observer};
use crate::report::{HeldoutScore, StepZero};
use crate::resume::{self, ModeState, ResumeError, RunState, Schedule};

/// The init modes a run trains: the configured one, and the other with `compare_init`.
pub(super) fn init_modes(cfg: &Config) -> Vec<InitMode> {
    let mut modes = vec![cfg.init.mode];
    if cfg.output.compare_init {
        modes.push(match cfg.init.mode {
            InitMode::Surface => InitMode::Sparse,
            InitMode::Sparse => InitMode::Surface,
        });
    }
    modes
}

/// The initial splats and schedule of a model, or where training continues from.
pub(super) struct Initialised {
    pub(super) summary: InitSummary,
    pub(super) schedule: Schedule,
    pub(super) step_zero: Option<StepZero>,
    /// Fresh splats; `None` when training continues from the checkpoint.
    pub(super) fresh: Option<Splats>,
}

/// Stage 3: the initial splats and the training schedule, unless training continues from a
/// checkpoint. The schedule is fixed once, before the first step, and saved: a resumed run must
/// train on the same one even when it came from timed probe steps.
pub(super) fn initialise(
    run: &RunOf<'_>,
    surfaces: &mut Surfaces,
    refs: &References,
    cfg: &Config,
    layout: &Layout,
    state: &mut RunState,
    observer: Observer<'_>,
) -> Result<Initialised, PipelineError> {
    let (mode, out) = (run.mode, &layout.out);
    let saved = state.modes.get(run.index).cloned();
    if let Some(continuing) = continuing_from_checkpoint(run, saved.as_ref(), layout, observer)? {
        return Ok(continuing);
    }
    observer(Event::Stage {
        index: 3,
        of: STAGES,
        what: format!("{mode} init"),
    });
    let mut init_cfg = cfg.init.clone();
    init_cfg.mode = mode;
    let budget = budget_applies(cfg, mode).then_some(&cfg.budget);
    if let Some(b) = budget {
        cap_at_budget_start(&mut init_cfg, b, surfaces, refs, observer);
    }
    let (mut splats, mut summary) = init::initialise(
        &surfaces.init,
        &init_cfg,
        cfg.renderer.exponent,
        cfg.training.seed,
    )?;
    if let Some(previous) = run.warm_start {
        warm_start(&mut splats, previous, &init_cfg, cfg, observer)?;
        summary.warm_start = Some(previous.model.clone());
    }
    observer(Event::Note(format!(
        "{} splats, SH degree {}{}",
        summary.splats,
        summary.sh_degree,
        summary
            .sh_fit_rms
            .map(|e| format!(
                " (SH fit RMS by degree: {:.4} {:.4} {:.4} {:.4})",
                e[0], e[1], e[2], e[3]
            ))
            .unwrap_or_default()
    )));
    let step_zero = colour_solve(mode, &mut splats, surfaces, refs, cfg, observer)?;
    // The points are not needed past here by the last model: release them before the time
    // budget's probe builds a trainer of its own (at a paper-scale frame they are 0.6 GB, and
    // with the probe's trainer on top they set the run's peak memory).
    if run.last {
        surfaces.release_init();
    }
    let schedule = match &saved {
        Some(m) => m.schedule,
        None => {
            let base = cfg.train_config(mode, summary.sh_degree);
            let schedule = plan(
                &splats,
                &refs.train,
                &base,
                cfg.training.scale_densify,
                budget,
            )?;
            state.modes.push(ModeState {
                mode,
                init: summary.clone(),
                schedule,
                step_zero: Some(step_zero.clone()),
                heldout_curve: Vec::new(),
                budget: BudgetSearch::default(),
                trained: None,
            });
            state.save(out)?;
            schedule
        }
    };
    Ok(Initialised {
        summary,
        schedule,
        step_zero: Some(step_zero),
        fresh: Some(splats),
    })
}

/// What the saved state says of this model: training continues from its checkpoint (the saved
/// init, schedule and step-0 figures), or `None` when it starts afresh. Refuses a saved model
/// of another init mode, and a trained one whose checkpoint is gone; removes a checkpoint the
/// state does not list.
fn continuing_from_checkpoint(
    run: &RunOf<'_>,
    saved: Option<&ModeState>,
    layout: &Layout,
    observer: Observer<'_>,
) -> Result<Option<Initialised>, PipelineError> {
    let (mode, k, out) = (run.mode, run.index, &layout.out);
    let ckpt = resume::checkpoint_path(out, mode);
    if let Some(m) = saved
        && m.mode != mode
    {
        return Err(ResumeError::Malformed {
            path: out.join(resume::STATE_FILE),
            problem: format!("run {k} is {} init, the configuration says {mode}", m.mode),
        }
        .into());
    }
    let Some(m) = saved else {
        // No checkpoint can belong to a mode the state does not list yet.
        remove_file_if_present(&ckpt)?;
        return Ok(None);
    };
    if !ckpt.is_file() {
        if m.trained.is_some() {
            return Err(ResumeError::Checkpoint {
                path: ckpt,
                problem: "the trained model's checkpoint is missing".into(),
            }
            .into());
        }
        // Killed before its first checkpoint, or the checkpoint removed since: the mode starts
        // again from its init (the same model, deterministically), which is said, not silent.
        observer(Event::Note(format!(
            "{mode} init: no checkpoint at {} to continue from; its training starts again",
            ckpt.display()
        )));
        return Ok(None);
    }
    observer(Event::Stage {
        index: 3,
        of: STAGES,
        what: format!("{mode} init: continuing from {}", ckpt.display()),
    });
    Ok(Some(Initialised {
        summary: m.init.clone(),
        schedule: m.schedule,
        step_zero: m.step_zero.clone(),
        fresh: None,
    }))
}

/// `--splats K` caps the splat budget's start, never raises it
/// (`BudgetConfig::start_splats`): the points merged to about the start before training.
fn cap_at_budget_start(
    init_cfg: &mut init::InitConfig,
    budget: &splat_train::BudgetConfig,
    surfaces: &Surfaces,
    refs: &References,
    observer: Observer<'_>,
) {
    let points = surfaces.init.len();
    let asked = init_cfg.splats;
    let start = budget.start_splats(points, mean_covered_pixels(&refs.train), asked);
    if start < asked.unwrap_or(points).min(points) {
        let asked = asked.map_or(String::new(), |k| format!(", under the {k} asked for"));
        observer(Event::Note(format!(
            "splat budget: {points} points merged to about {start} ({} per covered pixel \
             of the mean training view{asked}) before training",
            budget.splats_per_pixel
        )));
        init_cfg.splats = Some(start);
    }
}

/// Warm start: reproduces the previous frame's initialisation from its input and adds what
/// training changed in it to `splats` ([`init::carry_training`]).
pub(super) fn warm_start(
    splats: &mut Splats,
    previous: &WarmStart,
    init_cfg: &init::InitConfig,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(), PipelineError> {
    let warm_err = |problem: String| PipelineError::WarmStart {
        path: previous.model.clone(),
        problem,
    };
    let trained = splat_core::ply::read_splats(&previous.model)
        .map_err(|e| warm_err(format!("cannot read it: {e}")))?;
    let loaded = load(&previous.input, &crate::progress::ignore)?;
    let surfaces = Surfaces::of(loaded.model, cfg);
    let (initial, _) = init::initialise(
        &surfaces.init,
        init_cfg,
        cfg.renderer.exponent,
        cfg.training.seed,
    )?;
    let carried =
        init::carry_training(splats, &initial, &trained).map_err(|e| warm_err(e.to_string()))?;
    if let Some(c) = carried {
        observer(Event::Note(format!(
            "warm start: {} splats took the training corrections of {} (rigid motion {:.2}° and \
             {:.3} taken out; median distance {:.3})",
            c.splats,
            previous.model.display(),
            c.motion.angle_deg(),
            c.motion.translation.length(),
            c.median_distance
        )));
    }
    Ok(())
}

/// Whether the automatic splat budget runs for `mode`: surface init that does not densify (a
/// densifying run grows and prunes by its own rules).
fn budget_applies(cfg: &Config, mode: InitMode) -> bool {
    cfg.budget.auto && mode == InitMode::Surface && !cfg.init.densify_surface
}

/// The pixels the input covers in the mean training view (reference alpha above ½).
fn mean_covered_pixels(views: &[View]) -> f64 {
    let covered: usize = views
        .iter()
        .map(|v| match &v.mask {
            Some(m) => m.iter().filter(|&&a| from_unorm16(a) > 0.5).count(),
            None => v.image.len() / 3,
        })
        .sum();
    covered as f64 / views.len().max(1) as f64
}

/// Stage 3 (end): scores the initial splats on the held-out views and, for surface init with
/// `init.colour_solve_iterations` > 0, replaces their SH coefficients by the least-squares solve
/// against the training views (`splat_init::colour_solve`) and scores them again.
fn colour_solve(
    mode: InitMode,
    splats: &mut Splats,
    surfaces: &Surfaces,
    refs: &References,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<StepZero, PipelineError> {
    let score = |s: &Splats| -> Result<HeldoutScore, PipelineError> {
        let (m, _) = evaluate_views(
            s,
            &refs.heldout,
            surfaces.distance.as_ref(),
            &cfg.eval_options(),
        )?;
        Ok(HeldoutScore::from(&m))
    };
    let fit = score(splats)?;
    let iterations = cfg.init.colour_solve_iterations;
    if mode != InitMode::Surface || iterations == 0 {
        return Ok(StepZero {
            fit,
            solved: None,
            solve: None,
            solve_seconds: 0.0,
        });
    }
    let start = Instant::now();
    let report = splat_init::solve_colours(
        splats,
        &refs.train,
        &splat_init::SolveOptions {
            iterations,
            ..splat_init::SolveOptions::default()
        },
    )?;
    let solve_seconds = start.elapsed().as_secs_f64();
    let solved = score(splats)?;
    observer(Event::Note(format!(
        "colour solve ({} iterations, {solve_seconds:.1} s): held-out PSNR at step 0 {:.2} → {:.2} dB on black, {:.2} → {:.2} dB on white",
        report.iterations, fit.psnr_black, solved.psnr_black, fit.psnr_white, solved.psnr_white
    )));
    Ok(StepZero {
        fit,
        solved: Some(solved),
        solve: Some(report),
        solve_seconds,
    })
}
