//! Evaluation of a trained model against reference views: image metrics, masks, distance to the surface.
//!
//! Image metrics are computed on two backgrounds, black and white: the references are composited
//! on each with their coverage masks, the splats are rendered over each. A floater that happens to
//! match one background shows on the other. PSNR and SSIM are `splat_train::metrics`'.

use std::path::{Path, PathBuf};

use camera_model::Camera;
use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, Splats};
use splat_train::metrics;

use splat_init::PointIndex;

/// Errors of reading reference views.
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// The COLMAP model could not be read (colmap-io's message names the file).
    #[error("reference cameras: {source}")]
    Colmap {
        /// The model folder.
        path: PathBuf,
        /// The cause (boxed: COLMAP errors are large).
        source: Box<colmap_io::Error>,
    },
    /// An image or mask could not be read.
    #[error("cannot read {path}: {message}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// An image's size disagrees with its camera.
    #[error("{path} is {got_w}×{got_h} but its camera is {want_w}×{want_h}")]
    Size {
        /// The file.
        path: PathBuf,
        /// Image width.
        got_w: u32,
        /// Image height.
        got_h: u32,
        /// Camera width.
        want_w: u32,
        /// Camera height.
        want_h: u32,
    },
    /// The folder holds no images.
    #[error("no reference images in {0}")]
    Empty(PathBuf),
    /// No reference view covers a single pixel: an empty render would match every one of them
    /// (PSNR ∞, SSIM 1), so there is nothing to score.
    #[error(
        "none of the {views} reference views has a covered pixel (every mask or alpha is 0): there is nothing to score"
    )]
    NothingCovered {
        /// Number of reference views.
        views: usize,
    },
}

/// Reads reference views from a dataset folder: `sparse/0/` (text or binary, pinhole cameras),
/// `images/NAME`, and `masks/NAME` when present (else the image's own alpha channel, else full
/// coverage). Colours are taken as composited on black, as `transcode views` writes them.
pub fn load_reference_views(dir: &Path) -> Result<Vec<ReferenceView>, EvalError> {
    let sparse = dir.join("sparse/0");
    let rec = colmap_io::read_model(&sparse).map_err(|source| EvalError::Colmap {
        path: sparse.clone(),
        source: Box::new(source),
    })?;
    let mut views = Vec::with_capacity(rec.images.len());
    for (id, image) in &rec.images {
        let camera = rec.camera_of(*id).map_err(|source| EvalError::Colmap {
            path: sparse.clone(),
            source: Box::new(source),
        })?;
        let path = dir.join("images").join(&image.name);
        let img = read_image(&path)?;
        let (w, h) = (camera.intrinsics.width, camera.intrinsics.height);
        if (img.width(), img.height()) != (w, h) {
            return Err(EvalError::Size {
                path,
                got_w: img.width(),
                got_h: img.height(),
                want_w: w,
                want_h: h,
            });
        }
        let rgba = img.to_rgba32f();
        let mask_path = dir.join("masks").join(&image.name);
        let alpha: Vec<f32> = if mask_path.is_file() {
            let m = read_image(&mask_path)?;
            if (m.width(), m.height()) != (w, h) {
                return Err(EvalError::Size {
                    path: mask_path,
                    got_w: m.width(),
                    got_h: m.height(),
                    want_w: w,
                    want_h: h,
                });
            }
            m.to_luma32f().into_raw()
        } else {
            rgba.pixels().map(|p| p[3]).collect()
        };
        let rgb = rgba
            .pixels()
            .zip(&alpha)
            .flat_map(|(p, &a)| {
                // An RGBA image without a mask is straight colour: put it on black.
                let k = if mask_path.is_file() { 1.0 } else { a };
                [p[0] * k, p[1] * k, p[2] * k]
            })
            .collect();
        let name = Path::new(&image.name)
            .file_stem()
            .map_or_else(|| image.name.clone(), |s| s.to_string_lossy().into_owned());
        views.push(ReferenceView {
            name,
            camera,
            rgb,
            alpha,
        });
    }
    if views.is_empty() {
        return Err(EvalError::Empty(dir.to_path_buf()));
    }
    Ok(views)
}

fn read_image(path: &Path) -> Result<image::DynamicImage, EvalError> {
    image::ImageReader::open(path)
        .map_err(|e| EvalError::Image {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?
        .with_guessed_format()
        .map_err(|e| EvalError::Image {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?
        .decode()
        .map_err(|e| EvalError::Image {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
}

/// A reference view: a camera, its colours composited on black and its coverage.
#[derive(Debug, Clone, PartialEq)]
pub struct ReferenceView {
    /// Name, e.g. the image file's stem.
    pub name: String,
    /// The camera.
    pub camera: Camera,
    /// Interleaved RGB (3·W·H) composited on black, i.e. colour × coverage.
    pub rgb: Vec<f32>,
    /// Coverage in [0, 1] (W·H).
    pub alpha: Vec<f32>,
}

impl ReferenceView {
    /// The reference composited on `background`: rgb + (1 − alpha)·background.
    #[must_use]
    pub fn on_background(&self, background: Vec3) -> Vec<f32> {
        let bg = background.to_array();
        self.rgb
            .chunks_exact(3)
            .zip(&self.alpha)
            .flat_map(|(px, &a)| [0, 1, 2].map(|c| px[c] + (1.0 - a) * bg[c]))
            .collect()
    }
}

/// Scores of one view.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewMetrics {
    /// View name.
    pub name: String,
    /// PSNR (dB) on a black background.
    pub psnr_black: f64,
    /// PSNR (dB) on a white background.
    pub psnr_white: f64,
    /// SSIM on a black background.
    pub ssim_black: f64,
    /// SSIM on a white background.
    pub ssim_white: f64,
    /// Intersection over union of rendered coverage and the reference mask (both thresholded).
    pub alpha_iou: f64,
    /// Mean missing coverage (1 − rendered alpha) where the reference is fully covered: holes.
    pub hole_alpha: f64,
    /// Mean rendered alpha where the reference is empty: splats in free space.
    pub free_alpha: f64,
    /// Pixels the reference covers (alpha > 0). A view with none is scored but left out of the
    /// means: an empty render matches it perfectly whatever the model.
    #[serde(default)]
    pub covered_pixels: usize,
}

/// Opacity-weighted distance of splat centres to the input surface.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurfaceDistance {
    /// Point spacing of the surface points (file units) used as the unit below.
    pub spacing: f64,
    /// Weighted mean distance (file units).
    pub mean: f64,
    /// Weighted 95th percentile distance (file units).
    pub p95: f64,
    /// Share of the total opacity in splats farther than `threshold` ("floaters").
    pub floater_share: f64,
    /// The floater threshold: `floater_spacings` × spacing.
    pub threshold: f64,
    /// Number of splats farther than `threshold`.
    pub floaters: usize,
}

/// All metrics of a model on held-out views.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Mean PSNR (dB) on black.
    pub psnr_black: f64,
    /// Mean PSNR (dB) on white.
    pub psnr_white: f64,
    /// Mean SSIM on black.
    pub ssim_black: f64,
    /// Mean SSIM on white.
    pub ssim_white: f64,
    /// Mean alpha IoU.
    pub alpha_iou: f64,
    /// Mean hole alpha (see [`ViewMetrics::hole_alpha`]).
    pub hole_alpha: f64,
    /// Mean free-space alpha (see [`ViewMetrics::free_alpha`]).
    pub free_alpha: f64,
    /// Distance of splats to the input surface, when the surface is known.
    pub surface: Option<SurfaceDistance>,
    /// Number of splats.
    pub splats: usize,
    /// Per-view scores.
    pub views: Vec<ViewMetrics>,
}

/// The splats' render of one view on black, kept for the report's pictures.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedView {
    /// Colours on black, clamped to [0, 1].
    pub rgb: Vec<f32>,
    /// Coverage.
    pub alpha: Vec<f32>,
}

/// Settings of [`evaluate`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalOptions {
    /// Coverage above this counts as covered for the IoU.
    pub alpha_threshold: f32,
    /// Floater threshold in point spacings.
    pub floater_spacings: f64,
}

impl From<&crate::config::EvalConfig> for EvalOptions {
    fn from(c: &crate::config::EvalConfig) -> Self {
        Self {
            alpha_threshold: c.alpha_threshold,
            floater_spacings: c.floater_spacings,
        }
    }
}

/// Renders `splats` from every reference view on black and white and scores them; with the
/// input's surface points and spacing, also measures the splats' distance to the surface.
/// The means are over the views that cover at least one pixel; when none does, the result is
/// [`EvalError::NothingCovered`] rather than a perfect-looking score.
pub fn evaluate(
    splats: &Splats,
    views: &[ReferenceView],
    surface: Option<(&[Vec3], f32)>,
    opts: &EvalOptions,
) -> Result<(Metrics, Vec<RenderedView>), EvalError> {
    let covered: Vec<usize> = views
        .iter()
        .map(|v| v.alpha.iter().filter(|&&a| a > 0.0).count())
        .collect();
    if covered.iter().all(|&c| c == 0) {
        return Err(EvalError::NothingCovered { views: views.len() });
    }
    let mut raster = Rasterizer::new();
    let mut per_view = Vec::with_capacity(views.len());
    let mut renders = Vec::with_capacity(views.len());
    for (v, &covered_pixels) in views.iter().zip(&covered) {
        let cam = RenderCamera::from(&v.camera);
        let (w, h) = (cam.width, cam.height);
        let mut score = |bg: Vec3| -> (f64, f64, Vec<f32>, Vec<f32>) {
            let ropts = RenderOptions {
                background: bg,
                active_sh_degree: splats.sh_degree,
                antialiased: false,
            };
            let out = raster.forward(splats, &cam, &ropts);
            let render: Vec<f32> = out.rgb.par_iter().map(|x| x.clamp(0.0, 1.0)).collect();
            let target = v.on_background(bg);
            (
                metrics::psnr(&render, &target),
                metrics::ssim(&render, &target, w, h),
                render,
                out.alpha.clone(),
            )
        };
        let (psnr_black, ssim_black, rgb, alpha) = score(Vec3::ZERO);
        let (psnr_white, ssim_white, _, _) = score(Vec3::ONE);
        let alpha_iou = iou(&alpha, &v.alpha, opts.alpha_threshold);
        let (hole_alpha, free_alpha) = coverage_errors(&alpha, &v.alpha);
        per_view.push(ViewMetrics {
            name: v.name.clone(),
            psnr_black,
            psnr_white,
            ssim_black,
            ssim_white,
            alpha_iou,
            hole_alpha,
            free_alpha,
            covered_pixels,
        });
        renders.push(RenderedView { rgb, alpha });
    }
    let scored: Vec<&ViewMetrics> = per_view.iter().filter(|v| v.covered_pixels > 0).collect();
    let mean =
        |f: fn(&ViewMetrics) -> f64| scored.iter().map(|v| f(v)).sum::<f64>() / scored.len() as f64;
    let metrics = Metrics {
        psnr_black: mean(|v| v.psnr_black),
        psnr_white: mean(|v| v.psnr_white),
        ssim_black: mean(|v| v.ssim_black),
        ssim_white: mean(|v| v.ssim_white),
        alpha_iou: mean(|v| v.alpha_iou),
        hole_alpha: mean(|v| v.hole_alpha),
        free_alpha: mean(|v| v.free_alpha),
        surface: surface.and_then(|(points, spacing)| {
            surface_distance(splats, points, spacing, opts.floater_spacings)
        }),
        splats: splats.len(),
        views: per_view,
    };
    Ok((metrics, renders))
}

/// IoU of two coverage maps thresholded at `threshold` (1 when both are empty).
#[must_use]
pub fn iou(a: &[f32], b: &[f32], threshold: f32) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        let (x, y) = (x > threshold, y > threshold);
        inter += usize::from(x && y);
        union += usize::from(x || y);
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// Mean of 1 − `rendered` where `reference` ≥ 0.999 (holes) and of `rendered` where `reference`
/// ≤ 0.001 (free space); 0 for an empty set.
#[must_use]
pub fn coverage_errors(rendered: &[f32], reference: &[f32]) -> (f64, f64) {
    let (mut hole, mut nh, mut free, mut nf) = (0.0f64, 0usize, 0.0f64, 0usize);
    for (&r, &m) in rendered.iter().zip(reference) {
        if m >= 0.999 {
            hole += f64::from(1.0 - r);
            nh += 1;
        } else if m <= 0.001 {
            free += f64::from(r);
            nf += 1;
        }
    }
    (hole / nh.max(1) as f64, free / nf.max(1) as f64)
}

/// Opacity-weighted distance of splat centres to the nearest surface point; `None` without
/// splats or surface points.
#[must_use]
pub fn surface_distance(
    splats: &Splats,
    surface: &[Vec3],
    spacing: f32,
    floater_spacings: f64,
) -> Option<SurfaceDistance> {
    let index = PointIndex::new(surface)?;
    if splats.is_empty() {
        return None;
    }
    let mut d: Vec<(f64, f64)> = splats
        .means
        .par_iter()
        .zip(&splats.opacity_logits)
        .map(|(m, &o)| {
            (
                f64::from(index.nearest_distance(*m)),
                f64::from(splat_core::sigmoid(o)),
            )
        })
        .collect();
    let total: f64 = d.iter().map(|x| x.1).sum();
    let threshold = floater_spacings * f64::from(spacing);
    let floaters = d.iter().filter(|x| x.0 > threshold).count();
    if total <= 0.0 {
        return Some(SurfaceDistance {
            spacing: f64::from(spacing),
            mean: 0.0,
            p95: 0.0,
            floater_share: 0.0,
            threshold,
            floaters,
        });
    }
    let mean = d.iter().map(|x| x.0 * x.1).sum::<f64>() / total;
    // Adding 0.0 turns the empty sum's −0.0 into 0.0.
    let beyond = d
        .iter()
        .filter(|x| x.0 > threshold)
        .map(|x| x.1)
        .sum::<f64>()
        / total
        + 0.0;
    d.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0;
    let mut p95 = d.last().map_or(0.0, |x| x.0);
    for (dist, w) in &d {
        acc += w;
        if acc >= 0.95 * total {
            p95 = *dist;
            break;
        }
    }
    Some(SurfaceDistance {
        spacing: f64::from(spacing),
        mean,
        p95,
        floater_share: beyond,
        threshold,
        floaters,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_counts_overlap() {
        let a = [1.0, 1.0, 0.0, 0.0];
        let b = [1.0, 0.0, 1.0, 0.0];
        assert!((iou(&a, &b, 0.5) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(iou(&[0.0; 3], &[0.0; 3], 0.5), 1.0);
        let (hole, free) = coverage_errors(&[0.5, 1.0, 0.25, 0.0], &[1.0, 1.0, 0.0, 0.0]);
        assert_eq!((hole, free), (0.25, 0.125));
    }

    #[test]
    fn surface_distance_weights_by_opacity() {
        // Surface: points on the x axis at spacing 1; splats at distance 0, 0.5 and 10.
        let surface: Vec<Vec3> = (0..100).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
        let mut s = Splats::new(0);
        for (y, o) in [(0.0f32, 0.5f32), (0.5, 0.5), (10.0, 0.5)] {
            s.push(
                Vec3::new(50.0, y, 0.0),
                Vec3::ZERO,
                [1.0, 0.0, 0.0, 0.0],
                splat_core::logit(o),
                &[[0.0; 3]],
            );
        }
        let d = surface_distance(&s, &surface, 1.0, 2.0).unwrap();
        assert!((d.mean - 10.5 / 3.0).abs() < 1e-5, "{}", d.mean);
        assert!((d.floater_share - 1.0 / 3.0).abs() < 1e-9);
        assert_eq!(d.floaters, 1);
        assert!((d.p95 - 10.0).abs() < 1e-5);
    }

    /// A `w`×1 reference view straight down the z axis with the given coverage, grey where covered.
    fn strip(name: &str, alpha: Vec<f32>) -> ReferenceView {
        let w = alpha.len() as u32;
        ReferenceView {
            name: name.into(),
            camera: Camera::new(
                camera_model::Intrinsics::centered(w, 1, 1.0, 1.0),
                camera_model::Pose::IDENTITY,
            ),
            rgb: alpha.iter().flat_map(|&a| [0.5 * a; 3]).collect(),
            alpha,
        }
    }

    #[test]
    fn views_without_coverage_are_left_out_and_none_at_all_is_an_error() {
        let splats = Splats::new(0);
        let opts = EvalOptions {
            alpha_threshold: 0.5,
            floater_spacings: 2.0,
        };
        // Nothing covered anywhere: an empty model would score PSNR ∞ and SSIM 1; refused.
        let empty = [strip("a", vec![0.0; 16]), strip("b", vec![0.0; 16])];
        let e = evaluate(&splats, &empty, None, &opts).unwrap_err();
        assert!(matches!(e, EvalError::NothingCovered { views: 2 }), "{e}");
        assert!(
            e.to_string()
                .contains("none of the 2 reference views has a covered pixel")
        );
        // One covered view: the means are its scores, finite; the empty view is listed, unscored.
        let mut alpha = vec![0.0; 16];
        alpha[4..12].fill(1.0);
        let views = [strip("a", vec![0.0; 16]), strip("b", alpha)];
        let (m, renders) = evaluate(&splats, &views, None, &opts).unwrap();
        assert_eq!(renders.len(), 2);
        assert_eq!(
            (m.views[0].covered_pixels, m.views[1].covered_pixels),
            (0, 8)
        );
        // The empty model renders black: MSE on black = 8·3·0.25 / 48 = 1/8.
        let expected = -10.0 * (1.0f64 / 8.0).log10();
        assert!((m.psnr_black - expected).abs() < 1e-9, "{}", m.psnr_black);
        assert_eq!(m.psnr_black, m.views[1].psnr_black);
        assert!(m.views[0].psnr_black.is_infinite());
        assert_eq!(m.ssim_black, m.views[1].ssim_black);
    }

    #[test]
    fn reference_composites_with_alpha() {
        let v = ReferenceView {
            name: "v".into(),
            camera: Camera::new(
                camera_model::Intrinsics::centered(2, 1, 1.0, 1.0),
                camera_model::Pose::IDENTITY,
            ),
            rgb: vec![0.2, 0.4, 0.6, 0.0, 0.0, 0.0],
            alpha: vec![1.0, 0.0],
        };
        assert_eq!(
            v.on_background(Vec3::ONE),
            vec![0.2, 0.4, 0.6, 1.0, 1.0, 1.0]
        );
        assert_eq!(v.on_background(Vec3::ZERO), v.rgb);
    }
}
