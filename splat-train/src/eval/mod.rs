//! Evaluation of a model on held-out views: image metrics, coverage, distance to the surface.
//!
//! One scoring path serves every caller: a view is rendered over a background (at the model's
//! full SH degree, without antialiasing), the render is clamped to [0, 1] as Inria's evaluation
//! does, and it is scored with PSNR and SSIM against the view's colour over the same background
//! ([`View::on_background`]).
//!
//! - [`evaluate`] / [`evaluate_with`] score on one background (the trainer's, during a run).
//! - [`evaluate_views`] scores on black and on white (a floater that happens to match one
//!   background shows on the other), also over the object's pixels only (masked PSNR, as MPEG's
//!   Gaussian-splat coding evaluations report it, since a mostly empty background inflates the
//!   full-image figure), splits the error by region and into its alpha part ([`breakdown`]),
//!   measures how well the rendered coverage matches the views' masks, and, given the input's
//!   surface points, how far the splats are from them.
//! - [`psnr_black_and_white`] gives [`evaluate_views`]' two mean PSNRs alone from one render a
//!   view, for the splat budget's rounds, which score both branches several times a round.

use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, Splats};

pub mod breakdown;
pub mod surface;

pub use breakdown::{ErrorBreakdown, MASKED_ALPHA, RegionError};
pub use surface::{SurfaceDistance, surface_distance};

use crate::init::SurfaceIndex;
use crate::metrics::{psnr, psnr_from_mse, ssim};
use crate::view::View;

/// Errors of [`evaluate_views`].
#[derive(Debug, thiserror::Error)]
pub enum EvalError {
    /// A view cannot be rendered (its camera is skewed).
    #[error("view {name}: {problem}")]
    View {
        /// The view's name.
        name: String,
        /// What is wrong with it.
        problem: String,
    },
    /// No view covers a single pixel: an empty render would match every one of them
    /// (PSNR ∞, SSIM 1), so there is nothing to score.
    #[error(
        "none of the {views} reference views has a covered pixel (every mask or alpha is 0): there is nothing to score"
    )]
    NothingCovered {
        /// Number of views.
        views: usize,
    },
}

/// Scores of one view on one background.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewScore {
    /// View name.
    pub name: String,
    /// PSNR in dB.
    pub psnr: f64,
    /// Mean SSIM.
    pub ssim: f64,
}

/// Scores over a set of views on one background.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Evaluation {
    /// Mean PSNR over the views, in dB.
    pub psnr: f64,
    /// Mean SSIM over the views.
    pub ssim: f64,
    /// Per-view scores, in the order given.
    pub views: Vec<ViewScore>,
}

/// Renders `splats` (at their full SH degree, over `background`) from every view, clamps the
/// render to [0, 1] as Inria's evaluation does, and scores it against the view's image (composited
/// over `background` where the view has a mask). The means run over all views.
///
/// # Errors
/// [`EvalError::View`] when a view's camera cannot be rendered (skew).
pub fn evaluate(
    splats: &Splats,
    views: &[View],
    background: Vec3,
) -> Result<Evaluation, EvalError> {
    evaluate_with(splats, views, &render_options(splats, background, false))
}

/// [`evaluate`] with explicit render options.
///
/// # Errors
/// [`EvalError::View`] when a view's camera cannot be rendered (skew).
pub fn evaluate_with(
    splats: &Splats,
    views: &[View],
    opts: &RenderOptions,
) -> Result<Evaluation, EvalError> {
    let mut raster = Rasterizer::new();
    let scores: Vec<ViewScore> = views
        .iter()
        .map(|v| {
            let s = score(&mut raster, splats, v, opts)?;
            Ok(ViewScore {
                name: v.name.clone(),
                psnr: s.psnr,
                ssim: s.ssim,
            })
        })
        .collect::<Result<_, EvalError>>()?;
    let n = scores.len().max(1) as f64;
    Ok(Evaluation {
        psnr: scores.iter().map(|s| s.psnr).sum::<f64>() / n,
        ssim: scores.iter().map(|s| s.ssim).sum::<f64>() / n,
        views: scores,
    })
}

/// Options for rendering `splats` over `background` for evaluation: full SH degree, with the
/// antialiased opacity compensation or without.
fn render_options(splats: &Splats, background: Vec3, antialiased: bool) -> RenderOptions {
    RenderOptions {
        background,
        active_sh_degree: splats.sh_degree,
        antialiased,
        linear_colour: false,
    }
}

/// A render clamped to [0, 1] as Inria's evaluation clamps it; with `white`, first moved from
/// a black background to a white one by adding the transmittance left (`1 − alpha`) to every
/// channel, which is what the rasteriser adds for a white background.
fn clamped(rgb: &[f32], white: Option<&[f32]>) -> Vec<f32> {
    match white {
        None => rgb.par_iter().map(|x| x.clamp(0.0, 1.0)).collect(),
        Some(alpha) => rgb
            .par_chunks(3)
            .zip(alpha.par_iter())
            .flat_map_iter(|(px, &a)| px.iter().map(move |&c| clamped_on_white(c, a)))
            .collect(),
    }
}

/// One channel of a render on black with coverage `a`, moved onto white and clamped
/// ([`clamped`]).
#[inline(always)]
fn clamped_on_white(c: f32, a: f32) -> f32 {
    (c + (1.0 - a)).clamp(0.0, 1.0)
}

/// Pixels per parallel task of [`squared_errors_black_and_white`].
const ERROR_CHUNK: usize = 16 * 1024;

/// The summed squared errors of a render on black (`rgb`, coverage `alpha`), clamped, against
/// `view` on black, and of the same render moved onto white against `view` on white: what
/// [`psnr`] of [`clamped`] against [`View::on_background`] sums, in one parallel pass that
/// holds no whole image (the splat budget's rounds score 8 views, 8 times a round, and the
/// copies cost a quarter of a score). The chunks' sums are added in order, so the result does
/// not depend on the thread count.
fn squared_errors_black_and_white(rgb: &[f32], alpha: &[f32], view: &View) -> (f64, f64) {
    let pixels = alpha.len().min(rgb.len() / 3).min(view.image.len() / 3);
    let parts: Vec<(f64, f64)> = (0..pixels.div_ceil(ERROR_CHUNK))
        .into_par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(on_black, on_white), c| {
                let (first, last) = (c * ERROR_CHUNK, ((c + 1) * ERROR_CHUNK).min(pixels));
                on_black.resize(3 * (last - first), 0.0);
                on_white.resize(3 * (last - first), 0.0);
                view.target_part_into(first, on_black, [0.0; 3]);
                view.target_part_into(first, on_white, [1.0; 3]);
                // One running sum per channel and background: six independent chains.
                let (mut black, mut white) = ([0.0_f64; 3], [0.0_f64; 3]);
                let render = rgb[3 * first..3 * last].chunks_exact(3);
                let targets = on_black.chunks_exact(3).zip(on_white.chunks_exact(3));
                for ((px, &a), (tb, tw)) in render.zip(&alpha[first..last]).zip(targets) {
                    for ch in 0..3 {
                        let eb = f64::from(px[ch].clamp(0.0, 1.0) - tb[ch]);
                        let ew = f64::from(clamped_on_white(px[ch], a) - tw[ch]);
                        black[ch] += eb * eb;
                        white[ch] += ew * ew;
                    }
                }
                (black.iter().sum(), white.iter().sum())
            },
        )
        .collect();
    parts
        .iter()
        .fold((0.0, 0.0), |(b, w), &(pb, pw)| (b + pb, w + pw))
}

/// The mean held-out PSNR (dB) of `splats` on black and on white over `views`, as
/// [`evaluate_views`] reports [`Metrics::psnr_black`] and [`Metrics::psnr_white`] (to float
/// rounding), from one render a view: the render over white is the render over black plus the
/// transmittance left. None of the SSIM, breakdown or coverage scores: the splat budget's rounds
/// need only these two, eight times a round.
///
/// # Errors
/// As [`evaluate_views`]: a view whose camera cannot be rendered, or no covered pixel in any
/// view.
pub fn psnr_black_and_white(
    splats: &Splats,
    views: &[View],
    opts: &EvalOptions,
) -> Result<(f64, f64), EvalError> {
    let mut raster = Rasterizer::new();
    let (mut black, mut white, mut scored) = (0.0, 0.0, 0_usize);
    for v in views {
        if covered_pixels(v) == 0 {
            continue;
        }
        let cam = camera_of(v)?;
        let out = raster.forward(
            splats,
            &cam,
            &render_options(splats, Vec3::ZERO, opts.antialiased),
        );
        let (sse_black, sse_white) = squared_errors_black_and_white(&out.rgb, &out.alpha, v);
        let values = out.rgb.len().min(v.image.len()).max(1) as f64;
        black += psnr_from_mse(sse_black / values);
        white += psnr_from_mse(sse_white / values);
        scored += 1;
    }
    if scored == 0 {
        return Err(EvalError::NothingCovered { views: views.len() });
    }
    Ok((black / scored as f64, white / scored as f64))
}

/// The rasteriser's camera of `view`, or the evaluation error naming it.
fn camera_of(view: &View) -> Result<RenderCamera, EvalError> {
    view.render_camera().map_err(|problem| EvalError::View {
        name: view.name.clone(),
        problem,
    })
}

/// Pixels of `view` its reference covers (every pixel of a view without a mask).
fn covered_pixels(view: &View) -> usize {
    match &view.mask {
        Some(m) => m.iter().filter(|&&a| a > 0).count(),
        None => {
            let k = &view.camera.intrinsics;
            k.width as usize * k.height as usize
        }
    }
}

/// One view scored on one background, with the clamped render and its coverage.
struct Scored {
    psnr: f64,
    ssim: f64,
    rgb: Vec<f32>,
    alpha: Vec<f32>,
    target: Vec<f32>,
}

/// The one scoring path: render over `opts.background`, clamp to [0, 1], PSNR and SSIM against
/// the view over the same background.
fn score(
    raster: &mut Rasterizer,
    splats: &Splats,
    view: &View,
    opts: &RenderOptions,
) -> Result<Scored, EvalError> {
    let cam = camera_of(view)?;
    let out = raster.forward(splats, &cam, opts);
    let rgb = clamped(&out.rgb, None);
    let target = view.on_background(opts.background.to_array());
    Ok(Scored {
        psnr: psnr(&rgb, &target),
        ssim: ssim(&rgb, &target, cam.width, cam.height),
        rgb,
        alpha: out.alpha.clone(),
        target,
    })
}

/// Scores of one view on both backgrounds, with coverage errors.
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
    /// PSNR (dB) on black over the pixels where the reference or the render has coverage above
    /// [`MASKED_ALPHA`] (the object only).
    #[serde(default)]
    pub masked_psnr_black: f64,
    /// PSNR (dB) on white over the same pixels.
    #[serde(default)]
    pub masked_psnr_white: f64,
    /// The error split by region and into its alpha part.
    #[serde(default)]
    pub breakdown: ErrorBreakdown,
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
    /// Mean masked PSNR (dB) on black (see [`ViewMetrics::masked_psnr_black`]).
    #[serde(default)]
    pub masked_psnr_black: f64,
    /// Mean masked PSNR (dB) on white.
    #[serde(default)]
    pub masked_psnr_white: f64,
    /// Mean error breakdown over the views (see [`ErrorBreakdown`]).
    #[serde(default)]
    pub breakdown: ErrorBreakdown,
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

impl Metrics {
    /// One held-out score for both backgrounds: the PSNR of the mean of the black- and
    /// white-background MSEs (each the mean PSNR's MSE). A change that spoils the coverage at a
    /// dark object's silhouette is nearly invisible on black and plain on white; decisions that
    /// compare models (the splat budget's rounds, the SH bands) use this so they see both.
    #[must_use]
    pub fn psnr_both(&self) -> f64 {
        psnr_both(self.psnr_black, self.psnr_white)
    }
}

/// The PSNR of the mean of the MSEs behind a black- and a white-background PSNR
/// ([`Metrics::psnr_both`], for figures from [`psnr_black_and_white`] too).
#[must_use]
pub fn psnr_both(psnr_black: f64, psnr_white: f64) -> f64 {
    let mse = |psnr: f64| 10f64.powf(-psnr / 10.0);
    psnr_from_mse(0.5 * (mse(psnr_black) + mse(psnr_white)))
}

/// The splats' render of one view on black, kept for pictures.
#[derive(Debug, Clone, PartialEq)]
pub struct RenderedView {
    /// Colours on black, clamped to [0, 1].
    pub rgb: Vec<f32>,
    /// Coverage.
    pub alpha: Vec<f32>,
}

/// Settings of [`evaluate_views`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EvalOptions {
    /// Coverage above this counts as covered for the IoU.
    pub alpha_threshold: f32,
    /// Floater threshold in point spacings.
    pub floater_spacings: f64,
    /// Render with the antialiased (Mip-Splatting) opacity compensation, as a model trained
    /// that way must be seen.
    pub antialiased: bool,
}

/// Renders `splats` from every view on black and white and scores them; with the input's
/// surface points and spacing, also measures the splats' distance to the surface. A view
/// without a mask covers all its pixels. The means are over the views that cover at least one
/// pixel; when none does, the result is [`EvalError::NothingCovered`] rather than a
/// perfect-looking score. Returns the metrics and each view's render on black.
///
/// # Errors
/// [`EvalError::NothingCovered`] when no view covers a pixel.
pub fn evaluate_views(
    splats: &Splats,
    views: &[View],
    surface: Option<&SurfaceIndex>,
    opts: &EvalOptions,
) -> Result<(Metrics, Vec<RenderedView>), EvalError> {
    let covered: Vec<usize> = views.iter().map(covered_pixels).collect();
    if covered.iter().all(|&c| c == 0) {
        return Err(EvalError::NothingCovered { views: views.len() });
    }
    let mut raster = Rasterizer::new();
    let mut per_view = Vec::with_capacity(views.len());
    let mut renders = Vec::with_capacity(views.len());
    for (v, &covered_pixels) in views.iter().zip(&covered) {
        // The reference coverage as f32, one view at a time (1 everywhere without a mask).
        let reference = &v.coverage().unwrap_or_else(|| {
            let k = &v.camera.intrinsics;
            vec![1.0; k.width as usize * k.height as usize]
        });
        let black = score(
            &mut raster,
            splats,
            v,
            &render_options(splats, Vec3::ZERO, opts.antialiased),
        )?;
        let white = score(
            &mut raster,
            splats,
            v,
            &render_options(splats, Vec3::ONE, opts.antialiased),
        )?;
        let alpha_iou = iou(&black.alpha, reference, opts.alpha_threshold);
        let (hole_alpha, free_alpha) = coverage_errors(&black.alpha, reference);
        let (breakdown, [masked_psnr_black, masked_psnr_white]) =
            breakdown::analyse(&breakdown::Pair {
                width: v.camera.intrinsics.width as usize,
                reference_alpha: reference,
                rendered_alpha: &black.alpha,
                reference: [&black.target, &white.target],
                rendered: [&black.rgb, &white.rgb],
            });
        per_view.push(ViewMetrics {
            name: v.name.clone(),
            psnr_black: black.psnr,
            psnr_white: white.psnr,
            ssim_black: black.ssim,
            ssim_white: white.ssim,
            masked_psnr_black,
            masked_psnr_white,
            breakdown,
            alpha_iou,
            hole_alpha,
            free_alpha,
            covered_pixels,
        });
        renders.push(RenderedView {
            rgb: black.rgb,
            alpha: black.alpha,
        });
    }
    let scored: Vec<&ViewMetrics> = per_view.iter().filter(|v| v.covered_pixels > 0).collect();
    let mean =
        |f: fn(&ViewMetrics) -> f64| scored.iter().map(|v| f(v)).sum::<f64>() / scored.len() as f64;
    let metrics = Metrics {
        psnr_black: mean(|v| v.psnr_black),
        psnr_white: mean(|v| v.psnr_white),
        ssim_black: mean(|v| v.ssim_black),
        ssim_white: mean(|v| v.ssim_white),
        masked_psnr_black: mean(|v| v.masked_psnr_black),
        masked_psnr_white: mean(|v| v.masked_psnr_white),
        breakdown: ErrorBreakdown::mean(scored.iter().map(|v| &v.breakdown)),
        alpha_iou: mean(|v| v.alpha_iou),
        hole_alpha: mean(|v| v.hole_alpha),
        free_alpha: mean(|v| v.free_alpha),
        surface: surface.and_then(|s| surface_distance(splats, s, opts.floater_spacings)),
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

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::{Camera, Intrinsics, Pose};

    #[test]
    fn psnr_both_is_the_psnr_of_the_mean_mse() {
        let m = Metrics {
            psnr_black: 40.0,
            psnr_white: 30.0,
            ssim_black: 1.0,
            ssim_white: 1.0,
            masked_psnr_black: 0.0,
            masked_psnr_white: 0.0,
            breakdown: ErrorBreakdown::default(),
            alpha_iou: 1.0,
            hole_alpha: 0.0,
            free_alpha: 0.0,
            surface: None,
            splats: 0,
            views: Vec::new(),
        };
        // MSEs 1e-4 and 1e-3: their mean 5.5e-4 is 32.596 dB.
        assert!((m.psnr_both() - (-10.0 * 5.5e-4_f64.log10())).abs() < 1e-9);
        let same = Metrics {
            psnr_white: 40.0,
            ..m
        };
        assert!((same.psnr_both() - 40.0).abs() < 1e-9);
    }

    #[test]
    fn iou_counts_overlap() {
        let a = [1.0, 1.0, 0.0, 0.0];
        let b = [1.0, 0.0, 1.0, 0.0];
        assert!((iou(&a, &b, 0.5) - 1.0 / 3.0).abs() < 1e-12);
        assert_eq!(iou(&[0.0; 3], &[0.0; 3], 0.5), 1.0);
        let (hole, free) = coverage_errors(&[0.5, 1.0, 0.25, 0.0], &[1.0, 1.0, 0.0, 0.0]);
        assert_eq!((hole, free), (0.25, 0.125));
    }

    /// A `w`×1 view straight down the z axis with the given coverage, grey where covered.
    fn strip(name: &str, alpha: Vec<f32>) -> View {
        let w = alpha.len() as u32;
        let rgb: Vec<f32> = alpha.iter().flat_map(|&a| [0.5 * a; 3]).collect();
        View::from_premultiplied(
            name.into(),
            Camera::new(Intrinsics::centered(w, 1, 1.0, 1.0), Pose::IDENTITY),
            &rgb,
            &alpha,
        )
        .unwrap()
    }

    #[test]
    fn views_without_coverage_are_left_out_and_none_at_all_is_an_error() {
        let splats = Splats::new(0);
        let opts = EvalOptions {
            alpha_threshold: 0.5,
            floater_spacings: 2.0,
            antialiased: false,
        };
        // Nothing covered anywhere: an empty model would score PSNR ∞ and SSIM 1; refused.
        let empty = [strip("a", vec![0.0; 16]), strip("b", vec![0.0; 16])];
        let e = evaluate_views(&splats, &empty, None, &opts).unwrap_err();
        assert!(matches!(e, EvalError::NothingCovered { views: 2 }), "{e}");
        assert!(
            e.to_string()
                .contains("none of the 2 reference views has a covered pixel")
        );
        // One covered view: the means are its scores, finite; the empty view is listed, unscored.
        let mut alpha = vec![0.0; 16];
        alpha[4..12].fill(1.0);
        let views = [strip("a", vec![0.0; 16]), strip("b", alpha)];
        let (m, renders) = evaluate_views(&splats, &views, None, &opts).unwrap();
        assert_eq!(renders.len(), 2);
        assert_eq!(
            (m.views[0].covered_pixels, m.views[1].covered_pixels),
            (0, 8)
        );
        // The grey g is 0.5 in 16 bits (32768 / 65535): g² ≈ (1 − g)² ≈ ¼.
        let g = f64::from(crate::view::from_unorm16(32768));
        let (g2, w2) = (g * g, (1.0 - g) * (1.0 - g));
        // The empty model renders black: MSE on black = 8·3·g² / 48 = g²/2.
        let expected = -10.0 * (g2 / 2.0).log10();
        assert!((m.psnr_black - expected).abs() < 1e-9, "{}", m.psnr_black);
        assert_eq!(m.psnr_black, m.views[1].psnr_black);
        assert!(m.views[0].psnr_black.is_infinite());
        assert_eq!(m.ssim_black, m.views[1].ssim_black);
        // On white the uncovered pixels are white in both: MSE = 8·3·(1 − g)² / 48.
        let expected_white = -10.0 * (w2 / 2.0).log10();
        assert!(
            (m.psnr_white - expected_white).abs() < 1e-9,
            "{}",
            m.psnr_white
        );
        // Masked, only the 8 covered pixels count: MSE g² on black and (1 − g)² on white, where
        // all of it is the missing coverage (g grey on white against white).
        assert!((m.masked_psnr_black - -10.0 * g2.log10()).abs() < 1e-9);
        assert!((m.masked_psnr_white - -10.0 * w2.log10()).abs() < 1e-9);
        let b = &m.views[1].breakdown;
        assert_eq!(
            b.interior.pixels + b.silhouette.pixels + b.background.pixels,
            16
        );
        assert!((b.interior.mse_alpha + b.silhouette.mse_alpha - 0.5).abs() < 1e-9);
        // Nothing rendered: the 8 covered pixels are all hole, the rest free space with 0.
        assert_eq!(
            (
                m.views[1].alpha_iou,
                m.views[1].hole_alpha,
                m.views[1].free_alpha
            ),
            (0.0, 1.0, 0.0)
        );
    }

    /// The one-render PSNRs match a full evaluation's on both backgrounds, on a model that
    /// covers part of a view and misses part of its mask (so white and black differ), and
    /// refuse views with nothing covered as it does.
    #[test]
    fn one_render_psnrs_match_the_full_evaluation() {
        let means: Vec<Vec3> = (0..24)
            .map(|i| {
                Vec3::new(
                    (i % 6) as f32 * 0.1 - 0.25,
                    (i / 6) as f32 * 0.1 - 0.15,
                    2.0,
                )
            })
            .collect();
        let colours: Vec<[f32; 3]> = (0..24)
            .map(|i| [0.1 + 0.03 * i as f32, 0.8 - 0.02 * i as f32, 0.5])
            .collect();
        let splats =
            Splats::from_points(&means, &colours, &vec![Vec3::splat(0.04); 24], None, 0.7, 0)
                .unwrap();
        let (w, h) = (24_u32, 20_u32);
        let camera = Camera::new(Intrinsics::centered(w, h, 30.0, 30.0), Pose::IDENTITY);
        let views: Vec<View> = (0..3)
            .map(|k| {
                let alpha: Vec<f32> = (0..w * h)
                    .map(|p| if (p % w) as usize + k < 14 { 0.9 } else { 0.0 })
                    .collect();
                let rgb: Vec<f32> = alpha
                    .iter()
                    .flat_map(|&a| [0.6 * a, 0.3 * a, 0.2 * a])
                    .collect();
                View::from_premultiplied(format!("v{k}"), camera, &rgb, &alpha).unwrap()
            })
            .collect();
        let opts = EvalOptions {
            alpha_threshold: 0.5,
            floater_spacings: 2.0,
            antialiased: false,
        };
        let (m, _) = evaluate_views(&splats, &views, None, &opts).unwrap();
        let (black, white) = psnr_black_and_white(&splats, &views, &opts).unwrap();
        assert!((m.psnr_white - m.psnr_black).abs() > 0.1, "{m:?}");
        assert!(
            (black - m.psnr_black).abs() < 1e-4,
            "{black} {}",
            m.psnr_black
        );
        assert!(
            (white - m.psnr_white).abs() < 1e-4,
            "{white} {}",
            m.psnr_white
        );
        let empty = [View {
            mask: Some(vec![0; (w * h) as usize]),
            ..views[0].clone()
        }];
        assert!(matches!(
            psnr_black_and_white(&splats, &empty, &opts),
            Err(EvalError::NothingCovered { views: 1 })
        ));
    }

    /// The one-pass squared errors equal the sums over the whole clamped images against the
    /// whole targets (f64, in order), over several chunks and a partial last one, with a mask
    /// and without, with renders outside [0, 1] that the clamps must catch.
    #[test]
    fn one_pass_squared_errors_match_the_whole_image_sums() {
        let (w, h) = (300_u32, 131_u32);
        let pixels = (w * h) as usize;
        assert!(pixels > 2 * ERROR_CHUNK && !pixels.is_multiple_of(ERROR_CHUNK));
        let wave = |i: usize, f: f32| 0.5 + 0.7 * (i as f32 * f).sin();
        let rgb: Vec<f32> = (0..3 * pixels).map(|i| wave(i, 0.013)).collect();
        let alpha: Vec<f32> = (0..pixels)
            .map(|i| wave(i, 0.007).clamp(0.0, 1.0))
            .collect();
        let colour: Vec<f32> = (0..3 * pixels)
            .map(|i| wave(i, 0.011).clamp(0.0, 1.0))
            .collect();
        let cover: Vec<f32> = (0..pixels)
            .map(|i| wave(i, 0.005).clamp(0.0, 1.0))
            .collect();
        let camera = Camera::new(Intrinsics::centered(w, h, 200.0, 200.0), Pose::IDENTITY);
        let masked = View::from_straight("m".into(), camera, &colour, Some(&cover)).unwrap();
        let plain = View {
            mask: None,
            ..masked.clone()
        };
        let sse = |a: &[f32], b: &[f32]| -> f64 {
            a.iter()
                .zip(b)
                .map(|(x, y)| f64::from(x - y) * f64::from(x - y))
                .sum()
        };
        for view in [&masked, &plain] {
            let black = sse(&clamped(&rgb, None), &view.on_background([0.0; 3]));
            let white = sse(&clamped(&rgb, Some(&alpha)), &view.on_background([1.0; 3]));
            let (b, wh) = squared_errors_black_and_white(&rgb, &alpha, view);
            assert!(black > 1.0 && white > 1.0 && (black - white).abs() > 1.0);
            assert!((b - black).abs() <= 1e-12 * black, "{b} {black}");
            assert!((wh - white).abs() <= 1e-12 * white, "{wh} {white}");
        }
    }

    /// A view without a mask covers every pixel, and [`evaluate`] (one background, means over
    /// all views) scores it as [`evaluate_views`] does on that background.
    #[test]
    fn unmasked_views_cover_everything_and_both_entry_points_agree() {
        let splats = Splats::new(0);
        let view = View {
            name: "grey".into(),
            camera: Camera::new(Intrinsics::centered(16, 1, 1.0, 1.0), Pose::IDENTITY),
            // A quarter grey (16384 of 65535, a hair over ¼).
            image: vec![16384; 48],
            mask: None,
        };
        let opts = EvalOptions {
            alpha_threshold: 0.5,
            floater_spacings: 2.0,
            antialiased: false,
        };
        let (m, _) = evaluate_views(&splats, std::slice::from_ref(&view), None, &opts).unwrap();
        assert_eq!(m.views[0].covered_pixels, 16);
        // Black render against grey g: MSE g²; white render: MSE (1 − g)².
        let g = f64::from(crate::view::from_unorm16(16384));
        assert!((m.psnr_black - -10.0 * (g * g).log10()).abs() < 1e-6);
        assert!((m.psnr_white - -10.0 * ((1.0 - g) * (1.0 - g)).log10()).abs() < 1e-6);
        let black = evaluate(&splats, std::slice::from_ref(&view), Vec3::ZERO).unwrap();
        let white = evaluate(&splats, std::slice::from_ref(&view), Vec3::ONE).unwrap();
        assert_eq!((black.psnr, black.ssim), (m.psnr_black, m.ssim_black));
        assert_eq!((white.psnr, white.ssim), (m.psnr_white, m.ssim_white));
    }
}
