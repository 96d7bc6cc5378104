//! `transcode sequence INPUT --out DIR`: every frame of a folder or glob, warm-started,
//! resumable, and sharded for Slurm job arrays and Kubernetes Indexed Jobs.

use std::path::PathBuf;

use anyhow::bail;
use transcode::config::Config;
use transcode::sequence::{self, FrameState, Shard};

use super::config::Overrides;
use super::progress::Reporter;

/// Arguments of `transcode sequence`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The frames: a folder of PLY clouds, plenoptic PLYs or meshes, or a quoted glob such as
    /// 'frames/*.ply'; taken in natural order (frame_9 before frame_10).
    input: String,
    /// Output folder: frames/NAME/ per frame, shards/, sequence.json, sequence.html.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    #[command(flatten)]
    overrides: Overrides,
    /// Take the I-th of N contiguous blocks of frames (0-based), e.g. 2/10. Without it: the
    /// block a Slurm job array (SLURM_ARRAY_TASK_ID, SLURM_ARRAY_TASK_COUNT) or a Kubernetes
    /// Indexed Job (JOB_COMPLETION_INDEX, TRANSCODE_SHARD_COUNT) gives this task, else all.
    #[arg(long, value_name = "I/N")]
    shard: Option<String>,
    /// Only merge the shards' manifests into sequence.json and sequence.html (after the
    /// shards ran; the shard finishing last also does it).
    #[arg(long)]
    collect: bool,
    /// Start every frame from scratch (no warm start from the previous frame).
    #[arg(long)]
    cold: bool,
    /// Training steps of a warm-started frame as a share of `--iterations` (and of any time
    /// budget) (`sequence.warm_share`, default 0.3).
    #[arg(long, value_name = "SHARE")]
    warm_share: Option<f64>,
    /// Print nothing but errors.
    #[arg(long)]
    quiet: bool,
}

/// Runs `transcode sequence`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let frames = sequence::list_frames(&args.input)?;
    if args.collect {
        let merged = sequence::collect(&args.input, &frames, &args.out)?;
        summarise(&merged, &args.out, args.quiet);
        return whole(&merged);
    }
    let mut config = args.overrides.resolve(Config::default())?;
    if args.cold {
        config.sequence.warm_start = false;
    }
    if let Some(share) = args.warm_share {
        config.sequence.warm_share = share;
        config
            .validate()
            .map_err(|e| anyhow::anyhow!("{e} (from --warm-share)"))?;
    }
    let shard = match &args.shard {
        Some(text) => Shard::parse(text)?,
        None => Shard::from_env(|name| std::env::var(name).ok())?.unwrap_or_default(),
    };
    let block = shard.block(frames.len());
    let reporter = Reporter::new(args.quiet);
    let missing: Vec<&str> = frames
        .iter()
        .filter(|f| !f.path.exists())
        .map(|f| f.name.as_str())
        .collect();
    if !missing.is_empty() && !args.quiet {
        eprintln!(
            "warning: {} frame(s) missing from the numbering, reported as failed: {}",
            missing.len(),
            abbreviated(&missing)
        );
    }
    if !args.quiet {
        let which = if block.is_empty() {
            "no frames (more shards than frames)".to_string()
        } else {
            format!(
                "frames {}..{} ({} frames)",
                block.start + 1,
                block.end,
                block.len()
            )
        };
        eprintln!(
            "sequence of {} frames; shard {shard}: {which}{}",
            frames.len(),
            if config.sequence.warm_start {
                format!(
                    "; warm starts train {:.0} % of the steps",
                    100.0 * config.sequence.warm_share
                )
            } else {
                "; every frame cold".into()
            }
        );
    }
    let manifest = sequence::run_shard(&args.input, &frames, &args.out, &config, shard, &|e| {
        reporter.show(e)
    })
    .map_err(|e| anyhow::anyhow!("{e}"))?;
    let failed: Vec<&str> = manifest
        .frames
        .iter()
        .filter(|r| r.state == FrameState::Failed)
        .map(|r| r.name.as_str())
        .collect();
    if !args.quiet {
        println!(
            "shard {shard}: {} of {} frames finished; manifest {}",
            manifest.frames.len() - failed.len(),
            manifest.frames.len(),
            sequence::ShardManifest::path(&args.out, shard).display()
        );
    }
    // The shard that finds every frame done is the last: it merges the manifests. Its exit
    // status still speaks for its own frames only, so that a cluster engine marks (and retries)
    // the task whose frame failed, not the one that happened to finish last.
    if sequence::all_frames_done(&frames, &args.out)? {
        let merged = sequence::collect(&args.input, &frames, &args.out)?;
        summarise(&merged, &args.out, args.quiet);
    } else if shard.count > 1 && !args.quiet {
        println!("other shards are still running; the last one to finish writes sequence.json");
    }
    if !failed.is_empty() {
        bail!(
            "{} frame(s) of shard {shard} failed: {} (their errors are in {})",
            failed.len(),
            failed.join(", "),
            sequence::ShardManifest::path(&args.out, shard).display()
        );
    }
    Ok(())
}

/// `--collect`'s verdict on the whole sequence: an error unless every frame finished, so that a
/// collect job run after the shards (e.g. Slurm's `--dependency=afterany`) fails when a frame
/// failed or a shard was lost.
fn whole(m: &sequence::SequenceManifest) -> anyhow::Result<()> {
    let named = |state: FrameState| -> Vec<&str> {
        m.frames
            .iter()
            .filter(|r| r.state == state)
            .map(|r| r.name.as_str())
            .collect()
    };
    let failed = named(FrameState::Failed);
    let unfinished: Vec<&str> = named(FrameState::Running)
        .into_iter()
        .chain(named(FrameState::Pending))
        .collect();
    match (failed.is_empty(), unfinished.is_empty()) {
        (true, true) => Ok(()),
        (false, true) => bail!("{} frame(s) failed: {}", failed.len(), failed.join(", ")),
        (true, false) => bail!(
            "the sequence is not finished: {} frame(s) pending, running or killed ({}); run \
             their shards again",
            unfinished.len(),
            abbreviated(&unfinished)
        ),
        (false, false) => bail!(
            "{} frame(s) failed ({}) and {} are pending, running or killed ({})",
            failed.len(),
            abbreviated(&failed),
            unfinished.len(),
            abbreviated(&unfinished)
        ),
    }
}

/// At most ten names, then how many more.
fn abbreviated(names: &[&str]) -> String {
    if names.len() <= 10 {
        names.join(", ")
    } else {
        format!(
            "{}, … and {} more",
            names[..10].join(", "),
            names.len() - 10
        )
    }
}

/// Prints the merged manifest's summary and where it and the report are (nothing when quiet).
fn summarise(m: &sequence::SequenceManifest, out: &std::path::Path, quiet: bool) {
    if quiet {
        return;
    }
    let s = &m.summary;
    println!(
        "sequence: {} frames, {} finished, {} failed, {} running or killed, {} pending",
        s.frames, s.finished, s.failed, s.running, s.pending
    );
    if let (Some(cold), warm) = (s.cold_seconds_median, s.warm_seconds_median) {
        println!(
            "median frame time: {cold:.1} s cold{}",
            warm.map(|w| format!(", {w:.1} s warm")).unwrap_or_default()
        );
    }
    println!(
        "manifest: {}",
        sequence::SequenceManifest::path(out).display()
    );
    println!("report:   {}", out.join("sequence.html").display());
}
