//! The configuration shared by every subcommand: defaults, TOML files and command-line overrides.
//!
//! One [`Config`] holds every knob of the pipeline, grouped by stage. `transcode config
//! --defaults` prints [`Config::default`] as TOML; `--config FILE` loads a file in which every
//! key is optional (missing keys keep their defaults, unknown keys are errors so that typos are
//! caught); command-line flags are applied last.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

// The settings of each stage are defined by the crate that runs it; the configuration composes them.
pub use plenoptic_render::{RigConfig, ViewOptions};
pub use splat_init::{InitConfig, InitMode, MeshPoints, Sampling, ShDegree};
pub use splat_train::BudgetConfig;

/// Errors from loading or checking a configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read config file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not valid TOML or does not match the configuration's keys and types.
    #[error("bad config file {path}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// What the TOML parser said, with the key, line and column.
        message: String,
    },
    /// A value is out of its range.
    #[error("invalid configuration{}: `{key}` {problem}", source_suffix(.path))]
    Invalid {
        /// The file the value came from, if any.
        path: Option<PathBuf>,
        /// The dotted key, e.g. `rig.cameras`.
        key: String,
        /// What is wrong with it.
        problem: String,
    },
}

fn source_suffix(path: &Option<PathBuf>) -> String {
    path.as_ref()
        .map(|p| format!(" in {}", p.display()))
        .unwrap_or_default()
}

/// Every setting of the pipeline, grouped by stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Virtual cameras for training and for the held-out evaluation.
    pub rig: RigConfig,
    /// The reference renderer of the input (background is always black: references are
    /// composited on other backgrounds with their alpha).
    pub renderer: ViewOptions,
    /// Initial splats.
    pub init: InitConfig,
    /// The automatic splat budget (`--splats auto`): pruning rounds judged on held-out views.
    pub budget: BudgetConfig,
    /// The trainer.
    pub training: TrainingConfig,
    /// Evaluation on the held-out views.
    pub eval: EvalConfig,
    /// What is written besides the model.
    pub output: OutputConfig,
    /// Sequences (`transcode sequence`): warm starts between frames.
    pub sequence: SequenceConfig,
}

/// Trainer settings; learning rates and densification are `splat_train`'s own structures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TrainingConfig {
    /// Optimisation steps (one view each).
    pub iterations: u32,
    /// Wall-clock budget in seconds for training; stops early when spent.
    pub time_budget_s: Option<f64>,
    /// Seed of the view order, random backgrounds and random init.
    pub seed: u64,
    /// Weight λ of D-SSIM in the loss (Inria: 0.2).
    pub ssim_weight: f32,
    /// The loss's photometric term beside D-SSIM: `"l1"` (Inria's mean absolute error) or
    /// `"l2"` (the root mean squared error, which weighs large errors more: on the demo it
    /// buys white backgrounds 0.4 dB at about equal black, on the spider frame it costs black
    /// 0.3–0.5 dB; docs/benchmarks/fidelity.md §13).
    pub photometric: splat_train::Photometric,
    /// Weight of the L1 loss of rendered alpha against the reference masks.
    pub alpha_loss: f32,
    /// Train (and evaluate) with the antialiased opacity compensation of Mip-Splatting's 2-D
    /// filter: each splat's opacity is scaled by √(det Σ / det(Σ + 0.3 I)), so the dilation
    /// blurs without adding coverage. The PLY says so in a header comment (`SplatRenderMode:
    /// mip`) and the SPZ in its flag, which our viewer, Brush, PlayCanvas / SuperSplat and
    /// splat-transform read; a viewer that ignores them draws the model with more coverage than
    /// it was trained to have, so the default is off (the README demo's model trained so scores
    /// 42.55 / 38.99 dB held-out drawn as trained, and on its training views 47.2 dB on black
    /// compensated but 36.0 drawn plain: docs/benchmarks/fidelity.md §14).
    pub antialiased: bool,
    /// Coarse-to-fine warm-up: the first `warmup_share` of the steps train on views whose sides
    /// are reduced by this factor (1 = off). A reduced step touches a factor² fewer pixels.
    pub warmup_factor: u32,
    /// Share of the run's steps (in [0, 1]) trained on the reduced views of `warmup_factor`;
    /// with the splat budget on it ends where the budget's rounds start
    /// ([`Config::warmup_share`]).
    pub warmup_share: f64,
    /// Sparse init: one more SH band every this many steps (0 = all bands from the start).
    /// Surface init, whose fit sets every band, trains them all from the start.
    pub sh_degree_interval: u32,
    /// A random background colour every step, so the splats cannot bake the background in.
    pub random_background: bool,
    /// Record the training PSNR every this many steps (for the report's plot).
    pub history_every: u32,
    /// Learning rates per parameter group.
    pub lr: splat_train::LearningRates,
    /// Adaptive density control, used by sparse init (and surface init when asked). The schedule
    /// (`start`, `interval`, `stop`, `opacity_reset_interval`) is Inria's, meant for 30,000 steps.
    pub densify: splat_train::DensifyConfig,
    /// Scale the densification schedule to the run's step budget (`splat_train::schedule::scale_densify`);
    /// `false` uses `densify` as written.
    pub scale_densify: bool,
}

impl Default for TrainingConfig {
    fn default() -> Self {
        let t = splat_train::TrainConfig::default();
        Self {
            iterations: 2_000,
            time_budget_s: None,
            seed: t.seed,
            ssim_weight: t.ssim_weight,
            photometric: t.photometric,
            alpha_loss: 0.1,
            antialiased: false,
            warmup_factor: 2,
            warmup_share: 0.5,
            sh_degree_interval: 250,
            random_background: true,
            history_every: 25,
            lr: t.lr,
            densify: t.densify.unwrap_or_default(),
            scale_densify: true,
        }
    }
}

/// Evaluation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvalConfig {
    /// A splat is a floater beyond this many point spacings from the input surface.
    pub floater_spacings: f64,
    /// Rendered alpha above this counts as covered for the IoU.
    pub alpha_threshold: f32,
    /// Held-out views shown side by side in the report.
    pub report_views: usize,
    /// Score the held-out views every this many training steps (and at step 0 and the last
    /// step) for the report's held-out curve; 0: only at the end. Scoring is not training time.
    /// A multiple that a splat budget round trains past is scored at the first step after it.
    pub every: u32,
}

impl Default for EvalConfig {
    fn default() -> Self {
        Self {
            floater_spacings: 2.0,
            alpha_threshold: 0.5,
            report_views: 4,
            every: 0,
        }
    }
}

// `transcode eval` and the pipeline both run splat-train's evaluator with these options.
impl From<&EvalConfig> for splat_train::eval::EvalOptions {
    fn from(c: &EvalConfig) -> Self {
        Self {
            alpha_threshold: c.alpha_threshold,
            floater_spacings: c.floater_spacings,
            antialiased: false,
        }
    }
}

/// Output settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutputConfig {
    /// Write the training views as a COLMAP dataset (`dataset/`: images, masks, cameras and
    /// poses) for other trainers. Off, the views are rendered in memory only: the model is the
    /// same, and a sequence's frame takes about a fifth of the disk.
    pub dataset: bool,
    /// Write the dataset's PNGs with 16 bits per channel instead of 8.
    pub png16: bool,
    /// Also write the model as an antimatter15 `.splat` file.
    pub splat_file: bool,
    /// Also write every model as SPZ (`splats.spz`: Niantic's compressed format, about a tenth of
    /// the PLY, read by most web viewers).
    pub spz: bool,
    /// The SPZ version written: 3 (one gzip stream, which every SPZ reader reads) or 4 (a clear
    /// header and one zstd stream per attribute, Niantic's latest; older readers refuse it).
    /// The report's viewer always gets version 3.
    pub spz_version: u32,
    /// Also write every model as binary glTF with `KHR_gaussian_splatting` (`splats.glb`).
    pub glb: bool,
    /// Also train from the other init mode and compare both in the report.
    pub compare_init: bool,
    /// Save the trainer's state at most this many seconds of wall time apart, so that a killed
    /// run resumes (`--resume`) losing no more than this; 0 saves after every step.
    pub checkpoint_interval_s: f64,
}

impl Default for OutputConfig {
    fn default() -> Self {
        Self {
            dataset: true,
            png16: false,
            splat_file: false,
            spz: true,
            spz_version: splat_core::spz::VERSION,
            glb: false,
            compare_init: false,
            checkpoint_interval_s: DEFAULT_CHECKPOINT_INTERVAL_S,
        }
    }
}

/// Sequence settings (`transcode sequence`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SequenceConfig {
    /// Start each frame after the first of a shard's block from what training learnt on the
    /// previous frame (its training corrections carried onto this frame's own surface init,
    /// `splat_init::carry_training`) instead of from scratch.
    pub warm_start: bool,
    /// Training steps of a warm-started frame, as a share of `training.iterations` (and of
    /// `training.time_budget_s` when one is set).
    pub warm_share: f64,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        Self {
            warm_start: true,
            warm_share: 0.3,
        }
    }
}

/// Default wall time between two checkpoints: a minute is little to redo after a crash, and a
/// checkpoint (parameters and Adam moments, fsynced) costs well under a second at a million
/// splats, so under 2 % of the run.
pub const DEFAULT_CHECKPOINT_INTERVAL_S: f64 = 60.0;

impl Config {
    /// The trainer's configuration for one init mode: the `[training]` table, densification for
    /// sparse init (and surface init when asked), and surface splats frozen in place unless
    /// they may move or densify.
    #[must_use]
    pub fn train_config(&self, mode: InitMode, sh_degree: u32) -> splat_train::TrainConfig {
        let cfg = self;
        let t = &cfg.training;
        let surface = mode == InitMode::Surface;
        let mut tc = splat_train::TrainConfig {
            iterations: t.iterations,
            seed: t.seed,
            lr: t.lr,
            ssim_weight: t.ssim_weight,
            photometric: t.photometric,
            sh_degree: Some(sh_degree),
            // Surface init fits every band to the input's colours: switching the higher ones
            // off for the first steps would train the DC to stand in for them, and switch them
            // back on stale. Sparse init starts them at zero and steps them in, as Inria does.
            sh_degree_interval: if surface { 0 } else { t.sh_degree_interval },
            densify: if !surface || cfg.init.densify_surface {
                Some(t.densify)
            } else {
                None
            },
            background: if t.random_background {
                splat_train::Background::Random
            } else {
                splat_train::Background::Fixed([0.0; 3])
            },
            time_budget: t.time_budget_s.map(std::time::Duration::from_secs_f64),
            alpha_loss_weight: t.alpha_loss,
            antialiased: t.antialiased,
            history_every: t.history_every,
            warmup: (t.warmup_factor >= 2 && t.warmup_share > 0.0).then(|| splat_train::Warmup {
                factor: t.warmup_factor,
                until: (self.warmup_share() * f64::from(t.iterations)).round() as u32,
            }),
            ..splat_train::TrainConfig::default()
        };
        // Surface splats sit on the input's points: keep them there unless asked (or densifying).
        tc.frozen.positions = surface && !cfg.init.free_positions && tc.densify.is_none();
        tc
    }

    /// The share of the steps trained on reduced views: `training.warmup_share`, ending where
    /// the splat budget's first round starts (`budget.start_share`) if that comes sooner. A
    /// round judged on a model trained on reduced views finds every merge free, since the
    /// detail a merge removes was never fitted (measured: the paper frame merged down to a
    /// fifth of the splats at 0.9 dB below the full model).
    #[must_use]
    pub fn warmup_share(&self) -> f64 {
        let t = &self.training;
        if self.budget.auto {
            t.warmup_share.min(self.budget.start_share)
        } else {
            t.warmup_share
        }
    }

    /// The evaluator's options: `[eval]`, and the models rendered as they were trained
    /// (`training.antialiased`).
    #[must_use]
    pub fn eval_options(&self) -> splat_train::eval::EvalOptions {
        splat_train::eval::EvalOptions {
            antialiased: self.training.antialiased,
            ..splat_train::eval::EvalOptions::from(&self.eval)
        }
    }

    /// Reads a TOML file; missing keys keep their defaults.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        Self::load_over(path, &Self::default())
    }

    /// Reads a TOML file over `base`: the keys the file sets replace `base`'s, the others keep
    /// `base`'s values (so `transcode demo --config` keeps the demo's own settings for every key
    /// the file leaves out).
    pub fn load_over(path: &Path, base: &Self) -> Result<Self, ConfigError> {
        let bytes = std::fs::read(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        let parse = |message| ConfigError::Parse {
            path: path.to_path_buf(),
            message,
        };
        // TOML is UTF-8: name where it stops being so (the reader's own error named no place).
        let text = String::from_utf8(bytes).map_err(|e| {
            let at = e.utf8_error().valid_up_to();
            let line = 1 + e.as_bytes()[..at].iter().filter(|&&b| b == b'\n').count();
            parse(format!(
                "not UTF-8 text: byte {at} (line {line}) starts no UTF-8 character"
            ))
        })?;
        // Parsed alone first, so that a bad key or value is reported with its line.
        Self::from_toml(&text).map_err(parse)?;
        let file: toml::Table = toml::from_str(&text).map_err(|e| parse(e.to_string()))?;
        let mut merged = toml::Table::try_from(base).map_err(|e| parse(e.to_string()))?;
        merge_tables(&mut merged, file);
        let config = Self::deserialize(merged).map_err(|e| parse(e.to_string()))?;
        config.validate().map_err(|e| match e {
            ConfigError::Invalid { key, problem, .. } => ConfigError::Invalid {
                path: Some(path.to_path_buf()),
                key,
                problem,
            },
            other => other,
        })?;
        Ok(config)
    }

    /// Parses TOML text; the error message names the key and the line.
    pub fn from_toml(text: &str) -> Result<Self, String> {
        toml::from_str(text).map_err(|e| e.to_string().trim_end().to_string())
    }

    /// The configuration as TOML text.
    #[must_use]
    pub fn to_toml(&self) -> String {
        // Serialising plain data with string keys cannot fail.
        toml::to_string_pretty(self).unwrap_or_default()
    }

    /// Checks value ranges that the types do not, section by section.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let invalid = |(key, problem): (String, String)| ConfigError::Invalid {
            path: None,
            key,
            problem,
        };
        self.rig.validate().map_err(invalid)?;
        self.sequence.validate().map_err(invalid)?;
        self.renderer
            .validate()
            .map_err(|e| invalid(("renderer".into(), e.to_string())))?;
        self.budget.validate().map_err(invalid)?;
        self.init.validate().map_err(invalid)?;
        self.training.validate().map_err(invalid)?;
        self.eval.validate().map_err(invalid)?;
        self.output.validate().map_err(invalid)?;
        if self.init.points3d.is_some()
            && self.init.mode != InitMode::Sparse
            && !self.output.compare_init
        {
            return Err(invalid((
                "init.points3d".into(),
                "is set, but only sparse init reads it and no run here is one: add `--init \
                 sparse` (init.mode = \"sparse\") or `--compare-init`, or leave it out"
                    .into(),
            )));
        }
        Ok(())
    }
}

/// The longest time a budget or an interval may be given, in seconds: about 32 years. Anything
/// longer is a typo, and past about 1.8 × 10¹⁹ s a `Duration` cannot hold it.
pub const MAX_SECONDS: f64 = 1e9;

/// Checks a number of seconds: finite, at most [`MAX_SECONDS`], and positive (or zero where
/// `zero_allowed`).
///
/// # Errors
/// What is wrong with it, as the end of a sentence naming the setting.
pub fn check_seconds(s: f64, zero_allowed: bool) -> Result<(), String> {
    let low_ok = s > 0.0 || (zero_allowed && s == 0.0);
    if s.is_finite() && low_ok && s <= MAX_SECONDS {
        Ok(())
    } else {
        // (Exponent form for the large values: 1e300 written out is 301 digits.)
        let got = if s.abs() < 1e12 {
            format!("{s}")
        } else {
            format!("{s:e}")
        };
        Err(format!(
            "must be a number of seconds {} and at most {MAX_SECONDS:e}, got {got}",
            if zero_allowed { "≥ 0" } else { "> 0" }
        ))
    }
}

/// A section's refusal: the offending key and what is wrong with it.
fn bad(key: &str, problem: impl Into<String>) -> Result<(), (String, String)> {
    Err((key.to_string(), problem.into()))
}

impl TrainingConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// The offending key (`training.…`) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        if self.iterations == 0 {
            return bad("training.iterations", "must be at least 1");
        }
        if let Some(b) = self.time_budget_s {
            check_seconds(b, false).or_else(|p| bad("training.time_budget_s", p))?;
        }
        let w = self.ssim_weight;
        if !(w.is_finite() && (0.0..=1.0).contains(&w)) {
            return bad(
                "training.ssim_weight",
                format!("must be in [0, 1], got {w}"),
            );
        }
        let w = self.alpha_loss;
        if !(w.is_finite() && w >= 0.0) {
            return bad(
                "training.alpha_loss",
                format!("must be a finite number ≥ 0, got {w}"),
            );
        }
        let training = |(key, problem): (String, String)| (format!("training.{key}"), problem);
        self.lr.validate().map_err(training)?;
        self.densify.validate().map_err(training)?;
        // A window that ends before it starts is a contradiction in what the user wrote (the
        // trainer's own derived windows, as `transcode train`'s in short runs, may be empty).
        let (start, stop) = (self.densify.start, self.densify.stop);
        if stop <= start {
            return bad(
                "training.densify.stop",
                format!("must be after training.densify.start ({start}), got {stop}"),
            );
        }
        if self.history_every == 0 {
            return bad("training.history_every", "must be at least 1");
        }
        if self.warmup_factor == 0 {
            return bad(
                "training.warmup_factor",
                "must be at least 1 (1 = no warm-up)",
            );
        }
        if !(0.0..=1.0).contains(&self.warmup_share) {
            return bad(
                "training.warmup_share",
                format!("must be in [0, 1], got {}", self.warmup_share),
            );
        }
        Ok(())
    }
}

impl EvalConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// The offending key (`eval.…`) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let f = self.floater_spacings;
        if !(f.is_finite() && f > 0.0) {
            return bad(
                "eval.floater_spacings",
                format!("must be a finite number of point spacings > 0, got {f}"),
            );
        }
        let a = self.alpha_threshold;
        if !(a.is_finite() && (0.0..1.0).contains(&a)) {
            return bad(
                "eval.alpha_threshold",
                format!("must be in [0, 1) (alpha above it counts as covered), got {a}"),
            );
        }
        Ok(())
    }
}

impl OutputConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// The offending key (`output.…`) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let spz = self.spz_version;
        if ![splat_core::spz::VERSION, splat_core::spz::ZSTD_VERSION].contains(&spz) {
            return bad(
                "output.spz_version",
                format!("must be 3 (gzip) or 4 (zstd streams), got {spz}"),
            );
        }
        check_seconds(self.checkpoint_interval_s, true)
            .or_else(|p| bad("output.checkpoint_interval_s", p))
    }
}

impl SequenceConfig {
    /// Checks the ranges.
    ///
    /// # Errors
    /// The offending key (`sequence.…`) and what is wrong with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        if !(self.warm_share > 0.0 && self.warm_share <= 1.0) {
            return bad(
                "sequence.warm_share",
                format!("must be in (0, 1], got {}", self.warm_share),
            );
        }
        Ok(())
    }
}

/// Puts every key of `over` into `base`, descending into tables both have.
fn merge_tables(base: &mut toml::Table, over: toml::Table) {
    for (key, value) in over {
        match (base.get_mut(&key), value) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_tables(b, o),
            (_, value) => {
                base.insert(key, value);
            }
        }
    }
}

/// Loads `path` if given, else the defaults.
pub fn load_or_default(path: Option<&Path>) -> Result<Config, ConfigError> {
    match path {
        Some(p) => Config::load(p),
        None => Ok(Config::default()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_through_toml() {
        let c = Config::default();
        let text = c.to_toml();
        assert!(text.contains("[rig]"));
        assert!(text.contains("cameras = 44"));
        assert!(text.contains("exponent = 10"));
        assert!(text.contains("sh_degree = \"auto\""));
        assert_eq!(Config::from_toml(&text).unwrap(), c);
        c.validate().unwrap();
    }

    #[test]
    fn partial_file_keeps_other_defaults() {
        let c =
            Config::from_toml("[rig]\ncameras = 12\n[init]\nsh_degree = 2\nmode = \"sparse\"\n")
                .unwrap();
        assert_eq!(c.rig.cameras, 12);
        assert_eq!(c.rig.width, RigConfig::default().width);
        assert_eq!(c.init.sh_degree, ShDegree::Fixed(2));
        assert_eq!(c.init.mode, InitMode::Sparse);
    }

    #[test]
    fn partial_trainer_tables_keep_the_trainers_defaults() {
        // `[training.lr]` and `[training.densify]` are splat-train's own structures: a table
        // naming one field must keep Inria's defaults for the others.
        let c = Config::from_toml(
            "[training.lr]\nopacity = 0.02\n[training.densify]\nstart = 50\ninterval = 25\n",
        )
        .unwrap();
        let lr = splat_train::LearningRates::default();
        assert_eq!(c.training.lr.opacity, 0.02);
        assert_eq!(c.training.lr.position_init, lr.position_init);
        assert_eq!(c.training.lr.sh_dc, lr.sh_dc);
        assert_eq!(c.training.lr.scale, lr.scale);
        let d = splat_train::DensifyConfig::default();
        assert_eq!(
            (c.training.densify.start, c.training.densify.interval),
            (50, 25)
        );
        assert_eq!(c.training.densify.stop, d.stop);
        assert_eq!(c.training.densify.grad_threshold, d.grad_threshold);
        assert_eq!(
            c.training.densify.opacity_reset_interval,
            d.opacity_reset_interval
        );
        c.validate().unwrap();
    }

    #[test]
    fn warmup_settings_are_checked() {
        let invalid = |text: &str| {
            let c = Config::from_toml(text).unwrap();
            c.validate().unwrap_err().to_string()
        };
        let e = invalid("[training]\nwarmup_share = 1.5\n");
        assert!(e.contains("training.warmup_share"), "{e}");
        let e = invalid("[training]\nwarmup_factor = 0\n");
        assert!(e.contains("training.warmup_factor"), "{e}");
        // The budget's rounds start at a quarter of the run: a longer warm-up ends there with
        // the budget on, and runs its whole share with it off.
        let long = "[training]\nwarmup_factor = 2\nwarmup_share = 0.5\n";
        let until = |text: &str| {
            let c = Config::from_toml(text).unwrap();
            c.validate().unwrap();
            c.train_config(InitMode::Surface, 3)
                .warmup
                .map(|w| (w.factor, w.until))
        };
        assert_eq!(until(long), Some((2, 500)));
        assert_eq!(
            until(&format!("{long}[budget]\nauto = false\n")),
            Some((2, 1_000))
        );
        assert_eq!(
            until("[training]\nwarmup_factor = 1\nwarmup_share = 0.5\n"),
            None
        );
    }

    /// Each section's own check runs for the whole configuration and names its key.
    #[test]
    fn every_section_is_checked_naming_its_key() {
        for (text, key) in [
            ("[rig]\ncameras = 0\n", "`rig.cameras`"),
            ("[rig]\ncameras = 100000000\n", "`rig.cameras`"),
            (
                "[rig]\nheldout_cameras = 100000000\n",
                "`rig.heldout_cameras`",
            ),
            ("[rig]\nheldout_distances = []\n", "`rig.heldout_distances`"),
            ("[sequence]\nwarm_share = 0.0\n", "`sequence.warm_share`"),
            ("[renderer]\nsupersample = 9\n", "`renderer`"),
            ("[budget]\nkeep = 1.0\n", "`budget.keep`"),
            (
                "[init]\nnormal_neighbours = 2\n",
                "`init.normal_neighbours`",
            ),
            (
                "[training]\nhistory_every = 0\n",
                "`training.history_every`",
            ),
            ("[output]\nspz_version = 2\n", "`output.spz_version`"),
            ("[init]\npoints3d = \"sparse/0\"\n", "`init.points3d`"),
            // Found by an adversarial sweep: NaN, infinities and negatives that passed
            // `config --check` (two of them panicked the run, the eval ones gave wrong metrics).
            (
                "[training]\ntime_budget_s = 1e300\n",
                "`training.time_budget_s`",
            ),
            ("[training]\nssim_weight = nan\n", "`training.ssim_weight`"),
            ("[training]\nalpha_loss = -1.0\n", "`training.alpha_loss`"),
            ("[training.lr]\nsh_dc = inf\n", "`training.lr.sh_dc`"),
            (
                "[training.lr]\nposition_final = nan\n",
                "`training.lr.position_final`",
            ),
            (
                "[training.densify]\ngrad_threshold = nan\n",
                "`training.densify.grad_threshold`",
            ),
            // A second sweep: settings that passed and then failed late or did nothing.
            (
                "[training.densify]\nstart = 100\nstop = 10\n",
                "`training.densify.stop`",
            ),
            ("[init]\nmesh_samples = 0\n", "`init.mesh_samples`"),
            (
                "[training.densify]\npercent_dense = -1.0\n",
                "`training.densify.percent_dense`",
            ),
            (
                "[training.densify]\nmin_opacity = inf\n",
                "`training.densify.min_opacity`",
            ),
            (
                "[training.densify]\nmax_world_scale = nan\n",
                "`training.densify.max_world_scale`",
            ),
            (
                "[training.densify]\ninterval = 0\n",
                "`training.densify.interval`",
            ),
            ("[eval]\nalpha_threshold = nan\n", "`eval.alpha_threshold`"),
            ("[eval]\nalpha_threshold = 5.0\n", "`eval.alpha_threshold`"),
            (
                "[eval]\nfloater_spacings = -1.0\n",
                "`eval.floater_spacings`",
            ),
            ("[renderer]\nbackground = [0.5, 2.0, -1.0]\n", "`renderer`"),
            (
                "[output]\ncheckpoint_interval_s = 1e300\n",
                "`output.checkpoint_interval_s`",
            ),
            (
                "[output]\ncheckpoint_interval_s = -1.0\n",
                "`output.checkpoint_interval_s`",
            ),
        ] {
            let c = Config::from_toml(text).unwrap();
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains(key), "{text}: {e}");
        }
        Config::default().validate().unwrap();
    }

    #[test]
    fn bad_files_name_the_key_and_line() {
        let e = Config::from_toml("[rig]\ncamras = 12\n").unwrap_err();
        assert!(e.contains("camras") && e.contains("line 2"), "{e}");
        let e = Config::from_toml("[init]\nsh_degree = 5\n").unwrap_err();
        assert!(e.contains("SH degree"), "{e}");
        let e = Config::from_toml("[rig]\ncameras = \"many\"\n").unwrap_err();
        assert!(e.contains("cameras"), "{e}");
    }

    #[test]
    fn load_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.toml");
        std::fs::write(&p, "[training]\niterations = 0\n").unwrap();
        let e = Config::load(&p).unwrap_err().to_string();
        assert!(
            e.contains("c.toml") && e.contains("training.iterations"),
            "{e}"
        );
        std::fs::write(&p, "[rig\n").unwrap();
        let e = Config::load(&p).unwrap_err().to_string();
        assert!(e.contains("c.toml"), "{e}");
        let e = Config::load(&dir.path().join("missing.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.toml"), "{e}");
        // Bytes that are not UTF-8 are named by place (the reader said only "stream did not
        // contain valid UTF-8").
        std::fs::write(&p, b"[rig]\ncameras = 8\n# caf\xe9\n").unwrap();
        let e = Config::load(&p).unwrap_err().to_string();
        assert!(
            e.ends_with("c.toml: not UTF-8 text: byte 23 (line 3) starts no UTF-8 character"),
            "{e}"
        );
    }

    /// A file read over another configuration (the demo's) replaces only the keys it sets,
    /// in nested tables too, and still reports a misspelt key with its line.
    #[test]
    fn a_file_over_a_base_changes_only_its_own_keys() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("c.toml");
        let mut base = Config::default();
        base.rig.width = 256;
        base.training.time_budget_s = Some(60.0);
        base.training.lr.opacity = 0.03;
        std::fs::write(
            &p,
            "[init]\nscale_ratio = 1.0\n[training.lr]\nscale = 0.004\n",
        )
        .unwrap();
        let c = Config::load_over(&p, &base).unwrap();
        let mut want = base.clone();
        want.init.scale_ratio = 1.0;
        want.training.lr.scale = 0.004;
        assert_eq!(c, want);
        // Over the defaults it is `load`.
        assert_eq!(
            Config::load(&p).unwrap().rig.width,
            Config::default().rig.width
        );
        std::fs::write(&p, "[init]\nscale_ration = 1.0\n").unwrap();
        let e = Config::load_over(&p, &base).unwrap_err().to_string();
        assert!(
            e.contains("c.toml") && e.contains("scale_ration") && e.contains("line 2"),
            "{e}"
        );
    }

    #[test]
    fn sh_degree_parses_from_flags() {
        assert_eq!("auto".parse::<ShDegree>().unwrap(), ShDegree::Auto);
        assert_eq!("3".parse::<ShDegree>().unwrap(), ShDegree::Fixed(3));
        assert!("4".parse::<ShDegree>().is_err());
    }
}
