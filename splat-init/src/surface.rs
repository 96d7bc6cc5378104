//! Surface init: flat splats on the input's surface points, SH fitted to their colours.

use glam::Vec3;
use splat_core::Splats;

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
        warm_start: None,
    };
    Ok((splats, summary))
}
