//! The manifests of a sequence: one per shard (`shards/shard-I-of-N.json`), rewritten after
//! every change of a frame's state, and the merged `sequence.json`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::SequenceError;
use super::shard::Shard;
use super::temporal::TemporalPoint;
use plenoptic_render::FramingSphere;

/// Layout version of the manifests.
pub const MANIFEST_VERSION: u32 = 1;

/// Where a frame stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrameState {
    /// Not begun (or its shard has not reported).
    Pending,
    /// Begun and not finished: in flight, or killed (re-running resumes it).
    Running,
    /// Model, report and metrics written.
    Finished,
    /// Failed; `error` says why. The other frames went on.
    Failed,
}

/// What a finished frame produced, from its `report/report.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameResult {
    /// Wall time of the frame's whole pipeline (load to report), seconds.
    pub seconds: f64,
    /// Training wall time, seconds.
    pub train_seconds: f64,
    /// Training steps run.
    pub iterations: u32,
    /// Splats in the model.
    pub splats: usize,
    /// Size of `model/splats.ply`.
    pub model_bytes: u64,
    /// Size of `model/splats.spz`, when written.
    pub spz_bytes: Option<u64>,
    /// Held-out PSNR on black, dB.
    pub psnr_black: f64,
    /// Held-out PSNR on white, dB.
    pub psnr_white: f64,
    /// Held-out PSNR over the object's pixels only, on black, dB.
    pub masked_psnr_black: f64,
    /// Held-out SSIM on black.
    pub ssim_black: f64,
}

impl FrameResult {
    /// Reads the main model's figures from a run's `report/report.json`.
    pub fn from_report(path: &Path) -> Result<Self, SequenceError> {
        let malformed = |problem: String| SequenceError::Manifest {
            path: path.to_path_buf(),
            problem,
        };
        let text = std::fs::read_to_string(path).map_err(|source| SequenceError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let report: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| malformed(e.to_string()))?;
        let run = &report["runs"][0];
        let f = |v: &serde_json::Value, key: &str| {
            v[key]
                .as_f64()
                .ok_or_else(|| malformed(format!("no number at `{key}`")))
        };
        let m = &run["metrics"];
        let spz_bytes = run["compact_files"].as_array().and_then(|files| {
            files.iter().find_map(|f| {
                let path = f[0].as_str()?;
                path.ends_with(".spz").then(|| f[1].as_u64()).flatten()
            })
        });
        Ok(Self {
            seconds: f(&report, "total_seconds")?,
            train_seconds: f(run, "train_seconds")?,
            iterations: f(run, "iterations")? as u32,
            splats: f(m, "splats")? as usize,
            model_bytes: f(run, "model_bytes")? as u64,
            spz_bytes,
            psnr_black: f(m, "psnr_black")?,
            psnr_white: f(m, "psnr_white")?,
            masked_psnr_black: f(m, "masked_psnr_black")?,
            ssim_black: f(m, "ssim_black")?,
        })
    }
}

/// One frame in a manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// The frame's name (its file stem).
    pub name: String,
    /// The input file.
    pub input: PathBuf,
    /// Its output folder, relative to the sequence's: `frames/NAME`.
    pub dir: PathBuf,
    /// Where it stands.
    pub state: FrameState,
    /// The shard that ran it.
    pub shard: Shard,
    /// The frame whose trained model it started from (warm start); `None`: a cold start.
    pub warm_start: Option<String>,
    /// Its figures, once finished.
    pub result: Option<FrameResult>,
    /// Why it failed.
    pub error: Option<String>,
}

impl FrameRecord {
    /// A frame not yet begun, in `shard`'s block; its output folder is `frames/NAME`.
    #[must_use]
    pub fn pending(frame: &super::Frame, shard: Shard) -> Self {
        Self {
            name: frame.name.clone(),
            input: frame.path.clone(),
            dir: Path::new("frames").join(&frame.name),
            state: FrameState::Pending,
            shard,
            warm_start: None,
            result: None,
            error: None,
        }
    }
}

/// `shards/shard-I-of-N.json`: the frames of one shard.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardManifest {
    /// [`MANIFEST_VERSION`].
    pub version: u32,
    /// The sequence's input (folder or glob) as given.
    pub input: String,
    /// Which shard.
    pub shard: Shard,
    /// Frames in the whole sequence.
    pub frames_total: usize,
    /// The sphere every frame's cameras frame.
    pub sphere: FramingSphere,
    /// This shard's frames, in order.
    pub frames: Vec<FrameRecord>,
}

impl ShardManifest {
    /// `DIR/shards/shard-I-of-N.json`.
    #[must_use]
    pub fn path(out: &Path, shard: Shard) -> PathBuf {
        out.join("shards")
            .join(format!("shard-{}-of-{}.json", shard.index, shard.count))
    }

    /// `DIR/shards/.shard-I-of-N.lock`, held by the process running the shard.
    #[must_use]
    pub fn lock_path(out: &Path, shard: Shard) -> PathBuf {
        out.join("shards")
            .join(format!(".shard-{}-of-{}.lock", shard.index, shard.count))
    }

    /// Writes it atomically.
    pub fn save(&self, out: &Path) -> Result<(), SequenceError> {
        write_json(&Self::path(out, self.shard), self)
    }
}

/// Counts of the frames by state, and the figures a planner wants.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SequenceSummary {
    /// All frames.
    pub frames: usize,
    /// Finished frames.
    pub finished: usize,
    /// Failed frames.
    pub failed: usize,
    /// Frames begun but not finished.
    pub running: usize,
    /// Frames not begun.
    pub pending: usize,
    /// Median wall time of a cold-started frame, seconds.
    pub cold_seconds_median: Option<f64>,
    /// Median wall time of a warm-started frame, seconds.
    pub warm_seconds_median: Option<f64>,
    /// Sum of the finished frames' wall times, seconds (one machine, one frame at a time).
    pub total_seconds: f64,
}

/// `DIR/sequence.json`: every frame of the sequence, merged from the shards' manifests.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SequenceManifest {
    /// [`MANIFEST_VERSION`].
    pub version: u32,
    /// The sequence's input (folder or glob) as given.
    pub input: String,
    /// The shard counts whose manifests were merged.
    pub shard_counts: Vec<usize>,
    /// The sphere every frame's cameras frame.
    pub sphere: Option<FramingSphere>,
    /// Every frame, in natural order.
    pub frames: Vec<FrameRecord>,
    /// Counts and timings.
    pub summary: SequenceSummary,
    /// Temporal stability between consecutive finished frames.
    pub temporal: Vec<TemporalPoint>,
}

impl SequenceManifest {
    /// `DIR/sequence.json`.
    #[must_use]
    pub fn path(out: &Path) -> PathBuf {
        out.join("sequence.json")
    }

    /// Merges shard manifests (oldest first, as [`read_shard_manifests`] gives them) over
    /// `frames` (the sequence's frames in order, as listed now): each frame takes its latest
    /// report, where a `pending` one (a shard that has not reached the frame yet) leaves an
    /// earlier report standing; a frame no shard reports is pending. So a frame that failed in
    /// a re-run after an earlier run finished it shows the failure, and one running again shows
    /// that, whatever shard counts the runs had.
    pub fn merge(
        input: &str,
        frames: &[super::Frame],
        shards: &[ShardManifest],
    ) -> SequenceManifest {
        let mut records: Vec<FrameRecord> = frames
            .iter()
            .map(|f| FrameRecord::pending(f, Shard::default()))
            .collect();
        // The latest report wins (they come oldest first), but `pending` says nothing new.
        let mut reported = vec![false; records.len()];
        for record in shards.iter().flat_map(|s| &s.frames) {
            if let Some(k) = records.iter().position(|r| r.name == record.name)
                && (!reported[k] || record.state != FrameState::Pending)
            {
                records[k] = record.clone();
                reported[k] = true;
            }
        }
        let mut shard_counts: Vec<usize> = shards.iter().map(|s| s.shard.count).collect();
        shard_counts.sort_unstable();
        shard_counts.dedup();
        let summary = summarise(&records);
        SequenceManifest {
            version: MANIFEST_VERSION,
            input: input.to_string(),
            shard_counts,
            sphere: shards.first().map(|s| s.sphere),
            frames: records,
            summary,
            temporal: Vec::new(),
        }
    }

    /// Writes it atomically.
    pub fn save(&self, out: &Path) -> Result<(), SequenceError> {
        write_json(&Self::path(out), self)
    }
}

fn summarise(records: &[FrameRecord]) -> SequenceSummary {
    let count = |s: FrameState| records.iter().filter(|r| r.state == s).count();
    let seconds = |warm: bool| {
        let mut t: Vec<f64> = records
            .iter()
            .filter(|r| r.warm_start.is_some() == warm)
            .filter_map(|r| r.result.as_ref().map(|x| x.seconds))
            .collect();
        t.sort_by(f64::total_cmp);
        (!t.is_empty()).then(|| median_of_sorted(&t))
    };
    SequenceSummary {
        frames: records.len(),
        finished: count(FrameState::Finished),
        failed: count(FrameState::Failed),
        running: count(FrameState::Running),
        pending: count(FrameState::Pending),
        cold_seconds_median: seconds(false),
        warm_seconds_median: seconds(true),
        total_seconds: records
            .iter()
            .filter_map(|r| r.result.as_ref().map(|x| x.seconds))
            .sum(),
    }
}

/// The median of sorted, non-empty values (the mean of the middle two for an even count).
fn median_of_sorted(v: &[f64]) -> f64 {
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        (v[n / 2 - 1] + v[n / 2]) / 2.0
    }
}

/// Reads every `shard-*-of-*.json` in `DIR/shards` (none: an empty list).
pub fn read_shard_manifests(out: &Path) -> Result<Vec<ShardManifest>, SequenceError> {
    let dir = out.join("shards");
    let Ok(entries) = std::fs::read_dir(&dir) else {
        return Ok(Vec::new());
    };
    let paths: Vec<PathBuf> = entries
        .filter_map(Result::ok)
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(is_shard_manifest_name)
        })
        .collect();
    // Oldest first (by modification time, then name), for `SequenceManifest::merge`.
    let mut dated: Vec<(Option<std::time::SystemTime>, PathBuf)> = paths
        .into_iter()
        .map(|p| (std::fs::metadata(&p).and_then(|m| m.modified()).ok(), p))
        .collect();
    dated.sort();
    dated
        .iter()
        .map(|(_, p)| p)
        .map(|p| {
            let text = std::fs::read_to_string(p).map_err(|source| SequenceError::Io {
                path: p.clone(),
                source,
            })?;
            serde_json::from_str(&text).map_err(|e| SequenceError::Manifest {
                path: p.clone(),
                problem: e.to_string(),
            })
        })
        .collect()
}

/// Whether `name` is `shard-I-of-N.json`, as [`ShardManifest::path`] names them: other files
/// in `shards/` (notes, a backup) are not read as manifests.
fn is_shard_manifest_name(name: &str) -> bool {
    let digits = |s: &str| !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit());
    name.strip_prefix("shard-")
        .and_then(|n| n.strip_suffix(".json"))
        .and_then(|n| n.split_once("-of-"))
        .is_some_and(|(i, n)| digits(i) && digits(n))
}

fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), SequenceError> {
    let io = |source| SequenceError::Io {
        path: path.to_path_buf(),
        source,
    };
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(io)?;
    }
    let mut text = serde_json::to_string_pretty(value).map_err(|e| SequenceError::Manifest {
        path: path.to_path_buf(),
        problem: e.to_string(),
    })?;
    text.push('\n');
    atomic_output::write_atomic(path, text.as_bytes()).map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(name: &str, state: FrameState, seconds: Option<f64>, warm: bool) -> FrameRecord {
        FrameRecord {
            name: name.into(),
            input: PathBuf::from(format!("{name}.ply")),
            dir: Path::new("frames").join(name),
            state,
            shard: Shard::default(),
            warm_start: warm.then(|| "previous".to_string()),
            result: seconds.map(|seconds| FrameResult {
                seconds,
                train_seconds: seconds / 2.0,
                iterations: 10,
                splats: 5,
                model_bytes: 100,
                spz_bytes: None,
                psnr_black: 40.0,
                psnr_white: 39.0,
                masked_psnr_black: 30.0,
                ssim_black: 0.99,
            }),
            error: None,
        }
    }

    #[test]
    fn only_shard_manifests_are_read_from_the_shards_folder() {
        for name in ["shard-0-of-1.json", "shard-12-of-300.json"] {
            assert!(is_shard_manifest_name(name), "{name}");
        }
        for name in [
            "shard-notes.json",
            "shard-0-of-1.json.bak",
            "shard--of-2.json",
            "shard-a-of-2.json",
            ".shard-0-of-1.json.1.tmp",
        ] {
            assert!(!is_shard_manifest_name(name), "{name}");
        }
    }

    #[test]
    fn merge_takes_the_latest_report_and_counts() {
        let frames: Vec<super::super::Frame> = ["a", "b", "c", "d"]
            .iter()
            .map(|n| super::super::Frame {
                name: (*n).into(),
                path: PathBuf::from(format!("{n}.ply")),
            })
            .collect();
        let sphere = FramingSphere {
            center: [0.0; 3],
            radius: 1.0,
        };
        let shard = |frames: Vec<FrameRecord>| ShardManifest {
            version: MANIFEST_VERSION,
            input: "x".into(),
            shard: Shard::default(),
            frames_total: 4,
            sphere,
            frames,
        };
        let shards = [
            shard(vec![
                record("a", Finished, Some(10.0), false),
                record("b", Running, None, true),
            ]),
            shard(vec![
                record("b", Finished, Some(3.0), true),
                record("c", Failed, None, true),
                record("a", Pending, None, false),
                FrameRecord {
                    shard: Shard::parse("2/3").unwrap(),
                    ..record("d", Pending, None, false)
                },
            ]),
        ];
        let m = SequenceManifest::merge("x", &frames, &shards);
        let states: Vec<FrameState> = m.frames.iter().map(|r| r.state).collect();
        use FrameState::*;
        assert_eq!(states, [Finished, Finished, Failed, Pending]);
        // A frame only reported pending shows the shard that reported it, not a default.
        assert_eq!(m.frames[3].shard, Shard::parse("2/3").unwrap());
        assert_eq!(
            (m.summary.finished, m.summary.failed, m.summary.pending),
            (2, 1, 1)
        );
        assert_eq!(m.summary.cold_seconds_median, Some(10.0));
        assert_eq!(m.summary.warm_seconds_median, Some(3.0));
        assert_eq!(m.summary.total_seconds, 13.0);
        assert_eq!(median_of_sorted(&[1.0, 2.0, 4.0, 8.0]), 3.0);

        // A re-run with another shard count: what it reports beats the older run's records
        // (an old `finished` hid a fresh failure, and an old `failed` a frame running again).
        let rerun = [
            shard(vec![
                record("a", Finished, Some(1.0), false),
                record("b", Failed, None, false),
            ]),
            shard(vec![
                record("a", Failed, None, false),
                record("b", Running, None, false),
            ]),
        ];
        let m = SequenceManifest::merge("x", &frames[..2], &rerun);
        let states: Vec<FrameState> = m.frames.iter().map(|r| r.state).collect();
        assert_eq!(states, [Failed, Running]);
    }
}
