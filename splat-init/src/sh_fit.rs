//! The closed-form SH fit of plenoptic colours and the choice of SH degree.

use glam::Vec3;
#[cfg(target_arch = "x86_64")]
use plenoptic_io::view_color::interpolate8_avx2;
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
        let mut targets = vec![[0.0f32; 3]; m];
        let seen = SeenColour {
            point: p,
            cameras: &points.camera_positions,
            colors: cams,
            main,
            exponent,
        };
        seen.along(&self.dirs, &mut targets, splat_core::has_avx2());
        for t in &mut targets {
            *t = t.map(|c| c - 0.5);
        }
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

/// One point's plenoptic colour seen along many directions.
struct SeenColour<'a> {
    point: Vec3,
    cameras: &'a [Vec3],
    colors: &'a [[f32; 3]],
    main: [f32; 3],
    exponent: i32,
}

/// Directions [`SeenColour::along`] colours at once (one AVX2 vector of f32).
const LANES: usize = plenoptic_io::view_color::AVX2_LANES;

impl SeenColour<'_> {
    /// The colour seen along each of `dirs` (from a viewer at point − d) into `out`,
    /// [`LANES`] directions at a time: the AVX2 kernel where the CPU has it, else the
    /// portable one (the same operations, so the same bits as one call of
    /// [`plenoptic_io::view_color::interpolate`] a direction).
    fn along(&self, dirs: &[Vec3], out: &mut [[f32; 3]], avx2: bool) {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is only true when `splat_core::has_avx2()` is, so the CPU has AVX2.
            #[allow(unsafe_code)]
            return unsafe { self.along_avx2(dirs, out) };
        }
        let _ = avx2;
        self.along_portable(dirs, out);
    }

    /// [`SeenColour::along`] with the AVX2 kernel ([`interpolate8_avx2`]): the point in every
    /// lane, a direction a lane.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn along_avx2(&self, dirs: &[Vec3], out: &mut [[f32; 3]]) {
        let cameras = &self.cameras[..self.colors.len().min(self.cameras.len())];
        // The point's colour for each camera in every lane, channel by channel.
        let per_camera: Vec<[[f32; LANES]; 3]> = self.colors[..cameras.len()]
            .iter()
            .map(|c| c.map(|v| [v; LANES]))
            .collect();
        for (group, out) in dirs.chunks(LANES).zip(out.chunks_mut(LANES)) {
            // A short last group repeats its first direction in the spare lanes.
            let dir = |l: usize| *group.get(l).unwrap_or(&group[0]);
            let seen = interpolate8_avx2(
                &[self.point; LANES],
                &std::array::from_fn(|l| self.point - dir(l)),
                cameras,
                &per_camera,
                &[self.main; LANES],
                self.exponent,
            );
            out.copy_from_slice(&seen[..out.len()]);
        }
    }

    #[inline(always)]
    fn along_portable(&self, dirs: &[Vec3], out: &mut [[f32; 3]]) {
        for (group, out) in dirs.chunks(LANES).zip(out.chunks_mut(LANES)) {
            // A short last group repeats its first direction in the spare lanes.
            let dir = |l: usize| *group.get(l).unwrap_or(&group[0]);
            let seen = plenoptic_io::view_color::interpolate_lanes(
                [self.point; LANES],
                std::array::from_fn(|l| self.point - dir(l)),
                self.cameras,
                [self.colors; LANES],
                [self.main; LANES],
                self.exponent,
            );
            out.copy_from_slice(&seen[..out.len()]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_along_directions_are_the_bits_of_one_call_each() {
        let cameras: Vec<Vec3> = (0..13)
            .map(|i| {
                let a = i as f32 * 0.48;
                Vec3::new(
                    a.cos() * 3000.0,
                    (i % 4) as f32 * 300.0 - 400.0,
                    a.sin() * 3000.0,
                )
            })
            .collect();
        let colors: Vec<[f32; 3]> = (0..13)
            .map(|i| [i as f32 / 13.0, 0.25, 1.0 - i as f32 / 13.0])
            .collect();
        let point = Vec3::new(12.0, -40.0, 7.5);
        // 21 directions: two full groups of lanes and a short one, one of them zero.
        let mut dirs: Vec<Vec3> = (0..21)
            .map(|j| {
                let (a, b) = (j as f32 * 0.7, j as f32 * 0.31);
                Vec3::new(a.cos() * b.sin(), b.cos(), a.sin() * b.sin())
            })
            .collect();
        dirs[9] = Vec3::ZERO;
        let seen = SeenColour {
            point,
            cameras: &cameras,
            colors: &colors,
            main: [0.9, 0.8, 0.7],
            exponent: 10,
        };
        for avx2 in [false, splat_core::has_avx2()] {
            let mut out = vec![[0.0f32; 3]; dirs.len()];
            seen.along(&dirs, &mut out, avx2);
            for (d, got) in dirs.iter().zip(&out) {
                let want = plenoptic_io::view_color::interpolate(
                    point,
                    point - *d,
                    &cameras,
                    &colors,
                    [0.9, 0.8, 0.7],
                    10,
                );
                assert_eq!(
                    got.map(f32::to_bits),
                    want.map(f32::to_bits),
                    "{d}, AVX2 {avx2}"
                );
            }
        }
    }
}
