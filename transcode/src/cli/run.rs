//! `transcode run INPUT --out DIR`: the whole pipeline with a report.

use std::path::PathBuf;

use transcode::config::Config;
use transcode::pipeline::{Finish, RunOptions};

use super::config::{Overrides, flat, require_file};
use super::progress::Reporter;

/// Arguments of `transcode run`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input: plenoptic or coloured point cloud (PLY) or mesh (OBJ, glTF/GLB, PLY).
    input: PathBuf,
    /// Output folder (dataset/, model/, report/).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    #[command(flatten)]
    overrides: Overrides,
    /// Continue the run saved in DIR (after a crash or kill) from its last checkpoint, with the
    /// same input and settings; a finished run is left as it is.
    #[arg(long)]
    resume: bool,
    /// Save the training state at most this many seconds apart (`output.checkpoint_interval_s`,
    /// default 60; 0 = after every step).
    #[arg(long, value_name = "SECONDS", value_parser = super::config::parse_interval_seconds)]
    checkpoint_interval: Option<f64>,
    /// Print nothing but errors and the result (the held-out scores, where the model and report
    /// are, the total time).
    #[arg(long)]
    quiet: bool,
}

/// Runs `transcode run`.
pub fn run(args: Args) -> anyhow::Result<()> {
    require_file(&args.input, "input")?;
    let mut config = args.overrides.resolve(Config::default())?;
    if let Some(s) = args.checkpoint_interval {
        config.output.checkpoint_interval_s = s;
        config
            .validate()
            .map_err(|e| anyhow::anyhow!("{e} (from --checkpoint-interval)"))?;
    }
    let opts = RunOptions {
        resume: args.resume,
        ..RunOptions::default()
    };
    let reporter = Reporter::new(args.quiet);
    let outcome =
        transcode::pipeline::run_with(&args.input, &args.out, &config, opts, &|e| reporter.show(e));
    match outcome.map_err(flat)? {
        Finish::Completed(outcome) => print_outcome(&outcome),
        Finish::AlreadyFinished { model, html } => {
            println!(
                "the run in {} is already finished; nothing to resume",
                args.out.display()
            );
            println!("model:  {}", model.display());
            println!("report: {}", html.display());
        }
    }
    Ok(())
}

/// Prints the held-out PSNR of each run and where the model and report are.
pub fn print_outcome(outcome: &transcode::pipeline::Outcome) {
    for r in &outcome.report.runs {
        println!(
            "{} init: held-out PSNR {:.2} dB (black background), {:.2} dB (white); masked (object \
             only) {:.2} / {:.2} dB; SSIM {:.4} / {:.4}; alpha IoU {:.4}; {} splats; trained {:.1} s",
            r.init.mode,
            r.metrics.psnr_black,
            r.metrics.psnr_white,
            r.metrics.masked_psnr_black,
            r.metrics.masked_psnr_white,
            r.metrics.ssim_black,
            r.metrics.ssim_white,
            r.metrics.alpha_iou,
            r.metrics.splats,
            r.train_seconds
        );
    }
    println!("model:  {}", outcome.model.display());
    println!("report: {}", outcome.html.display());
    println!(
        "total:  {:.1} s{}",
        outcome.report.total_seconds,
        if outcome.report.resumed {
            " (this session; the run was resumed and its training time spans every session)"
        } else {
            ""
        }
    );
}
