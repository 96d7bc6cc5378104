//! How large a cloud's points must be drawn for the surface they sample to look closed.
//!
//! PccAppRenderer draws every point as a cube one voxel wide. That closes the surface of a
//! voxelised capture, which holds one point per voxel the surface passes through (8iVSLF), but a
//! cloud that samples its surface more sparsely, such as a random subset or a mesh sampled with
//! fewer points than its area in voxels, is then drawn as a sieve: the background and the far
//! side show through most of the object (a 3M-point frame sampled from the spider mesh on a 4095
//! grid fills about a quarter of its surface voxels; its views' mean coverage inside the object
//! was 0.69 at one voxel, 0.98 at two, 0.996 at 2.5). An ideal viewer of such a cloud shows the
//! surface, so the reference renderer grows the cubes with the cloud's spacing
//! ([`closing_point_size`]).
//!
//! A cloud that lies on no grid of the configured voxel size (arbitrary floats: a cloud in
//! metres, or a tenth of a unit across) has no voxel to draw; it is drawn at its own measured
//! spacing, so its views do not depend on its units ([`point_sizing`]).
//!
//! The spacing is measured, not guessed from the point count: around up to
//! [`SPACING_SAMPLES`] evenly strided points, the points within a radius R are counted, and
//! the area each point stands for is πR² over the median count (the surface is locally a plane at
//! the scale R, which holds R of a few spacings). R starts from the bounding box and is doubled
//! or halved until the median count lies in [`COUNT_RANGE`].

use glam::Vec3;
use rayon::prelude::*;

/// Most points the spacing is measured around (evenly strided over the cloud).
pub const SPACING_SAMPLES: usize = 20_000;

/// The median neighbour count the radius is tuned into: enough points for the count to be a
/// density (±20 % at 25), few enough that the disc stays local to the surface.
const COUNT_RANGE: std::ops::RangeInclusive<usize> = 24..=96;

/// Neighbours counted at most around one sample (well above [`COUNT_RANGE`]).
const COUNT_CAP: usize = 1024;

/// Most radius adjustments before the last one is used.
const MAX_ROUNDS: usize = 12;

/// Width of a cube, in spacings, that covers a randomly sampled surface: a regular grid is
/// closed by cubes one spacing wide, a random sample leaves holes of a few spacings, and cubes
/// 1.5 spacings wide cover all but about 0.5 % of the spider frame's object pixels.
const CLOSING_WIDTH: f32 = 1.5;

/// How much sparser than one point per `base`-wide cell a cloud may measure and still count as
/// dense: the measurement reads a regular grid up to 10 % wide.
const DENSE_TOLERANCE: f32 = 1.25;

/// How much of a voxel a coordinate may stray from its grid point and still lie on the grid
/// ([`lies_on_grid`]): a voxelised capture stores exact grid coordinates, and a cloud of
/// unrelated floats has all three of a point's coordinates this close to a grid point by chance
/// about once in 15,000 points.
const GRID_TOLERANCE: f64 = 0.02;

/// Share of the sampled points that must lie on the grid for the cloud to count as voxelised at
/// it (a few strays, such as points a capture added between voxels, do not change its nature).
const ON_GRID_SHARE: f64 = 0.9;

/// Fewest voxels a cloud must span to count as voxelised: a cloud a fraction of a voxel across
/// lies within [`GRID_TOLERANCE`] of one grid point whatever its points are, and a capture
/// spans hundreds (8iVSLF: 1024 or 4096 a side).
const MIN_GRID_SPAN: f32 = 8.0;

/// Most points whose coordinates [`grid_pitch`] reads: enough that nearly every grid plane a
/// paper-scale capture crosses (4,096 a side) holds one of them, few enough to sort at once.
const PITCH_SAMPLES: usize = 200_000;

/// How many of the first samples are tried as the grid's origin, so that a stray first point
/// cannot place the grid.
const ORIGIN_CANDIDATES: usize = 8;

/// How a cloud's points are sized for drawing ([`point_sizing`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PointSizing {
    /// At the configured size: a cloud voxelised at it about one point per voxel of its
    /// surface, or one too small to measure.
    AsConfigured,
    /// Voxelised at the configured size but sparser than one point per voxel: grown to this
    /// side (1.5 measured spacings) so the surface is closed.
    Grown(f32),
    /// Not on a grid of the configured size at all (a cloud in metres, say, whose points are
    /// arbitrary floats): the configured size says nothing about it, so its points are drawn
    /// 1.5 measured spacings wide, whatever the cloud's scale.
    OffGrid(f32),
    /// Voxelised on a grid of another pitch, this one (a voxelised capture scaled into metres,
    /// say), about one point per cell of its surface: drawn one cell wide, as the configured
    /// size draws a capture voxelised at it, so its views do not depend on its units.
    Voxelised(f32),
}

impl PointSizing {
    /// The cube side (the disc's half-size) this sizing draws with, given the configured one.
    #[must_use]
    pub fn size(self, base: f32) -> f32 {
        match self {
            Self::AsConfigured => base,
            Self::Grown(size) | Self::OffGrid(size) | Self::Voxelised(size) => size,
        }
    }
}

impl std::fmt::Display for PointSizing {
    /// What the choice was and why, for the person running the tool.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::AsConfigured => write!(
                f,
                "its points are drawn at the configured voxel size (renderer.point_size)"
            ),
            Self::Grown(size) => write!(
                f,
                "the cloud samples its surface more sparsely than one point per voxel: its \
                 points are drawn {size:.2} voxels wide so the surface is closed"
            ),
            Self::Voxelised(size) => {
                let decimals = significant_decimals(*size);
                write!(
                    f,
                    "the cloud's points lie on a grid of pitch {size:.decimals$} units, not of the \
                     configured voxel size: each is drawn one cell of it wide, as a voxelised \
                     capture is"
                )
            }
            Self::OffGrid(size) => {
                let decimals = significant_decimals(*size);
                write!(
                    f,
                    "the cloud's points lie on no grid of the configured voxel size: they are \
                     drawn {size:.decimals$} units wide, 1.5 times their measured spacing, so the \
                     surface is closed"
                )
            }
        }
    }
}

/// Decimals that print `size` with four significant digits at any scale: 0.002714, 27.14, 2714.
fn significant_decimals(size: f32) -> usize {
    (3.0 - f64::from(size).log10().floor()).clamp(0.0, 40.0) as usize
}

/// The side of the cubes (in the cloud's units) that draws the surface of `positions` closed,
/// [`point_sizing`]'s choice.
#[must_use]
pub fn closing_point_size(positions: &[Vec3], base: f32) -> f32 {
    point_sizing(positions, base).size(base)
}

/// How the points of `positions` are drawn given the configured voxel size `base`. A cloud
/// voxelised at `base` ([`lies_on_grid`]) keeps `base` while it is about as dense as one point
/// per voxel of its surface (measured spacing `s` ≤ 1.25 `base`), else it grows to 1.5 `s`,
/// where `s` is the side of the square of surface each point stands for; so a dense voxelised
/// capture is drawn exactly as PccAppRenderer draws it and a sparse one with cubes about 1.5
/// spacings wide. A cloud off that grid is drawn 1.5 `s` wide whatever its density (cubes one
/// unit wide would swallow a cloud a tenth of a unit across, the cameras inside them, and
/// blur one in thousands of units), unless it lies on a grid of another pitch ([`grid_pitch`])
/// about one point per cell: then one cell wide, as at the configured size. Clouds too small to
/// measure (under 24 points) use their extent over √n as the spacing when off the grid, else
/// keep `base`.
#[must_use]
pub fn point_sizing(positions: &[Vec3], base: f32) -> PointSizing {
    let finite = finite_points(positions);
    let on_grid = lies_on_grid(&finite, base);
    match finite_spacing(&finite) {
        Some(s) if !on_grid => match grid_pitch(&finite) {
            Some(pitch) if s <= DENSE_TOLERANCE * pitch => PointSizing::Voxelised(pitch),
            _ => PointSizing::OffGrid(CLOSING_WIDTH * s),
        },
        // Sparse on the configured grid, or dense on a coarser one (a capture voxelised at
        // twice the voxel: every point on even coordinates).
        Some(s) if s > DENSE_TOLERANCE * base => match grid_pitch(&finite) {
            Some(pitch) if pitch > base && s <= DENSE_TOLERANCE * pitch => {
                PointSizing::Voxelised(pitch)
            }
            _ => PointSizing::Grown((CLOSING_WIDTH * s).max(base)),
        },
        Some(_) => PointSizing::AsConfigured,
        None if on_grid => PointSizing::AsConfigured,
        None => match bounds(&finite) {
            Some((_, e)) if e > 0.0 => {
                PointSizing::OffGrid(CLOSING_WIDTH * e / (finite.len() as f32).sqrt())
            }
            _ => PointSizing::AsConfigured,
        },
    }
}

/// Whether at least 90 % of up to 20,000 evenly strided points have every coordinate within
/// 0.02 voxels of a grid of pitch `base` (its origin anywhere: one of the first eight samples
/// is taken as a grid point), over a box at least 8 voxels across.
#[must_use]
pub fn lies_on_grid(finite: &[Vec3], base: f32) -> bool {
    match bounds(finite) {
        Some((_, extent)) if extent >= MIN_GRID_SPAN * base => {}
        _ => return false,
    }
    let stride = finite.len().div_ceil(SPACING_SAMPLES).max(1);
    let samples: Vec<[f64; 3]> = finite
        .iter()
        .step_by(stride)
        .map(|p| p.to_array().map(|c| f64::from(c) / f64::from(base)))
        .collect();
    // Distance to the nearest grid point, in voxels, of a coordinate on a grid through `origin`.
    let off = |c: f64, origin: f64| {
        let d = (c - origin).rem_euclid(1.0);
        d.min(1.0 - d)
    };
    let needed = (ON_GRID_SHARE * samples.len() as f64).ceil() as usize;
    samples.iter().take(ORIGIN_CANDIDATES).any(|origin| {
        let on = samples
            .iter()
            .filter(|p| (0..3).all(|a| off(p[a], origin[a]) <= GRID_TOLERANCE))
            .count();
        on >= needed
    })
}

/// The pitch of the grid the points lie on, whatever the configured voxel size: on each axis
/// the median gap between the distinct coordinates of up to 200,000 points (a voxelised
/// surface fills nearly every grid plane it crosses, so most gaps are one pitch), taken when
/// the axes that have gaps (at least two) agree within 1 % and the points lie on that grid
/// ([`lies_on_grid`]); `None` otherwise (arbitrary floats, whose gaps are tiny and unequal).
#[must_use]
pub fn grid_pitch(finite: &[Vec3]) -> Option<f32> {
    // Up to PITCH_SAMPLES points spread by the golden ratio rather than a stride: a stride can
    // fall in step with the grid's rows and see every fifth plane only.
    let samples: Vec<Vec3> = if finite.len() <= PITCH_SAMPLES {
        finite.to_vec()
    } else {
        (0..PITCH_SAMPLES)
            .map(|k| {
                let at = (k as f64 * 0.618_033_988_749_894_9).fract() * finite.len() as f64;
                finite[(at as usize).min(finite.len() - 1)]
            })
            .collect()
    };
    let median_gap = |axis: usize| -> Option<f64> {
        let mut c: Vec<f32> = samples.iter().map(|p| p[axis]).collect();
        c.par_sort_unstable_by(f32::total_cmp);
        c.dedup();
        let c: Vec<f64> = c.into_iter().map(f64::from).collect();
        let mut gaps: Vec<f64> = c.windows(2).map(|w| w[1] - w[0]).collect();
        if gaps.is_empty() {
            return None;
        }
        let mid = gaps.len() / 2;
        Some(*gaps.select_nth_unstable_by(mid, f64::total_cmp).1)
    };
    // An axis with one coordinate (a plane across it) has no gap and says nothing.
    let gaps: Vec<f64> = (0..3).filter_map(median_gap).collect();
    let (lo, hi) = (
        gaps.iter().copied().fold(f64::INFINITY, f64::min),
        gaps.iter().copied().fold(0.0, f64::max),
    );
    if gaps.len() < 2 || !(lo > 0.0 && hi <= 1.01 * lo) {
        return None;
    }
    let pitch = ((lo + hi) / 2.0) as f32;
    (pitch.is_normal() && lies_on_grid(finite, pitch)).then_some(pitch)
}

/// The low corner of the finite points' bounding box and its longest side; `None` for no
/// points.
fn bounds(finite: &[Vec3]) -> Option<(Vec3, f32)> {
    let first = *finite.first()?;
    let (lo, hi) = finite
        .iter()
        .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    Some((lo, (hi - lo).max_element()))
}

/// The side of the square of surface each point stands for, √(area / points), measured as the
/// module describes; `None` for fewer than 24 finite points or a
/// cloud with no extent.
#[must_use]
pub fn surface_spacing(positions: &[Vec3]) -> Option<f32> {
    finite_spacing(&finite_points(positions))
}

/// The points of `positions` whose coordinates are all finite.
fn finite_points(positions: &[Vec3]) -> Vec<Vec3> {
    positions
        .iter()
        .copied()
        .filter(|p| p.is_finite())
        .collect()
}

/// [`surface_spacing`] of points known to be finite.
fn finite_spacing(finite: &[Vec3]) -> Option<f32> {
    if finite.len() < *COUNT_RANGE.start() {
        return None;
    }
    let (lo, extent) = bounds(finite)?;
    if extent <= 0.0 {
        return None;
    }
    // A surface of area ≈ extent² sampled by n points has spacing ≈ extent / √n; a radius of
    // five spacings holds about 80 of them.
    let mut radius = 5.0 * extent / (finite.len() as f32).sqrt();
    let mut median = 0;
    for _ in 0..MAX_ROUNDS {
        median = median_count(finite, lo, extent, radius);
        if median < *COUNT_RANGE.start() {
            radius *= 2.0;
        } else if median > *COUNT_RANGE.end() {
            radius *= 0.5;
        } else {
            break;
        }
    }
    let area = std::f32::consts::PI * radius * radius / median.max(1) as f32;
    Some(area.sqrt())
}

/// Median over the strided samples of the number of points (the sample included) within
/// `radius`, found through cells of side `radius` sorted by key.
fn median_count(points: &[Vec3], lo: Vec3, extent: f32, radius: f32) -> usize {
    // Cells of side `radius`, at most 2²⁰ a side so a key packs into 60 bits.
    let cell = radius.max(extent / (1 << 20) as f32);
    let coord = |p: Vec3| ((p - lo) / cell).floor().as_uvec3();
    let key = |c: glam::UVec3| (u64::from(c.x) << 40) | (u64::from(c.y) << 20) | u64::from(c.z);
    // Each point beside its key, so a cell's points are read together (through their indices
    // they were a cache miss each); a count does not depend on the order within a cell, so
    // the key alone orders them.
    let mut sorted: Vec<(u64, Vec3)> = points.par_iter().map(|&p| (key(coord(p)), p)).collect();
    sorted.par_sort_unstable_by_key(|e| e.0);
    // Where each occupied cell's points start, so that the searches run over the cells (tens
    // of points each, their keys in cache) rather than over the points.
    let cells: Vec<(u64, usize)> = sorted
        .iter()
        .enumerate()
        .filter(|&(i, e)| i == 0 || sorted[i - 1].0 != e.0)
        .map(|(i, e)| (e.0, i))
        .collect();
    let start_of = |cell: usize| cells.get(cell).map_or(sorted.len(), |c| c.1);
    let r2 = radius * radius;
    let mut counts: Vec<usize> = distinct_samples(points)
        .par_iter()
        .map(|&p| {
            let c = coord(p).as_ivec3();
            let mut n = 0;
            // The 27 cells around the sample's as 9 columns of three: the cells (x, y, z − 1),
            // (x, y, z) and (x, y, z + 1) have consecutive keys, so one search finds each
            // column (a search a cell through the 3 million points' keys, a cache miss at
            // most steps, was half of a paper-scale frame's measurement).
            for d in 0..9 {
                let (x, y) = (c.x + d % 3 - 1, c.y + d / 3 - 1);
                if x < 0 || y < 0 {
                    continue;
                }
                let cell_key = |z: i32| key(glam::IVec3::new(x, y, z).as_uvec3());
                let (first, last) = (cell_key((c.z - 1).max(0)), cell_key(c.z + 1));
                let from = cells.partition_point(|c| c.0 < first);
                let to = from + cells[from..].partition_point(|c| c.0 <= last);
                n += sorted[start_of(from)..start_of(to)]
                    .iter()
                    .filter(|e| e.1.distance_squared(p) <= r2)
                    .take(COUNT_CAP)
                    .count();
                // Past the cap the count only says "too many": stop, so a cloud of heaped
                // duplicates cannot make this quadratic.
                if n >= COUNT_CAP {
                    return COUNT_CAP;
                }
            }
            n
        })
        .collect();
    let mid = counts.len() / 2;
    *counts.select_nth_unstable(mid).1
}

/// Up to [`SPACING_SAMPLES`] evenly strided points, each position once: a heap of duplicates
/// (depth sensors' invalid returns at the origin, a point written thousands of times) is one
/// place on the surface, and as a majority of the samples it made the median count that of the
/// heap, so the spacing shrank towards zero and the views came out empty.
fn distinct_samples(points: &[Vec3]) -> Vec<Vec3> {
    let stride = points.len().div_ceil(SPACING_SAMPLES).max(1);
    let mut samples: Vec<Vec3> = points.iter().step_by(stride).copied().collect();
    let bits = |p: &Vec3| p.to_array().map(f32::to_bits);
    samples.sort_unstable_by_key(bits);
    samples.dedup_by_key(|p| bits(p));
    samples
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points on the z = 0 plane at a regular spacing `h` over `n` × `n`.
    fn grid(n: usize, h: f32) -> Vec<Vec3> {
        (0..n * n)
            .map(|i| Vec3::new((i % n) as f32 * h, (i / n) as f32 * h, 0.0))
            .collect()
    }

    /// `n` points of the Fibonacci lattice on a sphere of radius `radius` round the origin.
    fn fibonacci_sphere(n: usize, radius: f32) -> Vec<Vec3> {
        camera_model::rig::fibonacci_sphere(n)
            .into_iter()
            .map(|d| radius * d.as_vec3())
            .collect()
    }

    #[test]
    fn median_count_counts_what_a_brute_force_counts() {
        // A bumpy shell with heaped duplicates, some points near the box's low corner (cells
        // at coordinate 0, whose neighbours below do not exist), at radii from below the
        // spacing to past the count cap.
        let mut pts: Vec<Vec3> = (0..6000)
            .map(|i| {
                let t = i as f32 * 0.618;
                let r = 20.0 + 2.0 * (3.0 * t).sin();
                Vec3::new(
                    r * t.cos(),
                    r * t.sin() * (0.3 * t).cos(),
                    r * (0.3 * t).sin(),
                )
            })
            .collect();
        pts.extend(std::iter::repeat_n(Vec3::new(3.0, -2.0, 1.0), 1500));
        let (lo, hi) = pts.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        );
        let extent = (hi - lo).max_element();
        for radius in [0.3, 1.0, 2.5, 7.0, 40.0] {
            // Around each distinct sample position once (the heap of duplicates is one).
            let stride = pts.len().div_ceil(SPACING_SAMPLES).max(1);
            let mut samples: Vec<Vec3> = pts.iter().step_by(stride).copied().collect();
            samples.sort_by(|a, b| a.to_array().partial_cmp(&b.to_array()).unwrap());
            samples.dedup();
            let mut counts: Vec<usize> = samples
                .iter()
                .map(|&p| {
                    let n = pts
                        .iter()
                        .filter(|q| q.distance_squared(p) <= radius * radius)
                        .count();
                    n.min(COUNT_CAP)
                })
                .collect();
            let mid = counts.len() / 2;
            let want = *counts.select_nth_unstable(mid).1;
            assert_eq!(
                median_count(&pts, lo, extent, radius),
                want,
                "radius {radius}"
            );
        }
    }

    #[test]
    fn a_regular_plane_has_its_grid_spacing() {
        for h in [1.0, 0.25, 3.0] {
            let s = surface_spacing(&grid(400, h)).unwrap();
            assert!((s / h - 1.0).abs() < 0.1, "spacing {s} for grid {h}");
        }
    }

    #[test]
    fn a_heap_of_duplicates_does_not_shrink_the_spacing() {
        // A plane with half again as many copies of one point (a depth sensor's invalid returns
        // at the origin): the spacing was that of the heap, and the cloud was drawn 6e-6 wide.
        let mut pts = grid(200, 1.0);
        let plane = surface_spacing(&pts).unwrap();
        pts.extend(std::iter::repeat_n(Vec3::ZERO, pts.len() * 3 / 2));
        let heaped = surface_spacing(&pts).unwrap();
        assert!(
            (heaped / plane - 1.0).abs() < 0.05,
            "{heaped} against {plane}"
        );
    }

    #[test]
    fn a_quarter_of_the_points_doubles_the_spacing() {
        // Every other row and column: one point per 2 × 2 cell.
        let full = grid(600, 1.0);
        let sparse: Vec<Vec3> = full
            .iter()
            .copied()
            .filter(|p| (p.x as i32) % 2 == 0 && (p.y as i32) % 2 == 0)
            .collect();
        let s = surface_spacing(&sparse).unwrap();
        assert!((s - 2.0).abs() < 0.2, "spacing {s}");
    }

    #[test]
    fn a_sphere_shell_has_the_spacing_of_its_area() {
        // Fibonacci points on a sphere of radius 50: area 4π·50² over n points.
        let n = 40_000;
        let pts = fibonacci_sphere(n, 50.0);
        let truth = (4.0 * std::f32::consts::PI * 2500.0 / n as f32).sqrt();
        let s = surface_spacing(&pts).unwrap();
        assert!((s / truth - 1.0).abs() < 0.1, "spacing {s}, truth {truth}");
    }

    #[test]
    fn dense_clouds_keep_the_voxel_size_and_sparse_ones_grow() {
        let dense = grid(300, 1.0);
        assert_eq!(closing_point_size(&dense, 1.0), 1.0);
        // A random quarter of the voxels: spacing about 2, drawn 1.5 spacings wide.
        let sparse: Vec<Vec3> = grid(600, 1.0)
            .into_iter()
            .enumerate()
            .filter(|(i, _)| (*i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 62 == 0)
            .map(|(_, p)| p)
            .collect();
        let size = closing_point_size(&sparse, 1.0);
        assert!((size - 3.0).abs() < 0.3, "size {size}");
        // Every other voxel in both directions is a grid of pitch 2, dense on it: one cell wide,
        // whether the configured voxel is 1 or 2.
        let coarse = grid(300, 2.0);
        assert_eq!(point_sizing(&coarse, 1.0), PointSizing::Voxelised(2.0));
        assert_eq!(closing_point_size(&coarse, 2.0), 2.0);
    }

    #[test]
    fn grids_are_recognised_at_their_pitch_and_offset_only() {
        let plane = grid(200, 1.0);
        assert!(lies_on_grid(&plane, 1.0));
        // Shifted by half a voxel (the origin is taken from the points), and at a pitch of 0.1
        // (f32 multiples of 0.1 are not exact).
        let shifted: Vec<Vec3> = plane.iter().map(|&p| p + Vec3::splat(0.5)).collect();
        assert!(lies_on_grid(&shifted, 1.0));
        let fine = grid(200, 0.1);
        assert!(lies_on_grid(&fine, 0.1));
        assert!(!lies_on_grid(&fine, 1.0));
        // Arbitrary floats: a Fibonacci sphere.
        assert!(!lies_on_grid(&fibonacci_sphere(20_000, 37.3), 1.0));
        // A few strays, the first point among them, do not take a grid away.
        let mut strays = plane.clone();
        for p in strays.iter_mut().step_by(25) {
            *p += Vec3::new(0.31, 0.47, 0.0);
        }
        assert!(lies_on_grid(&strays, 1.0));
    }

    #[test]
    fn off_grid_clouds_are_drawn_at_their_own_spacing_at_every_scale() {
        // A plane at pitch 0.7 is on no grid of the voxel 1: it is drawn one cell of its own
        // grid wide; at 1/1000 of the scale (denser than one point per voxel) and at 1234.567
        // times it, the same in proportion.
        for scale in [1.0, 1e-3, 1234.567] {
            let pts = grid(300, 0.7 * scale);
            match point_sizing(&pts, 1.0) {
                PointSizing::Voxelised(size) => {
                    assert!(
                        (size / scale - 0.7).abs() < 1e-3,
                        "scale {scale}: size {size}"
                    );
                }
                other => panic!("scale {scale}: {other:?}"),
            }
            // The same plane jittered off every grid: 1.5 measured spacings.
            let jittered: Vec<Vec3> = pts
                .iter()
                .enumerate()
                .map(|(i, &p)| {
                    let h = (i as f32 * 0.618_034).fract() - 0.5;
                    p + Vec3::new(0.21 * h, 0.37 * h, 0.0) * 0.7 * scale
                })
                .collect();
            match point_sizing(&jittered, 1.0) {
                PointSizing::OffGrid(size) => {
                    assert!(
                        (size / scale - 1.05).abs() < 0.1,
                        "scale {scale}: size {size}"
                    );
                }
                other => panic!("jittered at scale {scale}: {other:?}"),
            }
        }
        // A voxelised grid scaled by 2, 1/2 and 1/1024 (voxels to a metre-sized object) keeps
        // its cell, and a sparse one (every other cell) is drawn 1.5 spacings wide.
        for pitch in [2.0f32, 0.5, 1.0 / 1024.0] {
            assert_eq!(
                point_sizing(&grid(200, pitch), 1.0),
                PointSizing::Voxelised(pitch)
            );
        }
        assert_eq!(grid_pitch(&fibonacci_sphere(20_000, 37.3)), None);
        // Too few points to measure: the extent over √n.
        let few = [Vec3::ZERO, Vec3::X * 0.2, Vec3::Y * 0.2, Vec3::Z * 0.2];
        match point_sizing(&few, 1.0) {
            PointSizing::OffGrid(size) => assert!((size - 0.15).abs() < 1e-6, "size {size}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn tiny_and_degenerate_clouds_keep_the_base() {
        assert_eq!(closing_point_size(&[Vec3::ZERO; 5], 1.0), 1.0);
        assert_eq!(closing_point_size(&vec![Vec3::ONE; 500], 1.0), 1.0);
        let mut with_nan = grid(100, 4.0);
        with_nan.push(Vec3::NAN);
        assert!(closing_point_size(&with_nan, 1.0) > 1.0);
    }
}
