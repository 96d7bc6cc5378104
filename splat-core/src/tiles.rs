//! Tile binning: every visible splat is listed in each 16×16 tile its 3σ square touches, each
//! tile's list front to back.
//!
//! This is Inria's single sort of (tile, depth) keys done as the two passes of an LSD radix sort:
//! one sort of the visible splats by (depth, index), then a stable counting sort by tile. The
//! index in the key makes the order total, so binning is identical for any thread count.

use rayon::prelude::*;

use crate::project::Projected;

/// Side of a square tile in pixels (Inria's `BLOCK_X = BLOCK_Y = 16`).
pub const TILE_SIZE: u32 = 16;
/// Pixels per tile.
pub(crate) const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;

/// Reusable binning buffers.
#[derive(Debug, Default)]
pub(crate) struct Bins {
    /// Visible splats as (depth bits ≪ 32 | index), sorted.
    order: Vec<u64>,
    /// Start of each tile's list in `list`; `offsets[t + 1] − offsets[t]` is its length.
    pub offsets: Vec<usize>,
    cursor: Vec<usize>,
    /// Splat indices, tile-major, front to back within a tile.
    pub list: Vec<u32>,
}

impl Bins {
    /// Bins the splats whose `visible` flag is set; `rects` are [x0, x1, y0, y1) in tiles.
    pub fn build(
        &mut self,
        proj: &[Projected],
        rects: &[[u32; 4]],
        visible: &[bool],
        tiles_x: u32,
        tiles_y: u32,
    ) {
        let n_tiles = (tiles_x * tiles_y) as usize;
        self.order.clear();
        // Depths are > 0 (near-plane culled), so their IEEE bits sort like the values.
        self.order.extend(
            proj.iter()
                .zip(visible)
                .enumerate()
                .filter(|(_, (_, v))| **v)
                .map(|(i, (p, _))| (u64::from(p.depth.to_bits()) << 32) | i as u64),
        );
        self.order.par_sort_unstable();

        self.offsets.clear();
        self.offsets.resize(n_tiles + 1, 0);
        for &key in &self.order {
            let [x0, x1, y0, y1] = rects[(key & 0xffff_ffff) as usize];
            for ty in y0..y1 {
                let row = (ty * tiles_x) as usize;
                for tx in x0..x1 {
                    self.offsets[row + tx as usize + 1] += 1;
                }
            }
        }
        for t in 0..n_tiles {
            self.offsets[t + 1] += self.offsets[t];
        }
        self.cursor.clear();
        self.cursor.extend_from_slice(&self.offsets[..n_tiles]);
        self.list.clear();
        self.list.resize(self.offsets[n_tiles], 0);
        for &key in &self.order {
            let i = (key & 0xffff_ffff) as u32;
            let [x0, x1, y0, y1] = rects[i as usize];
            for ty in y0..y1 {
                let row = (ty * tiles_x) as usize;
                for tx in x0..x1 {
                    let c = &mut self.cursor[row + tx as usize];
                    self.list[*c] = i;
                    *c += 1;
                }
            }
        }
    }

    /// Returns the number of (tile, splat) pairs.
    pub fn pairs(&self) -> usize {
        self.list.len()
    }
}

/// The pixels of a splat's 3σ-or-brighter region within one row of a tile: the x range (tile
/// local, inclusive) where alpha can reach 1/255, or `None`. Pixels outside it have
/// o·G < 1/255 and would be skipped by the per-pixel test anyway, so this only saves work.
#[inline]
pub(crate) fn row_span(
    p: &Projected,
    q_max: f32,
    dy: f32,
    x0: i32,
    width: i32,
) -> Option<(usize, usize)> {
    let [a, b, c] = p.conic;
    // Solve a·dx² + 2b·dy·dx + c·dy² ≤ q_max for dx.
    let disc = b * b * dy * dy - a * (c * dy * dy - q_max);
    if disc.is_nan() || disc < 0.0 {
        return None;
    }
    let s = disc.sqrt();
    let dx_lo = (-b * dy - s) / a;
    let dx_hi = (-b * dy + s) / a;
    // dx = x − px, so px ∈ [x − dx_hi, x − dx_lo], widened by a pixel for rounding.
    let lo = ((p.xy[0] - dx_hi).floor() as i32 - 1 - x0).max(0);
    let hi = ((p.xy[0] - dx_lo).ceil() as i32 + 1 - x0).min(width - 1);
    (lo <= hi).then_some((lo as usize, hi as usize))
}

/// The bound on the conic's quadratic form beyond which alpha < 1/255: o·e^(−q/2) ≥ 1/255
/// ⇔ q ≤ 2·ln(255·o); with a small relative margin so float rounding never drops a pixel.
#[inline]
pub(crate) fn quad_bound(opacity: f32) -> f32 {
    2.0 * (255.0 * opacity).ln() * 1.001 + 1e-3
}

/// Tile-local row range (inclusive) a splat can reach with alpha ≥ 1/255, or `None`.
#[inline]
pub(crate) fn row_range(p: &Projected, q_max: f32, y0: i32, height: i32) -> Option<(usize, usize)> {
    let [a, b, c] = p.conic;
    // max over dx of −q at fixed dy is −dy²·(ac − b²)/a, so rows need dy² ≤ q_max·a/(ac − b²).
    let det = a * c - b * b;
    let dy_max = (q_max * a / det).sqrt();
    if !dy_max.is_finite() {
        return Some((0, (height - 1) as usize));
    }
    let lo = ((p.xy[1] - dy_max).floor() as i32 - 1 - y0).max(0);
    let hi = ((p.xy[1] + dy_max).ceil() as i32 + 1 - y0).min(height - 1);
    (lo <= hi).then_some((lo as usize, hi as usize))
}
