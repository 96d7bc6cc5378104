//! Sequences: every frame of a folder (or glob) through the pipeline, each in its own output
//! folder, warm-started from the frame before, resumable, and split into shards for cluster
//! engines (a Slurm job array, a Kubernetes Indexed Job).
//!
//! - [`frames`]: which files are frames, in natural order.
//! - [`shard`]: which contiguous block of frames a task takes.
//! - [`manifest`]: the shard manifests and the merged `sequence.json`.
//! - [`temporal`]: consecutive-frame PSNR of the models beside that of the references.
//! - [`html`]: the sequence report.
//!
//! Layout of `DIR`: `frames/NAME/` (a `transcode run` output folder each), `shards/shard-I-of-N.json`,
//! `sequence.json`, `sequence.html`. Each frame's run writes atomically and resumes from its
//! checkpoints, and the shard manifest is rewritten atomically after every change, so a kill
//! at any moment loses at most the training since the frame's last checkpoint.

pub mod frames;
pub mod html;
pub mod manifest;
pub mod shard;
pub mod temporal;

use std::path::{Path, PathBuf};

use plenoptic_io::Model;
use plenoptic_render::FramingSphere;

use crate::config::Config;
use crate::pipeline::{self, Finish, PipelineError, RunOptions, WarmStart};
use crate::progress::{Event, Observer};
use crate::resume::{ResumeError, RunState, config_differences};
pub use frames::{Frame, list_frames};
pub use manifest::{
    FrameRecord, FrameResult, FrameState, SequenceManifest, ShardManifest, read_shard_manifests,
};
pub use shard::Shard;

/// Errors of a sequence as a whole (a frame's own failure is recorded in the manifest instead).
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    /// The input names no frames, or frames that cannot make a sequence.
    #[error("{0}")]
    NoFrames(String),
    /// A bad `--shard` or shard environment variable.
    #[error("{0}")]
    Shard(String),
    /// A frame cannot be part of this sequence (checked before its run).
    #[error("frame {frame}: {problem}")]
    Frame {
        /// The frame's file.
        frame: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A manifest or report cannot be read or is malformed.
    #[error("{path}: {problem}")]
    Manifest {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A file or folder cannot be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// A frame loaded to fix the rig could not be loaded.
    #[error("frame {frame}: {source}")]
    Load {
        /// The frame's file.
        frame: PathBuf,
        /// The cause.
        source: Box<PipelineError>,
    },
}

/// What every frame of a sequence must share with the first: the kind of input and the capture
/// rig (camera count and positions) of plenoptic clouds.
#[derive(Debug, Clone, PartialEq)]
struct CaptureRig {
    kind: &'static str,
    cameras: usize,
    positions: Vec<[f64; 3]>,
}

impl CaptureRig {
    fn of(model: &Model) -> Self {
        match model {
            Model::Cloud(c) => Self {
                kind: if c.num_cameras > 0 {
                    "plenoptic cloud"
                } else {
                    "point cloud"
                },
                cameras: c.num_cameras,
                positions: c.cameras.iter().map(|k| k.position.to_array()).collect(),
            },
            Model::Mesh(_) => Self {
                kind: "mesh",
                cameras: 0,
                positions: Vec::new(),
            },
        }
    }

    /// Why `self` (a frame's) differs from `first` (the sequence's first frame's), if it does.
    fn difference(&self, first: &Self, first_name: &str) -> Option<String> {
        if self.kind != first.kind {
            return Some(format!(
                "is a {}, frame {first_name} a {}",
                self.kind, first.kind
            ));
        }
        if self.cameras != first.cameras {
            return Some(format!(
                "has {} capture cameras, frame {first_name} has {}",
                self.cameras, first.cameras
            ));
        }
        let moved = self
            .positions
            .iter()
            .zip(&first.positions)
            .position(|(a, b)| {
                a.iter()
                    .zip(b)
                    .any(|(x, y)| (x - y).abs() > 1e-6 * x.abs().max(y.abs()).max(1.0))
            });
        if self.positions.len() != first.positions.len() || moved.is_some() {
            return Some(format!(
                "has a different capture rig from frame {first_name} (camera {} differs)",
                moved.unwrap_or(self.positions.len().min(first.positions.len()))
            ));
        }
        None
    }
}

/// The frame every other frame's capture rig is compared with: the first that loads.
struct RigReference {
    /// Its index in the sequence.
    index: usize,
    rig: CaptureRig,
}

/// The sphere every frame's cameras frame: the configured `rig.sphere`, else the smallest sphere
/// holding the bounding spheres of the sequence's first, middle and last frames (the same for
/// every shard, since every shard lists the same frames). A frame there that does not load is
/// replaced by the nearest one that does (forwards from the first and middle, backwards from the
/// last), so one bad frame fails alone, in its own shard, instead of stopping every shard. Also
/// returns the rig reference: the first frame that loads.
fn sequence_sphere(
    frames: &[Frame],
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(FramingSphere, RigReference), SequenceError> {
    let n = frames.len();
    // The first frame at or after `from` (or at or before it, going back) that loads.
    let loadable = |from: usize, forwards: bool| -> Option<(usize, pipeline::Loaded)> {
        let order: Box<dyn Iterator<Item = usize>> = if forwards {
            Box::new(from..n)
        } else {
            Box::new((0..=from).rev())
        };
        order
            .filter_map(|k| {
                pipeline::load(&frames[k].path, &crate::progress::ignore)
                    .ok()
                    .map(|l| (k, l))
            })
            .next()
    };
    let Some((first_index, first)) = loadable(0, true) else {
        // Every frame fails to load: name the first frame and why.
        let error = pipeline::load(&frames[0].path, &crate::progress::ignore)
            .err()
            .map_or_else(|| "cannot be loaded".to_string(), |e| e.to_string());
        return Err(SequenceError::NoFrames(format!(
            "no frame of the sequence loads; the first, {}: {error}",
            frames[0].path.display()
        )));
    };
    let reference = RigReference {
        index: first_index,
        rig: CaptureRig::of(&first.model),
    };
    if let Some(sphere) = cfg.rig.sphere {
        return Ok((sphere, reference));
    }
    let bounds = |model: &Model, k: usize| {
        plenoptic_render::bounding_sphere(model)
            .map(|(c, r)| FramingSphere {
                center: c.to_array(),
                radius: r,
            })
            .map_err(|e| SequenceError::Load {
                frame: frames[k].path.clone(),
                source: Box::new(PipelineError::from(e)),
            })
    };
    let mut sphere = bounds(&first.model, first_index)?;
    let mut used = vec![first_index];
    for (from, forwards) in [(n / 2, true), (n - 1, false)] {
        if let Some((k, loaded)) = loadable(from, forwards)
            && !used.contains(&k)
        {
            sphere = sphere.union(bounds(&loaded.model, k)?);
            used.push(k);
        }
    }
    let names: Vec<&str> = used.iter().map(|&k| frames[k].name.as_str()).collect();
    observer(Event::Note(format!(
        "cameras frame the sphere at ({:.3}, {:.3}, {:.3}), radius {:.3} (frames {})",
        sphere.center[0],
        sphere.center[1],
        sphere.center[2],
        sphere.radius,
        names.join(", ")
    )));
    Ok((sphere, reference))
}

/// Whether frames warm-start: asked for, and possible (surface init whose splats keep their
/// count through training, so that the previous frame's initial and trained splats pair up).
#[must_use]
pub fn warm_starts(cfg: &Config) -> bool {
    cfg.sequence.warm_start
        && cfg.init.mode == crate::config::InitMode::Surface
        && !cfg.init.densify_surface
}

/// The configuration of one frame: the sequence's, with the fixed sphere, and for a warm start
/// the shorter schedule (`sequence.warm_share` of the steps and of any time budget) and no
/// coarse warm-up: a warm start begins with the previous frame's detail, which steps on
/// reduced views would blur before the full ones fit it again.
#[must_use]
pub fn frame_config(cfg: &Config, sphere: FramingSphere, warm: bool) -> Config {
    let mut c = cfg.clone();
    c.rig.sphere = Some(sphere);
    if warm {
        let share = cfg.sequence.warm_share;
        c.training.iterations =
            ((f64::from(cfg.training.iterations) * share).round() as u32).max(1);
        c.training.time_budget_s = cfg.training.time_budget_s.map(|b| b * share);
        c.training.warmup_factor = 1;
    }
    c
}

/// Runs `shard`'s block of `frames` into `out`, skipping finished frames and resuming an
/// unfinished one; rewrites `shards/shard-I-of-N.json` after every change. A frame that fails
/// is recorded and the next one goes on (cold). Returns the shard's manifest.
pub fn run_shard(
    input: &str,
    frames: &[Frame],
    out: &Path,
    cfg: &Config,
    shard: Shard,
    observer: Observer<'_>,
) -> Result<ShardManifest, SequenceError> {
    cfg.validate()?;
    if frames.is_empty() {
        return Err(SequenceError::NoFrames(format!("{input} names no frames")));
    }
    let mut own = cfg.clone();
    if own.sequence.warm_start && own.budget.auto {
        // A warm start takes each splat's training corrections from the previous frame's splat
        // that began at the same point, so a frame's trained splats must match its initial ones
        // one to one: the automatic budget, which merges splats, is off in warm sequences (the
        // splat count is `--splats K`, or every point).
        own.budget.auto = false;
        observer(Event::Note(
            "warm starts need each frame's splats to match its initial points one to one: the \
             automatic splat budget is off (choose the count with --splats K)"
                .into(),
        ));
    }
    let cfg = &own;
    // One process a shard: a requeued task whose first attempt still runs, or an array
    // submitted twice, would rewrite this shard's manifest and frames under the other.
    let _writer = crate::lock::WriterLock::acquire(&ShardManifest::lock_path(out, shard))
        .map_err(|e| SequenceError::Shard(format!("shard {shard}: {e}")))?;
    let block = shard.block(frames.len());
    let (sphere, reference) = sequence_sphere(frames, cfg, observer)?;
    let mut manifest = ShardManifest {
        version: manifest::MANIFEST_VERSION,
        input: input.to_string(),
        shard,
        frames_total: frames.len(),
        sphere,
        frames: frames[block.clone()]
            .iter()
            .map(|f| FrameRecord::pending(f, shard))
            .collect(),
    };
    manifest.save(out)?;
    let of = frames.len();
    // Whether the previous frame of the block was trained (or finished training) in this
    // call: a frame warm-started from it must then be trained anew, whatever it saved.
    let mut previous_trained = false;
    for (k, i) in block.enumerate() {
        let frame = &frames[i];
        let dir = out.join("frames").join(&frame.name);
        // Warm from the previous frame of this block when it finished.
        let previous = (k > 0)
            .then(|| &manifest.frames[k - 1])
            .filter(|p| warm_starts(cfg) && p.state == FrameState::Finished)
            .map(|p| {
                let start = WarmStart {
                    input: p.input.clone(),
                    model: out.join(&p.dir).join("model").join("splats.ply"),
                };
                (p.name.clone(), start)
            });
        let (frame_cfg, warm) = choose_start(cfg, sphere, &dir, previous)?;
        manifest.frames[k].state = FrameState::Running;
        manifest.frames[k].warm_start = warm.as_ref().map(|(name, _)| name.clone());
        manifest.frames[k].error = None;
        manifest.save(out)?;
        observer(Event::Frame {
            index: i + 1,
            of,
            name: frame.name.clone(),
            what: match &warm {
                Some((name, _)) => format!("warm start from {name}"),
                None => "cold start".into(),
            },
        });
        let fresh = warm.is_some() && previous_trained;
        let outcome = check_rig(frame, &frames[reference.index], &reference.rig).and_then(|()| {
            let start = warm.map(|(_, start)| start);
            run_frame(frame, &dir, &frame_cfg, start, fresh, observer).map_err(|e| e.to_string())
        });
        previous_trained = matches!(outcome, Ok(Finish::Completed(_)));
        let record = &mut manifest.frames[k];
        match outcome {
            Ok(finish) => {
                if matches!(finish, Finish::AlreadyFinished { .. }) {
                    observer(Event::Note(format!("{} was finished already", frame.name)));
                    // What the model was made from, which the plan of this call may not be
                    // (a frame warm-started by an earlier call whose previous frame failed now).
                    record.warm_start = saved_warm_start(&dir);
                }
                record.result = Some(FrameResult::from_report(
                    &dir.join("report").join("report.json"),
                )?);
                record.state = FrameState::Finished;
            }
            Err(error) => {
                observer(Event::Note(format!("frame {} failed: {error}", frame.name)));
                record.state = FrameState::Failed;
                record.error = Some(error);
            }
        }
        manifest.save(out)?;
    }
    Ok(manifest)
}

/// Runs one frame into `dir`: continues its saved run (or leaves it when it finished), and
/// trains it anew when `fresh` (the frame it warms from was trained anew) or when the saved
/// run began with another input or configuration, which a note says: a sequence re-run after
/// a frame's file or the settings changed redoes what they changed.
fn run_frame(
    frame: &Frame,
    dir: &Path,
    cfg: &Config,
    warm_start: Option<WarmStart>,
    fresh: bool,
    observer: Observer<'_>,
) -> Result<Finish, PipelineError> {
    let run = |resume: bool| {
        let opts = RunOptions {
            resume,
            warm_start: warm_start.clone(),
        };
        pipeline::run_with(&frame.path, dir, cfg, opts, observer)
    };
    if fresh {
        return run(false);
    }
    match run(true) {
        Err(PipelineError::Resume(ResumeError::Mismatch { what, .. })) => {
            observer(Event::Note(format!(
                "{}: its earlier run began with {what}; it is trained again",
                frame.name
            )));
            run(false)
        }
        // A finished frame whose model or report was removed or cut short since: failing it
        // on every re-run, with advice to drop a `--resume` the command does not have, left it
        // failed until its folder was deleted by hand.
        Err(PipelineError::Resume(ResumeError::OutputsGone { problem, .. })) => {
            observer(Event::Note(format!(
                "{}: its earlier run finished, but {problem}; it is trained again",
                frame.name
            )));
            run(false)
        }
        other => other,
    }
}

/// The frame a finished run in `dir` was warm-started from, by the folder name of the model
/// its state records (`frames/NAME/model/splats.ply`); `None` for a cold start or no state.
fn saved_warm_start(dir: &Path) -> Option<String> {
    let state = RunState::load(dir).ok().flatten()?;
    let model = state.modes.iter().find_map(|m| m.init.warm_start.clone())?;
    let frame_dir = model.parent()?.parent()?;
    Some(frame_dir.file_name()?.to_string_lossy().into_owned())
}

/// The frame's configuration and warm start. A frame with a saved run keeps the start that
/// run began with (its configuration says which), so that re-running resumes it even when the
/// previous frame has since finished or failed; otherwise warm when `previous` is given.
fn choose_start(
    cfg: &Config,
    sphere: FramingSphere,
    dir: &Path,
    previous: Option<(String, WarmStart)>,
) -> Result<(Config, Option<(String, WarmStart)>), SequenceError> {
    let (cold, warm_cfg) = (
        frame_config(cfg, sphere, false),
        frame_config(cfg, sphere, true),
    );
    let saved = RunState::load(dir)
        .ok()
        .flatten()
        .and_then(|state| Config::from_toml(&state.config).ok());
    if let Some(mut saved) = saved {
        saved.sequence = cfg.sequence.clone(); // as the resume check does
        saved.output.checkpoint_interval_s = cfg.output.checkpoint_interval_s;
        if config_differences(&saved, &cold).is_empty() {
            return Ok((cold, None));
        }
        if config_differences(&saved, &warm_cfg).is_empty() {
            return Ok((warm_cfg, previous));
        }
    }
    Ok(match previous {
        Some(p) => (warm_cfg, Some(p)),
        None => (cold, None),
    })
}

/// Loads `frame` and refuses it when its input kind or capture rig differs from the first
/// frame's. (The pipeline loads it again: a load is seconds, a frame's training minutes.)
fn check_rig(frame: &Frame, first: &Frame, first_rig: &CaptureRig) -> Result<(), String> {
    if frame.path == first.path {
        return Ok(());
    }
    if !frame.path.exists() {
        return Err(SequenceError::Frame {
            frame: frame.path.clone(),
            problem: "is missing: the sequence's numbering has a hole here (the frames on \
                      either side exist)"
                .into(),
        }
        .to_string());
    }
    let loaded =
        pipeline::load(&frame.path, &crate::progress::ignore).map_err(|e| e.to_string())?;
    match CaptureRig::of(&loaded.model).difference(first_rig, &first.name) {
        Some(problem) => Err(SequenceError::Frame {
            frame: frame.path.clone(),
            problem,
        }
        .to_string()),
        None => Ok(()),
    }
}

/// Merges every shard manifest in `out` into `sequence.json` with the temporal-stability
/// figures and writes `sequence.html`. Returns the merged manifest.
pub fn collect(
    input: &str,
    frames: &[Frame],
    out: &Path,
) -> Result<SequenceManifest, SequenceError> {
    let shards = read_shard_manifests(out)?;
    let mut merged = SequenceManifest::merge(input, frames, &shards);
    for pair in merged.frames.windows(2) {
        let (a, b) = (&pair[0], &pair[1]);
        if a.state == FrameState::Finished
            && b.state == FrameState::Finished
            && let Some(point) = temporal::temporal_point(
                (&a.name, &out.join(&a.dir)),
                (&b.name, &out.join(&b.dir)),
            )?
        {
            merged.temporal.push(point);
        }
    }
    merged.save(out)?;
    html::write(out, &merged)?;
    Ok(merged)
}

/// Whether every frame has a finished or failed record in the shard manifests of `out`: the
/// shard that sees this after its own block is the last, and collects.
pub fn all_frames_done(frames: &[Frame], out: &Path) -> Result<bool, SequenceError> {
    let shards = read_shard_manifests(out)?;
    let merged = SequenceManifest::merge("", frames, &shards);
    Ok(merged
        .frames
        .iter()
        .all(|r| matches!(r.state, FrameState::Finished | FrameState::Failed)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use plenoptic_io::{CaptureCamera, PlenopticCloud};

    fn cloud(cameras: &[[f64; 3]]) -> Model {
        Model::Cloud(PlenopticCloud {
            num_cameras: cameras.len(),
            cameras: cameras
                .iter()
                .map(|p| CaptureCamera {
                    position: glam::DVec3::from(*p),
                    matrix: None,
                })
                .collect(),
            ..Default::default()
        })
    }

    #[test]
    fn capture_rigs_must_match() {
        let first = CaptureRig::of(&cloud(&[[0.0, 0.0, 10.0], [10.0, 0.0, 0.0]]));
        let same = CaptureRig::of(&cloud(&[[0.0, 0.0, 10.0], [10.0, 0.0, 1e-9]]));
        assert_eq!(same.difference(&first, "f0"), None);
        let fewer = CaptureRig::of(&cloud(&[[0.0, 0.0, 10.0]]));
        assert!(
            fewer
                .difference(&first, "f0")
                .unwrap()
                .contains("1 capture cameras")
        );
        let moved = CaptureRig::of(&cloud(&[[0.0, 0.0, 10.0], [10.0, 1.0, 0.0]]));
        assert!(
            moved
                .difference(&first, "f0")
                .unwrap()
                .contains("camera 1 differs")
        );
        let plain = CaptureRig::of(&cloud(&[]));
        assert!(
            plain
                .difference(&first, "f0")
                .unwrap()
                .contains("point cloud")
        );
    }

    #[test]
    fn warm_frames_train_the_configured_share() {
        let mut cfg = Config::default();
        cfg.training.iterations = 2000;
        cfg.training.time_budget_s = Some(100.0);
        cfg.sequence.warm_share = 0.3;
        let sphere = FramingSphere {
            center: [1.0, 2.0, 3.0],
            radius: 4.0,
        };
        let warm = frame_config(&cfg, sphere, true);
        assert_eq!(warm.training.iterations, 600);
        assert_eq!(warm.training.time_budget_s, Some(30.0));
        assert_eq!(warm.rig.sphere, Some(sphere));
        assert_eq!(
            warm.training.warmup_factor, 1,
            "no warm-up from a trained model"
        );
        let cold = frame_config(&cfg, sphere, false);
        assert_eq!(cold.training.iterations, 2000);
        assert_eq!(cold.training.warmup_factor, cfg.training.warmup_factor);
    }
}
