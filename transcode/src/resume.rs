//! The saved state of a pipeline run, so that a run killed at any moment can continue
//! (`transcode run --resume`) and an unfinished run never looks finished.
//!
//! `DIR/state.json` says `running` from the moment a run starts until its model and report are
//! written, then `finished`. It records what the run was asked to do (the input's path, size and
//! modification time; the whole configuration) and what it has done: whether the COLMAP dataset
//! is written and, for each init mode, the initialisation summary and the training schedule chosen
//! before its first step (with `--time-budget`, the step estimate from timed probe steps, which a
//! resumed run must not measure again), and whether its training is over. The trainer's own state
//! goes to `DIR/checkpoints/<mode>.ckpt` (see `splat_train::checkpoint`). Everything else (the
//! rendered views, the evaluation, the report) is recomputed on resume: it is deterministic.

use std::path::{Path, PathBuf};
use std::time::{Duration, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use crate::config::{Config, InitMode};
use atomic_output::write_atomic;
use splat_init::InitSummary;

/// Name of the state file in the output folder.
pub const STATE_FILE: &str = "state.json";
/// Folder of the trainer checkpoints in the output folder (removed when the run finishes).
pub const CHECKPOINT_DIR: &str = "checkpoints";
/// Version of the state file's layout.
const FORMAT: u32 = 1;

/// Whether a run is under way (or was interrupted) or finished.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    /// Started and not finished: the outputs are incomplete.
    Running,
    /// The model and the report are written.
    Finished,
}

/// What identifies the input file: a changed file must not be resumed as if it were the same.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InputStamp {
    /// The path as given, made absolute where possible.
    pub path: PathBuf,
    /// Size in bytes.
    pub bytes: u64,
    /// Modification time in nanoseconds since the Unix epoch (as a string: JSON numbers are
    /// doubles in many readers), when the file system keeps one.
    pub modified_ns: Option<String>,
}

impl InputStamp {
    /// The stamp of `path` now.
    pub fn of(path: &Path) -> std::io::Result<Self> {
        let meta = std::fs::metadata(path)?;
        let modified_ns = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
            .map(|d| d.as_nanos().to_string());
        Ok(Self {
            path: std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf()),
            bytes: meta.len(),
            modified_ns,
        })
    }
}

/// The training schedule of one init mode, fixed before its first step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Schedule {
    /// Steps the densification schedule is scaled to (`splat_train::schedule::scale_densify`): the iteration
    /// count, or the estimate from the probe steps under a time budget. `None` when the schedule
    /// is used as configured.
    pub densify_steps: Option<u32>,
    /// The training time budget left after the probe, when there is a budget.
    pub time_budget: Option<Duration>,
    /// When the automatic splat budget's rounds run; `None`: no search.
    #[serde(default)]
    pub budget: Option<splat_train::BudgetPlan>,
    /// Seconds a step took on the probe before training, when a probe ran (the run itself
    /// re-estimates as it goes: `splat_train::schedule::Pace`).
    #[serde(default)]
    pub step_estimate_s: Option<f64>,
    /// The speeds the probe timed, from which the run's own estimate starts.
    #[serde(default)]
    pub pace: Option<splat_train::schedule::Pace>,
}

/// What one init mode has done.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ModeState {
    /// Surface or sparse.
    pub mode: InitMode,
    /// Its initialisation, for the report (the splats themselves are rebuilt or checkpointed).
    pub init: InitSummary,
    /// Its training schedule.
    pub schedule: Schedule,
    /// Held-out scores at step 0, for the report.
    #[serde(default)]
    pub step_zero: Option<crate::report::StepZero>,
    /// Held-out curve up to the last checkpoint (`eval.every`).
    #[serde(default)]
    pub heldout_curve: Vec<crate::report::HeldoutPoint>,
    /// The automatic splat budget's rounds up to the last checkpoint.
    #[serde(default)]
    pub budget: splat_train::BudgetSearch,
    /// `Some` once training is over (its last state is in the checkpoint): whether the time
    /// budget stopped it.
    pub trained: Option<TrainedState>,
}

/// The end of a mode's training.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct TrainedState {
    /// Whether the time budget ended training before the iteration count.
    pub stopped_by_budget: bool,
}

/// Contents of `DIR/state.json`.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RunState {
    /// Layout version of this file.
    pub format: u32,
    /// Running or finished.
    pub status: Status,
    /// Version of the transcoder that started the run.
    pub version: String,
    /// The input.
    pub input: InputStamp,
    /// The configuration as TOML (TOML keeps every float exactly).
    pub config: String,
    /// Whether `DIR/dataset` is completely written.
    pub dataset_written: bool,
    /// The init modes begun, in the order they run.
    pub modes: Vec<ModeState>,
}

/// Why a run cannot be resumed.
#[derive(Debug, thiserror::Error)]
pub enum ResumeError {
    /// The state file cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The state file is not one this build wrote.
    #[error("{path} is not a valid run state ({problem}); run without --resume to start over")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A trainer checkpoint cannot be resumed from.
    #[error("cannot resume from {path}: {problem}; run without --resume to start over")]
    Checkpoint {
        /// The checkpoint.
        path: PathBuf,
        /// What is wrong with it.
        problem: String,
    },
    /// The run finished, but what it wrote is gone or damaged (its model or report removed,
    /// cut short or overwritten since).
    #[error("the run in {dir} finished, but {problem}; run without --resume to start over")]
    OutputsGone {
        /// The output folder.
        dir: PathBuf,
        /// What is missing or unreadable.
        problem: String,
    },
    /// The run was started with another configuration or input.
    #[error(
        "the run in {dir} was started with {what}; resume it with the same settings, or run \
         without --resume to start over"
    )]
    Mismatch {
        /// The output folder.
        dir: PathBuf,
        /// What differs.
        what: String,
    },
}

impl RunState {
    /// The state of a run that has just started.
    #[must_use]
    pub fn start(input: InputStamp, config: &Config) -> Self {
        Self {
            format: FORMAT,
            status: Status::Running,
            version: env!("CARGO_PKG_VERSION").to_string(),
            input,
            config: config.to_toml(),
            dataset_written: false,
            modes: Vec::new(),
        }
    }

    /// Reads `DIR/state.json`; `None` when there is none.
    pub fn load(dir: &Path) -> Result<Option<Self>, ResumeError> {
        let path = dir.join(STATE_FILE);
        let bytes = match std::fs::read(&path) {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(source) => return Err(ResumeError::Io { path, source }),
        };
        let state: Self = serde_json::from_slice(&bytes).map_err(|e| ResumeError::Malformed {
            path: path.clone(),
            problem: e.to_string(),
        })?;
        if state.format != FORMAT {
            return Err(ResumeError::Malformed {
                path,
                problem: format!("layout {}, this build reads {FORMAT}", state.format),
            });
        }
        Ok(Some(state))
    }

    /// Writes `DIR/state.json` atomically.
    pub fn save(&self, dir: &Path) -> Result<(), ResumeError> {
        let path = dir.join(STATE_FILE);
        // Plain data with string keys: encoding cannot fail.
        let json = serde_json::to_vec_pretty(self).unwrap_or_default();
        write_atomic(&path, &json).map_err(|source| ResumeError::Io { path, source })
    }

    /// Refuses to continue this saved run with another input or configuration. The checkpoint
    /// interval may differ: checkpoints do not change what is computed.
    pub fn check_same_run(
        &self,
        dir: &Path,
        input: &InputStamp,
        config: &Config,
    ) -> Result<(), ResumeError> {
        let mismatch = |what: String| ResumeError::Mismatch {
            dir: dir.to_path_buf(),
            what,
        };
        if self.input.path != input.path {
            return Err(mismatch(format!(
                "the input {}, not {}",
                self.input.path.display(),
                input.path.display()
            )));
        }
        if self.input != *input {
            return Err(mismatch(format!(
                "a different version of {} (size or modification time changed)",
                input.path.display()
            )));
        }
        let mut saved =
            Config::from_toml(&self.config).map_err(|problem| ResumeError::Malformed {
                path: dir.join(STATE_FILE),
                problem,
            })?;
        saved.output.checkpoint_interval_s = config.output.checkpoint_interval_s;
        // `[sequence]` only chooses each frame's settings (a warm frame's shorter schedule is
        // in `training`), so a sequence re-run with another warm share still finds its
        // finished and interrupted frames.
        saved.sequence = config.sequence.clone();
        if saved != *config {
            let keys = config_differences(&saved, config);
            return Err(mismatch(format!(
                "another configuration (differs in {})",
                if keys.is_empty() {
                    "its values".to_string()
                } else {
                    keys.join(", ")
                }
            )));
        }
        Ok(())
    }
}

/// The trainer checkpoint of `mode` in the output folder `dir`.
#[must_use]
pub fn checkpoint_path(dir: &Path, mode: InitMode) -> PathBuf {
    dir.join(CHECKPOINT_DIR).join(format!("{mode}.ckpt"))
}

/// Dotted keys whose values differ between two configurations, with both values.
#[must_use]
pub fn config_differences(saved: &Config, now: &Config) -> Vec<String> {
    fn walk(prefix: &str, a: &serde_json::Value, b: &serde_json::Value, out: &mut Vec<String>) {
        use serde_json::Value;
        match (a, b) {
            (Value::Object(x), Value::Object(y)) => {
                let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
                keys.sort();
                keys.dedup();
                for k in keys {
                    let key = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(
                        &key,
                        x.get(k).unwrap_or(&Value::Null),
                        y.get(k).unwrap_or(&Value::Null),
                        out,
                    );
                }
            }
            _ if a != b => out.push(format!("`{prefix}`: saved {a}, now {b}")),
            _ => {}
        }
    }
    let (Ok(a), Ok(b)) = (serde_json::to_value(saved), serde_json::to_value(now)) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    walk("", &a, &b, &mut out);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn state_round_trips_and_refuses_other_settings() {
        let dir = tempfile::tempdir().unwrap();
        let input = dir.path().join("in.ply");
        std::fs::write(&input, b"ply").unwrap();
        let stamp = InputStamp::of(&input).unwrap();
        let mut cfg = Config::default();
        cfg.training.time_budget_s = Some(0.1 + 0.2);
        let mut state = RunState::start(stamp.clone(), &cfg);
        state.dataset_written = true;
        state.save(dir.path()).unwrap();
        let back = RunState::load(dir.path()).unwrap().unwrap();
        assert!(back.dataset_written && back.status == Status::Running);

        // The same settings pass, whatever the checkpoint interval and the sequence settings
        // (they only choose a frame's settings); floats survive exactly.
        let mut same = cfg.clone();
        same.output.checkpoint_interval_s = 1.0;
        same.sequence.warm_share = 0.5;
        same.sequence.warm_start = false;
        back.check_same_run(dir.path(), &stamp, &same).unwrap();

        let mut other = cfg.clone();
        other.training.iterations += 1;
        other.rig.width = 100;
        let msg = back
            .check_same_run(dir.path(), &stamp, &other)
            .unwrap_err()
            .to_string();
        assert!(
            msg.contains("`rig.width`: saved 512, now 100")
                && msg.contains("`training.iterations`: saved 2000, now 2001")
                && msg.contains("without --resume"),
            "{msg}"
        );

        let mut changed = stamp.clone();
        changed.bytes += 1;
        let msg = back
            .check_same_run(dir.path(), &changed, &cfg)
            .unwrap_err()
            .to_string();
        assert!(msg.contains("different version"), "{msg}");

        std::fs::write(dir.path().join(STATE_FILE), b"{\"format\": 1").unwrap();
        let msg = RunState::load(dir.path()).unwrap_err().to_string();
        assert!(msg.contains("not a valid run state"), "{msg}");
        std::fs::remove_file(dir.path().join(STATE_FILE)).unwrap();
        assert!(RunState::load(dir.path()).unwrap().is_none());
    }
}
