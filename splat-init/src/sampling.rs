//! Choosing the input points that carry splats: voxel-grid and farthest-point sampling.

use glam::Vec3;
use rayon::prelude::*;

use crate::config::{InitConfig, Sampling};
use crate::points::SurfacePoints;

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

/// Axis-aligned bounds (min, max) of a non-empty point set.
#[must_use]
pub fn bounds(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
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
