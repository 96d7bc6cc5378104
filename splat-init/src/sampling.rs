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
    // Bisection in log(h): larger cells, fewer occupied. The smallest cell, diag / 10⁶, keeps
    // every cell coordinate below 2²¹, so a cell packs into one u64 key.
    let (mut small, mut large) = (diag / 1e6, diag);
    let mut keys = Vec::new();
    for _ in 0..30 {
        let mid = (small * large).sqrt();
        if occupied_cells(points, lo, mid, &mut keys) > k {
            small = mid;
        } else {
            large = mid;
        }
        if large / small < 1.01 {
            break;
        }
    }
    // Points grouped by cell, each cell's members in index order.
    let mut members: Vec<(u64, u32)> = points
        .par_iter()
        .enumerate()
        .map(|(i, &p)| (cell_key(p, lo, large), i as u32))
        .collect();
    members.par_sort_unstable();
    let cells: Vec<&[(u64, u32)]> = members.chunk_by(|a, b| a.0 == b.0).collect();
    let mut picked: Vec<usize> = cells
        .par_iter()
        .map(|cell| {
            let mean =
                cell.iter().map(|&(_, i)| points[i as usize]).sum::<Vec3>() / cell.len() as f32;
            cell.iter()
                .map(|&(_, i)| i as usize)
                .min_by(|&a, &b| {
                    points[a]
                        .distance_squared(mean)
                        .total_cmp(&points[b].distance_squared(mean))
                })
                .unwrap_or(cell[0].1 as usize)
        })
        .collect();
    picked.sort_unstable();
    picked
}

/// Bits of each cell coordinate in a [`cell_key`].
const CELL_BITS: u32 = 21;

/// The grid cell (of side `h`, from `lo`) that `p` falls in, its three coordinates packed into
/// one integer. Coordinates are floored and saturated into [0, 2²¹), which for the cell sizes
/// [`voxel_subsample`] tries (at least 10⁻⁶ of the bounds' diagonal) loses nothing.
fn cell_key(p: Vec3, lo: Vec3, h: f32) -> u64 {
    let c = ((p - lo) / h).floor();
    let coord = |v: f32| (v as i64).clamp(0, (1 << CELL_BITS) - 1) as u64;
    (coord(c.x) << (2 * CELL_BITS)) | (coord(c.y) << CELL_BITS) | coord(c.z)
}

/// Number of distinct cells of side `h` that `points` occupy, from their keys sorted in
/// parallel (`keys` is scratch). A hash set of 3M cells, filled serially, took about half of a
/// paper-scale frame's initialisation over the bisection's dozen tries.
fn occupied_cells(points: &[Vec3], lo: Vec3, h: f32, keys: &mut Vec<u64>) -> usize {
    keys.clear();
    keys.par_extend(points.par_iter().map(|&p| cell_key(p, lo, h)));
    keys.par_sort_unstable();
    keys.chunk_by(|a, b| a == b).count()
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
