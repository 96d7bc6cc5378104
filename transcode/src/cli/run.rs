//! `transcode run INPUT --out DIR`: the whole pipeline with a report.

use std::path::PathBuf;

use transcode::config::Config;

use super::config::{Overrides, flat, require_file};

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
    /// Print nothing but errors.
    #[arg(long)]
    quiet: bool,
}

/// Runs `transcode run`.
pub fn run(args: Args) -> anyhow::Result<()> {
    require_file(&args.input, "input")?;
    let config = args.overrides.resolve(Config::default())?;
    let outcome =
        transcode::pipeline::run(&args.input, &args.out, &config, args.quiet).map_err(flat)?;
    print_outcome(&outcome);
    Ok(())
}

/// Prints the held-out PSNR of each run and where the model and report are.
pub fn print_outcome(outcome: &transcode::pipeline::Outcome) {
    for r in &outcome.report.runs {
        println!(
            "{} init: held-out PSNR {:.2} dB (black background), {:.2} dB (white); SSIM {:.4} / {:.4}; \
             alpha IoU {:.4}; {} splats; trained {:.1} s",
            r.init.mode,
            r.metrics.psnr_black,
            r.metrics.psnr_white,
            r.metrics.ssim_black,
            r.metrics.ssim_white,
            r.metrics.alpha_iou,
            r.metrics.splats,
            r.train_seconds
        );
    }
    println!("model:  {}", outcome.model.display());
    println!("report: {}", outcome.html.display());
    println!("total:  {:.1} s", outcome.report.total_seconds);
}
