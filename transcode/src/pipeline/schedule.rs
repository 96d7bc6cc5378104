//! A run's schedule, fixed before its first step: under a time budget, the steps that fit in it
//! at the speed of timed probe steps, and where the splat budget's rounds fall.

use std::sync::Arc;
use std::time::{Duration, Instant};

use splat_core::Splats;
use splat_train::schedule::Pace;
use splat_train::{BudgetConfig, TrainConfig, Trainer, View};

use super::error::PipelineError;
use crate::resume::Schedule;

/// Fewest steps of each size timed (after one untimed step) to estimate a time-budgeted run's
/// length before its schedule is laid out.
const PROBE_STEPS: u32 = 4;

/// Most steps of each size the probe times: on small views a step takes milliseconds, and a
/// few of them measured the demo's steps 10-40 % off.
const PROBE_MAX_STEPS: u32 = 48;

/// The probe times more than [`PROBE_STEPS`] steps of a size until they have taken this share
/// of the time budget (or [`PROBE_MAX_STEPS`] are timed).
const PROBE_BUDGET_SHARE: f64 = 0.005;

/// A run whose steps, at the speed of the first [`PROBE_STEPS`] timed, would take no more than
/// this share of its time budget cannot be cut short by it, even with the splat budget's extra
/// branch steps: the probe stops there rather than time more (at a paper-scale frame those cost
/// about 5 s). The run still re-estimates its pace as it goes.
const PROBE_EASY_FIT: f64 = 0.5;

/// The number of steps a run will take: its iteration count, or, with a time budget, the steps
/// that fit in the budget at the speed of steps timed on a throw-away trainer after an untimed
/// one ([`PROBE_STEPS`] of them, more on fast steps ([`PROBE_BUDGET_SHARE`]) unless the run
/// fits in the budget with room to spare ([`PROBE_EASY_FIT`]); the probe's time
/// is taken from the budget; the arithmetic is [`splat_train::schedule::steps_in_budget`]).
/// With a coarse warm-up the probe times steps on the reduced views first, then on the full
/// ones, and the warm-up's share of the steps counts at its own speed. Returns the steps, the
/// remaining budget and the speeds timed (the run's [`Pace`] starts from them).
fn step_budget(
    splats: &Splats,
    views: &Arc<Vec<View>>,
    tc: &TrainConfig,
) -> Result<(u32, Option<Duration>, Option<Pace>), PipelineError> {
    let Some(budget) = tc.time_budget else {
        return Ok((tc.iterations, None, None));
    };
    // One untimed step (buffers, targets), then the timed ones; once per view size.
    let per_size = PROBE_MAX_STEPS + 1;
    let probe_cfg = TrainConfig {
        iterations: if tc.warmup.is_some() {
            2 * per_size
        } else {
            per_size
        },
        densify: None,
        time_budget: None,
        warmup: tc.warmup.map(|w| splat_train::Warmup {
            until: per_size,
            ..w
        }),
        ..tc.clone()
    };
    let enough = budget.mul_f64(PROBE_BUDGET_SHARE);
    let t0 = Instant::now();
    let mut probe = Trainer::new(splats.clone(), Arc::clone(views), probe_cfg)?;
    let setup = t0.elapsed();
    // One untimed step, then steps timed until there are enough; returns their time and count.
    // `run_step_s` turns the step time timed so far into the run's mean step time (a lower bound
    // of it while only the warm-up's size is timed).
    let time_steps = |probe: &mut Trainer, run_step_s: &dyn Fn(f64) -> f64| {
        probe.run_until(probe.iteration() + 1, |_| {});
        let t = Instant::now();
        let mut timed = 0;
        while keep_timing(timed, t.elapsed(), enough, |step_s| {
            run_step_s(step_s) * f64::from(tc.iterations) > PROBE_EASY_FIT * budget.as_secs_f64()
        }) {
            probe.run_until(probe.iteration() + 1, |_| {});
            timed += 1;
        }
        (t.elapsed(), timed)
    };
    // A full-size step takes at least as long as a warm-up step.
    let first = time_steps(&mut probe, &|step_s| step_s);
    let ((timed, timed_steps), coarse) = match tc.warmup {
        Some(w) => {
            probe.end_warmup();
            let share = (f64::from(w.until) / f64::from(tc.iterations.max(1))).min(1.0);
            let coarse_s = first.0.as_secs_f64() / f64::from(first.1);
            let full = time_steps(&mut probe, &|full_s| {
                splat_train::schedule::mean_step_s(full_s, Some((share, coarse_s)))
            });
            (full, Some((share, coarse_s)))
        }
        None => (first, None),
    };
    let (steps, left) = splat_train::schedule::steps_in_budget(
        tc.iterations,
        budget,
        t0.elapsed(),
        setup,
        timed,
        timed_steps,
        coarse,
    );
    let pace = Pace {
        step_s: Some(timed.as_secs_f64() / f64::from(timed_steps)),
        coarse_step_s: coarse.map(|(_, c)| c),
    };
    Ok((steps, Some(left), Some(pace)))
}

/// Whether the time-budget probe times one more step of a size, after `timed` steps took
/// `elapsed`: always up to [`PROBE_STEPS`], never beyond [`PROBE_MAX_STEPS`], and in between
/// while they have taken less than `enough` and the run, at their mean step time, `may_bind`
/// (could come near its budget).
fn keep_timing(
    timed: u32,
    elapsed: Duration,
    enough: Duration,
    may_bind: impl Fn(f64) -> bool,
) -> bool {
    timed < PROBE_MAX_STEPS
        && (timed < PROBE_STEPS
            || (elapsed < enough && may_bind(elapsed.as_secs_f64() / f64::from(timed))))
}

/// The schedule of a run about to start: with `scale_schedule` and densification, the steps the
/// densification schedule is scaled to ([`step_budget`]: timed probe steps under a time budget)
/// and the budget left after the probe; otherwise the configuration's own.
pub(super) fn plan(
    splats: &Splats,
    views: &Arc<Vec<View>>,
    tc: &TrainConfig,
    scale_schedule: bool,
    budget: Option<&BudgetConfig>,
) -> Result<Schedule, PipelineError> {
    let scaled = scale_schedule && tc.densify.is_some();
    // Rounds are placed at shares of the run's steps: under a time budget, the probe's estimate.
    let (steps, time_budget, pace) = if scaled || budget.is_some() {
        step_budget(splats, views, tc)?
    } else {
        (tc.iterations, tc.time_budget, None)
    };
    // The mean step of the planned run: its warm-up and full steps in their shares.
    let step_estimate_s = pace.and_then(|p| {
        let coarse = tc.warmup.zip(p.coarse_step_s);
        Some(splat_train::schedule::mean_step_s(
            p.step_s?,
            coarse.map(|(w, c)| (w.share(tc.iterations), c)),
        ))
    });
    Ok(Schedule {
        densify_steps: scaled.then_some(steps),
        time_budget: time_budget.or(tc.time_budget),
        budget: budget.and_then(|b| b.plan(steps)),
        step_estimate_s,
        pace,
    })
}

/// `tc` on `schedule`: the densification scaled to its steps, its time budget.
pub(super) fn scheduled_config(mut tc: TrainConfig, schedule: &Schedule) -> TrainConfig {
    if let (Some(steps), Some(d)) = (schedule.densify_steps, tc.densify) {
        tc.densify = Some(splat_train::schedule::scale_densify(
            &d,
            steps,
            tc.lr.opacity,
        ));
    }
    if schedule.time_budget.is_some() {
        tc.time_budget = schedule.time_budget;
    }
    tc
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Steps a probe times when each takes `step` and the run at that speed may bind or not.
    fn timed_steps(step: Duration, enough: Duration, binds: bool) -> u32 {
        let mut timed = 0;
        while keep_timing(timed, step * timed, enough, |s| {
            assert!((s - step.as_secs_f64()).abs() < 1e-9, "mean step {s}");
            binds
        }) {
            timed += 1;
        }
        timed
    }

    #[test]
    fn the_probe_times_more_steps_only_where_the_budget_may_bind() {
        let enough = Duration::from_secs(3);
        // Slow steps: the minimum either way, since four of them already take the share.
        let slow = Duration::from_secs(1);
        assert_eq!(timed_steps(slow, enough, true), PROBE_STEPS);
        assert_eq!(timed_steps(slow, enough, false), PROBE_STEPS);
        // 125 ms steps: timed until they have taken the share (24 of them), unless the run
        // fits easily.
        let paper = Duration::from_millis(125);
        assert_eq!(timed_steps(paper, enough, true), 24);
        assert_eq!(timed_steps(paper, enough, false), PROBE_STEPS);
        // Millisecond steps: capped.
        let fast = Duration::from_millis(1);
        assert_eq!(timed_steps(fast, enough, true), PROBE_MAX_STEPS);
        assert_eq!(timed_steps(fast, enough, false), PROBE_STEPS);
    }
}
