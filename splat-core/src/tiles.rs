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

/// Half-rows per tile: bit `2·row + half` of a [`RowSpans::mask`] stands for the 8 pixels
/// `row·16 + half·8 ..+ 8` of the tile-major per-tile buffers.
pub(crate) const HALF_ROWS: usize = 2 * TILE_SIZE as usize;

/// Where one splat can reach alpha ≥ 1/255 in one tile, for all 16 rows at once: each row's
/// x range (tile local, inclusive, as floats) and the half-rows that range touches.
///
/// Pixels outside a span have o·G < 1/255 and would fail the per-pixel test anyway, so spans
/// only save work: the images and gradients are those of the per-pixel tests alone. The 16 rows
/// are solved in one pass of fixed-length loops that LLVM turns into two 8-lane vector steps
/// (square root and division included) in the AVX2 instantiations, instead of a scalar square
/// root and two divisions per row with a branch on each.
pub(crate) struct RowSpans {
    /// Tile-local first pixel of each row's span (≥ 0).
    pub lo: [f32; TILE_SIZE as usize],
    /// Tile-local last pixel of each row's span (≤ tile width − 1); below `lo` when empty.
    pub hi: [f32; TILE_SIZE as usize],
    /// Splat centre minus pixel-row centre, per row.
    pub dy: [f32; TILE_SIZE as usize],
    /// Bit `2·row + half` set when that half-row has pixels in the span.
    pub mask: u32,
}

impl RowSpans {
    /// Solves the spans of splat `p` in the tile at pixel origin (`x0`, `y0`) of `tw` × `th`
    /// real pixels.
    #[inline(always)]
    pub fn new(p: &Projected, x0: i32, y0: i32, tw: i32, th: i32) -> Self {
        const N: usize = TILE_SIZE as usize;
        let [a, b, c] = p.conic;
        let q_max = p.q_max;
        let (x0f, y0f) = (x0 as f32, y0 as f32);
        let last_x = (tw - 1) as f32;
        let mut lo = [0.0_f32; N];
        let mut hi = [0.0_f32; N];
        let mut dy = [0.0_f32; N];
        for r in 0..N {
            let d = p.xy[1] - (y0f + r as f32);
            // Solve a·dx² + 2b·dy·dx + c·dy² ≤ q_max for dx (a > 0 for any projected splat).
            let disc = b * b * d * d - a * (c * d * d - q_max);
            let root = disc.max(0.0).sqrt();
            let dx_lo = (-b * d - root) / a;
            let dx_hi = (-b * d + root) / a;
            // dx = x − px, so x ∈ [px − dx_hi, px − dx_lo], widened by a pixel for rounding.
            let l = ((p.xy[0] - dx_hi).floor() - 1.0 - x0f).max(0.0);
            let h = ((p.xy[0] - dx_lo).ceil() + 1.0 - x0f).min(last_x);
            // A row without real solutions (or past the tile's real rows) gets an empty span.
            let empty = disc.is_nan() | (disc < 0.0) | (r as i32 >= th);
            lo[r] = l;
            hi[r] = if empty { -1.0 } else { h };
            dy[r] = d;
        }
        let half = (LANES_F32) - 1.0;
        let mut mask = 0_u32;
        for r in 0..N {
            let first = u32::from((lo[r] <= hi[r]) & (lo[r] <= half));
            let second = u32::from((lo[r] <= hi[r]) & (hi[r] > half));
            mask |= (first | (second << 1)) << (2 * r);
        }
        Self { lo, hi, dy, mask }
    }
}

/// Pixels in a half-row, as a float.
const LANES_F32: f32 = (TILE_SIZE / 2) as f32;

/// The bound on the conic's quadratic form beyond which alpha < 1/255: o·e^(−q/2) ≥ 1/255
/// ⇔ q ≤ 2·ln(255·o); with a small relative margin so float rounding never drops a pixel.
#[inline]
pub(crate) fn quad_bound(opacity: f32) -> f32 {
    2.0 * (255.0 * opacity).ln() * 1.001 + 1e-3
}
