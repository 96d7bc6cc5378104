//! `transcode views INPUT --out DIR`: render the reference views of an input and write the COLMAP
//! dataset only (no training).

use std::path::PathBuf;

use anyhow::Context as _;
use indicatif::{ProgressBar, ProgressStyle};
use plenoptic_render::{self as views, BitDepth, DatasetOptions, PointShape, ViewOptions};
use transcode::config::Config;

use super::config::{ConfigFile, RigFlags, require_file, validated};

/// Arguments of `transcode views`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Input: plenoptic or coloured point cloud (PLY) or mesh (OBJ, glTF/GLB, PLY).
    input: PathBuf,
    /// Dataset folder to write (images/, masks/, sparse/0/).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    #[command(flatten)]
    file: ConfigFile,
    #[command(flatten)]
    rig: RigFlags,
    /// Point size in voxels (cube side, or the disc's half-size), used as given (without it a
    /// sparse cloud's points grow until its surface is closed, and a cloud on no voxel grid is
    /// drawn at its own spacing).
    #[arg(long)]
    point_size: Option<f32>,
    /// Draw points as view-aligned discs instead of voxel cubes.
    #[arg(long)]
    disc: bool,
    /// Supersampling factor for anti-aliasing (1 = off).
    #[arg(long, value_name = "K")]
    supersample: Option<u32>,
    /// Exponent n of the view interpolation weight max(0, cos)^n.
    #[arg(long, value_name = "N")]
    exponent: Option<i32>,
    /// Write 16-bit PNGs.
    #[arg(long)]
    png16: bool,
    /// Also write depth maps (depth/view_NNN.exr).
    #[arg(long)]
    depth: bool,
}

/// Runs `transcode views`.
pub fn run(args: Args) -> anyhow::Result<()> {
    require_file(&args.input, "input")?;
    let mut config = args.file.load(Config::default())?;
    args.rig.apply(&mut config);
    let config = validated(config)?;
    let mut view = config.renderer.clone();
    if let Some(s) = args.point_size {
        view.point_size = s;
        view.close_surface = false;
    }
    if args.disc {
        view.point_shape = PointShape::Disc;
    }
    if let Some(k) = args.supersample {
        view.supersample = k;
    }
    if let Some(n) = args.exponent {
        view.exponent = n;
    }
    view.validate()?;
    let opts = DatasetOptions {
        bit_depth: if args.png16 || config.output.png16 {
            BitDepth::Sixteen
        } else {
            BitDepth::Eight
        },
        masks: true,
        depth: args.depth,
    };

    // An earlier dataset in the folder must not look complete if this one fails before it
    // is written.
    views::remove_dataset_model(&args.out)
        .with_context(|| format!("cannot clear the dataset {}", args.out.display()))?;
    transcode::pipeline::refuse_splat_model(&args.input)?;
    let model = plenoptic_io::load(&args.input)
        .with_context(|| format!("cannot read {}", args.input.display()))?;
    plenoptic_render::degenerate::check_model(&args.input, &model)?;
    let sizing = view.point_sizing(&model);
    let chosen = view.sized(sizing);
    if sizing != views::PointSizing::AsConfigured {
        println!(
            "{sizing} (--point-size {} draws them at {0})",
            view.point_size
        );
    }
    // The images are written, not kept: depth only where `depth/` is (the writer asks for it).
    let view = ViewOptions {
        depth: false,
        ..chosen
    };
    let (center, radius) = views::bounding_sphere(&model)?;
    let cameras = views::fibonacci_rig(center, radius, &config.rig)?;

    let bar = ProgressBar::new(cameras.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} views [{elapsed} < {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    // The images are on disk: nothing of them is kept in memory.
    let written = views::write_dataset(
        &args.out,
        &model,
        &cameras,
        &view,
        &opts,
        &|| bar.inc(1),
        |_, _| (),
    )
    .with_context(|| format!("cannot write the dataset {}", args.out.display()))?;
    bar.finish_and_clear();
    println!(
        "wrote {} views of {}×{} to {} (images/, masks/, sparse/0/ in text and binary)",
        written.len(),
        config.rig.width,
        config.rig.height,
        args.out.display()
    );
    Ok(())
}
