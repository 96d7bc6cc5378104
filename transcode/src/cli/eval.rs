//! `transcode eval MODEL --reference DIR [--antialiased | --plain]`: metrics of a splat model
//! (.ply, .spz, .splat or .glb) against reference views, the model drawn as its file says it was
//! trained (or `training.antialiased` in the configuration) unless told otherwise.

use std::path::{Path, PathBuf};

use anyhow::Context as _;
use splat_init as init;
use splat_train::eval::evaluate_views;
use splat_train::init::SurfaceIndex;
use transcode::config::Config;

use super::config::{ConfigFile, flat, require_file};

/// Arguments of `transcode eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model, by its extension: 3DGS PLY, SPZ, `.splat` or `.glb`.
    model: PathBuf,
    /// Folder of reference views: images/, sparse/0/ (COLMAP cameras) and optionally masks/.
    #[arg(long, value_name = "DIR")]
    reference: PathBuf,
    /// The input model, to measure the splats' distance to its surface.
    #[arg(long, value_name = "FILE")]
    surface: Option<PathBuf>,
    /// Also write the metrics as JSON to this file.
    #[arg(long, value_name = "FILE")]
    json: Option<PathBuf>,
    #[command(flatten)]
    drawing: super::render::Drawing,
    #[command(flatten)]
    file: ConfigFile,
}

/// Runs `transcode eval`.
pub fn run(args: Args) -> anyhow::Result<()> {
    require_file(&args.model, "model")?;
    if let Some(json) = &args.json {
        let dataset = args.reference.as_path();
        let surface: Vec<&Path> = args.surface.iter().map(PathBuf::as_path).collect();
        super::outputs::refuse_overwriting_inputs(
            json,
            "--json",
            &[&[args.model.as_path()], surface.as_slice()].concat(),
            &[
                &dataset.join("images"),
                &dataset.join("masks"),
                &dataset.join("sparse").join("0"),
            ],
        )?;
    }
    let config = args.file.resolve(Config::default())?;
    let file = splat_core::model_file::read_model(&args.model).map_err(flat)?;
    let splats = file.splats;
    let antialiased = args
        .drawing
        .antialiased(file.antialiased || config.training.antialiased);
    let mut views = splat_train::read_dataset(&args.reference, 1.0)
        .map_err(flat)?
        .views;
    // Views are listed by their file's stem.
    for v in &mut views {
        if let Some(stem) = Path::new(&v.name).file_stem() {
            v.name = stem.to_string_lossy().into_owned();
        }
    }
    let surface = match &args.surface {
        Some(path) => {
            let model = plenoptic_io::load(path).map_err(flat)?;
            let (points, normals) = match model {
                plenoptic_io::Model::Cloud(c) => (c.positions, c.normals),
                plenoptic_io::Model::Mesh(m) => {
                    let samples = init::sample_mesh(&m, 200_000, 0);
                    (samples.positions, samples.normals)
                }
            };
            SurfaceIndex::new(&points, normals.as_deref())
        }
        None => None,
    };
    let options = splat_train::eval::EvalOptions {
        antialiased,
        ..config.eval_options()
    };
    let (metrics, _) = evaluate_views(&splats, &views, surface.as_ref(), &options)
        .with_context(|| format!("cannot evaluate against {}", args.reference.display()))?;
    println!(
        "{} views, {} splats, drawn {}",
        views.len(),
        metrics.splats,
        if antialiased {
            "antialiased (opacity compensated)"
        } else {
            "plain"
        }
    );
    println!("view                 PSNR black  PSNR white  SSIM black  SSIM white  alpha IoU");
    for v in &metrics.views {
        if v.covered_pixels == 0 {
            println!(
                "{:<20} no covered pixel in the reference: not scored",
                v.name
            );
            continue;
        }
        println!(
            "{:<20} {:>10.2} {:>11.2} {:>11.4} {:>11.4} {:>10.4}",
            v.name, v.psnr_black, v.psnr_white, v.ssim_black, v.ssim_white, v.alpha_iou
        );
    }
    println!(
        "{:<20} {:>10.2} {:>11.2} {:>11.4} {:>11.4} {:>10.4}",
        "mean",
        metrics.psnr_black,
        metrics.psnr_white,
        metrics.ssim_black,
        metrics.ssim_white,
        metrics.alpha_iou
    );
    println!(
        "masked PSNR (object pixels only): {:.2} dB on black, {:.2} dB on white",
        metrics.masked_psnr_black, metrics.masked_psnr_white
    );
    if let Some(d) = &metrics.surface {
        println!(
            "distance to surface: mean {:.4}, p95 {:.4} (spacing {:.4}); {} splats beyond {:.4} hold {:.2}% of the opacity",
            d.mean,
            d.p95,
            d.spacing,
            d.far,
            d.threshold,
            100.0 * d.far_share
        );
        let interior = if d.oriented {
            format!(
                "{} inside the object ({:.2}%)",
                d.interior,
                100.0 * d.interior_share
            )
        } else {
            "none told inside (the surface has no normals)".to_string()
        };
        println!(
            "of them: {interior}; {} floaters out of their 3-sigma reach of the surface ({:.2}%)",
            d.floaters,
            100.0 * d.floater_share
        );
    }
    if let Some(path) = &args.json {
        let json = serde_json::to_vec_pretty(&metrics)?;
        atomic_output::write_atomic(path, &json)
            .with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(())
}
