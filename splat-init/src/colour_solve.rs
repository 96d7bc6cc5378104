//! Colour that starts right: the SH coefficients of fixed splats by linear least squares against
//! the training views.
//!
//! With positions, shapes and opacities fixed, a render over a background b is
//! `Σᵢ wᵢ(p)·(shᵢ(dᵢ)·xᵢ + 0.5) + (1 − α(p))·b` per channel (before the clamp at 0, which a good
//! colour rarely hits): a linear map A of the coefficients x plus a constant. The solve compares
//! on mid grey, b = 0.5, where the constant is exactly 0.5 whatever the coverage α: on black the
//! colour would learn to make up for coverage errors (darker where the splats cover too much),
//! which shows on white, and the other way round; grey is both backgrounds' mean and the mean of
//! the random backgrounds training uses. It minimises `Σ_views ‖A x + 0.5 − y_grey‖² + λ‖x − x₀‖²`
//! from the per-camera fit x₀ by conjugate gradients on
//! the normal equations, one solve per channel sharing every render: A p is a render in
//! `linear_colour` mode of the coefficients p, and Aᵀ r is the rasteriser's backward pass of
//! `Σ r·rgb` with respect to the SH coefficients (its adjoint, checked in splat-core's tests).
//! Each iteration is one forward and one backward pass over every view. Starting from x₀ and
//! stopping after a few iterations also regularises: coefficients the views do not constrain
//! stay at the fit.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use splat_core::{Rasterizer, RenderOptions, SplatGrads, Splats};
use splat_train::View;

/// Settings of [`solve_colours`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolveOptions {
    /// Conjugate-gradient iterations (each one forward and one backward pass over every view).
    pub iterations: u32,
    /// Ridge weight λ pulling the coefficients towards the starting fit, in the units of AᵀA
    /// (squared blending weight × pixels).
    pub ridge: f32,
}

impl Default for SolveOptions {
    fn default() -> Self {
        Self {
            iterations: 5,
            ridge: 1e-3,
        }
    }
}

/// What a solve did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SolveReport {
    /// Iterations run (fewer than asked when the residual vanished).
    pub iterations: u32,
    /// Root-mean-square error of the linear model over all views' pixel values (over mid grey),
    /// before the solve.
    pub rms_before: f64,
    /// Norm of the normal equations' residual after each iteration, relative to the first
    /// (the largest of the three channels).
    pub residuals: Vec<f64>,
}

/// Errors of [`solve_colours`].
#[derive(Debug, thiserror::Error)]
pub enum SolveError {
    /// A view's camera cannot be rendered, or its image does not fit it.
    #[error("colour solve: view {name}: {problem}")]
    View {
        /// The view's name.
        name: String,
        /// What is wrong with it.
        problem: String,
    },
}

/// Replaces the SH coefficients of `splats` (all bands of their degree) by the least-squares
/// solution against `views` (module docs), starting from the current ones.
///
/// # Errors
/// [`SolveError::View`] when a view's camera or image does not fit.
pub fn solve_colours(
    splats: &mut Splats,
    views: &[View],
    opts: &SolveOptions,
) -> Result<SolveReport, SolveError> {
    let cameras = views
        .iter()
        .map(|v| {
            v.check().map_err(|problem| SolveError::View {
                name: v.name.clone(),
                problem,
            })?;
            v.render_camera().map_err(|problem| SolveError::View {
                name: v.name.clone(),
                problem,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let targets: Vec<Vec<f32>> = views.iter().map(|v| v.on_background([0.5; 3])).collect();
    let render = RenderOptions {
        background: Vec3::ZERO,
        active_sh_degree: splats.sh_degree,
        antialiased: false,
        linear_colour: true,
    };
    let mut raster = Rasterizer::new();
    let mut grads = SplatGrads::zeros_like(splats);

    // Right-hand side: g = Aᵀ(y − 0.5 − A x₀), the gradient at the start, with δ = x − x₀.
    let mut work = splats.clone();
    let mut sq_error = 0.0f64;
    let mut values = 0usize;
    grads.reset(&work);
    for (cam, y) in cameras.iter().zip(&targets) {
        let out = raster.forward(&work, cam, &render);
        let residual: Vec<f32> = out.rgb.iter().zip(y).map(|(ax, y)| y - 0.5 - ax).collect();
        sq_error += residual.iter().map(|r| f64::from(*r).powi(2)).sum::<f64>();
        values += residual.len();
        raster.backward(&work, cam, &render, &residual, None, None, &mut grads);
    }
    let rms_before = (sq_error / values.max(1) as f64).sqrt();

    // Conjugate gradients on (AᵀA + λI) δ = g, one per channel over shared renders.
    let n = splats.sh.len();
    let mut delta = vec![[0.0f32; 3]; n];
    let mut r = grads.sh.clone();
    let mut p = r.clone();
    let mut rs = dot(&r, &r);
    let first = rs.map(f64::sqrt);
    let mut residuals = Vec::new();
    let mut done = 0;
    for _ in 0..opts.iterations {
        if rs.iter().all(|&v| v == 0.0) {
            break;
        }
        // q = (AᵀA + λI) p.
        work.sh.copy_from_slice(&p);
        grads.reset(&work);
        for cam in &cameras {
            let ap = raster.forward(&work, cam, &render).rgb.clone();
            raster.backward(&work, cam, &render, &ap, None, None, &mut grads);
        }
        let mut q = std::mem::take(&mut grads.sh);
        for (qk, pk) in q.iter_mut().zip(&p) {
            for c in 0..3 {
                qk[c] += opts.ridge * pk[c];
            }
        }
        let pq = dot(&p, &q);
        let step: [f32; 3] = [0, 1, 2].map(|c| {
            if pq[c] > 0.0 {
                (rs[c] / pq[c]) as f32
            } else {
                0.0
            }
        });
        for k in 0..n {
            for c in 0..3 {
                delta[k][c] += step[c] * p[k][c];
                r[k][c] -= step[c] * q[k][c];
            }
        }
        let rs_next = dot(&r, &r);
        for k in 0..n {
            for c in 0..3 {
                let beta = if rs[c] > 0.0 { rs_next[c] / rs[c] } else { 0.0 };
                p[k][c] = r[k][c] + beta as f32 * p[k][c];
            }
        }
        rs = rs_next;
        done += 1;
        residuals.push(
            (0..3)
                .map(|c| {
                    if first[c] > 0.0 {
                        rs[c].sqrt() / first[c]
                    } else {
                        0.0
                    }
                })
                .fold(0.0, f64::max),
        );
    }
    for (x, d) in splats.sh.iter_mut().zip(&delta) {
        for c in 0..3 {
            x[c] += d[c];
        }
    }
    Ok(SolveReport {
        iterations: done,
        rms_before,
        residuals,
    })
}

/// Per-channel dot products in f64.
fn dot(a: &[[f32; 3]], b: &[[f32; 3]]) -> [f64; 3] {
    let mut s = [0.0f64; 3];
    for (x, y) in a.iter().zip(b) {
        for c in 0..3 {
            s[c] += f64::from(x[c]) * f64::from(y[c]);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::{Camera, Intrinsics, Pose};
    use glam::DVec3;

    /// Views of `splats` (an ordinary render over black, with its coverage as mask) from a ring
    /// and two poles of cameras.
    fn views_of(splats: &Splats) -> Vec<View> {
        let mut raster = Rasterizer::new();
        let mut eyes: Vec<DVec3> = (0..10)
            .map(|i| {
                let t = f64::from(i) * std::f64::consts::TAU / 10.0;
                DVec3::new(4.0 * t.cos(), 1.0 + 0.3 * t.sin(), 4.0 * t.sin())
            })
            .collect();
        eyes.push(DVec3::new(0.1, 4.0, 0.2));
        eyes.push(DVec3::new(-0.2, -4.0, 0.1));
        eyes.iter()
            .enumerate()
            .map(|(i, &eye)| {
                let camera = Camera::new(
                    Intrinsics::from_fov_y(48, 48, 40.0),
                    Pose::look_at(eye, DVec3::ZERO, DVec3::new(0.0, 0.0, 1.0)),
                );
                let cam = splat_core::RenderCamera::try_from(&camera).unwrap();
                let out = raster.forward(splats, &cam, &RenderOptions::default());
                View::from_premultiplied(format!("v{i}"), camera, &out.rgb, out.alpha.clone())
            })
            .collect()
    }

    /// Squared error of an ordinary render of `splats` over black against the views.
    fn image_error(splats: &Splats, views: &[View]) -> f64 {
        let mut raster = Rasterizer::new();
        views
            .iter()
            .map(|v| {
                let out = raster.forward(
                    splats,
                    &v.render_camera().unwrap(),
                    &RenderOptions::default(),
                );
                splat_train::metrics::mse(&out.rgb, &v.on_background([0.0; 3]))
            })
            .sum()
    }

    /// Splats with known degree-2 colours make the views; from a wrong start (grey, no view
    /// dependence) the solve brings the renders back to the views: the image error falls by
    /// a thousandfold and the normal equations' residual ends below 1 % of its start.
    #[test]
    fn recovers_the_colours_that_made_the_views() {
        let mut truth = Splats::new(2);
        let mut seed = 3u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        };
        for i in 0..60 {
            let t = i as f32 * 0.7;
            let mean = Vec3::new(t.cos(), (i as f32 / 30.0) - 1.0, t.sin()) * 0.8;
            let mut sh = vec![[0.0f32; 3]; 9];
            // DC between 0.3 and 0.7 in colour, small view dependence: no clamping.
            sh[0] = [next() * 1.4, next() * 1.4, next() * 1.4];
            for c in &mut sh[1..] {
                *c = [next() * 0.2, next() * 0.2, next() * 0.2];
            }
            truth.push(mean, Vec3::splat(-2.0), [1.0, 0.0, 0.0, 0.0], 1.5, &sh);
        }
        let views = views_of(&truth);
        let mut start = truth.clone();
        for c in &mut start.sh {
            *c = [0.0; 3];
        }
        let before = image_error(&start, &views);
        let mut solved = start.clone();
        let report = solve_colours(
            &mut solved,
            &views,
            &SolveOptions {
                iterations: 40,
                ridge: 0.0,
            },
        )
        .unwrap();
        let after = image_error(&solved, &views);
        assert!(before > 1e-3, "{before}");
        assert!(after < 1e-3 * before, "image error {before} → {after}");
        assert_eq!(report.iterations as usize, report.residuals.len());
        assert!(report.rms_before > 0.01);
        assert!(
            report.residuals.last().unwrap() < &1e-2,
            "{:?}",
            report.residuals
        );
        // Zero iterations leave the coefficients alone.
        let mut same = start.clone();
        let r = solve_colours(
            &mut same,
            &views,
            &SolveOptions {
                iterations: 0,
                ridge: 0.0,
            },
        )
        .unwrap();
        assert_eq!((same.sh, r.iterations), (start.sh, 0));
    }
}
