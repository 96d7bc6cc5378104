//! Splat initialisation: from the input's surface (with a closed-form SH fit) or from sparse points.
//!
//! Surface init puts one flat splat at each chosen surface point (all input points, mesh samples,
//! or a subset of K by voxel-grid or farthest-point sampling), turned into the surface plane by its
//! normal (from the file or by k-nearest-neighbour PCA), with its in-plane scale from the local point
//! spacing and a thin normal axis. Its SH coefficients are the ridge-regularised least-squares fit
//! of the plenoptic colour ([`plenoptic_io::view_color::interpolate`]) over many view directions,
//! in `splat_core::sh`'s basis: because the directions are the same for every point, the fit is one
//! precomputed matrix applied to each point's samples.
//!
//! Sparse init follows the usual 3DGS pipeline: COLMAP points3D or random points in the bounds,
//! isotropic scales from the 3 nearest neighbours, low opacity, then densification while training.

use std::num::NonZero;
use std::path::{Path, PathBuf};

use glam::Vec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;
use serde::Serialize;
use splat_core::Splats;

use crate::config::{InitConfig, InitMode, Sampling, ShDegree};

pub mod surface;
pub use surface::{SurfacePoints, sample_mesh};

/// Errors of initialisation.
#[derive(Debug, thiserror::Error)]
pub enum InitError {
    /// The input has no points to put splats on.
    #[error("the input has no points to initialise splats from")]
    Empty,
    /// The COLMAP model given for sparse init could not be read.
    #[error("sparse init from COLMAP points3D: {source}")]
    Colmap {
        /// The model folder.
        path: PathBuf,
        /// The cause (boxed: COLMAP errors are large).
        source: Box<colmap_io::Error>,
    },
    /// The COLMAP model has no 3D points.
    #[error("the COLMAP model in {0} has no 3D points")]
    NoColmapPoints(PathBuf),
    /// splat-core refused the splats (a bug if it happens: the arrays are built together).
    #[error("building splats: {0}")]
    Splats(#[from] splat_core::Error),
}

/// What initialisation did, for the report.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct InitSummary {
    /// Surface or sparse.
    pub mode: InitMode,
    /// Number of splats made.
    pub splats: usize,
    /// SH degree of the model.
    pub sh_degree: u32,
    /// RMS error (colour units) of the SH fit at degrees 0..=3 on a sample of points, when fitted.
    pub sh_fit_rms: Option<[f64; 4]>,
    /// Median distance between neighbouring input points (file units).
    pub point_spacing: f32,
    /// Where the normals came from: "file", "pca" or "none".
    pub normals: String,
    /// Where sparse points came from: "surface", "colmap" or "random".
    pub source: String,
}

/// A k-d tree over points for nearest-neighbour queries.
pub struct PointIndex {
    tree: ImmutableKdTree<f32, 3>,
    len: usize,
}

impl PointIndex {
    /// Builds the index; `None` for an empty or unindexable set.
    #[must_use]
    pub fn new(points: &[Vec3]) -> Option<Self> {
        if points.is_empty() {
            return None;
        }
        let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
        let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&coords).ok()?;
        Some(Self {
            tree,
            len: points.len(),
        })
    }

    /// Distance from `p` to the nearest indexed point.
    #[must_use]
    pub fn nearest_distance(&self, p: Vec3) -> f32 {
        self.tree
            .query(&p.to_array())
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute()
            .distance
            .sqrt()
    }

    /// Indices of the `k` nearest indexed points to `p` (nearest first; includes `p` itself if indexed).
    #[must_use]
    pub fn nearest_n(&self, p: Vec3, k: usize) -> Vec<usize> {
        let want = NonZero::new(k.min(self.len).max(1)).unwrap_or(NonZero::<usize>::MIN);
        self.tree
            .query(&p.to_array())
            .nearest_n::<SquaredEuclidean<f32>>(want)
            .execute()
            .iter()
            .map(|r| r.item as usize)
            .collect()
    }
}

/// Median distance from a point to its nearest other point, on up to 20,000 evenly strided points.
#[must_use]
pub fn point_spacing(points: &[Vec3]) -> f32 {
    let Some(index) = PointIndex::new(points) else {
        return 0.0;
    };
    if points.len() < 2 {
        return 0.0;
    }
    let stride = points.len().div_ceil(20_000).max(1);
    let mut d: Vec<f32> = points
        .par_iter()
        .step_by(stride)
        .map(|&p| {
            let near = index.nearest_n(p, 2);
            near.iter()
                .map(|&j| points[j].distance(p))
                .find(|&d| d > 0.0)
                .unwrap_or(0.0)
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}

/// About `k` representative points: one per occupied cell of a voxel grid whose cell size is found
/// by bisection so that about `k` cells are occupied; each cell keeps the point nearest its mean.
#[must_use]
pub fn voxel_subsample(points: &[Vec3], k: usize) -> Vec<usize> {
    if k >= points.len() {
        return (0..points.len()).collect();
    }
    let (lo, hi) = bounds(points);
    let diag = (hi - lo).length().max(f32::MIN_POSITIVE);
    let cells = |h: f32| -> std::collections::HashMap<[i32; 3], Vec<usize>> {
        let mut m: std::collections::HashMap<[i32; 3], Vec<usize>> = Default::default();
        for (i, p) in points.iter().enumerate() {
            let c = ((*p - lo) / h).floor();
            m.entry([c.x as i32, c.y as i32, c.z as i32])
                .or_default()
                .push(i);
        }
        m
    };
    let count = |h: f32| -> usize {
        let mut s = std::collections::HashSet::new();
        for p in points {
            let c = ((*p - lo) / h).floor();
            s.insert([c.x as i32, c.y as i32, c.z as i32]);
        }
        s.len()
    };
    // Bisection in log(h): larger cells, fewer occupied. i32 cell keys need h ≥ diag / 2^30.
    let (mut small, mut large) = (diag / 1e6, diag);
    for _ in 0..30 {
        let mid = (small * large).sqrt();
        if count(mid) > k {
            small = mid;
        } else {
            large = mid;
        }
        if large / small < 1.01 {
            break;
        }
    }
    let mut picked: Vec<usize> = cells(large)
        .into_values()
        .map(|members| {
            let mean = members.iter().map(|&i| points[i]).sum::<Vec3>() / members.len() as f32;
            members
                .iter()
                .copied()
                .min_by(|&a, &b| {
                    points[a]
                        .distance_squared(mean)
                        .total_cmp(&points[b].distance_squared(mean))
                })
                .unwrap_or(members[0])
        })
        .collect();
    picked.sort_unstable();
    picked
}

/// Exactly `k` points by farthest-point sampling from point 0 (O(N·K), parallel over points).
#[must_use]
pub fn farthest_point_sample(points: &[Vec3], k: usize) -> Vec<usize> {
    if k >= points.len() {
        return (0..points.len()).collect();
    }
    let mut chosen = Vec::with_capacity(k);
    let mut dist = vec![f32::INFINITY; points.len()];
    let mut next = 0usize;
    for _ in 0..k {
        chosen.push(next);
        let c = points[next];
        dist.par_iter_mut()
            .zip(points.par_iter())
            .for_each(|(d, p)| *d = d.min(p.distance_squared(c)));
        next = dist
            .par_iter()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map_or(0, |(i, _)| i);
    }
    chosen.sort_unstable();
    chosen
}

/// Unit normals by PCA of each point's `k` nearest neighbours: the eigenvector of the smallest
/// eigenvalue of their covariance (sign arbitrary: a flat splat looks the same from both sides).
#[must_use]
pub fn pca_normals(points: &[Vec3], k: usize) -> Vec<Vec3> {
    let Some(index) = PointIndex::new(points) else {
        return Vec::new();
    };
    points
        .par_iter()
        .map(|&p| {
            let near = index.nearest_n(p, k);
            let mean = near.iter().map(|&j| points[j]).sum::<Vec3>() / near.len() as f32;
            let mut cov = nalgebra::Matrix3::<f32>::zeros();
            for &j in &near {
                let d = points[j] - mean;
                let v = nalgebra::Vector3::new(d.x, d.y, d.z);
                cov += v * v.transpose();
            }
            let eig = nalgebra::SymmetricEigen::new(cov);
            let smallest = eig.eigenvalues.imin();
            let n = eig.eigenvectors.column(smallest);
            let n = Vec3::new(n[0], n[1], n[2]);
            if n.is_finite() && n.length_squared() > 0.0 {
                n.normalize()
            } else {
                Vec3::Z
            }
        })
        .collect()
}

/// The ridge-regularised least-squares SH fit of one degree over fixed view directions.
pub struct ShFit {
    degree: u32,
    /// SH directions (camera → point, the rasteriser's convention).
    dirs: Vec<Vec3>,
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

/// Picks the input points that carry splats: all, or about `cfg.splats` by the chosen sampling.
#[must_use]
pub fn choose_points(points: &SurfacePoints, cfg: &InitConfig) -> SurfacePoints {
    match cfg.splats {
        Some(k) if k < points.len() => {
            let idx = match cfg.sampling {
                Sampling::Voxel => voxel_subsample(&points.positions, k),
                Sampling::Farthest => farthest_point_sample(&points.positions, k),
            };
            points.subset(&idx)
        }
        _ => points.clone(),
    }
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

/// Surface init: flat splats on `points` (already chosen), SH fitted to their colours.
pub fn surface_init(
    points: &SurfacePoints,
    cfg: &InitConfig,
    exponent: i32,
) -> Result<(Splats, InitSummary), InitError> {
    if points.is_empty() {
        return Err(InitError::Empty);
    }
    let spacing = point_spacing(&points.positions);
    let (normals, normal_source) = match &points.normals {
        Some(n) => (n.clone(), "file"),
        None => (pca_normals(&points.positions, cfg.normal_neighbours), "pca"),
    };
    let (degree, errors) = decide_sh_degree(points, cfg, exponent);
    let sigma = splat_train::init::scales_from_knn(&points.positions);
    let thin = cfg.thin_ratio.ln();
    let scales: Vec<Vec3> = sigma
        .iter()
        .map(|s| Vec3::new(s.x, s.y, s.z + thin).exp())
        .collect();
    let mut splats = Splats::from_points(
        &points.positions,
        &points.colors,
        &scales,
        Some(&normals),
        cfg.surface_opacity,
        degree,
    )?;
    if points.is_plenoptic() {
        splats.sh = ShFit::new(degree, cfg.fit_directions, cfg.ridge)
            .fit_all(points, exponent)
            .0;
    }
    let summary = InitSummary {
        mode: InitMode::Surface,
        splats: splats.len(),
        sh_degree: degree,
        sh_fit_rms: errors,
        point_spacing: spacing,
        normals: normal_source.to_string(),
        source: "surface".to_string(),
    };
    Ok((splats, summary))
}

/// Sparse init: COLMAP points3D from `cfg.points3d`, else `cfg.random_points` uniform points in
/// the bounding box of `input`; isotropic splats (Inria's 3-NN scale, identity rotation).
pub fn sparse_init(
    input: &SurfacePoints,
    cfg: &InitConfig,
    exponent: i32,
    seed: u64,
) -> Result<(Splats, InitSummary), InitError> {
    if input.is_empty() {
        return Err(InitError::Empty);
    }
    let (positions, colors, source) = match &cfg.points3d {
        Some(dir) => {
            let (p, c) = read_points3d(dir)?;
            (p, c, "colmap")
        }
        None => {
            let (lo, hi) = bounds(&input.positions);
            let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
            let p: Vec<Vec3> = (0..cfg.random_points)
                .map(|_| lo + (hi - lo) * Vec3::new(rng.random(), rng.random(), rng.random()))
                .collect();
            // Uninformed colour: mid grey (SH DC 0), as Inria's random init for synthetic scenes.
            let c = vec![[0.5f32; 3]; p.len()];
            (p, c, "random")
        }
    };
    let (degree, errors) = decide_sh_degree(input, cfg, exponent);
    let scales: Vec<Vec3> = splat_train::init::scales_from_knn(&positions)
        .into_iter()
        .map(Vec3::exp)
        .collect();
    let splats = Splats::from_points(
        &positions,
        &colors,
        &scales,
        None,
        cfg.sparse_opacity,
        degree,
    )?;
    let summary = InitSummary {
        mode: InitMode::Sparse,
        splats: splats.len(),
        sh_degree: degree,
        sh_fit_rms: errors,
        point_spacing: point_spacing(&input.positions),
        normals: "none".to_string(),
        source: source.to_string(),
    };
    Ok((splats, summary))
}

/// Initialises splats from the input's surface points as `cfg.mode` says.
pub fn initialise(
    input: &SurfacePoints,
    cfg: &InitConfig,
    exponent: i32,
    seed: u64,
) -> Result<(Splats, InitSummary), InitError> {
    match cfg.mode {
        InitMode::Surface => surface_init(&choose_points(input, cfg), cfg, exponent),
        InitMode::Sparse => sparse_init(input, cfg, exponent, seed),
    }
}

fn read_points3d(dir: &Path) -> Result<(Vec<Vec3>, Vec<[f32; 3]>), InitError> {
    let rec = colmap_io::read_model(dir).map_err(|source| InitError::Colmap {
        path: dir.to_path_buf(),
        source: Box::new(source),
    })?;
    if rec.points3d.is_empty() {
        return Err(InitError::NoColmapPoints(dir.to_path_buf()));
    }
    let positions = rec.points3d.values().map(|p| p.xyz.as_vec3()).collect();
    let colors = rec
        .points3d
        .values()
        .map(|p| p.rgb.map(|c| f32::from(c) / 255.0))
        .collect();
    Ok((positions, colors))
}

/// Axis-aligned bounds (min, max) of a non-empty point set.
#[must_use]
pub fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::InitConfig;

    /// One point at the origin seen by `n` capture cameras on two rings (as the 8iVSLF rigs),
    /// each with its own colour.
    fn plenoptic_point(n: usize) -> SurfacePoints {
        let rings = camera_model::rig::rings(&[
            camera_model::rig::Ring {
                elevation_deg: 10.0,
                count: n.div_ceil(2),
                azimuth_offset_deg: 0.0,
            },
            camera_model::rig::Ring {
                elevation_deg: 45.0,
                count: n / 2,
                azimuth_offset_deg: 15.0,
            },
        ]);
        let cams: Vec<Vec3> = rings.iter().map(|d| (d * 2000.0).as_vec3()).collect();
        let colors: Vec<[f32; 3]> = (0..cams.len())
            .map(|k| {
                let t = k as f32 / cams.len() as f32;
                [0.2 + 0.6 * t, 0.8 - 0.5 * t, 0.5 + 0.3 * (6.0 * t).sin()]
            })
            .collect();
        SurfacePoints {
            positions: vec![Vec3::ZERO],
            normals: Some(vec![Vec3::Y]),
            colors: vec![[0.5, 0.5, 0.5]],
            camera_positions: cams,
            camera_colors: colors,
        }
    }

    /// RMS difference between the fitted SH colour (splat-core's evaluation, +0.5, clamped at 0)
    /// and the interpolated colour over `dirs` SH directions that the fit did not use.
    fn rms_against_interpolation(p: &SurfacePoints, degree: u32, coeffs: &[[f32; 3]]) -> f64 {
        let dirs = camera_model::rig::fibonacci_sphere(997);
        let mut sse = 0.0f64;
        for d in &dirs {
            let d = d.as_vec3();
            let want = plenoptic_io::view_color::interpolate(
                Vec3::ZERO,
                -d,
                &p.camera_positions,
                p.camera_colors_of(0),
                p.colors[0],
                10,
            );
            let got = splat_core::sh::color(degree, d, coeffs);
            for c in 0..3 {
                sse += f64::from(got[c] - want[c]).powi(2);
            }
        }
        (sse / (3.0 * dirs.len() as f64)).sqrt()
    }

    #[test]
    fn sh_fit_residual_is_orthogonal_to_the_basis() {
        // Least squares without ridge: Bᵀ(B a − y) = 0, checked directly from the residuals.
        let p = plenoptic_point(13);
        let fit = ShFit::new(3, 256, 0.0);
        let (coeffs, _) = fit.fit_point(&p, 0, 10);
        let mut grad = [[0.0f64; 3]; 16];
        let mut b = [0.0f32; 16];
        for d in &fit.dirs {
            splat_core::sh::basis(3, *d, &mut b);
            let y = plenoptic_io::view_color::interpolate(
                Vec3::ZERO,
                -*d,
                &p.camera_positions,
                p.camera_colors_of(0),
                p.colors[0],
                10,
            );
            for c in 0..3 {
                let r: f32 =
                    b.iter().zip(&coeffs).map(|(bk, a)| bk * a[c]).sum::<f32>() + 0.5 - y[c];
                for k in 0..16 {
                    grad[k][c] += f64::from(b[k] * r);
                }
            }
        }
        for g in grad.iter().flatten() {
            assert!(g.abs() / 256.0 < 1e-5, "normal equations violated: {g}");
        }
    }

    #[test]
    fn sh_fit_reproduces_interpolated_colours() {
        // 13 cameras as in 8iVSLF. Measured RMS error against the interpolated colour on 997
        // directions the fit never saw, with neighbouring cameras of very different colours:
        // degree 0/1/2/3 ≈ 0.139/0.090/0.045/0.037 (colour units in [0, 1]).
        let p = plenoptic_point(13);
        let cfg = InitConfig::default();
        let mut errs = [0.0; 4];
        for (degree, e) in errs.iter_mut().enumerate() {
            let (coeffs, fit_rms) =
                ShFit::new(degree as u32, cfg.fit_directions, cfg.ridge).fit_all(&p, 10);
            *e = rms_against_interpolation(&p, degree as u32, &coeffs);
            // The fit's own residual predicts the error on unseen directions.
            assert!(
                (*e - fit_rms).abs() < 0.01,
                "degree {degree}: {e} vs {fit_rms}"
            );
        }
        eprintln!("SH fit RMS error by degree: {errs:?}");
        assert!(errs[3] < 0.05, "{errs:?}");
        assert!(
            errs[0] > errs[1] && errs[1] > errs[2] && errs[2] > errs[3],
            "{errs:?}"
        );
    }

    #[test]
    fn view_independent_colour_is_fitted_exactly_at_degree_zero() {
        let mut p = plenoptic_point(13);
        for c in &mut p.camera_colors {
            *c = [0.9, 0.3, 0.1];
        }
        p.colors[0] = [0.9, 0.3, 0.1];
        let cfg = InitConfig::default();
        let errors = sh_fit_errors(&p, &cfg, 10);
        assert!(errors.iter().all(|e| *e < 1e-6), "{errors:?}");
        assert_eq!(auto_degree(&errors, cfg.sh_tolerance), 0);
        let (coeffs, _) = ShFit::new(0, 64, 1e-3).fit_all(&p, 10);
        let rgb = splat_core::sh_dc_to_rgb(coeffs[0]);
        for (a, b) in rgb.iter().zip([0.9, 0.3, 0.1]) {
            assert!((a - b).abs() < 1e-5);
        }
    }

    #[test]
    fn auto_degree_picks_the_lowest_within_tolerance() {
        assert_eq!(auto_degree(&[0.1, 0.05, 0.031, 0.03], 0.01), 2);
        assert_eq!(auto_degree(&[0.1, 0.035, 0.031, 0.03], 0.01), 1);
        assert_eq!(auto_degree(&[0.1, 0.05, 0.035, 0.03], 0.001), 3);
    }

    fn grid(n: usize) -> Vec<Vec3> {
        (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, (i / n) as f32, 0.0))
            .collect()
    }

    #[test]
    fn pca_normals_of_a_plane_are_its_normal() {
        for n in pca_normals(&grid(20), 12) {
            assert!((n.z.abs() - 1.0).abs() < 1e-4, "{n}");
        }
    }

    #[test]
    fn spacing_and_subsampling() {
        let pts = grid(40);
        assert!((point_spacing(&pts) - 1.0).abs() < 1e-6);
        let v = voxel_subsample(&pts, 400);
        assert!((300..=500).contains(&v.len()), "{}", v.len());
        let f = farthest_point_sample(&pts, 4);
        // From corner (0,0): the opposite corner, then the two others.
        let mut got: Vec<Vec3> = f.iter().map(|&i| pts[i]).collect();
        got.sort_by(|a, b| (a.x + 100.0 * a.y).total_cmp(&(b.x + 100.0 * b.y)));
        assert_eq!(
            got,
            vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(39.0, 0.0, 0.0),
                Vec3::new(0.0, 39.0, 0.0),
                Vec3::new(39.0, 39.0, 0.0)
            ]
        );
    }

    #[test]
    fn surface_init_makes_flat_discs_on_the_points() {
        let pts = grid(10);
        let sp = SurfacePoints {
            positions: pts.clone(),
            normals: None,
            colors: vec![[0.2, 0.4, 0.6]; pts.len()],
            ..SurfacePoints::default()
        };
        let (s, summary) = surface_init(&sp, &InitConfig::default(), 10).unwrap();
        assert_eq!(s.means, pts);
        assert_eq!(summary.sh_degree, 0);
        assert_eq!(summary.normals, "pca");
        for i in 0..s.len() {
            let scale = s.scale(i);
            // Spacing 1: in-plane σ = √(mean of 3-NN squared distances) ∈ [1, √2], normal σ a tenth.
            assert!(scale.x >= 0.99 && scale.x <= 1.42 && (scale.z / scale.x - 0.1).abs() < 1e-4);
            let normal = s.rotation(i) * Vec3::Z;
            assert!((normal.z.abs() - 1.0).abs() < 1e-4);
            let rgb = splat_core::sh_dc_to_rgb(s.sh_of(i)[0]);
            assert!((rgb[2] - 0.6).abs() < 1e-5);
        }
    }

    #[test]
    fn sparse_init_reads_colmap_points3d() {
        let dir = std::path::PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../testdata/colmap/maupertuis/sparse/0"
        ));
        // Independent truth: the text file's own data lines (id x y z r g b error track…).
        let text = std::fs::read_to_string(dir.join("points3D.txt")).unwrap();
        let mut expected: Vec<([f32; 3], [f32; 3])> = text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .map(|l| {
                let f: Vec<f32> = l
                    .split_whitespace()
                    .take(7)
                    .map(|v| v.parse().unwrap())
                    .collect();
                (
                    [f[1], f[2], f[3]],
                    [f[4] / 255.0, f[5] / 255.0, f[6] / 255.0],
                )
            })
            .collect();
        assert_eq!(expected.len(), 1039);
        let sp = SurfacePoints {
            positions: grid(10),
            colors: vec![[0.5; 3]; 100],
            ..SurfacePoints::default()
        };
        let cfg = InitConfig {
            mode: InitMode::Sparse,
            points3d: Some(dir),
            sh_degree: ShDegree::Fixed(0),
            ..InitConfig::default()
        };
        let (s, summary) = initialise(&sp, &cfg, 10, 3).unwrap();
        assert_eq!(summary.source, "colmap");
        assert_eq!(s.len(), expected.len());
        let mut got: Vec<([f32; 3], [f32; 3])> = (0..s.len())
            .map(|i| {
                (
                    s.means[i].to_array(),
                    splat_core::sh_dc_to_rgb(s.sh_of(i)[0]),
                )
            })
            .collect();
        let key = |a: &([f32; 3], [f32; 3])| (a.0[0], a.0[1], a.0[2]);
        expected.sort_by(|a, b| key(a).partial_cmp(&key(b)).unwrap());
        got.sort_by(|a, b| key(a).partial_cmp(&key(b)).unwrap());
        for (g, e) in got.iter().zip(&expected) {
            for k in 0..3 {
                assert!((g.0[k] - e.0[k]).abs() < 1e-5, "{g:?} {e:?}");
                assert!((g.1[k] - e.1[k]).abs() < 1e-5, "{g:?} {e:?}");
            }
        }
        // Isotropic splats with Inria's initial opacity.
        for i in 0..s.len() {
            let sc = s.scale(i);
            assert!((sc.x - sc.y).abs() < 1e-6 * sc.x && (sc.x - sc.z).abs() < 1e-6 * sc.x);
            assert!((s.opacity(i) - cfg.sparse_opacity).abs() < 1e-5);
        }
        // A folder without a COLMAP model names the folder.
        let missing = InitConfig {
            points3d: Some(std::path::PathBuf::from("/nonexistent/sparse/0")),
            ..cfg
        };
        let e = initialise(&sp, &missing, 10, 3).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/sparse/0"), "{e}");
    }

    #[test]
    fn sparse_random_init_fills_the_bounds() {
        let sp = SurfacePoints {
            positions: grid(10),
            colors: vec![[0.5; 3]; 100],
            ..SurfacePoints::default()
        };
        let cfg = InitConfig {
            mode: InitMode::Sparse,
            random_points: 500,
            ..InitConfig::default()
        };
        let (s, summary) = initialise(&sp, &cfg, 10, 3).unwrap();
        assert_eq!(s.len(), 500);
        assert_eq!(summary.source, "random");
        assert!(
            s.means
                .iter()
                .all(|m| m.x >= 0.0 && m.x <= 9.0 && m.z == 0.0)
        );
    }
}
