//! Tile geometry: the 16×16 tiles a view is drawn in, each tile row's two half-rows of 8
//! pixels (the tile walks' SIMD vectors, named by [`HalfRowId`]), and the offsets both walks
//! take from them.

/// Side of a square tile in pixels (Inria's `BLOCK_X = BLOCK_Y = 16`).
pub const TILE_SIZE: u32 = 16;
/// Pixels per tile.
pub(crate) const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;

/// Pixels per inner loop: half a tile row, seen through fixed-size lane views (no per-lane
/// bounds checks); the lane bodies are branch-free (masks, no early exits) so they map one to
/// one onto SIMD lanes.
pub(crate) const LANES: usize = TILE_SIZE as usize / 2;

/// Half-rows per tile: bit `2·row + half` of a half-row mask (as
/// [`RowSpans::mask`](crate::spans::RowSpans::mask)) stands for the 8 pixels
/// `row·16 + half·8 ..+ 8` of the tile-major per-tile buffers.
pub(crate) const HALF_ROWS: usize = 2 * TILE_SIZE as usize;

/// One of a tile's `HALF_ROWS` half-rows (bit 2·row + half of a half-row mask), below
/// `HALF_ROWS` by construction: the walks' views of a half-row in their per-pixel buffers then
/// need no bounds check (a compare and a branch in every half-row of three loops).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct HalfRowId(u8);

impl HalfRowId {
    /// The half-row of `mask`'s lowest set bit (of a zero mask, half-row 0).
    #[inline(always)]
    pub(crate) fn lowest(mask: u32) -> Self {
        Self((mask.trailing_zeros() % HALF_ROWS as u32) as u8)
    }

    /// Its bit in a half-row mask: 2·row + half.
    #[inline(always)]
    pub(crate) fn index(self) -> usize {
        usize::from(self.0)
    }

    /// Its row in the tile (reduced modulo the tile's rows, which it is below already, so that
    /// indexing a row array needs no check).
    #[inline(always)]
    pub(crate) fn row(self) -> usize {
        usize::from(self.0 >> 1) % TILE_SIZE as usize
    }

    /// 0 for the tile's left half, 1 for its right.
    #[inline(always)]
    pub(crate) fn half(self) -> usize {
        usize::from(self.0 & 1)
    }

    /// Its `LANES` pixels in a tile's per-pixel buffer.
    #[inline(always)]
    pub(crate) fn lanes<T>(self, buf: &mut [T; TILE_PIXELS]) -> &mut [T; LANES] {
        let base = self.index() * LANES;
        debug_assert!(base + LANES <= TILE_PIXELS);
        // SAFETY: the index is below HALF_ROWS (every constructor reduces it modulo
        // HALF_ROWS), so base + LANES ≤ HALF_ROWS·LANES = TILE_PIXELS: the LANES elements from
        // base lie in `buf`, and [T; LANES] has T's alignment.
        #[allow(unsafe_code)]
        unsafe {
            &mut *buf.as_mut_ptr().add(base).cast::<[T; LANES]>()
        }
    }
}

/// The (pixel, splat) pairs a falloff over the half-rows of `todo` evaluates in a tile `tw`
/// pixels wide: each half-row's real columns (`RenderStats::pixel_evaluations`), counted once
/// an entry from its mask instead of lane by lane.
#[inline(always)]
pub(crate) fn evaluated_pixels(todo: u32, tw: i32) -> u64 {
    const LEFT: u32 = 0x5555_5555;
    let lanes = LANES as i32;
    let left = u64::from((todo & LEFT).count_ones()) * tw.clamp(0, lanes) as u64;
    let right = u64::from((todo & !LEFT).count_ones()) * (tw - lanes).clamp(0, lanes) as u64;
    left + right
}

/// The tile-local x of half-row `hr`'s first pixel, 0 or `LANES`, as a float: through `i32`,
/// since a `usize` converts to a float in about nine instructions, once a half-row in both
/// tile walks.
#[inline(always)]
pub(crate) fn half_row_x(hr: usize) -> f32 {
    ((hr & 1) as i32 * LANES as i32) as f32
}

/// Splat centre `centre_x` minus the first pixel of half-row `hr` in the tile whose first
/// column is `x0`: lane `l`'s dx is this minus `l`, in the falloff and the backward's moments.
#[inline(always)]
pub(crate) fn half_row_dx(centre_x: f32, x0: i32, hr: usize) -> f32 {
    centre_x - (x0 as f32 + half_row_x(hr))
}

#[cfg(test)]
mod tests {
    use super::{HalfRowId, LANES, TILE_PIXELS};

    /// A half-row's id from each bit of a mask (and from an empty one), its row and half, and
    /// its view of a per-pixel buffer: the same elements as the checked slice.
    #[test]
    fn half_row_ids_view_their_own_pixels() {
        let mut buf: [u32; TILE_PIXELS] = std::array::from_fn(|i| i as u32);
        for bit in 0..32_u32 {
            let hr = HalfRowId::lowest((1 << bit) | (1 << 31));
            assert_eq!(hr.index(), bit as usize);
            assert_eq!(
                (hr.row(), hr.half()),
                ((bit / 2) as usize, (bit % 2) as usize)
            );
            let want: [u32; LANES] = std::array::from_fn(|l| bit * LANES as u32 + l as u32);
            assert_eq!(*hr.lanes(&mut buf), want);
        }
        assert_eq!(HalfRowId::lowest(0).index(), 0);
    }
}
