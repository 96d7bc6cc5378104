//! `transcode colmap info DIR [--json]` and `transcode colmap convert IN OUT --to txt|bin`.

use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use colmap_io::{Format, Reconstruction, detect_format, read_model_as, write_model};
use glam::DVec3;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::json;

/// `transcode colmap` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Print what a COLMAP model holds: counts, cameras, reprojection error, scene extent.
    Info(InfoArgs),
    /// Write a COLMAP model in the other encoding (text ↔ binary), exactly.
    Convert(ConvertArgs),
}

/// Arguments of `transcode colmap info`.
#[derive(Debug, clap::Args)]
pub struct InfoArgs {
    /// The model folder (holding cameras/images/points3D .bin or .txt), or a dataset folder
    /// with the model in sparse/0.
    pub dir: PathBuf,
    /// Print one JSON object instead of the human-readable report.
    #[arg(long)]
    pub json: bool,
}

/// Encoding chosen on the command line.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
pub enum Encoding {
    /// cameras.txt, images.txt, points3D.txt.
    Txt,
    /// cameras.bin, images.bin, points3D.bin.
    Bin,
}

impl From<Encoding> for Format {
    fn from(e: Encoding) -> Self {
        match e {
            Encoding::Txt => Format::Text,
            Encoding::Bin => Format::Binary,
        }
    }
}

/// Arguments of `transcode colmap convert`.
#[derive(Debug, clap::Args)]
pub struct ConvertArgs {
    /// The model folder to read (or a dataset folder with the model in sparse/0).
    pub input: PathBuf,
    /// The folder to write the model into (created if needed).
    pub output: PathBuf,
    /// Encoding to write.
    #[arg(long)]
    pub to: Encoding,
}

/// Runs the subcommand.
pub fn run(cmd: Command) -> anyhow::Result<()> {
    match cmd {
        Command::Info(args) => info(&args),
        Command::Convert(args) => convert(&args),
    }
}

/// The model folder for `dir`: itself if it holds a model, else `dir/sparse/0` or `dir/sparse`.
fn locate_model(dir: &Path) -> anyhow::Result<(PathBuf, Format)> {
    if !dir.is_dir() {
        anyhow::bail!("{} is not a folder", dir.display());
    }
    for candidate in [
        dir.to_path_buf(),
        dir.join("sparse").join("0"),
        dir.join("sparse"),
    ] {
        if let Some(format) = detect_format(&candidate) {
            return Ok((candidate, format));
        }
    }
    anyhow::bail!(
        "no COLMAP model in {} (looked for cameras, images and points3D, all .bin or all .txt, there and in sparse/0 and sparse)",
        dir.display()
    )
}

/// Reads the model behind a spinner (large binary models take a moment).
fn load(dir: &Path) -> anyhow::Result<(PathBuf, Format, Reconstruction)> {
    let (model_dir, format) = locate_model(dir)?;
    let spinner = ProgressBar::new_spinner().with_style(
        ProgressStyle::with_template("{spinner} reading {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    spinner.set_message(model_dir.display().to_string());
    spinner.enable_steady_tick(Duration::from_millis(120));
    let rec = read_model_as(&model_dir, format);
    spinner.finish_and_clear();
    let rec =
        rec.with_context(|| format!("reading the COLMAP model in {}", model_dir.display()))?;
    Ok((model_dir, format, rec))
}

fn format_name(format: Format) -> &'static str {
    match format {
        Format::Text => "text",
        Format::Binary => "binary",
    }
}

/// Axis-aligned bounds of a set of points.
fn bounds(points: impl Iterator<Item = DVec3>) -> Option<(DVec3, DVec3)> {
    points.fold(None, |acc, p| match acc {
        None => Some((p, p)),
        Some((lo, hi)) => Some((lo.min(p), hi.max(p))),
    })
}

fn median(values: &[f64]) -> Option<f64> {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied()
}

fn info(args: &InfoArgs) -> anyhow::Result<()> {
    let (model_dir, format, rec) = load(&args.dir)?;
    let observations = rec.num_observations();
    let cameras: Vec<_> = rec
        .cameras
        .values()
        .map(|c| {
            json!({"id": c.id, "model": c.model.name(), "width": c.width, "height": c.height,
                   "param_names": c.model.param_names(), "params": c.params})
        })
        .collect();
    // Reprojection through camera-model needs pinhole cameras; distorted models are named instead.
    let reprojection = match rec.reprojection_errors() {
        Ok(errors) if !errors.is_empty() => {
            let mean = errors.iter().sum::<f64>() / errors.len() as f64;
            json!({"mean_px": mean, "median_px": median(&errors), "max_px": errors.iter().copied().fold(0.0, f64::max)})
        }
        Ok(_) => json!({"unavailable": "the model has no observations"}),
        Err(e) => json!({"unavailable": e.to_string()}),
    };
    let points = bounds(rec.points3d.values().map(|p| p.xyz));
    let centres: Vec<DVec3> = rec.images.values().map(|im| im.pose().center()).collect();
    let cam_bounds = bounds(centres.iter().copied());
    // Inria's scene extent: 1.1 × the largest distance of a camera centre from their mean.
    let extent = (!centres.is_empty()).then(|| {
        let mean = centres.iter().sum::<DVec3>() / centres.len() as f64;
        1.1 * centres.iter().map(|c| c.distance(mean)).fold(0.0, f64::max)
    });
    let extras: Vec<&str> = ["rigs.bin", "frames.bin", "rigs.txt", "frames.txt"]
        .into_iter()
        .filter(|n| model_dir.join(n).is_file())
        .collect();
    let bbox = |b: Option<(DVec3, DVec3)>| {
        b.map(|(lo, hi)| json!({"min": lo.to_array(), "max": hi.to_array(), "size": (hi - lo).to_array()}))
    };
    let report = json!({
        "model": model_dir.display().to_string(),
        "format": format_name(format),
        "cameras": rec.cameras.len(),
        "images": rec.images.len(),
        "points3d": rec.points3d.len(),
        "observations": observations,
        "mean_track_length": if rec.points3d.is_empty() { 0.0 } else { observations as f64 / rec.points3d.len() as f64 },
        "camera_list": cameras,
        "reprojection_error": reprojection,
        "points_bounds": bbox(points),
        "camera_centre_bounds": bbox(cam_bounds),
        "scene_extent": extent,
        "ignored_files": extras,
    });
    if args.json {
        println!("{report}");
        return Ok(());
    }
    println!(
        "COLMAP model {} ({} files)",
        model_dir.display(),
        format_name(format)
    );
    println!(
        "  cameras {}, images {}, points3D {}, observations {} (mean track length {:.3})",
        rec.cameras.len(),
        rec.images.len(),
        rec.points3d.len(),
        observations,
        report["mean_track_length"].as_f64().unwrap_or(0.0)
    );
    for c in rec.cameras.values() {
        let params: Vec<String> = c
            .model
            .param_names()
            .iter()
            .zip(&c.params)
            .map(|(n, v)| format!("{n}={v}"))
            .collect();
        println!(
            "  camera {}: {} {}x{} {}",
            c.id,
            c.model.name(),
            c.width,
            c.height,
            params.join(" ")
        );
    }
    match (
        reprojection["mean_px"].as_f64(),
        reprojection["median_px"].as_f64(),
    ) {
        (Some(mean), Some(med)) => {
            println!(
                "  reprojection error: mean {mean:.4} px, median {med:.4} px (through camera-model, pinhole)"
            );
        }
        _ => println!(
            "  reprojection error: n/a ({})",
            reprojection["unavailable"].as_str().unwrap_or("")
        ),
    }
    if let Some((lo, hi)) = points {
        println!("  points span {:.4} .. {:.4} (size {:.4})", lo, hi, hi - lo);
    }
    if let Some((lo, hi)) = cam_bounds {
        println!("  camera centres span {:.4} .. {:.4}", lo, hi);
    }
    if let Some(e) = extent {
        println!("  scene extent (1.1 x max camera distance from their mean, as Inria): {e:.4}");
    }
    if !extras.is_empty() {
        println!(
            "  ignored: {} (rig/frame files of newer COLMAP; the model reads without them)",
            extras.join(", ")
        );
    }
    Ok(())
}

fn convert(args: &ConvertArgs) -> anyhow::Result<()> {
    let (model_dir, from, rec) = load(&args.input)?;
    let to = Format::from(args.to);
    write_model(&args.output, &rec, to)
        .with_context(|| format!("writing the model into {}", args.output.display()))?;
    println!(
        "wrote {} cameras, {} images, {} points from {} ({}) to {} ({})",
        rec.cameras.len(),
        rec.images.len(),
        rec.points3d.len(),
        model_dir.display(),
        format_name(from),
        args.output.display(),
        format_name(to)
    );
    // COLMAP and the trainers prefer .bin when both encodings are present.
    if to == Format::Text && detect_format(&args.output) == Some(Format::Binary) {
        eprintln!(
            "warning: {} also holds a binary model, which COLMAP and trainers read in preference to the text files just written",
            args.output.display()
        );
    }
    Ok(())
}
