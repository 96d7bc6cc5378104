//! Training configuration with Inria's 3DGS defaults (`arguments/__init__.py`).

use std::time::Duration;

use serde::{Deserialize, Serialize};

use crate::adam::AdamParams;
use crate::error::Error;

/// Learning rates per parameter group.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LearningRates {
    /// Initial position rate, multiplied by the scene extent (Inria `position_lr_init`).
    pub position_init: f32,
    /// Final position rate, multiplied by the scene extent (Inria `position_lr_final`).
    pub position_final: f32,
    /// Iterations over which the position rate decays; `None` = the run's iteration count.
    pub position_max_steps: Option<u32>,
    /// Rate of the SH DC coefficients (Inria `feature_lr`).
    pub sh_dc: f32,
    /// Rate of the higher SH bands = `sh_dc / sh_rest_divisor`. Inria divides by 20 for its
    /// 30,000 steps; runs of a few thousand steps learn view dependence too slowly at that rate,
    /// and 5 gave +0.2 to +0.4 dB held-out on every scene with view dependence we measured
    /// (the demo, the spider frame, splat-scene; docs/benchmarks/fidelity.md §11).
    pub sh_rest_divisor: f32,
    /// Opacity-logit rate (Inria 2023 `opacity_lr`).
    pub opacity: f32,
    /// Log-scale rate (Inria `scaling_lr`).
    pub scale: f32,
    /// Quaternion rate (Inria `rotation_lr`).
    pub rotation: f32,
}

impl Default for LearningRates {
    fn default() -> Self {
        Self {
            position_init: 1.6e-4,
            position_final: 1.6e-6,
            position_max_steps: None,
            sh_dc: 2.5e-3,
            sh_rest_divisor: 5.0,
            opacity: 0.05,
            scale: 5e-3,
            rotation: 1e-3,
        }
    }
}

impl LearningRates {
    /// Checks the ranges: every rate in [0, 1], the higher bands' divisor at least 1.
    ///
    /// # Errors
    /// The offending key (`lr.…`) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let rates = [
            ("position_init", self.position_init),
            ("position_final", self.position_final),
            ("sh_dc", self.sh_dc),
            ("opacity", self.opacity),
            ("scale", self.scale),
            ("rotation", self.rotation),
        ];
        for (key, v) in rates {
            if !(v.is_finite() && (0.0..=1.0).contains(&v)) {
                return Err((
                    format!("lr.{key}"),
                    format!("must be a learning rate in [0, 1], got {v}"),
                ));
            }
        }
        let d = self.sh_rest_divisor;
        if !(d.is_finite() && d >= 1.0) {
            return Err((
                "lr.sh_rest_divisor".into(),
                format!("must be a finite number ≥ 1, got {d}"),
            ));
        }
        if self.position_max_steps == Some(0) {
            return Err((
                "lr.position_max_steps".into(),
                "must be at least 1 (leave it out for the run's step count)".into(),
            ));
        }
        Ok(())
    }
}

/// Attribute groups held fixed during training: a frozen group is never written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct Frozen {
    /// Means.
    pub positions: bool,
    /// Log-scales.
    pub scales: bool,
    /// Quaternions.
    pub rotations: bool,
    /// Opacity logits.
    pub opacities: bool,
    /// SH coefficients.
    pub colors: bool,
}

/// Inria's adaptive density control (`densify_and_prune`, `reset_opacity`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct DensifyConfig {
    /// Densify every this many iterations (Inria `densification_interval`).
    pub interval: u32,
    /// Densify only after this iteration (Inria `densify_from_iter`).
    pub start: u32,
    /// Densify and reset opacity only before this iteration (Inria `densify_until_iter`).
    pub stop: u32,
    /// Mean view-space gradient norm (NDC units) that selects a splat (Inria 2e-4).
    pub grad_threshold: f32,
    /// Splats larger than this fraction of the extent split, smaller ones clone (Inria 0.01).
    pub percent_dense: f32,
    /// Clamp every opacity to 0.01 every this many iterations (Inria 3000); 0 = never.
    pub opacity_reset_interval: u32,
    /// Prune splats less opaque than this (Inria 0.005).
    pub min_opacity: f32,
    /// After the first opacity reset, prune splats larger than this fraction of the extent (Inria 0.1).
    pub max_world_scale: f32,
    /// Never grow beyond this many splats; candidates with the largest gradients go first.
    pub max_splats: usize,
}

impl DensifyConfig {
    /// Checks the ranges: a step interval of at least 1, finite positive thresholds, room for
    /// at least one splat.
    ///
    /// # Errors
    /// The offending key (`densify.…`) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |key: &str, problem: String| Err((format!("densify.{key}"), problem));
        if self.interval == 0 {
            return bad("interval", "must be at least 1".into());
        }
        let positive = [
            ("grad_threshold", self.grad_threshold),
            ("percent_dense", self.percent_dense),
            ("max_world_scale", self.max_world_scale),
        ];
        for (key, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(key, format!("must be a finite number > 0, got {v}"));
            }
        }
        let m = self.min_opacity;
        if !(m.is_finite() && (0.0..1.0).contains(&m)) {
            return bad("min_opacity", format!("must be in [0, 1), got {m}"));
        }
        if self.max_splats == 0 {
            return bad("max_splats", "must be at least 1".into());
        }
        Ok(())
    }
}

impl Default for DensifyConfig {
    fn default() -> Self {
        Self {
            interval: 100,
            start: 500,
            stop: 15_000,
            grad_threshold: 2e-4,
            percent_dense: 0.01,
            opacity_reset_interval: 3000,
            min_opacity: 0.005,
            max_world_scale: 0.1,
            max_splats: 3_000_000,
        }
    }
}

/// Coarse-to-fine warm-up: the first steps train on views reduced by an integer factor, which
/// costs a fraction of a full step (the 3DGS paper, §7.1, warms up at 1/4 resolution).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Warmup {
    /// Reduction factor of the image sides (≥ 2).
    pub factor: u32,
    /// Steps 1..=until train on the reduced views.
    pub until: u32,
}

impl Warmup {
    /// The share of a schedule of `iterations` steps it spans, in [0, 1].
    #[must_use]
    pub fn share(&self, iterations: u32) -> f64 {
        (f64::from(self.until) / f64::from(iterations.max(1))).min(1.0)
    }
}

/// The photometric term of the training loss, (1 − λ)·term + λ·D-SSIM.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Photometric {
    /// Mean absolute error (3DGS paper, Eq. 7): every pixel pulls with the same strength.
    #[default]
    L1,
    /// Root mean squared error √(mean (r − g)²), the measure PSNR is a logarithm of: a pixel
    /// pulls in proportion to its error, so the few large errors (silhouettes composited on
    /// a random background) weigh more than under L1. Its gradient, (r − g)/(n·RMSE), has
    /// about the L1's mean size, so λ keeps its meaning.
    L2,
}

/// Background colour composited behind the splats.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Background {
    /// The same colour every step (RGB in [0, 1]).
    Fixed([f32; 3]),
    /// A uniform random colour drawn every step (for views with a mask).
    Random,
}

/// Everything that steers a training run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainConfig {
    /// Number of optimisation steps (one view per step).
    pub iterations: u32,
    /// Seed of the run's random generator (view order, random background, split samples).
    pub seed: u64,
    /// Learning rates per group.
    pub lr: LearningRates,
    /// Adam hyper-parameters.
    pub adam: AdamParams,
    /// Weight λ of the D-SSIM term (Inria 0.2).
    pub ssim_weight: f32,
    /// The photometric term beside it (L1 where a checkpoint of an older build names none).
    #[serde(default)]
    pub photometric: Photometric,
    /// Highest SH degree trained; `None` = the model's degree.
    pub sh_degree: Option<u32>,
    /// One more SH band every this many iterations (Inria 1000); 0 = all bands from the start.
    pub sh_degree_interval: u32,
    /// Attribute groups that are not trained.
    pub frozen: Frozen,
    /// Adaptive density control; `None` keeps the splat set fixed.
    pub densify: Option<DensifyConfig>,
    /// Background behind the splats.
    pub background: Background,
    /// Render with the anti-aliased (Mip-Splatting style) opacity compensation.
    pub antialiased: bool,
    /// Stop early once this much training time has passed.
    pub time_budget: Option<Duration>,
    /// Weight of the L1 loss of rendered alpha against a view's mask (0 = off).
    pub alpha_loss_weight: f32,
    /// Record a history entry every this many iterations (and at the last).
    pub history_every: u32,
    /// Optional coarse-to-fine warm-up.
    pub warmup: Option<Warmup>,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            iterations: 30_000,
            seed: 0,
            lr: LearningRates::default(),
            adam: AdamParams::default(),
            ssim_weight: 0.2,
            photometric: Photometric::L1,
            sh_degree: None,
            sh_degree_interval: 1000,
            frozen: Frozen::default(),
            densify: Some(DensifyConfig::default()),
            background: Background::Fixed([0.0; 3]),
            antialiased: false,
            time_budget: None,
            alpha_loss_weight: 0.0,
            history_every: 10,
            warmup: None,
        }
    }
}

impl TrainConfig {
    /// Checks ranges and combinations, naming the first bad field.
    ///
    /// # Errors
    /// [`Error::Config`] naming the field and the value.
    pub fn validate(&self) -> Result<(), Error> {
        let field = |(key, problem): (String, String)| Error::Config(format!("{key}: {problem}"));
        self.lr.validate().map_err(field)?;
        let a = &self.adam;
        if !((0.0..1.0).contains(&a.beta1) && (0.0..1.0).contains(&a.beta2) && a.eps > 0.0) {
            return Err(Error::Config(format!("Adam parameters {a:?} out of range")));
        }
        if !(self.ssim_weight.is_finite() && (0.0..=1.0).contains(&self.ssim_weight)) {
            return Err(Error::Config(format!(
                "ssim_weight = {} not in [0, 1]",
                self.ssim_weight
            )));
        }
        if !(self.alpha_loss_weight.is_finite() && self.alpha_loss_weight >= 0.0) {
            return Err(Error::Config(format!(
                "alpha_loss_weight = {} must be finite and non-negative",
                self.alpha_loss_weight
            )));
        }
        if let Some(d) = self.sh_degree
            && d > 3
        {
            return Err(Error::Config(format!("sh_degree = {d} exceeds 3")));
        }
        if let Background::Fixed(c) = self.background
            && !c.iter().all(|v| v.is_finite())
        {
            return Err(Error::Config(format!("background {c:?} is not finite")));
        }
        if let Some(d) = &self.densify {
            if self.frozen.positions {
                return Err(Error::Config(
                    "densification moves and removes splats, so it cannot run with frozen positions"
                        .into(),
                ));
            }
            d.validate().map_err(field)?;
        }
        if let Some(w) = self.warmup
            && w.factor < 2
        {
            return Err(Error::Config(format!(
                "warmup.factor = {} must be at least 2",
                w.factor
            )));
        }
        if self.history_every == 0 {
            return Err(Error::Config("history_every must be at least 1".into()));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_inria() {
        let c = TrainConfig::default();
        c.validate().unwrap();
        assert_eq!(c.ssim_weight, 0.2);
        assert_eq!(c.densify.unwrap().grad_threshold, 2e-4);
    }

    #[test]
    fn rejects_bad_values() {
        let mut c = TrainConfig::default();
        c.lr.scale = f32::NAN;
        assert!(matches!(c.validate(), Err(Error::Config(m)) if m.contains("lr.scale")));
        let mut c = TrainConfig::default();
        c.frozen.positions = true;
        assert!(c.validate().is_err());
        c.densify = None;
        c.validate().unwrap();
    }
}
