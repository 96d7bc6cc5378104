//! Surface init: flat splats on the input's surface points, SH fitted to their colours.

use glam::Vec3;
use rayon::prelude::*;
use splat_core::Splats;
use splat_train::init::PointIndex;

use crate::config::{InitConfig, InitMode};
use crate::neighbours::{pca_normals, point_spacing};
use crate::points::SurfacePoints;
use crate::sh_fit::{ShFit, decide_sh_degree};
use crate::{InitError, InitSummary};

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
        .zip(scale_ratios(points, cfg))
        .map(|(s, r)| {
            let along = r.ln();
            (*s + Vec3::new(along, along, along + thin)).exp()
        })
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
        warm_start: None,
    };
    Ok((splats, summary))
}

/// Neighbours (besides the point itself) whose colours decide whether a point is on a texture
/// edge.
const EDGE_NEIGHBOURS: usize = 8;

/// Each point's in-plane σ as a share of its local spacing: `cfg.scale_ratio` where its colour
/// matches its [`EDGE_NEIGHBOURS`] nearest neighbours', `cfg.edge_scale_ratio` where one of
/// them differs by `cfg.edge_contrast` or more in some channel, linear in between. Small discs
/// at texture edges keep the edge as sharp as the points draw it; large ones elsewhere cover
/// the surface without gaps.
#[must_use]
pub(crate) fn scale_ratios(points: &SurfacePoints, cfg: &InitConfig) -> Vec<f32> {
    let Some(index) = PointIndex::new(&points.positions) else {
        return vec![cfg.scale_ratio; points.len()];
    };
    points
        .positions
        .par_iter()
        .zip(&points.colors)
        .map(|(&p, c)| {
            let contrast = index
                .nearest_n(p, EDGE_NEIGHBOURS + 1)
                .into_iter()
                .map(|j| {
                    let d = points.colors[j];
                    (0..3).map(|k| (d[k] - c[k]).abs()).fold(0.0_f32, f32::max)
                })
                .fold(0.0_f32, f32::max);
            let t = (contrast / cfg.edge_contrast).min(1.0);
            cfg.scale_ratio + (cfg.edge_scale_ratio - cfg.scale_ratio) * t
        })
        .collect()
}
