//! The closed-form SH fit of plenoptic colours and the choice of SH degree.

use glam::Vec3;
use rayon::prelude::*;

use crate::config::{InitConfig, ShDegree};
use crate::points::SurfacePoints;

/// The ridge-regularised least-squares SH fit of one degree over fixed view directions.
pub struct ShFit {
    degree: u32,
    /// SH directions (camera → point, the rasteriser's convention).
    pub(crate) dirs: Vec<Vec3>,
    /// (BᵀB/M + λD)⁻¹ Bᵀ/M, coefficient-major: `solve[k * M + j]`.
    solve: Vec<f32>,
    /// B, direction-major: `basis[j * n + k]`.
    basis: Vec<f32>,
}

impl ShFit {
    /// Prepares the fit of `degree` over `directions` Fibonacci-sphere directions with ridge `ridge`
    /// on every coefficient but the constant one.
    #[must_use]
    pub fn new(degree: u32, directions: usize, ridge: f64) -> Self {
        let n = splat_core::num_sh_coeffs(degree);
        let dirs: Vec<Vec3> = camera_model::rig::fibonacci_sphere(directions)
            .into_iter()
            .map(|d| d.as_vec3())
            .collect();
        let m = dirs.len();
        let mut basis = vec![0.0f32; m * n];
        for (j, d) in dirs.iter().enumerate() {
            splat_core::sh::basis(degree, *d, &mut basis[j * n..(j + 1) * n]);
        }
        let b = nalgebra::DMatrix::<f64>::from_fn(m, n, |j, k| f64::from(basis[j * n + k]));
        let mut normal = b.transpose() * &b / m as f64;
        for k in 1..n {
            normal[(k, k)] += ridge;
        }
        // The normal matrix is symmetric positive definite when the directions determine every
        // coefficient (enough Fibonacci directions, or a ridge); otherwise the pseudo-inverse
        // gives the minimum-norm least-squares fit.
        let inv = match normal.clone().cholesky() {
            Some(c) => c.inverse(),
            None => normal
                .pseudo_inverse(1e-12)
                .unwrap_or_else(|_| nalgebra::DMatrix::zeros(n, n)),
        };
        let solve_m = inv * b.transpose() / m as f64;
        let solve = (0..n)
            .flat_map(|k| (0..m).map(move |j| (k, j)))
            .map(|(k, j)| solve_m[(k, j)] as f32)
            .collect();
        Self {
            degree,
            dirs,
            solve,
            basis,
        }
    }

    /// Fits point `i` of `points` with the PccAppRenderer exponent `exponent`: returns the
    /// coefficients and the sum of squared residuals over directions and channels.
    #[must_use]
    pub fn fit_point(
        &self,
        points: &SurfacePoints,
        i: usize,
        exponent: i32,
    ) -> (Vec<[f32; 3]>, f64) {
        let n = splat_core::num_sh_coeffs(self.degree);
        let m = self.dirs.len();
        let p = points.positions[i];
        let main = points.colors[i];
        let cams = points.camera_colors_of(i);
        // Targets: colour seen along SH direction d, i.e. from a viewer at p − d, minus SH's +0.5.
        let targets: Vec<[f32; 3]> = self
            .dirs
            .iter()
            .map(|d| {
                let c = plenoptic_io::view_color::interpolate(
                    p,
                    p - *d,
                    &points.camera_positions,
                    cams,
                    main,
                    exponent,
                );
                [c[0] - 0.5, c[1] - 0.5, c[2] - 0.5]
            })
            .collect();
        let mut coeffs = vec![[0.0f32; 3]; n];
        for (k, coeff) in coeffs.iter_mut().enumerate() {
            let row = &self.solve[k * m..(k + 1) * m];
            for (w, t) in row.iter().zip(&targets) {
                for c in 0..3 {
                    coeff[c] += w * t[c];
                }
            }
        }
        let mut sse = 0.0f64;
        for (j, t) in targets.iter().enumerate() {
            let b = &self.basis[j * n..(j + 1) * n];
            for c in 0..3 {
                let v: f32 = b.iter().zip(&coeffs).map(|(bk, a)| bk * a[c]).sum();
                sse += f64::from(v - t[c]).powi(2);
            }
        }
        (coeffs, sse)
    }

    /// Fits every point; returns splat-major coefficients and the RMS residual (colour units).
    #[must_use]
    pub fn fit_all(&self, points: &SurfacePoints, exponent: i32) -> (Vec<[f32; 3]>, f64) {
        let fits: Vec<(Vec<[f32; 3]>, f64)> = (0..points.len())
            .into_par_iter()
            .map(|i| self.fit_point(points, i, exponent))
            .collect();
        let count = (points.len() * self.dirs.len() * 3).max(1) as f64;
        let sse: f64 = fits.iter().map(|f| f.1).sum();
        let coeffs = fits.into_iter().flat_map(|f| f.0).collect();
        (coeffs, (sse / count).sqrt())
    }
}

/// RMS fit errors at degrees 0..=3 on up to 2,000 evenly strided points.
#[must_use]
pub fn sh_fit_errors(points: &SurfacePoints, cfg: &InitConfig, exponent: i32) -> [f64; 4] {
    let stride = points.len().div_ceil(2_000).max(1);
    let sample = points.subset(&(0..points.len()).step_by(stride).collect::<Vec<_>>());
    let mut errors = [0.0; 4];
    for (d, e) in errors.iter_mut().enumerate() {
        *e = ShFit::new(d as u32, cfg.fit_directions, cfg.ridge)
            .fit_all(&sample, exponent)
            .1;
    }
    errors
}

/// The lowest degree whose error is within `tolerance` of degree 3's.
#[must_use]
pub fn auto_degree(errors: &[f64; 4], tolerance: f64) -> u32 {
    (0..4u32)
        .find(|&d| errors[d as usize] <= errors[3] + tolerance)
        .unwrap_or(3)
}

/// The SH degree and fit errors for `cfg.sh_degree` on `points` (degree 0 for view-independent input).
#[must_use]
pub fn decide_sh_degree(
    points: &SurfacePoints,
    cfg: &InitConfig,
    exponent: i32,
) -> (u32, Option<[f64; 4]>) {
    if !points.is_plenoptic() {
        return (
            match cfg.sh_degree {
                ShDegree::Fixed(d) => d,
                ShDegree::Auto => 0,
            },
            None,
        );
    }
    let errors = sh_fit_errors(points, cfg, exponent);
    let degree = match cfg.sh_degree {
        ShDegree::Fixed(d) => d,
        ShDegree::Auto => auto_degree(&errors, cfg.sh_tolerance),
    };
    (degree, Some(errors))
}
