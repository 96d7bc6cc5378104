//! `transcode render MODEL --colmap DIR --out OUTDIR [--background R,G,B] [--images NAME,...]
//! [--antialiased | --plain]`: renders a splat model (.ply, .spz, .splat or .glb) from the
//! cameras of a COLMAP model to PNG files named like its images, drawn as its file says it was
//! trained (antialiased or plain) unless told otherwise.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use indicatif::{ProgressBar, ProgressStyle};
use splat_core::{Rasterizer, RenderCamera, RenderOptions};

/// Arguments of `transcode render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The model to render, by its extension: a 3DGS PLY (Inria layout; any property order,
    /// float or double), SPZ, `.splat` or `.glb`.
    pub splats: PathBuf,
    /// COLMAP model folder (with cameras/images files), or a dataset root holding sparse/0.
    #[arg(long)]
    pub colmap: PathBuf,
    /// Output folder for the PNG files.
    #[arg(long)]
    pub out: PathBuf,
    /// Background colour in [0, 1], as R,G,B (or three values: R G B).
    #[arg(
        long,
        value_delimiter = ',',
        num_args = 1..=3,
        allow_hyphen_values = true,
        default_values_t = [0.0, 0.0, 0.0]
    )]
    pub background: Vec<f32>,
    /// Render only these images (names as in the model), comma-separated.
    #[arg(long, value_delimiter = ',')]
    pub images: Option<Vec<String>>,
    /// Highest SH degree to evaluate, 0..=3 (default: the model's).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=3))]
    pub sh_degree: Option<u32>,
    #[command(flatten)]
    pub drawing: Drawing,
}

/// How a model is drawn: with the antialiased opacity compensation where its file says it was
/// trained so (a PLY's `SplatRenderMode: mip` comment, SPZ's flag), unless told otherwise.
#[derive(Debug, Clone, Copy, Default, clap::Args)]
pub struct Drawing {
    /// Draw with the antialiased (Mip-Splatting) opacity compensation whatever the file says.
    #[arg(long, conflicts_with = "plain")]
    pub antialiased: bool,
    /// Draw without the compensation whatever the file says, as a viewer that ignores a file's
    /// render mode draws it.
    #[arg(long)]
    pub plain: bool,
}

impl Drawing {
    /// Whether to draw antialiased a model whose file (or configuration) says `trained`.
    #[must_use]
    pub fn antialiased(self, trained: bool) -> bool {
        self.antialiased || (trained && !self.plain)
    }
}

/// The model folder: `DIR` itself if it holds a model, else `DIR/sparse/0`.
pub(crate) fn model_dir(dir: &Path) -> PathBuf {
    let nested = dir.join("sparse").join("0");
    if colmap_io::detect_format(dir).is_none() && colmap_io::detect_format(&nested).is_some() {
        nested
    } else {
        dir.to_path_buf()
    }
}

/// Renders every selected image of the model and writes it as PNG.
pub fn run(args: Args) -> anyhow::Result<()> {
    let file = splat_core::model_file::read_model(&args.splats)?;
    let splats = file.splats;
    let model = model_dir(&args.colmap);
    let rec = colmap_io::read_model(&model)
        .with_context(|| format!("reading the COLMAP model in {}", model.display()))?;
    let mut selected: Vec<u32> = rec.images.keys().copied().collect();
    if let Some(names) = &args.images {
        let missing: Vec<&String> = names
            .iter()
            .filter(|n| !rec.images.values().any(|i| &i.name == *n))
            .collect();
        if !missing.is_empty() {
            bail!("images not in the model {}: {missing:?}", model.display());
        }
        selected.retain(|id| names.contains(&rec.images[id].name));
    }
    let [r, g, b] = args.background[..] else {
        bail!(
            "--background takes three components, R,G,B in [0, 1]; got {}",
            args.background.len()
        );
    };
    let bg = glam::Vec3::new(r, g, b);
    // (Not through min/max_element, which pass over a NaN.)
    if !args.background.iter().all(|c| (0.0..=1.0).contains(c)) {
        bail!("--background components must lie in [0, 1], got {bg}");
    }
    let outputs = output_files(&args.out, &rec, &selected)?;
    let root = dataset_root(&model);
    for path in outputs.values() {
        super::outputs::refuse_overwriting_inputs(
            path,
            "the render",
            &[&args.splats],
            &[&model, &root.join("images"), &root.join("masks")],
        )?;
    }
    let opts = RenderOptions {
        background: bg,
        active_sh_degree: args.sh_degree.unwrap_or(splats.sh_degree),
        antialiased: args.drawing.antialiased(file.antialiased),
        linear_colour: false,
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let bar = ProgressBar::new(selected.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} {msg} ({elapsed}, eta {eta})")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut r = Rasterizer::new();
    for id in selected {
        let image = &rec.images[&id];
        bar.set_message(image.name.clone());
        let camera = rec
            .camera_of(id)
            .with_context(|| format!("camera of image {}", image.name))?;
        let cam = RenderCamera::try_from(&camera)
            .with_context(|| format!("camera of image {}", image.name))?;
        let out = r
            .try_forward(&splats, &cam, &opts)
            .with_context(|| format!("camera of image {}", image.name))?;
        let pixels: Vec<u8> = out
            .rgb
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let path = &outputs[&id];
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        let mut png = Vec::new();
        image::ImageEncoder::write_image(
            image::codecs::png::PngEncoder::new(&mut png),
            &pixels,
            cam.width,
            cam.height,
            image::ExtendedColorType::Rgb8,
        )
        .with_context(|| format!("encoding {}", path.display()))?;
        atomic_output::write_atomic(path, &png)
            .with_context(|| format!("cannot write {}", path.display()))?;
        bar.inc(1);
    }
    bar.finish_with_message(format!("wrote {}", args.out.display()));
    Ok(())
}

/// The dataset folder a COLMAP model belongs to: the folder holding `sparse/N` when the model
/// is such a folder, else the model's own folder.
fn dataset_root(model: &Path) -> PathBuf {
    match (model.parent(), model.parent().and_then(Path::file_name)) {
        (Some(sparse), Some(name)) if name == "sparse" => {
            sparse.parent().unwrap_or(Path::new(".")).to_path_buf()
        }
        _ => model.to_path_buf(),
    }
}

/// The PNG each selected image is written to: its name in the model (subfolders kept) with the
/// extension `.png`, under `out`. A name that would leave `out` (absolute, `..`, empty) is
/// refused, as are two images that would share one file (`a.jpg` and `a.png`).
fn output_files(
    out: &Path,
    rec: &colmap_io::Reconstruction,
    selected: &[u32],
) -> anyhow::Result<std::collections::BTreeMap<u32, PathBuf>> {
    let mut by_file: std::collections::HashMap<PathBuf, &str> = std::collections::HashMap::new();
    let mut outputs = std::collections::BTreeMap::new();
    for id in selected {
        let image = &rec.images[id];
        let name = &image.name;
        let Some(relative) = image.relative_file() else {
            bail!(
                "image {id} is named {name:?}, which would be written outside --out {}: render \
                 writes each image under its name in the model, so the name must be a relative \
                 path without `..`",
                out.display()
            );
        };
        let file = relative.with_extension("png");
        if let Some(other) = by_file.insert(file.clone(), name) {
            bail!(
                "images {other:?} and {name:?} would both be written to {}: render names each \
                 PNG after its image; render them into separate folders with --images",
                out.join(&file).display()
            );
        }
        outputs.insert(*id, out.join(file));
    }
    Ok(outputs)
}
