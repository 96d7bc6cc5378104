//! The automatic splat budget: train, score every splat by what it contributes to the training
//! views, prune the least important, continue, and stop at the smallest model whose held-out
//! quality stays within a tolerance of the full model's.
//!
//! A round is an experiment with a control. From the same trained state the model is trained
//! [`BudgetPlan::trial`] steps twice: once whole (the control) and once with the lower-scoring
//! share of its splats removed. Both branches are scored on the held-out views at the same steps
//! (where a time budget binds the schedule: the same training times), [`SCORE_POINTS`] times
//! over the trial's last quarter, so the round measures what the pruning costs and not what
//! the extra steps gained, above the step-to-step noise of a single score. The pruned
//! branch is kept while the drops of the accepted rounds add up to no more than
//! [`BudgetConfig::tolerance_db`]; a round that would exceed it is undone (training goes on from
//! the control) and the next round tries to remove half as many splats
//! ([`BudgetSearch::next_keep`]), until [`MAX_REFUSED_ROUNDS`] were refused. A merged branch
//! recovers for long after its merge, so a round refused near the tolerance trains both
//! branches on and is judged again ([`BudgetConfig::second_look_within`]), and if still refused
//! near it, at the end of the run ([`BudgetConfig::final_look_within`]). The thrown-away
//! branch's time still counts against the run's time budget.
//!
//! What a merge costs is its members' contributions (the blending weight each supplies, summed
//! over the pixels of every training view: Mini-Splatting's importance) times how far their
//! colours are from the merged one ([`plan_merges`]), so flat regions end with few large splats
//! and detailed or glossy ones keep many. The search is here; the merges (which groups, and the
//! Gaussian that replaces each) are in `budget/merge.rs`, the groups' growth in
//! `budget/clusters.rs` and the 3 × 3 eigen-decomposition both use in `budget/eigen.rs`.

use serde::{Deserialize, Serialize};
use std::time::Instant;

use splat_core::Splats;

use crate::trainer::{Snapshot, Trainer};

mod clusters;
mod eigen;
mod merge;

pub use merge::{Merges, merge_group, plan_merges};

/// A round that could not go on: the trainer refused to prune or to return to a branch.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("splat budget round at step {iteration}: {problem}")]
pub struct RoundError {
    /// The step the round started at.
    pub iteration: u32,
    /// What failed.
    pub problem: String,
}

/// Settings of the automatic splat budget (the transcoder's `[budget]` table).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BudgetConfig {
    /// Search for the smallest model within `tolerance_db` of the full one (`--splats auto`);
    /// false keeps every initial splat.
    pub auto: bool,
    /// The held-out PSNR (dB, as the round's scorer measures it: the pipeline's is
    /// [`crate::Metrics::psnr_both`]) the pruning may cost in all, against the full model
    /// trained for the same steps: the accepted rounds' costs summed with their signs
    /// ([`BudgetSearch::spent_db`]), so a round that gained leaves more to the next.
    pub tolerance_db: f64,
    /// The first round starts after this share of the run's planned steps.
    pub start_share: f64,
    /// Each branch of a round trains this share of the planned steps.
    pub trial_share: f64,
    /// The fewest steps a branch trains, so a prune can heal before it is judged.
    pub min_trial_steps: u32,
    /// Runs planned for fewer steps do not search (too short to heal a prune and judge it).
    pub min_run_steps: u32,
    /// Rounds end by this share of the planned steps, leaving the rest to train the chosen model.
    pub end_share: f64,
    /// The share of the splats a round keeps.
    pub keep: f64,
    /// The most rounds (the smallest model is `keep`^`max_rounds` of the initial one).
    pub max_rounds: u32,
    /// No round prunes below this many splats.
    pub min_splats: usize,
    /// The longest a merged group may be ([`plan_merges`]): the standard deviation of its
    /// member positions along its longest axis, in median nearest-neighbour spacings. Longer
    /// lets one round merge a flat region into fewer, larger splats.
    pub merge_reach: f32,
    /// A refused round whose cost is at most this many times what is left of `tolerance_db`
    /// trains both branches on for `second_look_trials` trials and is judged again on that,
    /// where the rounds' steps (up to `end_share`) leave room for it (0: never). A merged
    /// branch is still recovering at the end of its first trial: the demo's quarter cost
    /// 0.44 dB there, 0.28 one trial later, 0.16 two trials later and 0.11–0.18 at the end of
    /// the run (docs/benchmarks/budget.md §Session 40).
    pub second_look_within: f64,
    /// How many trials (of `trial_share`) a second look trains both branches on for, scored
    /// over the last quarter of them.
    pub second_look_trials: u32,
    /// A round refused at its second look at a cost of at most this many times what is left of
    /// `tolerance_db` trains both branches on to the end of the run and is decided there (0:
    /// never), where the time budget, if any, holds both: the merged branch goes on recovering
    /// for most of the rest of the run. The demo's quarter costs 0.20–0.30 dB at its second
    /// look across seeds, against a tolerance of 0.25, and nothing by the run's end against a
    /// whole model with the same warm-up (docs/benchmarks/budget.md §Session 64). The search
    /// ends with such a round, whichever branch it keeps.
    pub final_look_within: f64,
    /// Once accepted rounds have spent some of `tolerance_db`, the search ends when less than
    /// this is left (dB): a round's measured cost moves by about as much with the steps it is
    /// scored at, so such a round would be decided by that noise, and it costs a trial of
    /// training thrown away either way.
    pub least_left_db: f64,
    /// Whether a round that cannot cost less than what is left of `tolerance_db`
    /// ([`BudgetSearch::cost_floor`]), or whose first look cannot cost little enough to be
    /// looked at again ([`BudgetSearch::first_look_floor`] over `second_look_within` times what
    /// is left), is skipped without training its branches: it counts as refused, and the next,
    /// gentler merge is tried in its place.
    pub skip_hopeless: bool,
    /// After training: the held-out PSNR (dB) dropping SH bands may cost, within what the rounds
    /// left of `tolerance_db` ([`crate::sh_bands::choose_bands`]).
    pub bands_tolerance_db: f64,
    /// After training: splats whose bands above 0 add less than this RMS colour (0–1 units) over
    /// all view directions lose them.
    pub static_sh_rms: f32,
    /// Initial splats per covered pixel of the mean training view: a cloud denser than that is
    /// voxel-merged to it before training (a splat smaller than a pixel in every view cannot be
    /// told from its neighbours).
    pub splats_per_pixel: f64,
}

impl Default for BudgetConfig {
    fn default() -> Self {
        Self {
            auto: true,
            tolerance_db: 0.25,
            start_share: 0.25,
            trial_share: 0.08,
            min_trial_steps: 50,
            min_run_steps: 500,
            end_share: 0.65,
            keep: 0.5,
            max_rounds: 4,
            min_splats: 256,
            merge_reach: 7.0,
            splats_per_pixel: 2.0,
            least_left_db: 0.05,
            second_look_within: 2.0,
            second_look_trials: 2,
            final_look_within: 2.0,
            skip_hopeless: true,
            bands_tolerance_db: 0.05,
            static_sh_rms: 0.002,
        }
    }
}

impl BudgetConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// The offending key (`budget.…`) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |k: &str, m: &str| Err((format!("budget.{k}"), m.to_string()));
        if !(self.tolerance_db.is_finite() && self.tolerance_db >= 0.0) {
            return bad("tolerance_db", "must be a finite number ≥ 0");
        }
        if !(self.keep > 0.0 && self.keep < 1.0) {
            return bad("keep", "must be between 0 and 1 (exclusive)");
        }
        for (k, v) in [
            ("start_share", self.start_share),
            ("trial_share", self.trial_share),
            ("end_share", self.end_share),
        ] {
            if !(v > 0.0 && v < 1.0) {
                return bad(k, "must be between 0 and 1 (exclusive)");
            }
        }
        if self.start_share + self.trial_share > self.end_share {
            return bad(
                "end_share",
                "must leave room for one round after start_share (start_share + trial_share ≤ end_share)",
            );
        }
        if !(self.bands_tolerance_db.is_finite() && self.bands_tolerance_db >= 0.0) {
            return bad("bands_tolerance_db", "must be a finite number ≥ 0");
        }
        if !(self.second_look_within.is_finite() && self.second_look_within >= 0.0) {
            return bad("second_look_within", "must be a finite number ≥ 0");
        }
        if self.second_look_trials == 0 {
            return bad("second_look_trials", "must be at least 1");
        }
        if !(self.final_look_within.is_finite() && self.final_look_within >= 0.0) {
            return bad("final_look_within", "must be a finite number ≥ 0");
        }
        if !(self.least_left_db.is_finite() && self.least_left_db >= 0.0) {
            return bad("least_left_db", "must be a finite number ≥ 0");
        }
        if !(self.static_sh_rms.is_finite() && self.static_sh_rms >= 0.0) {
            return bad("static_sh_rms", "must be a finite number ≥ 0");
        }
        if !(self.splats_per_pixel.is_finite() && self.splats_per_pixel > 0.0) {
            return bad("splats_per_pixel", "must be a finite number > 0");
        }
        if !(self.merge_reach.is_finite() && self.merge_reach > 0.0) {
            return bad("merge_reach", "must be a finite number > 0");
        }
        Ok(())
    }

    /// When rounds run in a run of `steps` planned steps; `None` when the search is off or the
    /// run is too short to hold one round.
    #[must_use]
    pub fn plan(&self, steps: u32) -> Option<BudgetPlan> {
        if !self.auto || self.max_rounds == 0 || steps < self.min_run_steps {
            return None;
        }
        let share = |s: f64| (s * f64::from(steps)).round() as u32;
        let first = share(self.start_share);
        let trial = share(self.trial_share).max(self.min_trial_steps);
        let end = share(self.end_share);
        let rounds = ((end.saturating_sub(first)) / trial).min(self.max_rounds);
        (rounds > 0).then_some(BudgetPlan {
            first,
            trial,
            rounds,
        })
    }

    /// The initial splat count for `points` input points when the mean training view covers
    /// `covered_pixels` pixels and at most `asked` were asked for (`--splats K`): the points, or
    /// fewer when they outnumber what was asked or, with the search on, the pixels. What was
    /// asked caps the start and never raises it: splats beyond what the views can tell apart
    /// are training time spent for nothing.
    #[must_use]
    pub fn start_splats(&self, points: usize, covered_pixels: f64, asked: Option<usize>) -> usize {
        let points = asked.map_or(points, |k| k.min(points));
        if !self.auto {
            return points;
        }
        let cap = (self.splats_per_pixel * covered_pixels).round().max(1.0) as usize;
        points.min(cap.max(self.min_splats))
    }
}

/// The steps at which a run's rounds start.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct BudgetPlan {
    /// The first round starts after this many steps.
    pub first: u32,
    /// Steps each branch of a round trains; round r starts at `first + r · trial`.
    pub trial: u32,
    /// The most rounds that fit.
    pub rounds: u32,
}

impl BudgetPlan {
    /// The step at which round `r` (0-based) starts.
    #[must_use]
    pub fn start_of(&self, r: u32) -> u32 {
        self.first + r * self.trial
    }
}

/// A model's held-out PSNR (dB) on a black and on a white background: what a round scores its
/// two branches by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldoutPsnr {
    /// On black.
    pub black: f64,
    /// On white.
    pub white: f64,
}

/// What one round measured and decided.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BudgetRound {
    /// The step the round started at.
    pub iteration: u32,
    /// Splats before the round.
    pub splats: usize,
    /// Splats the pruned branch kept.
    pub candidate: usize,
    /// Held-out PSNR (dB, on black) of the whole model over the trial's last quarter (the mean
    /// of [`SCORE_POINTS`] scores).
    pub kept_psnr: f64,
    /// Held-out PSNR (dB, on black) of the pruned model over the same steps or, where a time
    /// budget binds the schedule, the same training times (`None`: the control ran out of time
    /// and the pruned branch did not run).
    pub pruned_psnr: Option<f64>,
    /// [`BudgetRound::kept_psnr`] on white (`None` in rounds saved before it was measured).
    #[serde(default)]
    pub kept_psnr_white: Option<f64>,
    /// [`BudgetRound::pruned_psnr`] on white.
    #[serde(default)]
    pub pruned_psnr_white: Option<f64>,
    /// Whether the pruned branch was kept.
    pub accepted: bool,
    /// Whether a branch was cut short by the time budget (the round then decides nothing).
    pub out_of_time: bool,
    /// Steps the pruned branch trained: `BudgetPlan::trial`, or more where a time budget binds
    /// the schedule and both branches train for the same time.
    #[serde(default)]
    pub steps_pruned: u32,
    /// The cost ([`BudgetRound::drop_db`]) at the end of the first trial, when the round was
    /// looked at again ([`BudgetConfig::second_look_within`]): the PSNR fields and the decision
    /// are then the second look's, after `second_look_trials` more trials of both branches.
    /// `None`: one look.
    #[serde(default)]
    pub first_look_db: Option<f64>,
    /// The cost at the end of the second look, when the round was then decided at the end of
    /// the run ([`BudgetConfig::final_look_within`]): the PSNR fields and the decision are then
    /// the final look's. `None`: decided before the run's end.
    #[serde(default)]
    pub second_look_db: Option<f64>,
    /// Where the round's wall time went (zero in rounds saved before it was measured).
    #[serde(default)]
    pub seconds: RoundSeconds,
}

/// The wall time of one round, by what it was spent on (seconds).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RoundSeconds {
    /// Scoring every splat's contribution, planning the merges and applying them (with the
    /// snapshots the branches start from and, when the merge is refused, going back).
    pub planning: f64,
    /// The control branch's training steps (the trainer's clock).
    pub control: f64,
    /// The merged branch's training steps (the trainer's clock).
    pub merged: f64,
    /// Scoring both branches on the held-out views.
    pub scoring: f64,
}

impl RoundSeconds {
    /// The whole round.
    #[must_use]
    pub fn total(&self) -> f64 {
        self.planning + self.control + self.merged + self.scoring
    }

    /// The round's time outside the branches' steps (planning and scoring), which the round
    /// counts on the trainer's clock as it goes ([`crate::Trainer::count_time_between_steps`]).
    #[must_use]
    pub fn between_steps(&self) -> f64 {
        self.planning + self.scoring
    }
}

impl BudgetRound {
    /// Takes the branches' mean held-out scores (the control's, where given); a branch scored
    /// at no point leaves its fields as they were.
    fn take_scores(&mut self, kept: Option<&Scores>, pruned: &Scores) {
        if let Some(kept) = kept.filter(|k| k.count > 0) {
            let k = kept.mean();
            self.kept_psnr = k.black;
            self.kept_psnr_white = Some(k.white);
        }
        if pruned.count > 0 {
            let p = pruned.mean();
            self.pruned_psnr = Some(p.black);
            self.pruned_psnr_white = Some(p.white);
        }
    }

    /// The training time of the branch the round threw away: the control's when the merged
    /// branch was kept, the merged branch's when it was refused (none when the control ran out
    /// of time: training goes on from it).
    #[must_use]
    pub fn discarded_seconds(&self) -> f64 {
        if self.accepted {
            self.seconds.control
        } else {
            self.seconds.merged
        }
    }

    /// What the pruning cost (dB): the larger of its costs on black and on white, so that no
    /// background loses more than the search allows (a merge can sharpen a dark object's
    /// silhouettes, which only white shows, while blurring its texture, which black shows);
    /// negative when the pruned branch scored higher on both; `None` when it did not run.
    #[must_use]
    pub fn drop_db(&self) -> Option<f64> {
        let black = self.pruned_psnr.map(|p| self.kept_psnr - p)?;
        match (self.kept_psnr_white, self.pruned_psnr_white) {
            (Some(k), Some(p)) => Some(black.max(k - p)),
            _ => Some(black),
        }
    }
}

/// The state of a search over a run: its plan and the rounds done.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BudgetSearch {
    /// When rounds run; `None`: no search.
    pub plan: Option<BudgetPlan>,
    /// The rounds done, in order.
    pub rounds: Vec<BudgetRound>,
    /// Whether a round found nothing left to merge (the search is then over).
    #[serde(default)]
    pub exhausted: bool,
    /// Whether the accepted rounds left less than [`BudgetConfig::least_left_db`] of the
    /// tolerance (the search is then over).
    #[serde(default)]
    pub tolerance_spent: bool,
    /// Whether a time budget had too little left for the next round's two branches when it was
    /// due (the search is then over, and training goes on without it).
    #[serde(default)]
    pub no_time_left: bool,
    /// Merges not tried because they could not have cost less than what was left of the
    /// tolerance ([`BudgetConfig::skip_hopeless`]); each counts as a refused round.
    #[serde(default)]
    pub skipped: Vec<SkippedRound>,
}

/// A merge the search did not try: the least it could have cost, from the rounds before it,
/// was more than what was left of the tolerance.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SkippedRound {
    /// The step at which it was due.
    pub iteration: u32,
    /// The share of the splats it would have kept.
    pub keep: f64,
    /// The least it could have cost (dB): [`BudgetSearch::cost_floor`].
    pub floor_db: f64,
    /// The least its first look could have cost (dB): [`BudgetSearch::first_look_floor`].
    #[serde(default)]
    pub first_look_floor_db: f64,
    /// What was left of the tolerance (dB).
    pub left_db: f64,
}

/// The least share of a refused (or skipped) merge's cost that the next, gentler one (half as
/// many splats removed) has cost: measured 0.30–0.68 (the spider frame's 124,627 → 62,313 at
/// 0.299 dB, then → 93,469 at 0.204; 62,313 → 31,157 at 0.836, then → 46,733 at 0.260; the
/// demo's 15,703 → 7,851 at 1.2–1.5, then → 11,776 at 0.36–0.51, then → 13,740 at 0.07–0.16;
/// docs/benchmarks/budget.md §Session 36).
pub const GENTLER_COST_SHARE: f64 = 0.25;

impl BudgetSearch {
    /// The total cost of the accepted rounds (dB), gains included: each round is scored
    /// against its control, the model before it, so the sum is the model's distance from the
    /// whole one.
    #[must_use]
    pub fn spent_db(&self) -> f64 {
        self.rounds
            .iter()
            .filter(|r| r.accepted)
            .filter_map(|r| r.drop_db())
            .sum()
    }

    /// What the accepted rounds leave of `tolerance_db` (dB; more than it where they gained).
    #[must_use]
    pub fn left_db(&self, tolerance_db: f64) -> f64 {
        tolerance_db - self.spent_db()
    }

    /// Whether no more rounds will run: no plan, all planned rounds done, nothing left to
    /// merge, too little of the tolerance left, a round ran out of time, had no time left to
    /// start or was decided at the run's end, or [`MAX_REFUSED_ROUNDS`] rounds were refused.
    #[must_use]
    pub fn finished(&self) -> bool {
        let Some(plan) = self.plan else { return true };
        self.exhausted
            || self.tolerance_spent
            || self.no_time_left
            || self.rounds.len() as u32 >= plan.rounds
            || self
                .rounds
                .last()
                .is_some_and(|r| r.out_of_time || r.second_look_db.is_some())
            || self.refused() >= MAX_REFUSED_ROUNDS
    }

    /// Rounds whose pruned branch was measured and refused, and merges skipped as hopeless.
    fn refused(&self) -> u32 {
        let measured = self
            .rounds
            .iter()
            .filter(|r| !r.accepted && !r.out_of_time)
            .count();
        (measured + self.skipped.len()) as u32
    }

    /// The least the next round can cost (dB), from the last try: a merge as large as an
    /// accepted one costs at least what that one did, since it takes as many splats from a
    /// model that has fewer (every such pair measured: −0.223 → +0.190 → +0.836, −0.055 →
    /// +0.299, −0.178 → +0.213 dB); a gentler merge after a refused or skipped one at least
    /// [`GENTLER_COST_SHARE`] of that one's cost (or floor). Zero with no try before it.
    #[must_use]
    pub fn cost_floor(&self) -> f64 {
        self.floor_of(BudgetRound::drop_db, |s| s.floor_db)
    }

    /// The least the next round's first look can cost (dB): [`BudgetSearch::cost_floor`] from
    /// the first looks of the tries before it that had two (it is first looked at as soon
    /// after its merge as they were).
    #[must_use]
    pub fn first_look_floor(&self) -> f64 {
        self.floor_of(
            |r| r.first_look_db.or(r.drop_db()),
            |s| s.first_look_floor_db.max(s.floor_db),
        )
    }

    /// The cost floor from the last try, its cost taken by `cost` (a round) or `skip_floor` (a
    /// skipped merge).
    fn floor_of(
        &self,
        cost: impl Fn(&BudgetRound) -> Option<f64>,
        skip_floor: impl Fn(&SkippedRound) -> f64,
    ) -> f64 {
        let last_round = self.rounds.last();
        // A skip at a round's step comes before that round (the round is tried in its place).
        if let Some(skip) = self
            .skipped
            .last()
            .filter(|s| last_round.is_none_or(|r| s.iteration > r.iteration))
        {
            return GENTLER_COST_SHARE * skip_floor(skip);
        }
        match last_round {
            Some(r) if !r.out_of_time => {
                let cost = cost(r).unwrap_or(0.0).max(0.0);
                if r.accepted {
                    cost
                } else {
                    GENTLER_COST_SHARE * cost
                }
            }
            _ => 0.0,
        }
    }

    /// The share of its splats the next round keeps: `keep`, and after each refused round
    /// half as many removed as the last try (0.5, 0.75, 0.875, …), so a search that cannot
    /// halve the model tries a gentler merge before it stops.
    #[must_use]
    pub fn next_keep(&self, keep: f64) -> f64 {
        (0..self.refused()).fold(keep, |k, _| 0.5 * (1.0 + k))
    }

    /// Whether the next round is due at `iteration`: its planned start is reached (a round
    /// judged at equal time ends past the next one's planned start, which is then due at once).
    #[must_use]
    pub fn due(&self, iteration: u32) -> bool {
        match self.plan {
            Some(p) if !self.finished() => iteration >= p.start_of(self.rounds.len() as u32),
            _ => false,
        }
    }

    /// Forgets rounds that started at or after `iteration` (resuming from a checkpoint taken
    /// before them: they are run again, identically).
    pub fn rewind(&mut self, iteration: u32) {
        self.rounds.retain(|r| r.iteration < iteration);
        self.skipped.retain(|s| s.iteration < iteration);
        // Where the search found nothing to merge, spent its tolerance or ran short of time is
        // found again.
        self.exhausted = false;
        self.tolerance_spent = false;
        self.no_time_left = false;
    }

    /// Runs the due round on `trainer`: scores its splats, trains both branches
    /// `plan.trial` steps, scores them with `heldout_psnr` (black and white) and keeps the
    /// pruned branch when the search's total ([`BudgetRound::drop_db`]: the worse background)
    /// stays within `cfg.tolerance_db`; a round refused near what is left is looked at again
    /// after more training ([`BudgetConfig::second_look_within`]) and, refused again near it,
    /// at the end of the run ([`BudgetConfig::final_look_within`]). `on_step` sees every step
    /// of both branches. Merges that cannot cost less than what is left of the tolerance are
    /// skipped first ([`BudgetConfig::skip_hopeless`], recorded in [`BudgetSearch::skipped`]),
    /// each counting as refused, so the round tries the next, gentler one. Returns the round (also
    /// recorded), or `None` when nothing is left to merge, when every merge the search could
    /// still try was skipped, or, under a time budget, when the trainer's horizon has no room
    /// for both branches' steps ([`BudgetSearch::no_time_left`]; a round started then could
    /// only run out of time, its planning, scoring and merged steps spent for nothing): the
    /// search is then over and no step was trained.
    ///
    /// # Errors
    /// What `heldout_psnr` returns; a [`RoundError`] when no round is planned or the trainer
    /// cannot prune or return to a branch.
    pub fn run_round<E: From<RoundError>>(
        &mut self,
        trainer: &mut Trainer,
        cfg: &BudgetConfig,
        heldout_psnr: &mut dyn FnMut(&Splats) -> Result<HeldoutPsnr, E>,
        on_step: &mut dyn FnMut(&crate::Progress),
    ) -> Result<Option<BudgetRound>, E> {
        let iteration = trainer.iteration();
        let fail = |problem: String| E::from(RoundError { iteration, problem });
        let Some(plan) = self.plan else {
            return Err(fail("no budget search is planned".into()));
        };
        if trainer.config().time_budget.is_some() && iteration + 2 * plan.trial > trainer.horizon()
        {
            self.no_time_left = true;
            return Ok(None);
        }
        if self.skip_hopeless(cfg, iteration) {
            return Ok(None);
        }
        let n = trainer.splats().len();
        // The round's planning and scoring are counted on the trainer's clock as they happen
        // (a time budget is wall time, and a round near its end must not run past it); each
        // branch's time is its steps alone, which is what the branches are matched on.
        let planning = Instant::now();
        let mut seconds = RoundSeconds::default();
        let contributions = trainer.contributions();
        let keep = self.next_keep(cfg.keep);
        // At most `keep` of the splats: a quarter of 31,406 is 7,851, not 7,852.
        let target_count = ((n as f64 * keep).floor() as usize).max(cfg.min_splats.min(n));
        let merges = plan_merges(
            trainer.splats(),
            &contributions,
            target_count,
            cfg.merge_reach,
        );
        let candidate = n - merges.removed();
        if merges.removed() == 0 {
            // Nothing left to merge (at `min_splats`, or no cell holds two splats): done.
            self.exhausted = true;
            count_since(trainer, planning);
            return Ok(None);
        }
        let target = iteration + plan.trial;
        let start = trainer.snapshot();
        seconds.planning = count_since(trainer, planning);
        // The control, scored at the scoring points of the trial.
        let control = run_branch(trainer, iteration, plan.trial, None, heldout_psnr, on_step)?;
        seconds.control = control.training_s;
        seconds.scoring = control.scoring_s;
        let kept_mean = control.scores.mean();
        let mut round = BudgetRound {
            iteration,
            splats: n,
            candidate,
            kept_psnr: kept_mean.black,
            pruned_psnr: None,
            kept_psnr_white: Some(kept_mean.white),
            pruned_psnr_white: None,
            accepted: false,
            out_of_time: control.ended_at < target,
            steps_pruned: 0,
            first_look_db: None,
            second_look_db: None,
            seconds,
        };
        if round.out_of_time {
            self.rounds.push(round);
            return Ok(Some(round));
        }
        let merging = Instant::now();
        let kept = trainer.swap_snapshot(start).map_err(fail)?;
        let keep = merges.apply(trainer.state_mut(), &contributions);
        trainer
            .prune(&keep)
            .map_err(|e| fail(format!("pruning: {e}")))?;
        round.seconds.planning += count_since(trainer, merging);
        // The pruned branch, scored at the same steps, or where a time budget binds the
        // schedule at the same training times: there the branches get equal time, and the
        // smaller model's faster steps are part of what the prune buys (more of the schedule's
        // steps fit).
        let pruned = run_branch(
            trainer,
            iteration,
            plan.trial,
            Some(&control.times),
            heldout_psnr,
            on_step,
        )?;
        round.seconds.scoring += pruned.scoring_s;
        round.seconds.merged = pruned.training_s;
        round.steps_pruned = pruned.ended_at - iteration;
        round.out_of_time = pruned.scores.count < SCORE_POINTS;
        round.take_scores(None, &pruned.scores);
        round.accepted = self.within_tolerance(cfg, &round);
        let kept =
            self.look_further(trainer, cfg, plan, kept, &mut round, heldout_psnr, on_step)?;
        if !round.accepted {
            let restoring = Instant::now();
            trainer.restore_snapshot(kept).map_err(fail)?;
            round.seconds.planning += count_since(trainer, restoring);
        }
        self.rounds.push(round);
        self.tolerance_spent =
            self.spent_db() > 0.0 && self.left_db(cfg.tolerance_db) < cfg.least_left_db;
        Ok(Some(round))
    }

    /// Whether `round`'s cost (the worse background), added to what the accepted rounds spent,
    /// stays within the tolerance (a round that ran out of time never does).
    fn within_tolerance(&self, cfg: &BudgetConfig, round: &BudgetRound) -> bool {
        !round.out_of_time
            && self.spent_db() + round.drop_db().unwrap_or(f64::INFINITY).max(0.0)
                <= cfg.tolerance_db
    }

    /// Skips the merges that cannot cost less than what is left of the tolerance, and those
    /// whose first look cannot come near enough to it to be looked at again
    /// ([`BudgetConfig::second_look_within`]): each counts as refused and is recorded in
    /// [`Self::skipped`], and the next, gentler merge is considered in its place. Returns whether
    /// that ended the search.
    fn skip_hopeless(&mut self, cfg: &BudgetConfig, iteration: u32) -> bool {
        while cfg.skip_hopeless
            && let floor = self.cost_floor()
            && let first_look_floor = self.first_look_floor()
            && let left = self.left_db(cfg.tolerance_db)
            && first_look_floor > 0.0
            && (floor > left || first_look_floor > cfg.second_look_within.max(1.0) * left)
        {
            self.skipped.push(SkippedRound {
                iteration,
                keep: self.next_keep(cfg.keep),
                floor_db: floor,
                first_look_floor_db: first_look_floor,
                left_db: left,
            });
            if self.finished() {
                return true;
            }
        }
        false
    }

    /// Looks again at a round refused near what is left of the tolerance: a cost within
    /// [`BudgetConfig::second_look_within`] of it is looked at after more training of both
    /// branches (the merged branch is still recovering from its merges, and its cost at the end
    /// of the run has been half of this or less), where the rounds' steps leave room (they end
    /// by `end_share` of the run's steps; under a time budget, of those it now expects); a
    /// second look still refused within [`BudgetConfig::final_look_within`] trains both branches
    /// on to the end of the run, where the merged branch has finished recovering, and the round
    /// is decided on the models the run would end with. Updates `round` (its looks and its
    /// decision) and returns the control's snapshot as it then stands.
    #[allow(clippy::too_many_arguments)]
    fn look_further<E: From<RoundError>>(
        &self,
        trainer: &mut Trainer,
        cfg: &BudgetConfig,
        plan: BudgetPlan,
        mut kept: Snapshot,
        round: &mut BudgetRound,
        heldout_psnr: &mut dyn FnMut(&Splats) -> Result<HeldoutPsnr, E>,
        on_step: &mut dyn FnMut(&crate::Progress),
    ) -> Result<Snapshot, E> {
        let left = self.left_db(cfg.tolerance_db);
        let rounds_end = (cfg.end_share * f64::from(trainer.horizon())).round() as u32;
        let second_look = !round.accepted
            && !round.out_of_time
            && round
                .drop_db()
                .is_some_and(|d| d <= cfg.second_look_within * left)
            && round.iteration + (1 + cfg.second_look_trials) * plan.trial <= rounds_end;
        if second_look {
            round.first_look_db = round.drop_db();
            let steps = cfg.second_look_trials * plan.trial;
            kept = look_again(trainer, kept, &|_| steps, round, heldout_psnr, on_step)?;
            round.accepted = self.within_tolerance(cfg, round);
        }
        let end = trainer.config().iterations;
        let final_look = second_look
            && !round.accepted
            && !round.out_of_time
            && round
                .drop_db()
                .is_some_and(|d| d <= cfg.final_look_within * left)
            && trainer.iteration() < end
            && !trainer.budget_binds()
            && trainer.time_left_for(2 * (end - trainer.iteration()));
        if final_look {
            round.second_look_db = round.drop_db();
            kept = look_again(
                trainer,
                kept,
                &|from| end.saturating_sub(from),
                round,
                heldout_psnr,
                on_step,
            )?;
            round.accepted = self.within_tolerance(cfg, round);
        }
        Ok(kept)
    }
}

/// Counts the wall time since `since` on the trainer's clock, as time spent between its steps
/// (a time budget is wall time, and a round near its end must not run past it); returns it.
fn count_since(trainer: &mut Trainer, since: Instant) -> f64 {
    let took = since.elapsed().as_secs_f64();
    trainer.count_time_between_steps(took);
    took
}

/// Looks at a round again: the control (`kept`), then the merged branch (the trainer's), each
/// trained on `steps(start)` steps from the step `start` it stands at and scored as a trial's
/// branches are (the merged branch at the control's training times where a time budget binds).
/// The round takes this look's scores, step count and out-of-time flag, and adds its times;
/// the trainer is left holding the merged branch, and the control is returned.
fn look_again<E: From<RoundError>>(
    trainer: &mut Trainer,
    kept: Snapshot,
    steps: &dyn Fn(u32) -> u32,
    round: &mut BudgetRound,
    heldout_psnr: &mut dyn FnMut(&Splats) -> Result<HeldoutPsnr, E>,
    on_step: &mut dyn FnMut(&crate::Progress),
) -> Result<Snapshot, E> {
    let iteration = round.iteration;
    let fail = |problem: String| E::from(RoundError { iteration, problem });
    let swapping = Instant::now();
    let merged = trainer.swap_snapshot(kept).map_err(fail)?;
    round.seconds.planning += count_since(trainer, swapping);
    let start = trainer.iteration();
    let control = run_branch(trainer, start, steps(start), None, heldout_psnr, on_step)?;
    round.seconds.control += control.training_s;
    round.seconds.scoring += control.scoring_s;
    let swapping = Instant::now();
    let kept = trainer.swap_snapshot(merged).map_err(fail)?;
    round.seconds.planning += count_since(trainer, swapping);
    let start = trainer.iteration();
    let pruned = run_branch(
        trainer,
        start,
        steps(start),
        Some(&control.times),
        heldout_psnr,
        on_step,
    )?;
    round.seconds.scoring += pruned.scoring_s;
    round.seconds.merged += pruned.training_s;
    round.steps_pruned = pruned.ended_at - iteration;
    round.out_of_time = control.scores.count < SCORE_POINTS || pruned.scores.count < SCORE_POINTS;
    round.take_scores(Some(&control.scores), &pruned.scores);
    Ok(kept)
}

/// One branch of a round: its held-out scores and what it took.
struct Branch {
    scores: Scores,
    /// The training time (seconds, scoring excluded) at each scoring point.
    times: Vec<f64>,
    /// The step it ended at.
    ended_at: u32,
    /// Its training steps' time.
    training_s: f64,
    /// Its scoring's time.
    scoring_s: f64,
}

/// Trains the trainer's branch over the trial of `trial` steps from step `start`, scoring it at
/// the trial's scoring points. A control (`match_times` `None`) trains the trial's steps; a
/// merged branch matches the control's scoring points: where a time budget binds the schedule
/// ([`Trainer::budget_binds`]) it trains until each of the control's training times (equal
/// time), otherwise to the same steps. A budget that does not bind leaves the run every
/// configured step, so there the smaller model's faster steps buy it nothing at the end, and
/// matching times would score it on steps it never gets and make the round's outcome depend on
/// the machine's speed at that moment.
fn run_branch<E>(
    trainer: &mut Trainer,
    start: u32,
    trial: u32,
    match_times: Option<&[f64]>,
    heldout_psnr: &mut dyn FnMut(&Splats) -> Result<HeldoutPsnr, E>,
    on_step: &mut dyn FnMut(&crate::Progress),
) -> Result<Branch, E> {
    let clock = |trainer: &Trainer| trainer.report(false).elapsed_s;
    let before = clock(trainer);
    let equal_time = match_times.is_some() && trainer.budget_binds();
    let mut branch = Branch {
        scores: Scores::default(),
        times: Vec::new(),
        ended_at: trainer.iteration(),
        training_s: 0.0,
        scoring_s: 0.0,
    };
    let mut now = trainer.report(false);
    for k in 1..=SCORE_POINTS {
        let at = scoring_step(start, trial, k);
        match match_times {
            Some(times) if k as usize > times.len() => break,
            Some(times) if equal_time => {
                let t = times[k as usize - 1];
                while now.elapsed_s - before - branch.scoring_s < t
                    && now.iterations < trainer.horizon()
                {
                    now = trainer.run_until(now.iterations + 1, &mut *on_step);
                    if now.stopped_by_budget {
                        break;
                    }
                }
                if now.stopped_by_budget {
                    break;
                }
            }
            _ => {
                now = trainer.run_until(at, &mut *on_step);
                if now.iterations < at {
                    break;
                }
            }
        }
        branch.times.push(now.elapsed_s - before - branch.scoring_s);
        let scoring = Instant::now();
        branch.scores.add(heldout_psnr(trainer.splats())?);
        let took = scoring.elapsed().as_secs_f64();
        trainer.count_time_between_steps(took);
        branch.scoring_s += took;
        // The clock as it stands after the score, which the next point's steps start from.
        now = trainer.report(false);
    }
    branch.ended_at = trainer.iteration();
    branch.training_s = clock(trainer) - before - branch.scoring_s;
    Ok(branch)
}

/// Refused rounds after which the search stops: with the default `keep` of ½ it tries to
/// remove ½, ¼ and ⅛ of the splats before it gives up.
pub const MAX_REFUSED_ROUNDS: u32 = 3;

/// How many times each branch of a round is scored, evenly over the last quarter of its trial
/// (the last at its end): one held-out score moves by a few tenths of a dB from step to step (each
/// step follows one view), as much as the tolerance, so a round compares the branches' means.
pub const SCORE_POINTS: u32 = 4;

/// The step of a round's `k`-th scoring point (1-based, up to [`SCORE_POINTS`]): evenly over
/// the last quarter of the trial that starts at `start`, the last at its end. Earlier than that
/// the pruned branch would still be recovering from its merges, and the round would charge it
/// for steps it has not had yet.
fn scoring_step(start: u32, trial: u32, k: u32) -> u32 {
    start + trial - trial * (SCORE_POINTS - k) / (4 * SCORE_POINTS)
}

/// Held-out scores summed over a branch's scoring points.
#[derive(Debug, Clone, Copy, Default)]
struct Scores {
    black: f64,
    white: f64,
    count: u32,
}

impl Scores {
    fn add(&mut self, p: HeldoutPsnr) {
        self.black += p.black;
        self.white += p.white;
        self.count += 1;
    }

    /// The mean scores (of at least one).
    fn mean(&self) -> HeldoutPsnr {
        let n = f64::from(self.count.max(1));
        HeldoutPsnr {
            black: self.black / n,
            white: self.white / n,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_round_costs_what_the_worse_background_lost() {
        let round = BudgetRound {
            iteration: 10,
            splats: 100,
            candidate: 50,
            kept_psnr: 40.0,
            pruned_psnr: Some(39.9),
            kept_psnr_white: Some(35.0),
            pruned_psnr_white: Some(34.6),
            accepted: false,
            out_of_time: false,
            steps_pruned: 5,
            first_look_db: None,
            second_look_db: None,
            seconds: RoundSeconds::default(),
        };
        assert!((round.drop_db().unwrap() - 0.4).abs() < 1e-9);
        let better_on_white = BudgetRound {
            pruned_psnr_white: Some(35.5),
            ..round
        };
        assert!((better_on_white.drop_db().unwrap() - 0.1).abs() < 1e-9);
        let better_on_both = BudgetRound {
            pruned_psnr: Some(40.2),
            pruned_psnr_white: Some(35.3),
            ..round
        };
        assert!((better_on_both.drop_db().unwrap() + 0.2).abs() < 1e-9);
        // Rounds saved before white was measured cost their black drop.
        let old = BudgetRound {
            kept_psnr_white: None,
            pruned_psnr_white: None,
            ..round
        };
        assert!((old.drop_db().unwrap() - 0.1).abs() < 1e-9);
        let unrun = BudgetRound {
            pruned_psnr: None,
            ..round
        };
        assert_eq!(unrun.drop_db(), None);
    }

    #[test]
    fn branches_are_scored_over_the_last_quarter_of_the_trial() {
        for (start, trial) in [(500, 160), (375, 120), (10, 50), (0, 7)] {
            let steps: Vec<u32> = (1..=SCORE_POINTS)
                .map(|k| scoring_step(start, trial, k))
                .collect();
            assert_eq!(*steps.last().unwrap(), start + trial, "{steps:?}");
            assert!(4 * (steps[0] - start) >= 3 * trial, "{steps:?}");
            if trial >= 4 * SCORE_POINTS {
                assert!(steps.windows(2).all(|w| w[0] < w[1]), "{steps:?}");
            }
        }
        assert_eq!(
            (1..=SCORE_POINTS)
                .map(|k| scoring_step(500, 160, k))
                .collect::<Vec<_>>(),
            [630, 640, 650, 660]
        );
    }

    /// The least the next round can cost: an accepted merge's cost for one as large, a quarter
    /// of a refused (or skipped) merge's for the gentler one after it, nothing with no try
    /// before it or after a round that ran out of time.
    #[test]
    fn the_cost_floor_follows_the_last_try() {
        let round = |iteration, accepted, out_of_time, pruned: f64| BudgetRound {
            iteration,
            splats: 100,
            candidate: 50,
            kept_psnr: 30.0,
            pruned_psnr: Some(30.0 - pruned),
            kept_psnr_white: Some(30.0),
            pruned_psnr_white: Some(30.0 - 0.5 * pruned),
            accepted,
            out_of_time,
            steps_pruned: 10,
            first_look_db: None,
            second_look_db: None,
            seconds: RoundSeconds::default(),
        };
        let mut search = BudgetSearch::default();
        assert_eq!(search.cost_floor(), 0.0);
        search.rounds.push(round(10, true, false, -0.2));
        assert_eq!(search.cost_floor(), 0.0, "a gain is no floor");
        search.rounds.push(round(20, true, false, 0.19));
        assert!((search.cost_floor() - 0.19).abs() < 1e-12);
        search.rounds.push(round(30, false, false, 0.8));
        assert!((search.cost_floor() - GENTLER_COST_SHARE * 0.8).abs() < 1e-12);
        search.skipped.push(SkippedRound {
            iteration: 40,
            keep: 0.75,
            floor_db: 0.2,
            first_look_floor_db: 0.2,
            left_db: 0.06,
        });
        assert!((search.cost_floor() - GENTLER_COST_SHARE * 0.2).abs() < 1e-12);
        // The round tried in the skipped one's place, at the same step, is the last try.
        search.rounds.push(round(40, false, false, 0.26));
        assert!((search.cost_floor() - GENTLER_COST_SHARE * 0.26).abs() < 1e-12);
        search.rounds.push(round(50, false, true, 0.0));
        assert_eq!(search.cost_floor(), 0.0);
        // Skipped merges count as refused: the next keeps half as many removed again.
        assert_eq!(search.refused(), 3);
        assert!((search.next_keep(0.5) - 0.9375).abs() < 1e-12);
        // A round looked at twice bounds the next merge's first look by its first look.
        let mut search = BudgetSearch::default();
        search.rounds.push(BudgetRound {
            first_look_db: Some(0.34),
            ..round(10, true, false, 0.09)
        });
        assert!((search.cost_floor() - 0.09).abs() < 1e-12);
        assert!((search.first_look_floor() - 0.34).abs() < 1e-12);
        search.rounds.push(BudgetRound {
            first_look_db: Some(0.5),
            ..round(20, false, false, 0.3)
        });
        assert!((search.cost_floor() - GENTLER_COST_SHARE * 0.3).abs() < 1e-12);
        assert!((search.first_look_floor() - GENTLER_COST_SHARE * 0.5).abs() < 1e-12);
        search.skipped.push(SkippedRound {
            iteration: 30,
            keep: 0.875,
            floor_db: 0.075,
            first_look_floor_db: 0.125,
            left_db: 0.06,
        });
        assert!((search.cost_floor() - GENTLER_COST_SHARE * 0.075).abs() < 1e-12);
        assert!((search.first_look_floor() - GENTLER_COST_SHARE * 0.125).abs() < 1e-12);
    }

    /// After each refused round the next removes half as many splats as the last try, and the
    /// search ends at the third refusal; out of time ends it at once.
    #[test]
    fn a_refused_round_makes_the_next_gentler() {
        let round = |accepted, out_of_time| BudgetRound {
            iteration: 0,
            splats: 100,
            candidate: 50,
            kept_psnr: 30.0,
            pruned_psnr: Some(29.0),
            kept_psnr_white: None,
            pruned_psnr_white: None,
            accepted,
            out_of_time,
            steps_pruned: 10,
            first_look_db: None,
            second_look_db: None,
            seconds: RoundSeconds::default(),
        };
        let mut search = BudgetSearch {
            plan: BudgetConfig::default().plan(10_000),
            ..BudgetSearch::default()
        };
        search.plan.as_mut().unwrap().rounds = 10;
        let mut keeps = vec![search.next_keep(0.5)];
        search.rounds.push(round(true, false));
        keeps.push(search.next_keep(0.5));
        for _ in 0..MAX_REFUSED_ROUNDS {
            assert!(!search.finished());
            search.rounds.push(round(false, false));
            keeps.push(search.next_keep(0.5));
        }
        assert_eq!(keeps, [0.5, 0.5, 0.75, 0.875, 0.9375]);
        assert!(search.finished());
        search.rounds.truncate(2);
        assert!(!search.finished());
        search.rounds.push(round(false, true));
        assert!(search.finished(), "out of time");
    }

    #[test]
    fn rounds_are_planned_at_shares_of_the_run() {
        let c = BudgetConfig::default();
        let p = c.plan(2000).unwrap();
        assert_eq!((p.first, p.trial), (500, 160));
        assert_eq!(p.start_of(2), 820);
        // 0.65 · 2000 = 1300: (1300 − 500) / 160 = 5 rounds fit, 4 are allowed.
        assert_eq!(p.rounds, 4);
        assert_eq!(c.plan(499), None, "too short a run");
        assert_eq!(BudgetConfig { auto: false, ..c }.plan(2000), None);
        assert_eq!(c.start_splats(3_000_000, 300_000.0, None), 600_000);
        assert_eq!(c.start_splats(30_000, 300_000.0, None), 30_000);
        assert_eq!(
            BudgetConfig { auto: false, ..c }.start_splats(3_000_000, 1.0, None),
            3_000_000
        );
        // What was asked caps the start (below the pixels' share) and never raises it.
        assert_eq!(c.start_splats(3_000_000, 300_000.0, Some(250_000)), 250_000);
        assert_eq!(c.start_splats(3_000_000, 100_000.0, Some(250_000)), 200_000);
        assert_eq!(c.start_splats(30_000, 300_000.0, Some(250_000)), 30_000);
        assert_eq!(
            BudgetConfig { auto: false, ..c }.start_splats(3_000_000, 1.0, Some(250_000)),
            250_000
        );
    }

    #[test]
    fn bad_settings_name_their_key() {
        let c = BudgetConfig::default();
        assert!(c.validate().is_ok());
        let key = |c: BudgetConfig| c.validate().unwrap_err().0;
        assert_eq!(key(BudgetConfig { keep: 1.0, ..c }), "budget.keep");
        assert_eq!(
            key(BudgetConfig {
                tolerance_db: f64::NAN,
                ..c
            }),
            "budget.tolerance_db"
        );
        assert_eq!(
            key(BudgetConfig {
                start_share: 0.6,
                ..c
            }),
            "budget.end_share"
        );
        assert_eq!(
            key(BudgetConfig {
                splats_per_pixel: 0.0,
                ..c
            }),
            "budget.splats_per_pixel"
        );
        for least_left_db in [-0.01, f64::INFINITY] {
            assert_eq!(
                key(BudgetConfig { least_left_db, ..c }),
                "budget.least_left_db"
            );
        }
        for merge_reach in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            assert_eq!(key(BudgetConfig { merge_reach, ..c }), "budget.merge_reach");
        }
    }
}
