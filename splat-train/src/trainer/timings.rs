//! Where a run's time goes: each phase's wall time, and the steps timed at the model size a
//! time-budget probe measured.

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::schedule::Pace;

/// Wall time spent in each phase, summed over the steps of this session.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Timings {
    /// Forward rasterisation (projection, sorting, compositing).
    pub forward: Duration,
    /// Loss and its image gradient.
    pub loss: Duration,
    /// Backward rasterisation; without a densification strategy, up to its per-splat sums
    /// (the chain to the parameters then runs inside the update, chunk by chunk).
    pub backward: Duration,
    /// Adam updates, clamps and the non-finite scan; without a densification strategy, also the
    /// backward's chain to the parameters.
    pub adam: Duration,
    /// Refinement strategy.
    pub refine: Duration,
    /// Steps timed.
    pub steps: u64,
    /// Wall time of the steps run through [`Trainer::run_until`](crate::Trainer::run_until), each whole (as the time
    /// budget counts it), including those of branches a splat-budget round threw away.
    #[serde(default)]
    pub step_wall: Duration,
    /// The part of `step_wall` spent in steps of the coarse warm-up.
    #[serde(default)]
    pub coarse_wall: Duration,
    /// Steps of the coarse warm-up counted in `coarse_wall`.
    #[serde(default)]
    pub coarse_steps: u64,
    /// Steps counted in `step_wall`.
    #[serde(default)]
    pub walled_steps: u64,
    /// The part of `step_wall` spent at the model size the trainer was made with: what a probe
    /// that timed steps on that model is to be compared with, since a budget round or a
    /// refinement that changes the size changes the step's cost.
    #[serde(default)]
    pub at_initial_size: SizedSteps,
}

/// Wall time of the steps taken at one model size, the full-size and the warm-up's apart.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SizedSteps {
    /// The model's splat count.
    pub splats: u64,
    /// Wall time of the full-size steps at that count.
    pub full_wall: Duration,
    /// Full-size steps at that count.
    pub full_steps: u64,
    /// Wall time of the warm-up's steps at that count.
    pub coarse_wall: Duration,
    /// Warm-up steps at that count.
    pub coarse_steps: u64,
}

impl SizedSteps {
    /// Adds a step's wall time.
    pub(super) fn add(&mut self, wall: Duration, coarse: bool) {
        if coarse {
            self.coarse_wall += wall;
            self.coarse_steps += 1;
        } else {
            self.full_wall += wall;
            self.full_steps += 1;
        }
    }

    /// The mean wall seconds of each kind of step (`None` for a kind with no steps).
    #[must_use]
    pub fn mean_pace(&self) -> Pace {
        Pace {
            step_s: mean_seconds(self.full_wall, self.full_steps),
            coarse_step_s: mean_seconds(self.coarse_wall, self.coarse_steps),
        }
    }
}

/// `wall / steps` in seconds, `None` without steps.
fn mean_seconds(wall: Duration, steps: u64) -> Option<f64> {
    (steps > 0).then(|| wall.as_secs_f64() / steps as f64)
}

impl Timings {
    /// The mean wall seconds of the full-size steps and of the warm-up's steps run so far, as
    /// a [`Pace`] (a kind is `None` until one of its steps has run): what a probe's estimate
    /// is to be compared with.
    #[must_use]
    pub fn mean_pace(&self) -> Pace {
        Pace {
            step_s: mean_seconds(
                self.step_wall.saturating_sub(self.coarse_wall),
                self.walled_steps - self.coarse_steps.min(self.walled_steps),
            ),
            coarse_step_s: mean_seconds(self.coarse_wall, self.coarse_steps),
        }
    }
}
