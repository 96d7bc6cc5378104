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
        Some(n) => file_normals(n, &points.positions, cfg.normal_neighbours),
        None => (
            pca_normals(&points.positions, cfg.normal_neighbours),
            "pca".to_string(),
        ),
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
        normals: normal_source,
        source: "surface".to_string(),
        warm_start: None,
    };
    Ok((splats, summary))
}

/// The file's normals as they are, those whose square overflows or vanishes in f32 scaled by
/// their largest component (so that (10³⁰, 10³⁰, 0) is a direction too), and those that name no
/// direction (zero, not finite) replaced by fitted ones ([`pca_normals`] of `k` neighbours);
/// and where they came from. Exporters write zero normals for "none": taken as they were,
/// every such disc faced +z.
fn file_normals(normals: &[Vec3], positions: &[Vec3], k: usize) -> (Vec<Vec3>, String) {
    let unit = |n: Vec3| {
        let square = n.length_squared();
        if square.is_normal() && square.is_finite() {
            return Some(n);
        }
        let largest = n.abs().max_element();
        (largest.is_finite() && largest > 0.0).then(|| (n / largest).normalize())
    };
    let scaled: Vec<Option<Vec3>> = normals.par_iter().map(|&n| unit(n)).collect();
    let missing = scaled.iter().filter(|n| n.is_none()).count();
    if missing == 0 {
        return (scaled.into_iter().flatten().collect(), "file".into());
    }
    let fitted = pca_normals(positions, k);
    let merged = scaled
        .iter()
        .zip(&fitted)
        .map(|(n, f)| n.unwrap_or(*f))
        .collect();
    let source = if missing == normals.len() {
        "pca (the file's normals are all zero or not finite)".to_string()
    } else {
        format!("file ({missing} zero or not finite, fitted instead)")
    };
    (merged, source)
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
