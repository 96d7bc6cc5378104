//! Sparse init, as the usual 3DGS pipeline does it: COLMAP points3D or random points in the
//! bounds, isotropic splats sized from their 3 nearest neighbours, low opacity.

use std::path::Path;

use glam::Vec3;
use rand::{RngExt, SeedableRng};
use splat_core::Splats;

use crate::config::{InitConfig, InitMode};
use crate::neighbours::point_spacing;
use crate::points::SurfacePoints;
use crate::sampling::bounds;
use crate::sh_fit::decide_sh_degree;
use crate::{InitError, InitSummary};

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
            let (p, c) = random_points(lo, hi, cfg.random_points, seed);
            (p, c, "random")
        }
    };
    let (degree, errors) = decide_sh_degree(input, cfg, exponent);
    let splats = sparse_splats(&positions, &colors, cfg.sparse_opacity, degree)?;
    let summary = InitSummary {
        mode: InitMode::Sparse,
        splats: splats.len(),
        sh_degree: degree,
        sh_fit_rms: errors,
        point_spacing: point_spacing(&input.positions),
        normals: "none".to_string(),
        source: source.to_string(),
        warm_start: None,
    };
    Ok((splats, summary))
}

/// `count` uniform random points in the box [`lo`, `hi`] (seeded), all mid grey (SH DC 0): an
/// uninformed colour, which is what Inria's random init amounts to (random SH of at most 1/255).
#[must_use]
pub fn random_points(lo: Vec3, hi: Vec3, count: usize, seed: u64) -> (Vec<Vec3>, Vec<[f32; 3]>) {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let p: Vec<Vec3> = (0..count)
        .map(|_| lo + (hi - lo) * Vec3::new(rng.random(), rng.random(), rng.random()))
        .collect();
    let c = vec![[0.5f32; 3]; p.len()];
    (p, c)
}

/// The positions and colours (8-bit to [0, 1]) of a COLMAP model's 3D points.
#[must_use]
pub fn colmap_points(rec: &colmap_io::Reconstruction) -> (Vec<Vec3>, Vec<[f32; 3]>) {
    rec.points3d
        .values()
        .map(|p| (p.xyz.as_vec3(), p.rgb.map(|c| f32::from(c) / 255.0)))
        .unzip()
}

/// Isotropic splats on `positions` with `colors` (SH DC; higher bands of `degree` zero), identity
/// rotation, `opacity`, and Inria's scale: the RMS distance to the 3 nearest other points.
pub fn sparse_splats(
    positions: &[Vec3],
    colors: &[[f32; 3]],
    opacity: f32,
    degree: u32,
) -> Result<Splats, InitError> {
    let scales: Vec<Vec3> = splat_train::init::scales_from_knn(positions)
        .into_iter()
        .map(Vec3::exp)
        .collect();
    Ok(Splats::from_points(
        positions, colors, &scales, None, opacity, degree,
    )?)
}

fn read_points3d(dir: &Path) -> Result<(Vec<Vec3>, Vec<[f32; 3]>), InitError> {
    let rec = colmap_io::read_model(dir).map_err(|source| InitError::Colmap {
        path: dir.to_path_buf(),
        source: Box::new(source),
    })?;
    if rec.points3d.is_empty() {
        return Err(InitError::NoColmapPoints(dir.to_path_buf()));
    }
    Ok(colmap_points(&rec))
}
