//! The automatic splat budget: train, score every splat by what it contributes to the training
//! views, prune the least important, continue, and stop at the smallest model whose held-out
//! quality stays within a tolerance of the full model's.
//!
//! A round is an experiment with a control. From the same trained state the model is trained
//! [`BudgetPlan::trial`] steps twice: once whole (the control) and once with the lower-scoring
//! share of its splats removed. Both branches are scored on the held-out views at the same step,
//! so the round measures what the pruning costs and not what the extra steps gained. The pruned
//! branch is kept while the drops of the accepted rounds add up to no more than
//! [`BudgetConfig::tolerance_db`]; the first round that would exceed it is undone (training goes
//! on from the control) and ends the search. The thrown-away branch's time still counts against
//! the run's time budget.
//!
//! What a merge costs is its members' contributions (the blending weight each supplies, summed
//! over the pixels of every training view: Mini-Splatting's importance) times how far their
//! colours are from the merged one ([`plan_merges`]), so flat regions end with few large splats
//! and detailed or glossy ones keep many.

use serde::{Deserialize, Serialize};
use std::collections::HashMap;

use glam::{Mat3, Quat, Vec3};
use splat_core::{Splats, sigmoid};

use crate::init::point_spacing;
use crate::state::ParamState;
use crate::trainer::Trainer;

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
    /// trained for the same steps.
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
            splats_per_pixel: 2.0,
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
        if !(self.static_sh_rms.is_finite() && self.static_sh_rms >= 0.0) {
            return bad("static_sh_rms", "must be a finite number ≥ 0");
        }
        if !(self.splats_per_pixel.is_finite() && self.splats_per_pixel > 0.0) {
            return bad("splats_per_pixel", "must be a finite number > 0");
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
    /// `covered_pixels` pixels: the points, or fewer when they outnumber the pixels.
    #[must_use]
    pub fn start_splats(&self, points: usize, covered_pixels: f64) -> usize {
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
    /// Held-out PSNR (dB, on black) of the whole model after the trial steps.
    pub kept_psnr: f64,
    /// Held-out PSNR (dB, on black) of the pruned model after the same steps (`None`: the
    /// control ran out of time and the pruned branch did not run).
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
    /// Steps the pruned branch trained: `BudgetPlan::trial`, or more under a time budget, where
    /// both branches train for the same time.
    #[serde(default)]
    pub steps_pruned: u32,
}

impl BudgetRound {
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
}

impl BudgetSearch {
    /// The total cost of the accepted rounds (dB), each counted as at least 0.
    #[must_use]
    pub fn spent_db(&self) -> f64 {
        self.rounds
            .iter()
            .filter(|r| r.accepted)
            .filter_map(|r| r.drop_db())
            .map(|d| d.max(0.0))
            .sum()
    }

    /// Whether no more rounds will run: no plan, all planned rounds done, or a round was
    /// refused or ran out of time.
    #[must_use]
    pub fn finished(&self) -> bool {
        let Some(plan) = self.plan else { return true };
        self.exhausted
            || self.rounds.len() as u32 >= plan.rounds
            || self
                .rounds
                .last()
                .is_some_and(|r| !r.accepted || r.out_of_time)
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
        // Where the search found nothing to merge is found again.
        self.exhausted = false;
    }

    /// Runs the due round on `trainer`: scores its splats, trains both branches
    /// `plan.trial` steps, scores them with `heldout_psnr` (black and white) and keeps the
    /// pruned branch when the search's total ([`BudgetRound::drop_db`]: the worse background)
    /// stays within `cfg.tolerance_db`. `on_step` sees every step of both
    /// branches. Returns the round (also recorded), or `None` when nothing is left to merge (the
    /// search is then over and no step was trained).
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
        let n = trainer.splats().len();
        let contributions = trainer.contributions();
        let target_count = ((n as f64 * cfg.keep).round() as usize).max(cfg.min_splats.min(n));
        let merges = plan_merges(trainer.splats(), &contributions, target_count);
        let candidate = n - merges.removed();
        if merges.removed() == 0 {
            // Nothing left to merge (at `min_splats`, or no cell holds two splats): done.
            self.exhausted = true;
            return Ok(None);
        }
        let target = iteration + plan.trial;
        let start = trainer.snapshot();
        let started_s = trainer.report(false).elapsed_s;
        let control = trainer.run_until(target, &mut *on_step);
        let control_s = control.elapsed_s - started_s;
        let kept = heldout_psnr(trainer.splats())?;
        let mut round = BudgetRound {
            iteration,
            splats: n,
            candidate,
            kept_psnr: kept.black,
            pruned_psnr: None,
            kept_psnr_white: Some(kept.white),
            pruned_psnr_white: None,
            accepted: false,
            out_of_time: control.iterations < target,
            steps_pruned: 0,
        };
        if round.out_of_time {
            self.rounds.push(round);
            return Ok(Some(round));
        }
        let kept = trainer.snapshot();
        trainer.restore_snapshot(start).map_err(fail)?;
        let keep = merges.apply(trainer.state_mut(), &contributions);
        trainer
            .prune(&keep)
            .map_err(|e| fail(format!("pruning: {e}")))?;
        let equal_time = trainer.config().time_budget.is_some();
        let pruned = if equal_time {
            // Under a time budget the branches get equal time: the smaller model's faster steps
            // are part of what the prune buys.
            let before = trainer.report(false).elapsed_s;
            let mut r = trainer.report(false);
            while r.elapsed_s - before < control_s && r.iterations < trainer.horizon() {
                r = trainer.run_until(r.iterations + 1, &mut *on_step);
                if r.stopped_by_budget {
                    break;
                }
            }
            r
        } else {
            trainer.run_until(target, &mut *on_step)
        };
        round.steps_pruned = pruned.iterations - iteration;
        round.out_of_time = pruned.stopped_by_budget || (!equal_time && pruned.iterations < target);
        let pruned = heldout_psnr(trainer.splats())?;
        round.pruned_psnr = Some(pruned.black);
        round.pruned_psnr_white = Some(pruned.white);
        round.accepted = !round.out_of_time
            && self.spent_db() + round.drop_db().unwrap_or(f64::INFINITY).max(0.0)
                <= cfg.tolerance_db;
        if !round.accepted {
            trainer.restore_snapshot(kept).map_err(fail)?;
        }
        self.rounds.push(round);
        Ok(Some(round))
    }
}

/// Groups of splats to merge into one each: the plan of a round's pruned branch.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Merges {
    /// Each group's members (at least two), the first of which takes the merged splat's place.
    pub groups: Vec<Vec<usize>>,
}

impl Merges {
    /// Splats the merges remove.
    #[must_use]
    pub fn removed(&self) -> usize {
        self.groups.iter().map(|g| g.len() - 1).sum()
    }

    /// Replaces each group's first member by the group's merged splat ([`merge_group`]) with
    /// fresh optimiser moments; returns the keep flags that then remove the other members.
    pub fn apply(&self, state: &mut ParamState, weights: &[f64]) -> Vec<bool> {
        let mut keep = vec![true; state.len()];
        for g in &self.groups {
            merge_group(&mut state.splats, g, weights);
            state.reset_moments(g[0]);
            for &j in &g[1..] {
                keep[j] = false;
            }
        }
        keep
    }
}

/// Plans merges that bring `splats` down to about `target` splats, cheapest first.
///
/// The splats are binned in cubic cells 1.5 times their median nearest-neighbour spacing (on a
/// surface a cell holds about two; larger cells where that cannot reach the target). Merging a cell costs what flattening its colours would:
/// the members' `weights` (contributions) times the squared distance of their colour (SH DC and
/// the higher bands' norm, opacity-weighted) from the cell's weighted mean. Cells are merged in
/// order of cost per splat saved until enough are gone, so flat regions merge first and
/// detailed or glossy ones keep their splats.
#[must_use]
pub fn plan_merges(splats: &Splats, weights: &[f64], target: usize) -> Merges {
    let n = splats.len();
    if n <= target || n < 2 {
        return Merges::default();
    }
    let spacing = point_spacing(&splats.means);
    let sig = signatures(splats);
    // The smallest cells that hold enough merges: 1.5 spacings (about two splats a cell on a
    // surface) first, larger where the splats are too sparse for that.
    let mut groups = Vec::new();
    for factor in CELL_SPACINGS {
        let cell = factor * spacing;
        if !(cell.is_finite() && cell > 0.0) {
            return Merges::default();
        }
        groups = cell_groups(splats, cell, &sig, weights);
        if groups.iter().map(|g| g.2.len() - 1).sum::<usize>() >= n - target {
            break;
        }
    }
    // By cost, then by cell, so the plan does not depend on the hash map's order.
    groups.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
    let mut removed = 0;
    let mut chosen = Vec::new();
    for (_, _, mut members) in groups {
        if removed >= n - target {
            break;
        }
        // The member carrying most of the images stands for the group.
        members.sort_by(|&a, &b| weights[b].total_cmp(&weights[a]).then(a.cmp(&b)));
        removed += members.len() - 1;
        chosen.push(members);
    }
    Merges { groups: chosen }
}

/// Cell sizes tried by [`plan_merges`], in median nearest-neighbour spacings.
const CELL_SPACINGS: [f32; 4] = [1.5, 2.0, 3.0, 4.0];

/// The cells of size `cell` holding more than one splat: (cell, flattening cost per splat
/// saved, members).
fn cell_groups(
    splats: &Splats,
    cell: f32,
    sig: &[[f32; 4]],
    weights: &[f64],
) -> Vec<([i64; 3], f64, Vec<usize>)> {
    let mut cells: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, p) in splats.means.iter().enumerate() {
        let key = (*p / cell).floor().as_i64vec3().to_array();
        cells.entry(key).or_default().push(i);
    }
    cells
        .into_iter()
        .filter(|(_, m)| m.len() > 1)
        .map(|(key, members)| {
            let cost = flattening_cost(&members, sig, weights);
            (key, cost / (members.len() - 1) as f64, members)
        })
        .collect()
}

/// Each splat's colour signature: opacity times (SH DC, norm of the higher bands).
fn signatures(splats: &Splats) -> Vec<[f32; 4]> {
    let k = splats.coeffs_per_splat();
    (0..splats.len())
        .map(|i| {
            let sh = &splats.sh[i * k..(i + 1) * k];
            let o = sigmoid(splats.opacity_logits[i]);
            let rest: f32 = sh[1..].iter().flatten().map(|v| v * v).sum::<f32>().sqrt();
            [o * sh[0][0], o * sh[0][1], o * sh[0][2], o * rest]
        })
        .collect()
}

/// Σ wⱼ‖sⱼ − s̄‖² over `members` with s̄ their weighted mean signature.
fn flattening_cost(members: &[usize], sig: &[[f32; 4]], weights: &[f64]) -> f64 {
    let w = |j: usize| weights[j].max(0.0);
    let total: f64 = members.iter().map(|&j| w(j)).sum();
    if total <= 0.0 {
        return 0.0;
    }
    let mut mean = [0.0_f64; 4];
    for &j in members {
        for (m, v) in mean.iter_mut().zip(sig[j]) {
            *m += w(j) * f64::from(v) / total;
        }
    }
    members
        .iter()
        .map(|&j| {
            w(j) * sig[j]
                .iter()
                .zip(mean)
                .map(|(&v, m)| (f64::from(v) - m).powi(2))
                .sum::<f64>()
        })
        .sum()
}

/// Replaces splat `group[0]` by one Gaussian with the group's moments: the `weights`-weighted
/// mean of the members' positions, and their mean covariance plus the spread of their
/// positions (moment matching of a Gaussian mixture); SH the weighted mean of theirs; opacity
/// the largest of theirs (the group covered at least as much as its most opaque member).
pub fn merge_group(splats: &mut Splats, group: &[usize], weights: &[f64]) {
    let raw: Vec<f64> = group.iter().map(|&j| weights[j].max(0.0)).collect();
    let sum: f64 = raw.iter().sum();
    let w: Vec<f32> = if sum > 0.0 {
        raw.iter().map(|&v| (v / sum) as f32).collect()
    } else {
        vec![1.0 / group.len() as f32; group.len()]
    };
    let mean: Vec3 = group
        .iter()
        .zip(&w)
        .map(|(&j, &wj)| wj * splats.means[j])
        .sum();
    let mut second = Mat3::ZERO;
    for (&j, &wj) in group.iter().zip(&w) {
        let r = Mat3::from_quat(splats.rotation(j));
        let s2 = Mat3::from_diagonal(splats.scale(j) * splats.scale(j));
        let d = splats.means[j] - mean;
        let outer = Mat3::from_cols(d * d.x, d * d.y, d * d.z);
        second += (r * s2 * r.transpose() + outer) * wj;
    }
    let (rotation, variances) = symmetric_eigen(second);
    let k = splats.coeffs_per_splat();
    let mut sh = vec![[0.0_f32; 3]; k];
    for (&j, &wj) in group.iter().zip(&w) {
        for (acc, member) in sh.iter_mut().zip(&splats.sh[j * k..(j + 1) * k]) {
            for (a, m) in acc.iter_mut().zip(member) {
                *a += wj * m;
            }
        }
    }
    let opacity = group
        .iter()
        .map(|&j| splats.opacity_logits[j])
        .fold(f32::NEG_INFINITY, f32::max);
    let i = group[0];
    let floor = splats.log_scales[i].min_element();
    splats.means[i] = mean;
    splats.log_scales[i] = variances.max(Vec3::ZERO).map(|v| (0.5 * v.ln()).max(floor));
    let q = rotation.normalize();
    splats.rotations[i] = [q.w, q.x, q.y, q.z];
    splats.opacity_logits[i] = opacity;
    splats.sh[i * k..(i + 1) * k].copy_from_slice(&sh);
}

/// The eigen-decomposition of a symmetric 3×3 matrix by Jacobi rotations: the rotation whose
/// columns are the eigenvectors (a proper rotation) and the eigenvalues. Written out because
/// it is a dozen lines and the crate has no linear-algebra dependency; merges call it once per
/// group.
fn symmetric_eigen(m: Mat3) -> (Quat, Vec3) {
    let mut a = [
        [m.x_axis.x, m.y_axis.x, m.z_axis.x],
        [m.x_axis.y, m.y_axis.y, m.z_axis.y],
        [m.x_axis.z, m.y_axis.z, m.z_axis.z],
    ]
    .map(|r| r.map(f64::from));
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0_f64]];
    for _ in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale.max(f64::MIN_POSITIVE) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in &mut a {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for col in 0..3 {
                a[p][col] = c * row_p[col] - s * row_q[col];
                a[q][col] = s * row_p[col] + c * row_q[col];
            }
            for row in &mut v {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
        }
    }
    let col = |j: usize| Vec3::new(v[0][j] as f32, v[1][j] as f32, v[2][j] as f32);
    let (x, y) = (col(0), col(1));
    // A proper rotation: the third axis from the first two.
    let z = x.cross(y);
    let rot = Mat3::from_cols(x, y, z);
    let values = Vec3::new(a[0][0] as f32, a[1][1] as f32, a[2][2] as f32);
    (Quat::from_mat3(&rot), values)
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

    fn approx(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    /// The decomposition rebuilds the matrix, its eigenvectors form a proper rotation, and the
    /// eigenvalues of a diagonal matrix turned by a known rotation are its diagonal.
    #[test]
    fn symmetric_eigen_rebuilds_the_matrix() {
        let turn = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 0.7);
        let r = Mat3::from_quat(turn);
        let d = Vec3::new(4.0, 0.25, 1.5);
        let m = r * Mat3::from_diagonal(d) * r.transpose();
        let (q, values) = symmetric_eigen(m);
        let e = Mat3::from_quat(q);
        let rebuilt = e * Mat3::from_diagonal(values) * e.transpose();
        for c in 0..3 {
            for k in 0..3 {
                assert!(
                    approx(rebuilt.col(c)[k], m.col(c)[k], 1e-5),
                    "{rebuilt} vs {m}"
                );
            }
        }
        assert!(approx(e.determinant(), 1.0, 1e-5));
        let mut got = values.to_array();
        got.sort_by(f32::total_cmp);
        for (g, want) in got.iter().zip([0.25, 1.5, 4.0]) {
            assert!(approx(*g, want, 1e-5), "{got:?}");
        }
        // Already diagonal (no rotation to find) and all equal (any axes will do).
        let (_, v) = symmetric_eigen(Mat3::from_diagonal(Vec3::new(2.0, 3.0, 5.0)));
        assert_eq!(v, Vec3::new(2.0, 3.0, 5.0));
        let (q, v) = symmetric_eigen(Mat3::IDENTITY * 7.0);
        assert_eq!(v, Vec3::splat(7.0));
        assert!(q.is_normalized());
    }

    /// Two equal axis-aligned splats at ±d on x merge, by moment matching, into one at the
    /// origin with variance s² + d² along x and s² across; the colour is the weights' mean and
    /// the opacity the larger one.
    #[test]
    fn a_merge_matches_the_moments_of_its_members() {
        let (s, d) = (0.1_f32, 0.3_f32);
        let means = [Vec3::new(-d, 0.0, 0.0), Vec3::new(d, 0.0, 0.0)];
        let mut splats = Splats::from_points(
            &means,
            &[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            &[Vec3::splat(s); 2],
            None,
            0.5,
            1,
        )
        .unwrap();
        splats.opacity_logits[1] = 2.0;
        let dc = [splats.sh[0][0], splats.sh[4][0]];
        merge_group(&mut splats, &[0, 1], &[3.0, 1.0]);
        assert!(
            splats.means[0].length() < 1e-6 + 0.5 * d,
            "{}",
            splats.means[0]
        );
        // Weighted 3:1, the mean sits at −d/2 and the spread is the weighted variance.
        let mean_x = 0.75 * -d + 0.25 * d;
        assert!(approx(splats.means[0].x, mean_x, 1e-5));
        let var_x = s * s + 0.75 * (-d - mean_x).powi(2) + 0.25 * (d - mean_x).powi(2);
        let scale = splats.scale(0);
        let axis_x = Mat3::from_quat(splats.rotation(0)) * Vec3::X;
        let mut sorted = scale.to_array();
        sorted.sort_by(f32::total_cmp);
        assert!(
            approx(sorted[2] * sorted[2], var_x, 1e-4),
            "{scale} vs {var_x}"
        );
        assert!(approx(sorted[0], s, 1e-4) && approx(sorted[1], s, 1e-4));
        // The widest axis is x (up to sign).
        let widest = (0..3)
            .max_by(|&a, &b| scale[a].total_cmp(&scale[b]))
            .unwrap();
        let col = Mat3::from_quat(splats.rotation(0)).col(widest);
        assert!(col.x.abs() > 0.999, "{col} {axis_x}");
        assert!(approx(splats.sh[0][0], 0.75 * dc[0] + 0.25 * dc[1], 1e-6));
        assert_eq!(splats.opacity_logits[0], 2.0);
    }

    /// A flat single-colour sheet beside a sheet of random colours: the plan merges the flat
    /// sheet first and reaches the target.
    #[test]
    fn merges_take_flat_regions_first() {
        let mut means = Vec::new();
        let mut colours = Vec::new();
        let mut x = 1_u64;
        let mut rand = move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 / (1u64 << 24) as f32
        };
        for i in 0..40 {
            for j in 0..40 {
                // Left half (x < 0) flat grey, right half random colours.
                let p = Vec3::new(i as f32 * 0.05 - 1.0, j as f32 * 0.05, 0.0);
                let c = if p.x < 0.0 {
                    [0.5; 3]
                } else {
                    [rand(), rand(), rand()]
                };
                means.push(p);
                colours.push(c);
            }
        }
        let n = means.len();
        let splats =
            Splats::from_points(&means, &colours, &vec![Vec3::splat(0.03); n], None, 0.8, 0)
                .unwrap();
        let weights = vec![1.0; n];
        let plan = plan_merges(&splats, &weights, n * 3 / 4);
        assert!(plan.removed() >= n / 4, "removed {}", plan.removed());
        assert!(plan.removed() < n / 4 + 8, "removed {}", plan.removed());
        let flat_removed: usize = plan
            .groups
            .iter()
            .flat_map(|g| &g[1..])
            .filter(|&&j| means[j].x < 0.0)
            .count();
        assert_eq!(flat_removed, plan.removed(), "only the flat half merges");
        // Deterministic.
        assert_eq!(plan, plan_merges(&splats, &weights, n * 3 / 4));
        // Applying it keeps each group's first member and drops the rest.
        let mut state = ParamState::new(splats);
        let keep = plan.apply(&mut state, &weights);
        assert_eq!(keep.iter().filter(|&&k| !k).count(), plan.removed());
        assert!(plan.groups.iter().all(|g| keep[g[0]]));
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
        assert_eq!(c.start_splats(3_000_000, 300_000.0), 600_000);
        assert_eq!(c.start_splats(30_000, 300_000.0), 30_000);
        assert_eq!(
            BudgetConfig { auto: false, ..c }.start_splats(3_000_000, 1.0),
            3_000_000
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
    }
}
