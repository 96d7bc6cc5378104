//! Schedules: Inria's learning-rate and SH-degree schedules, its densification schedule scaled
//! to a run's length, the length of a time-budgeted run (estimated before it starts, then
//! re-estimated at every step by its [`Pace`]), and where a run pauses.

use std::time::Duration;

use crate::config::DensifyConfig;

/// Log-linear interpolation from `init` to `last` over `max_steps` (Inria's `get_expon_lr_func`
/// without the delay, which its trainer leaves inactive): lr(t) = exp((1−s)·ln init + s·ln last),
/// s = clamp(t / max_steps, 0, 1).
#[must_use]
pub fn exponential_lr(init: f32, last: f32, step: u32, max_steps: u32) -> f32 {
    if init <= 0.0 || last <= 0.0 {
        return 0.0;
    }
    let s = if max_steps == 0 {
        1.0
    } else {
        (step as f64 / f64::from(max_steps)).clamp(0.0, 1.0)
    };
    ((1.0 - s) * f64::from(init).ln() + s * f64::from(last).ln()).exp() as f32
}

/// Active SH degree at `iteration` (0-based): one more band every `interval` iterations up to
/// `max_degree` ("Every 1000 its we increase the levels of SH up to a maximum degree", Inria).
#[must_use]
pub fn sh_degree_at(iteration: u32, interval: u32, max_degree: u32) -> u32 {
    if interval == 0 {
        return max_degree;
    }
    (iteration / interval).min(max_degree)
}

/// Scene extent as Inria's `getNerfppNorm`: 1.1 × the largest distance of a camera centre from
/// the mean centre (a single camera gives 1.1 × 0, replaced by 1 so rates stay positive).
#[must_use]
pub fn camera_extent(centres: &[glam::DVec3]) -> f64 {
    if centres.is_empty() {
        return 1.0;
    }
    let mean = centres.iter().copied().sum::<glam::DVec3>() / centres.len() as f64;
    let r = centres.iter().map(|c| c.distance(mean)).fold(0.0, f64::max) * 1.1;
    if r > 0.0 && r.is_finite() { r } else { 1.0 }
}

/// Length of the run Inria's densification schedule is written for (`iterations` = 30,000).
pub const INRIA_ITERATIONS: f64 = 30_000.0;

/// Fewest steps between two densifications: the statistic that selects splats is a splat's
/// view-space gradient averaged over the steps since the last densification, and with one view
/// per step fewer than about ten views make it noise.
pub const MIN_DENSIFY_INTERVAL: u32 = 10;

/// Inria's densification schedule, written for 30,000 steps, scaled to a run of `steps` steps.
///
/// `start`, `interval`, `stop` and `opacity_reset_interval` are multiplied by `steps / 30,000`
/// (so 30,000 steps keep Inria's 500 / 100 / 15,000 / 3,000). Floors keep the result meaningful
/// for short runs: the interval is at least [`MIN_DENSIFY_INTERVAL`], `start` at least one
/// interval, `stop` after the first densification (which comes one interval after `start`), and
/// opacity resets are at least the steps Adam needs to bring a reset
/// opacity back: a reset sets opacity 0.01 (logit −4.6) and Adam moves a parameter by about its
/// learning rate per step, so climbing back to 0.5 takes 4.6 / `opacity_lr` steps (92 at Inria's
/// 0.05). Resets happen only before `stop`, so a run shorter than about twice that floor
/// densifies without them; the half of the run after `stop` leaves time to recover from the last.
/// The gradient and opacity thresholds are not changed.
#[must_use]
pub fn scale_densify(d: &DensifyConfig, steps: u32, opacity_lr: f32) -> DensifyConfig {
    let k = f64::from(steps) / INRIA_ITERATIONS;
    let scale = |v: u32| (f64::from(v) * k).round() as u32;
    let interval = scale(d.interval).max(MIN_DENSIFY_INTERVAL);
    let start = scale(d.start).max(interval);
    // Inria's reset clamps opacity to 0.01; climbing from its logit back to 0 (opacity 0.5).
    let reset_logit = (0.99f64 / 0.01).ln();
    let recovery = (reset_logit / f64::from(opacity_lr.max(1e-6))).ceil() as u32;
    let reset = if d.opacity_reset_interval == 0 {
        0
    } else {
        scale(d.opacity_reset_interval).max(recovery)
    };
    DensifyConfig {
        interval,
        start,
        stop: scale(d.stop).max(start + interval + 1),
        opacity_reset_interval: reset,
        ..*d
    }
}

/// The steps of a time-budgeted run, from steps timed on a probe before it starts.
///
/// `timed` is the time `timed_steps` steps took (after an untimed warm-up step), `spent` the whole
/// time the probe took (it comes out of the budget) and `setup` the part of it spent setting up,
/// which the real run spends again. With a coarse warm-up, `coarse` holds its share of the steps
/// and the seconds one of its steps took ([`steps_fitting`]). Returns the steps that fit in what
/// is left of `budget` at the timed speeds, at most `iterations` and at least 1, and what is left
/// of the budget.
#[must_use]
pub fn steps_in_budget(
    iterations: u32,
    budget: Duration,
    spent: Duration,
    setup: Duration,
    timed: Duration,
    timed_steps: u32,
    coarse: Option<(f64, f64)>,
) -> (u32, Duration) {
    let per_step = timed.as_secs_f64() / f64::from(timed_steps);
    let left = budget.saturating_sub(spent);
    let fit = steps_fitting(
        0,
        left.saturating_sub(setup).as_secs_f64(),
        per_step,
        coarse,
    );
    (
        iterations.min(fit.min(f64::from(u32::MAX)) as u32).max(1),
        left,
    )
}

/// Weight of the newest step in [`Pace`]'s moving average: the estimate follows a change of
/// speed (the machine getting busy, the model shrinking) within about ten steps, and one slow
/// step moves it by a tenth.
pub const PACE_SMOOTHING: f64 = 0.1;

/// How fast a time-budgeted run is going, and so how many steps its schedule spans.
///
/// A run with a time budget lays its schedules (learning-rate decay, SH bands, the coarse
/// warm-up) over the steps that fit in the budget rather than over its configured iteration
/// count, so that it ends with the schedule complete rather than stopped half-way. Those steps
/// are re-estimated after every step from the smoothed step time and the time left, so a run
/// that slows down (a busy machine, a budget round's discarded branch) ends its schedule sooner
/// and one that speeds up later; the run then ends within about a step of its budget.
///
/// A coarse warm-up's steps (reduced views) cost a fraction of a full step, so the two are
/// averaged apart and the horizon counts the warm-up's share of it at the coarse speed
/// ([`steps_fitting`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pace {
    /// Exponential moving average of the seconds a full-resolution step takes
    /// ([`PACE_SMOOTHING`]), once one has been timed.
    pub step_s: Option<f64>,
    /// The same for the warm-up's steps on reduced views.
    #[serde(default)]
    pub coarse_step_s: Option<f64>,
}

/// A warm-up as the [`Pace`] sees it: the share of the schedule's steps it spans and how much
/// its views are reduced.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WarmupShare {
    /// Warm-up steps over the schedule's steps, in [0, 1].
    pub share: f64,
    /// Reduction factor of the image sides (≥ 2).
    pub factor: u32,
}

impl Pace {
    /// Takes one more step's time into the average of its kind (`coarse`: a warm-up step).
    pub fn observe(&mut self, step_s: f64, coarse: bool) {
        if !(step_s.is_finite() && step_s >= 0.0) {
            return;
        }
        let avg = if coarse {
            &mut self.coarse_step_s
        } else {
            &mut self.step_s
        };
        *avg = Some(match *avg {
            Some(avg) => avg + PACE_SMOOTHING * (step_s - avg),
            None => step_s,
        });
    }

    /// The steps the run's schedule spans: `done` plus the steps that fit in what is left of
    /// `budget_s` after `elapsed_s` ([`steps_fitting`]), at most `iterations`; `iterations`
    /// until a step has been timed.
    ///
    /// With a `warmup` still to finish, a speed not yet timed is guessed from the other: a
    /// full step as the coarse one times the factor² pixels (more than it costs, since the
    /// per-splat work does not shrink with the views, so the guess errs short), a coarse step
    /// as a full one.
    #[must_use]
    pub fn horizon(
        &self,
        iterations: u32,
        done: u32,
        elapsed_s: f64,
        budget_s: f64,
        warmup: Option<WarmupShare>,
    ) -> u32 {
        let (full_s, coarse) = match (self.step_s, warmup) {
            (None, None) => return iterations,
            (Some(f), None) => (f, None),
            (f, Some(w)) => {
                let pixels = f64::from(w.factor).powi(2);
                let (full_s, coarse_s) = match (f, self.coarse_step_s) {
                    (None, None) => return iterations,
                    (Some(f), None) => (f, f),
                    (None, Some(c)) => (c * pixels, c),
                    (Some(f), Some(c)) => (f, c),
                };
                (full_s, Some((w.share, coarse_s)))
            }
        };
        let left = (budget_s - elapsed_s).max(0.0);
        let fit = steps_fitting(done, left, full_s, coarse).min(f64::from(u32::MAX));
        iterations.min(fit as u32).max(done.min(iterations))
    }
}

/// The mean seconds a step of a run whose steps take `full_s`, or with `coarse = Some((share,
/// coarse_s))` whose first `share` of the steps are a warm-up at `coarse_s` a step.
#[must_use]
pub fn mean_step_s(full_s: f64, coarse: Option<(f64, f64)>) -> f64 {
    coarse.map_or(full_s, |(share, coarse_s)| {
        share * coarse_s + (1.0 - share) * full_s
    })
}

/// The most steps H a run that has done `done` can plan when `left_s` seconds remain, a
/// full-resolution step takes `full_s` and, with `coarse = Some((share, coarse_s))`, the first
/// `share`·H steps are a warm-up at `coarse_s` a step (floored).
///
/// While the warm-up is not over (`done` < share·H) the time left pays for share·H − `done`
/// coarse steps and (1 − share)·H full ones: H = (left + done·coarse) / (share·coarse +
/// (1 − share)·full). Once it is over, every step left is a full one: H = done + left / full.
#[must_use]
pub fn steps_fitting(done: u32, left_s: f64, full_s: f64, coarse: Option<(f64, f64)>) -> f64 {
    let d = f64::from(done);
    let after_warmup = d + left_s / full_s.max(1e-9);
    let Some((share, coarse_s)) = coarse else {
        return after_warmup.floor();
    };
    let per_step = mean_step_s(full_s, Some((share, coarse_s)));
    let during = (left_s + d * coarse_s) / per_step.max(1e-9);
    if share * during > d {
        during.floor()
    } else {
        after_warmup.floor()
    }
}

/// `steps` of a schedule written for `iterations` steps, stretched over `horizon` steps
/// (rounded; a positive count stays at least 1, 0 stays 0).
#[must_use]
pub fn scale_steps(steps: u32, horizon: u32, iterations: u32) -> u32 {
    if steps == 0 || horizon >= iterations || iterations == 0 {
        return steps;
    }
    ((f64::from(steps) * f64::from(horizon) / f64::from(iterations)).round() as u32).max(1)
}

/// The next step count at which a run that has done `done` of `total` steps pauses: the next
/// multiple of `every_a` or of `every_b` (0: never), or the end.
#[must_use]
pub fn next_stop(done: u32, total: u32, every_a: u32, every_b: u32) -> u32 {
    let next = |k: u32| {
        done.checked_div(k)
            .map_or(total, |q| (q + 1).saturating_mul(k))
    };
    next(every_a).min(next(every_b)).min(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pace_averages_step_times_and_ignores_nonsense() {
        let mut p = Pace::default();
        assert_eq!(
            p.horizon(3000, 0, 0.0, 60.0, None),
            3000,
            "untimed: the configured count"
        );
        p.observe(0.05, false);
        assert_eq!(p.step_s, Some(0.05));
        p.observe(0.15, false);
        assert!((p.step_s.unwrap() - 0.06).abs() < 1e-12);
        p.observe(f64::NAN, false);
        p.observe(-1.0, false);
        assert!((p.step_s.unwrap() - 0.06).abs() < 1e-12);
        // Warm-up steps have their own average.
        p.observe(0.01, true);
        assert_eq!(
            (p.step_s.map(|s| (s * 1e6).round()), p.coarse_step_s),
            (Some(60_000.0), Some(0.01))
        );
    }

    #[test]
    fn the_horizon_is_the_steps_that_fit_in_the_time_left() {
        let p = Pace {
            step_s: Some(0.05),
            coarse_step_s: None,
        };
        // 50 s left at 0.05 s a step: 1,000 more steps.
        assert_eq!(p.horizon(3000, 200, 10.0, 60.0, None), 1200);
        // Capped at the configured count.
        assert_eq!(p.horizon(1000, 200, 10.0, 60.0, None), 1000);
        // Out of time: the schedule ends where the run is.
        assert_eq!(p.horizon(3000, 700, 61.0, 60.0, None), 700);
        // A slower machine shortens it.
        let slow = Pace {
            step_s: Some(0.1),
            coarse_step_s: None,
        };
        assert_eq!(slow.horizon(3000, 200, 10.0, 60.0, None), 700);
    }

    #[test]
    fn a_busy_machine_shrinks_the_horizon_and_the_run_ends_on_budget() {
        // Simulated clock: 20 ms steps that become 60 ms at t = 10 s; the run takes a step
        // while it is short of its horizon, which is re-estimated after each step.
        let (budget, iterations) = (30.0, 100_000);
        let mut pace = Pace::default();
        let (mut t, mut done) = (0.0_f64, 0_u32);
        while done < pace.horizon(iterations, done, t, budget, None) && t < budget {
            let step = if t < 10.0 { 0.02 } else { 0.06 };
            t += step;
            done += 1;
            pace.observe(step, false);
        }
        assert!(
            (t - budget).abs() <= 0.06 + 1e-9,
            "ended at {t} s of {budget}"
        );
        // 500 fast steps, then 20 s of slow ones.
        assert!(
            (done as f64 - (500.0 + 20.0 / 0.06)).abs() <= 2.0,
            "{done} steps"
        );
    }

    #[test]
    fn steps_fitting_counts_the_warmup_at_its_own_speed() {
        // No warm-up: 50 s at 0.05 s a step after 200 steps.
        assert_eq!(steps_fitting(200, 50.0, 0.05, None), 1200.0);
        // A quarter of the steps at 0.01 s, the rest at 0.04 s, 30 s from the start:
        // 30 / (0.25 · 0.01 + 0.75 · 0.04) = 923.08.
        assert_eq!(steps_fitting(0, 30.0, 0.04, Some((0.25, 0.01))), 923.0);
        // 100 coarse steps done (1 s), 29 s left: the same plan.
        assert_eq!(steps_fitting(100, 29.0, 0.04, Some((0.25, 0.01))), 923.0);
        // Past the warm-up every step left is a full one: 400 done, 20 s left.
        assert_eq!(steps_fitting(400, 20.0, 0.04, Some((0.25, 0.01))), 900.0);
        // All warm-up: the coarse speed alone.
        assert_eq!(steps_fitting(0, 10.0, 0.04, Some((1.0, 0.01))), 1000.0);
    }

    #[test]
    fn a_warmup_run_ends_on_budget_with_its_share_of_coarse_steps() {
        // Simulated clock: coarse steps 10 ms, full ones 40 ms; a step is coarse while the run
        // is short of a quarter of its horizon (and never again once a full one has run, as
        // the trainer does), the horizon re-estimated after each step.
        let (budget, iterations) = (30.0, 100_000);
        let warmup = Some(WarmupShare {
            share: 0.25,
            factor: 2,
        });
        let mut pace = Pace::default();
        let (mut t, mut done, mut coarse_steps, mut over) = (0.0_f64, 0_u32, 0_u32, false);
        loop {
            let horizon = pace.horizon(iterations, done, t, budget, warmup);
            if done >= horizon || t >= budget {
                break;
            }
            let coarse = !over && f64::from(done + 1) <= 0.25 * f64::from(horizon);
            over |= !coarse;
            let step = if coarse { 0.01 } else { 0.04 };
            t += step;
            done += 1;
            coarse_steps += u32::from(coarse);
            pace.observe(step, coarse);
        }
        assert!(
            (t - budget).abs() <= 0.04 + 1e-9,
            "ended at {t} s of {budget}"
        );
        // The closed form: 30 / (0.25 · 0.01 + 0.75 · 0.04) = 923 steps, 231 of them coarse.
        assert!((f64::from(done) - 923.0).abs() <= 2.0, "{done} steps");
        assert!(
            (f64::from(coarse_steps) - 231.0).abs() <= 2.0,
            "{coarse_steps} coarse steps"
        );
    }

    #[test]
    fn schedules_stretch_with_the_horizon() {
        assert_eq!(scale_steps(1000, 1500, 3000), 500);
        assert_eq!(scale_steps(1000, 3000, 3000), 1000);
        assert_eq!(scale_steps(1000, 4000, 3000), 1000);
        assert_eq!(scale_steps(0, 10, 3000), 0);
        assert_eq!(scale_steps(1, 10, 3000), 1);
    }

    #[test]
    fn densify_schedule_scales_to_the_step_budget() {
        let inria = DensifyConfig::default();
        // 30,000 steps keep Inria's schedule.
        assert_eq!(scale_densify(&inria, 30_000, 0.05), inria);
        // 3,000 steps: a tenth of every step count.
        let d = scale_densify(&inria, 3_000, 0.05);
        assert_eq!(
            (d.start, d.interval, d.stop, d.opacity_reset_interval),
            (50, 10, 1_500, 300)
        );
        assert_eq!(d.grad_threshold, inria.grad_threshold);
        // 300 steps: the interval floor (10), start one interval in, stop at half the run, and
        // resets no more often than Adam needs to restore a reset opacity: ⌈4.6 / 0.05⌉ = 92.
        let d = scale_densify(&inria, 300, 0.05);
        assert_eq!(
            (d.start, d.interval, d.stop, d.opacity_reset_interval),
            (10, 10, 150, 92)
        );
        // A short run still densifies once: the trainer densifies at multiples of the interval
        // after `start` and before `stop`.
        let d = scale_densify(&inria, 5, 0.05);
        assert_eq!((d.start, d.interval, d.stop), (10, 10, 21));
        assert_eq!(
            (d.start + 1..d.stop)
                .filter(|i| i % d.interval == 0)
                .count(),
            1
        );
        // Resets stay off when they were off.
        let none = DensifyConfig {
            opacity_reset_interval: 0,
            ..inria
        };
        assert_eq!(scale_densify(&none, 300, 0.05).opacity_reset_interval, 0);
    }

    #[test]
    fn budgeted_steps_fit_what_is_left() {
        let s = Duration::from_secs;
        let ms = Duration::from_millis;
        // 4 steps in 2 s: 0.5 s a step. 100 s budget, 3 s spent by the probe, 1 s of which was
        // setup: 97 s left, 96 s of it for steps → 192 steps.
        assert_eq!(
            steps_in_budget(10_000, s(100), s(3), s(1), s(2), 4, None),
            (192, s(97))
        );
        // The first quarter a warm-up at 0.125 s a step: 96 / (0.25 · 0.125 + 0.75 · 0.5) = 236.3.
        assert_eq!(
            steps_in_budget(10_000, s(100), s(3), s(1), s(2), 4, Some((0.25, 0.125))),
            (236, s(97))
        );
        // Never more than asked for, never fewer than one.
        assert_eq!(
            steps_in_budget(50, s(100), s(3), s(1), s(2), 4, None),
            (50, s(97))
        );
        assert_eq!(
            steps_in_budget(50, s(1), s(3), s(1), s(2), 4, None),
            (1, Duration::ZERO)
        );
        // Steps too fast to time still give a finite count, capped at `iterations`.
        assert_eq!(
            steps_in_budget(u32::MAX, s(10), ms(1), ms(0), Duration::ZERO, 4, None).0,
            u32::MAX
        );
    }

    #[test]
    fn runs_pause_at_multiples_and_at_the_end() {
        // Evaluate every 100, checkpoint every 30: pauses at 30, 60, 90, 100, 120, ….
        assert_eq!(next_stop(0, 1000, 100, 30), 30);
        assert_eq!(next_stop(90, 1000, 100, 30), 100);
        assert_eq!(next_stop(100, 1000, 100, 30), 120);
        // 0 means never: only the other interval or the end.
        assert_eq!(next_stop(0, 1000, 0, 30), 30);
        assert_eq!(next_stop(0, 1000, 0, 0), 1000);
        // Never past the end, and no overflow near u32::MAX.
        assert_eq!(next_stop(990, 1000, 100, 0), 1000);
        assert_eq!(next_stop(u32::MAX - 1, u32::MAX, u32::MAX - 1, 0), u32::MAX);
    }

    #[test]
    fn lr_endpoints_and_midpoint_are_geometric() {
        assert!((exponential_lr(1.6e-4, 1.6e-6, 0, 100) - 1.6e-4).abs() < 1e-10);
        assert!((exponential_lr(1.6e-4, 1.6e-6, 100, 100) - 1.6e-6).abs() < 1e-12);
        assert!((exponential_lr(1.6e-4, 1.6e-6, 500, 100) - 1.6e-6).abs() < 1e-12);
        assert!((exponential_lr(1.6e-4, 1.6e-6, 50, 100) - 1.6e-5).abs() < 1e-10);
    }

    #[test]
    fn sh_degree_steps() {
        assert_eq!(sh_degree_at(0, 1000, 3), 0);
        assert_eq!(sh_degree_at(999, 1000, 3), 0);
        assert_eq!(sh_degree_at(1000, 1000, 3), 1);
        assert_eq!(sh_degree_at(9000, 1000, 3), 3);
        assert_eq!(sh_degree_at(5, 0, 2), 2);
    }

    #[test]
    fn extent_of_ring() {
        let c = [
            glam::DVec3::X,
            -glam::DVec3::X,
            glam::DVec3::Y * 2.0,
            -glam::DVec3::Y * 2.0,
        ];
        assert!((camera_extent(&c) - 2.2).abs() < 1e-12);
    }
}
