//! Colour that starts right: the SH coefficients of fixed splats by linear least squares against
//! the training views.
//!
//! With positions, shapes and opacities fixed, a render over black is
//! `Σᵢ wᵢ(p)·(shᵢ(dᵢ)·xᵢ + 0.5)` per channel (before the clamp at 0, which a good colour rarely
//! hits): `A x + 0.5·α` with A linear in the coefficients x and α the render's coverage. The
//! solve compares straight colour, `(A x)/α + 0.5` against the view's colour, on the pixels that
//! both the view and the render cover (coverage ≥ [`COVERED`]), and nowhere else: where the
//! coverage disagrees (a hole between initial splats, a soft silhouette) no colour is right on
//! every background, and a solve that counted those pixels bends the colours to make up for them
//! on one background at the other's expense (measured: on black targets the demo's step-0 PSNR
//! rose 4 dB on black and fell on white). Coverage is geometry's job, left to training.
//!
//! It minimises `Σ_views Σ_covered ‖(A x)/α + 0.5 − y‖² + λ‖x − x₀‖²` from the per-camera fit x₀
//! by conjugate gradients on the normal equations, one solve per channel sharing every render:
//! A p is a render in `linear_colour` mode of the coefficients p, and Aᵀ r is the rasteriser's
//! backward pass of `Σ r·rgb` with respect to the SH coefficients (its adjoint, checked in
//! splat-core's tests); the division by the fixed α is a diagonal scaling on both sides. Each
//! iteration is one forward and one backward pass over every view. Starting from x₀ and
//! stopping after a few iterations also regularises: coefficients the views do not constrain
//! stay at the fit.

use glam::Vec3;
use serde::{Deserialize, Serialize};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats};
use splat_train::{View, from_unorm16};

/// Coverage from which a pixel counts as covered, in the view and in the render, for the solve.
pub const COVERED: f32 = 0.95;

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
    /// Root-mean-square colour error over the pixels the solve uses, before it.
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
    let cameras = view_cameras(views)?;
    // Straight colour of each view and its coverage (1 everywhere for a view without a mask),
    // as the views hold them: 16-bit fractions, read value by value (`from_unorm16`) rather than
    // expanded, which would double the views' memory while the solve runs.
    let targets: Vec<(&[u16], Option<&[u16]>)> = views
        .iter()
        .map(|v| (v.image.as_slice(), v.mask.as_deref()))
        .collect();
    let mut system = NormalEquations {
        work: splats.clone(),
        grads: SplatGrads::zeros_like(splats),
        raster: Rasterizer::new(),
        render: RenderOptions {
            background: Vec3::ZERO,
            active_sh_degree: splats.sh_degree,
            antialiased: false,
            linear_colour: true,
        },
        cameras,
        scales: Vec::new(),
        ridge: opts.ridge,
    };
    let (g, rms_before) = system.right_hand_side(&targets);
    let solution = conjugate_gradients(g, opts.iterations, |p| system.apply(p));
    for (x, d) in splats.sh.iter_mut().zip(&solution.delta) {
        for c in 0..3 {
            x[c] += d[c];
        }
    }
    Ok(SolveReport {
        iterations: solution.iterations,
        rms_before,
        residuals: solution.residuals,
    })
}

/// Each view's camera, the view checked against it.
fn view_cameras(views: &[View]) -> Result<Vec<RenderCamera>, SolveError> {
    views
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
        .collect()
}

/// The solve's normal equations (BᵀB + λI) δ = g over the views, with B = D⁻¹A restricted to
/// the pixels that view and render both cover, applied through renders and backward passes.
struct NormalEquations {
    /// The splats whose coefficients the renders take (the starting ones, then each direction).
    work: Splats,
    grads: SplatGrads,
    raster: Rasterizer,
    render: RenderOptions,
    cameras: Vec<RenderCamera>,
    /// Per view, 1/α on the pixels both cover and 0 elsewhere: the row scaling D⁻¹.
    scales: Vec<Vec<f32>>,
    ridge: f32,
}

impl NormalEquations {
    /// One pass over the views at x₀ gives both the row scaling (coverage does not depend on
    /// colour) and the right-hand side g = Bᵀ(y − 0.5 − B x₀), with δ = x − x₀; also the RMS
    /// colour error over the pixels used, before the solve.
    fn right_hand_side(&mut self, targets: &[(&[u16], Option<&[u16]>)]) -> (Vec<[f32; 3]>, f64) {
        let mut sq_error = 0.0f64;
        let mut values = 0usize;
        self.scales.clear();
        self.grads.reset(&self.work);
        for (vi, (y, mask)) in targets.iter().enumerate() {
            let cam = &self.cameras[vi];
            let out = self.raster.forward(&self.work, cam, &self.render);
            let scale: Vec<f32> = out
                .alpha
                .iter()
                .enumerate()
                .map(|(i, &a)| {
                    let reference = mask.map_or(1.0, |m| from_unorm16(m[i]));
                    if a >= COVERED && reference >= COVERED {
                        1.0 / a
                    } else {
                        0.0
                    }
                })
                .collect();
            let mut d_rgb = vec![0.0f32; out.rgb.len()];
            for (i, &s) in scale.iter().enumerate() {
                if s == 0.0 {
                    continue;
                }
                for c in 3 * i..3 * i + 3 {
                    let r = from_unorm16(y[c]) - 0.5 - s * out.rgb[c];
                    sq_error += f64::from(r).powi(2);
                    values += 1;
                    d_rgb[c] = s * r;
                }
            }
            self.add_adjoint(vi, &d_rgb);
            self.scales.push(scale);
        }
        let rms_before = (sq_error / values.max(1) as f64).sqrt();
        (std::mem::take(&mut self.grads.sh), rms_before)
    }

    /// Adds Aᵀ `d_rgb` for view `vi` (the backward pass of `Σ d_rgb·rgb` with respect to the SH
    /// coefficients of `work`) into the gradients.
    fn add_adjoint(&mut self, vi: usize, d_rgb: &[f32]) {
        let cam = &self.cameras[vi];
        self.raster.backward(
            &self.work,
            cam,
            &self.render,
            d_rgb,
            None,
            None,
            &mut self.grads,
        );
    }

    /// q = (BᵀB + λI) p, where BᵀB p = Aᵀ D⁻² A p on the covered pixels.
    fn apply(&mut self, p: &[[f32; 3]]) -> Vec<[f32; 3]> {
        self.work.sh.copy_from_slice(p);
        self.grads.reset(&self.work);
        for vi in 0..self.cameras.len() {
            let cam = &self.cameras[vi];
            let mut d_rgb = self
                .raster
                .forward(&self.work, cam, &self.render)
                .rgb
                .clone();
            for (px, &s) in d_rgb.chunks_exact_mut(3).zip(&self.scales[vi]) {
                for v in px {
                    *v *= s * s;
                }
            }
            self.add_adjoint(vi, &d_rgb);
        }
        let mut q = std::mem::take(&mut self.grads.sh);
        for (qk, pk) in q.iter_mut().zip(p) {
            for c in 0..3 {
                qk[c] += self.ridge * pk[c];
            }
        }
        q
    }
}

/// What [`conjugate_gradients`] found.
struct CgSolution {
    /// The solution δ, per channel.
    delta: Vec<[f32; 3]>,
    /// Iterations run.
    iterations: u32,
    /// The residual's norm after each iteration relative to the first, the largest channel's.
    residuals: Vec<f64>,
}

/// Conjugate gradients on M δ = g from δ = 0, one independent solve per channel sharing each
/// product `apply(p)` = M p (M symmetric positive semi-definite); at most `iterations` steps,
/// fewer once every channel's residual is exactly zero.
fn conjugate_gradients(
    g: Vec<[f32; 3]>,
    iterations: u32,
    mut apply: impl FnMut(&[[f32; 3]]) -> Vec<[f32; 3]>,
) -> CgSolution {
    let n = g.len();
    let mut delta = vec![[0.0f32; 3]; n];
    let mut r = g;
    let mut p = r.clone();
    let mut rs = dot(&r, &r);
    let first = rs.map(f64::sqrt);
    let mut residuals = Vec::new();
    let mut done = 0;
    for _ in 0..iterations {
        if rs.iter().all(|&v| v == 0.0) {
            break;
        }
        let q = apply(&p);
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
    CgSolution {
        delta,
        iterations: done,
        residuals,
    }
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

    /// Knuth's MMIX linear congruential generator from `seed`: the tests' fixed pseudo-random
    /// numbers (each takes the high bits it needs).
    fn lcg(mut seed: u64) -> impl FnMut() -> u64 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            seed
        }
    }

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
                let cam = RenderCamera::try_from(&camera).unwrap();
                let out = raster.forward(splats, &cam, &RenderOptions::default());
                View::from_premultiplied(format!("v{i}"), camera, &out.rgb, &out.alpha).unwrap()
            })
            .collect()
    }

    /// Mean squared error of an ordinary render of `splats` over black against the views, on
    /// the pixels both cover (where the solve compares colours; the geometry is the views', so
    /// the coverage agrees everywhere else too and only colour differs).
    fn image_error(splats: &Splats, views: &[View]) -> f64 {
        let mut raster = Rasterizer::new();
        let (mut sum, mut n) = (0.0f64, 0usize);
        for v in views {
            let out = raster.forward(
                splats,
                &v.render_camera().unwrap(),
                &RenderOptions::default(),
            );
            let target = v.on_background([0.0; 3]);
            let mask = v.coverage().unwrap();
            for (i, (&a, &m)) in out.alpha.iter().zip(&mask).enumerate() {
                if a >= COVERED && m >= COVERED {
                    let (got, want) = (&out.rgb[3 * i..3 * i + 3], &target[3 * i..3 * i + 3]);
                    for (g, w) in got.iter().zip(want) {
                        sum += f64::from(g - w).powi(2);
                        n += 1;
                    }
                }
            }
        }
        assert!(n > 1000, "too few covered pixels: {n}");
        sum / n as f64
    }

    /// The per-channel solver against Gaussian elimination in f64 on three different symmetric
    /// positive-definite 6 × 6 systems (one a channel): within six steps it reaches their
    /// solutions, its residual history falls to rounding, and it stops early once every
    /// channel's residual is exactly zero (a zero right-hand side: no step at all).
    #[test]
    fn conjugate_gradients_solve_each_channel_s_system() {
        const N: usize = 6;
        let mut raw = lcg(11);
        let mut next = || (raw() >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
        // M_c = L Lᵀ + I with a random L, per channel; g random.
        let m: Vec<[[f64; N]; N]> = (0..3)
            .map(|_| {
                let l: [[f64; N]; N] = std::array::from_fn(|_| std::array::from_fn(|_| next()));
                std::array::from_fn(|i| {
                    std::array::from_fn(|j| {
                        (0..N).map(|k| l[i][k] * l[j][k]).sum::<f64>()
                            + if i == j { 1.0 } else { 0.0 }
                    })
                })
            })
            .collect();
        let g: Vec<[f32; 3]> = (0..N)
            .map(|_| [next() as f32, next() as f32, next() as f32])
            .collect();
        let apply = |p: &[[f32; 3]]| -> Vec<[f32; 3]> {
            (0..N)
                .map(|i| {
                    [0, 1, 2].map(|c| {
                        (0..N).map(|j| m[c][i][j] * f64::from(p[j][c])).sum::<f64>() as f32
                    })
                })
                .collect()
        };
        let solution = conjugate_gradients(g.clone(), 6, apply);
        assert_eq!(solution.iterations, 6);
        assert!(
            *solution.residuals.last().unwrap() < 1e-4,
            "{:?}",
            solution.residuals
        );
        for c in 0..3 {
            // Gaussian elimination with partial pivoting in f64.
            let mut a = m[c];
            let mut b: [f64; N] = std::array::from_fn(|i| f64::from(g[i][c]));
            for col in 0..N {
                let piv = (col..N)
                    .max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))
                    .unwrap();
                a.swap(col, piv);
                b.swap(col, piv);
                let (pivot_row, pivot_b) = (a[col], b[col]);
                for (row, b_row) in a.iter_mut().zip(&mut b).skip(col + 1) {
                    let f = row[col] / pivot_row[col];
                    for (v, p) in row.iter_mut().zip(&pivot_row).skip(col) {
                        *v -= f * p;
                    }
                    *b_row -= f * pivot_b;
                }
            }
            let mut x = [0.0f64; N];
            for row in (0..N).rev() {
                let tail: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
                x[row] = (b[row] - tail) / a[row][row];
            }
            for (i, (d, want)) in solution.delta.iter().zip(x).enumerate() {
                let got = f64::from(d[c]);
                assert!(
                    (got - want).abs() < 1e-4 * (1.0 + want.abs()),
                    "channel {c}, unknown {i}: {got} against {want}"
                );
            }
        }
        let zero = conjugate_gradients(vec![[0.0; 3]; N], 6, apply);
        assert_eq!(zero.iterations, 0);
        assert!(zero.delta.iter().all(|d| *d == [0.0; 3]));
    }

    /// Splats with known degree-2 colours make the views; from a wrong start (grey, no view
    /// dependence) the solve brings the renders back to the views where both cover: the error falls by
    /// a thousandfold and the normal equations' residual ends below 1 % of its start.
    #[test]
    fn recovers_the_colours_that_made_the_views() {
        let mut truth = Splats::new(2);
        let mut raw = lcg(3);
        let mut next = || (raw() >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
        for i in 0..60 {
            let t = i as f32 * 0.7;
            let mean = Vec3::new(t.cos(), (i as f32 / 30.0) - 1.0, t.sin()) * 0.8;
            let mut sh = vec![[0.0f32; 3]; 9];
            // DC between 0.3 and 0.7 in colour, small view dependence: no clamping.
            sh[0] = [next() * 1.4, next() * 1.4, next() * 1.4];
            for c in &mut sh[1..] {
                *c = [next() * 0.2, next() * 0.2, next() * 0.2];
            }
            truth.push(mean, Vec3::splat(-1.5), [1.0, 0.0, 0.0, 0.0], 5.0, &sh);
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
