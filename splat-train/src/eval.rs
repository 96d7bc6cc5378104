//! Evaluation of a model on held-out views: PSNR and SSIM on the model's background.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, Splats};

use crate::metrics::{psnr, ssim};
use crate::view::View;

/// Scores of one view.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ViewScore {
    /// View name.
    pub name: String,
    /// PSNR in dB.
    pub psnr: f64,
    /// Mean SSIM.
    pub ssim: f64,
}

/// Scores over a set of views.
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
/// over `background` where the view has a mask).
#[must_use]
pub fn evaluate(splats: &Splats, views: &[View], background: glam::Vec3) -> Evaluation {
    let opts = RenderOptions {
        background,
        active_sh_degree: splats.sh_degree,
        antialiased: false,
    };
    evaluate_with(splats, views, &opts)
}

/// [`evaluate`] with explicit render options.
#[must_use]
pub fn evaluate_with(splats: &Splats, views: &[View], opts: &RenderOptions) -> Evaluation {
    let mut raster = Rasterizer::new();
    let mut scores = Vec::with_capacity(views.len());
    for v in views {
        let cam = RenderCamera::from(&v.camera);
        let out = raster.forward(splats, &cam, opts);
        let render: Vec<f32> = out.rgb.par_iter().map(|x| x.clamp(0.0, 1.0)).collect();
        let target: Vec<f32> = match &v.mask {
            Some(mask) => v
                .image
                .chunks_exact(3)
                .zip(mask)
                .flat_map(|(px, &a)| {
                    let bg = opts.background.to_array();
                    [0, 1, 2].map(|c| px[c] * a + bg[c] * (1.0 - a))
                })
                .collect(),
            None => v.image.clone(),
        };
        scores.push(ViewScore {
            name: v.name.clone(),
            psnr: psnr(&render, &target),
            ssim: ssim(&render, &target, cam.width, cam.height),
        });
    }
    let n = scores.len().max(1) as f64;
    Evaluation {
        psnr: scores.iter().map(|s| s.psnr).sum::<f64>() / n,
        ssim: scores.iter().map(|s| s.ssim).sum::<f64>() / n,
        views: scores,
    }
}
