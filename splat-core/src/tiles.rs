//! Tile geometry and binning: every visible splat is listed in each 16×16 tile its 3σ square
//! touches within the box of its alpha ≥ 1/255 ellipse (`project::within_reach`), each tile's
//! list front to back; and, per (tile, splat) pair, the row spans and the
//! Gaussian falloff that both tile loops (forward and backward) work from.
//!
//! This is Inria's single sort of (tile, depth) keys done as the two passes of an LSD radix sort:
//! one sort of the visible splats by (depth, index), then a stable counting sort by tile. The
//! index in the key makes the order total, so binning is identical for any thread count.

use rayon::prelude::*;

use crate::disjoint::DisjointWrites;
use crate::projected::Projected;
use crate::splats::ROUND_TO_INTEGER;

/// Side of a square tile in pixels (Inria's `BLOCK_X = BLOCK_Y = 16`).
pub const TILE_SIZE: u32 = 16;
/// Pixels per tile.
pub(crate) const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;

/// Slices of the depth-sorted splats that bin in parallel (a constant, so the split does not
/// depend on the thread count; the output would not either).
const BIN_SLICES: usize = 16;

/// Splats per block while the visible splats' keys are gathered: a few hundred blocks at a
/// paper-scale frame's 250k splats, enough to balance 16 threads.
const KEY_BLOCK: usize = 1024;

/// Reusable binning buffers.
#[derive(Debug, Default)]
pub(crate) struct Bins {
    /// Visible splats as (depth bits ≪ 32 | index), sorted.
    order: Vec<u64>,
    /// Visible splats per block of `KEY_BLOCK` splats, while `order` is filled.
    block_counts: Vec<usize>,
    /// The radix sort's other buffer and its per-(slice, digit) counts.
    sort_scratch: Vec<u64>,
    digit_counts: Vec<usize>,
    /// Start of each tile's list in `list`; `offsets[t + 1] − offsets[t]` is its length.
    pub offsets: Vec<usize>,
    /// The tile rectangle of each splat of `order`, in that order, so that the counting and
    /// scattering passes read them forwards (through `order` they are scattered over memory).
    sorted_rects: Vec<[u32; 4]>,
    /// Per (slice of `order`, tile): pair count, then the next write position.
    slice_counts: Vec<usize>,
    /// Per slice, the rectangles' corner grid the counts are summed from.
    corner_counts: Vec<isize>,
    /// Per tile, the start of the next slice's run while the runs are laid out.
    run_starts: Vec<usize>,
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
        self.collect_visible(proj, visible);
        sort_by_depth(
            &mut self.order,
            &mut self.sort_scratch,
            &mut self.digit_counts,
        );
        self.sorted_rects.clear();
        self.sorted_rects.par_extend(
            self.order
                .par_iter()
                .map(|&key| rects[(key & 0xffff_ffff) as usize]),
        );

        // The counting sort runs in parallel over a fixed number of slices of `order`: each
        // slice counts its pairs per tile, every (tile, slice) gets the next run of its tile's
        // list, and each slice fills its runs in its own (depth) order. The result is the one
        // stable order, whatever the thread count.
        let slice_len = self.order.len().div_ceil(BIN_SLICES).max(1);
        let n_slices = self.order.len().div_ceil(slice_len);
        self.slice_counts.clear();
        self.slice_counts.resize(n_slices * n_tiles, 0);
        // Each rectangle counted through its four corners in a (tiles_x + 1) × (tiles_y + 1)
        // difference grid, then the grid's running sums: four branch-free updates a splat
        // instead of a loop over its tiles (whose short, varying trip counts mispredicted).
        let (gx, gy) = (tiles_x as usize + 1, tiles_y as usize + 1);
        self.corner_counts.clear();
        self.corner_counts.resize(n_slices * gx * gy, 0);
        self.sorted_rects
            .par_chunks(slice_len)
            .zip(self.slice_counts.par_chunks_mut(n_tiles))
            .zip(self.corner_counts.par_chunks_mut(gx * gy))
            .for_each(|((slice_rects, counts), grid)| {
                for &[x0, x1, y0, y1] in slice_rects {
                    let (x0, x1) = (x0 as usize, x1 as usize);
                    let (r0, r1) = (y0 as usize * gx, y1 as usize * gx);
                    grid[r0 + x0] += 1;
                    grid[r0 + x1] -= 1;
                    grid[r1 + x0] -= 1;
                    grid[r1 + x1] += 1;
                }
                // Running sums along each row, then down each column, give each tile's count.
                for row in grid.chunks_mut(gx) {
                    let mut run = 0;
                    for c in row {
                        run += *c;
                        *c = run;
                    }
                }
                for ty in 1..gy {
                    let (above, here) = grid.split_at_mut(ty * gx);
                    for (c, a) in here[..gx].iter_mut().zip(&above[(ty - 1) * gx..]) {
                        *c += *a;
                    }
                }
                for (ty, counts_row) in counts.chunks_mut(tiles_x as usize).enumerate() {
                    for (c, &g) in counts_row.iter_mut().zip(&grid[ty * gx..]) {
                        *c = g as usize;
                    }
                }
            });
        // Turn the counts into each (tile, slice) run's start, tile-major then slice order:
        // each tile's total, the tiles' starts, then each slice's start within its tile. Every
        // pass runs along one slice's counts (tile by tile down the slices, the loop read 16
        // strided cache lines a tile).
        self.offsets.clear();
        self.offsets.resize(n_tiles + 1, 0);
        for counts in self.slice_counts.chunks(n_tiles) {
            for (total, &c) in self.offsets.iter_mut().zip(counts) {
                *total += c;
            }
        }
        let mut next = 0;
        for o in &mut self.offsets {
            let n = *o;
            *o = next;
            next += n;
        }
        // `offsets` now holds each tile's start (the extra last entry, with no count, the end).
        self.run_starts.clear();
        self.run_starts.extend_from_slice(&self.offsets[..n_tiles]);
        for counts in self.slice_counts.chunks_mut(n_tiles) {
            for (start, c) in self.run_starts.iter_mut().zip(counts) {
                let n = *c;
                *c = *start;
                *start += n;
            }
        }
        // Not cleared: the scatter below writes every position.
        self.list.resize(next, 0);
        let list = DisjointWrites::new(&mut self.list);
        self.order
            .par_chunks(slice_len)
            .zip(self.sorted_rects.par_chunks(slice_len))
            .zip(self.slice_counts.par_chunks_mut(n_tiles))
            .for_each(|((keys, slice_rects), cursor)| {
                for (&key, &[x0, x1, y0, y1]) in keys.iter().zip(slice_rects) {
                    let i = (key & 0xffff_ffff) as u32;
                    for ty in y0..y1 {
                        let row = (ty * tiles_x) as usize;
                        for c in &mut cursor[row + x0 as usize..row + x1 as usize] {
                            // SAFETY: slice `sl` writes only its own runs
                            // [start(t, sl), start(t, sl) + count(t, sl)), which are disjoint
                            // from every other (tile, slice) run.
                            #[allow(unsafe_code)]
                            unsafe {
                                list.write(*c, i);
                            }
                            *c += 1;
                        }
                    }
                }
            });
    }

    /// Fills `order` with the visible splats' keys (depth bits ≪ 32 | index) in index order:
    /// each block of `KEY_BLOCK` splats counts its visible ones, then writes its keys to its own
    /// run. (A parallel filter-and-collect appended its pieces one after another, and on 16
    /// threads took a third of the bin's time.)
    fn collect_visible(&mut self, proj: &[Projected], visible: &[bool]) {
        self.block_counts.clear();
        self.block_counts.par_extend(
            visible
                .par_chunks(KEY_BLOCK)
                .map(|v| v.iter().filter(|&&v| v).count()),
        );
        self.order.clear();
        self.order.resize(self.block_counts.iter().sum(), 0);
        let mut runs = Vec::with_capacity(self.block_counts.len());
        let mut rest = self.order.as_mut_slice();
        for &count in &self.block_counts {
            let (run, tail) = rest.split_at_mut(count);
            runs.push(run);
            rest = tail;
        }
        runs.into_par_iter()
            .zip(
                proj.par_chunks(KEY_BLOCK)
                    .zip(visible.par_chunks(KEY_BLOCK)),
            )
            .enumerate()
            .for_each(|(block, (run, (proj, visible)))| {
                let first = block * KEY_BLOCK;
                let keys = (proj.iter().zip(visible).enumerate())
                    .filter(|(_, (_, v))| **v)
                    // Depths are > 0 (near-plane culled), so their IEEE bits sort like the
                    // values.
                    .map(|(i, (p, _))| (u64::from(p.depth.to_bits()) << 32) | (first + i) as u64);
                for (slot, key) in run.iter_mut().zip(keys) {
                    *slot = key;
                }
            });
    }

    /// Adds each (tile, splat) pair's record `per_pair[p]` (in `list` order) to its splat's
    /// `per_splat` entry with `add`, splat by splat in tile order: the same order for any
    /// number of threads, so floating-point sums come out bit-identical.
    ///
    /// Each task owns a range of splats and scans the whole list for their entries, testing
    /// a block of entries at once (vector compares into a bit mask where the CPU has AVX2) so
    /// that the scans, which every task repeats, stay cheap as the tasks multiply.
    pub fn reduce_per_splat<T: Send, R: Sync>(
        &self,
        per_splat: &mut [T],
        per_pair: &[R],
        add: impl Fn(&mut T, &R) + Sync,
        avx2: bool,
    ) {
        debug_assert_eq!(per_pair.len(), self.list.len());
        let tasks = rayon::current_num_threads().max(1);
        let per_task = per_splat.len().div_ceil(tasks).max(1);
        per_splat
            .par_chunks_mut(per_task)
            .enumerate()
            .for_each(|(task, owned)| {
                let first = task * per_task;
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports
                    // the enabled features.
                    #[allow(unsafe_code)]
                    return unsafe { add_owned_avx2(&self.list, per_pair, owned, first, &add) };
                }
                let _ = avx2;
                add_owned(
                    &self.list,
                    per_pair,
                    owned,
                    first,
                    &add,
                    |ids, first, count| owned_bits(ids, first, count),
                );
            });
    }

    /// Returns the number of (tile, splat) pairs.
    pub fn pairs(&self) -> usize {
        self.list.len()
    }
}

/// List entries per block of a scan in [`add_owned`]: one bit each in a `u64` mask.
const SCAN_BLOCK: usize = 64;

/// One task of `Bins::reduce_per_splat`: adds the records of the entries of `list` whose splat
/// is in `owned` (splats `first..first + owned.len()`), in list order. `block_mask` gives the
/// bits of a block's entries that are owned ([`owned_bits`] or a vector form of it).
///
/// Every task scans the whole list, so the scan is what grows with the thread count: with a
/// scalar scan (about 2 ns an entry), 16 tasks' scans of a paper-scale view's 0.6M pairs cost
/// more than all their adds together.
#[inline(always)]
fn add_owned<T, R>(
    list: &[u32],
    per_pair: &[R],
    owned: &mut [T],
    first: usize,
    add: &impl Fn(&mut T, &R),
    block_mask: impl Fn(&[u32; SCAN_BLOCK], u32, u32) -> u64,
) {
    // Splat indices are u32 (the list's type), so both bounds fit.
    let (first, count) = (first as u32, owned.len() as u32);
    // A function, not a closure: as a closure it was left out of line, compiled without the
    // AVX2 of `add_owned_avx2`.
    #[inline(always)]
    fn add_block<T, R>(
        mut mask: u64,
        ids: &[u32],
        records: &[R],
        owned: &mut [T],
        first: u32,
        add: &impl Fn(&mut T, &R),
    ) {
        while mask != 0 {
            let k = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            add(&mut owned[(ids[k] - first) as usize], &records[k]);
        }
    }
    let blocks = list.chunks_exact(SCAN_BLOCK);
    let (tail, tail_records) = (
        blocks.remainder(),
        &per_pair[list.len() - blocks.remainder().len()..],
    );
    for (ids, records) in blocks.zip(per_pair.chunks_exact(SCAN_BLOCK)) {
        let ids: &[u32; SCAN_BLOCK] = ids
            .try_into()
            .unwrap_or_else(|_| unreachable!("exact chunks"));
        add_block(
            block_mask(ids, first, count),
            ids,
            records,
            owned,
            first,
            add,
        );
    }
    add_block(
        owned_bits(tail, first, count),
        tail,
        tail_records,
        owned,
        first,
        add,
    );
}

/// Bit k set when `ids[k]` is in `first..first + count` (`ids` at most 64 entries long).
#[inline(always)]
fn owned_bits(ids: &[u32], first: u32, count: u32) -> u64 {
    let mut mask = 0_u64;
    for (k, &sid) in ids.iter().enumerate() {
        mask |= u64::from(sid.wrapping_sub(first) < count) << k;
    }
    mask
}

/// [`add_owned`] compiled with AVX2, its blocks' masks taken eight entries an instruction.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_owned_avx2<T, R>(
    list: &[u32],
    per_pair: &[R],
    owned: &mut [T],
    first: usize,
    add: &impl Fn(&mut T, &R),
) {
    add_owned(list, per_pair, owned, first, add, |ids, first, count| {
        owned_bits_avx2(ids, first, count)
    });
}

/// [`owned_bits`] of a whole block in AVX2: per 8 entries a subtraction, an unsigned range test
/// (min(sid − first, count − 1) = sid − first) and a movemask. Written with intrinsics because
/// LLVM compiles the scalar form's bit packing lane by lane.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn owned_bits_avx2(ids: &[u32; SCAN_BLOCK], first: u32, count: u32) -> u64 {
    use std::arch::x86_64::{
        _mm256_castsi256_ps, _mm256_cmpeq_epi32, _mm256_loadu_si256, _mm256_min_epu32,
        _mm256_movemask_ps, _mm256_set1_epi32, _mm256_sub_epi32,
    };
    debug_assert!(count > 0, "a task owns at least one splat");
    // The lanes hold the u32 bits; the intrinsics take them as i32.
    let first = _mm256_set1_epi32(first.cast_signed());
    let last = _mm256_set1_epi32(count.wrapping_sub(1).cast_signed());
    let mut mask = 0_u64;
    for (j, lanes) in ids.chunks_exact(8).enumerate() {
        // SAFETY: `lanes` is 8 u32s, the 32 bytes an unaligned 256-bit load reads.
        #[allow(unsafe_code)]
        let v = unsafe { _mm256_loadu_si256(lanes.as_ptr().cast()) };
        let offset = _mm256_sub_epi32(v, first);
        let inside = _mm256_cmpeq_epi32(_mm256_min_epu32(offset, last), offset);
        let bits = _mm256_movemask_ps(_mm256_castsi256_ps(inside)).cast_unsigned();
        mask |= u64::from(bits) << (8 * j);
    }
    mask
}

/// Pixels per inner loop: half a tile row, seen through fixed-size lane views (no per-lane
/// bounds checks); the lane bodies are branch-free (masks, no early exits) so they map one to
/// one onto SIMD lanes.
pub(crate) const LANES: usize = TILE_SIZE as usize / 2;

/// Half-rows per tile: bit `2·row + half` of a [`RowSpans::mask`] stands for the 8 pixels
/// `row·16 + half·8 ..+ 8` of the tile-major per-tile buffers.
pub(crate) const HALF_ROWS: usize = 2 * TILE_SIZE as usize;

/// How far beyond the exact solution of its row a span reaches, in pixels: room for the
/// rounding of the row's solution and of the tile loops' own falloff (it was one to two
/// pixels, which around the small splats of a paper-scale frame drew many lanes and half-rows
/// that could not pass the alpha test).
/// `spans_hold_every_pixel_the_lane_test_passes` finds 0.1 px too little for splats thousands
/// of pixels long and 0.3 px enough.
const SPAN_MARGIN: f32 = 0.5;

/// Bits of depth each pass of [`sort_by_depth`] sorts by.
const DIGIT_BITS: u32 = 8;
/// Buckets of one pass.
const DIGITS: usize = 1 << DIGIT_BITS;

/// Sorts `keys` (depth bits ≪ 32 | index, made in index order) by depth, equal depths in index
/// order: a stable least-significant-digit radix sort of the 32 depth bits, four passes of one
/// byte, each a parallel counting sort over `BIN_SLICES` fixed slices (so the order does not
/// depend on the thread count, and nothing in it is serial but the 16 × 256 counts' prefix sum).
///
/// Written here rather than taken from a crate: the radix-sort crates sort the whole 64-bit key
/// (eight passes, since the index bits differ), and the parallel ones are not stable, which the
/// tie order by index needs. A comparison sort (rayon's parallel quicksort) took 4.5 ms of the
/// bin's 10 at 250k splats on two threads and scaled worst of its phases.
fn sort_by_depth(keys: &mut Vec<u64>, scratch: &mut Vec<u64>, counts: &mut Vec<usize>) {
    let n = keys.len();
    if n < 2 {
        return;
    }
    let slice_len = n.div_ceil(BIN_SLICES);
    let n_slices = n.div_ceil(slice_len);
    scratch.resize(n, 0);
    for pass in 0..32 / DIGIT_BITS {
        let shift = 32 + pass * DIGIT_BITS;
        let digit = |k: u64| ((k >> shift) as usize) & (DIGITS - 1);
        counts.clear();
        counts.resize(n_slices * DIGITS, 0);
        keys.par_chunks(slice_len)
            .zip(counts.par_chunks_mut(DIGITS))
            .for_each(|(slice, c)| {
                for &k in slice {
                    c[digit(k)] += 1;
                }
            });
        // A pass where every key has the same digit leaves the order as it is.
        if (0..DIGITS).any(|d| (0..n_slices).map(|s| counts[s * DIGITS + d]).sum::<usize>() == n) {
            continue;
        }
        // Each (slice, digit) run starts after the runs of the smaller digits, then after the
        // earlier slices' runs of its digit.
        let mut next = 0;
        for d in 0..DIGITS {
            for s in 0..n_slices {
                let c = &mut counts[s * DIGITS + d];
                let len = *c;
                *c = next;
                next += len;
            }
        }
        let out = DisjointWrites::new(scratch);
        keys.par_chunks(slice_len)
            .zip(counts.par_chunks_mut(DIGITS))
            .for_each(|(slice, cursor)| {
                for &k in slice {
                    let c = &mut cursor[digit(k)];
                    // SAFETY: slice `s` writes only its own runs, one per digit, which are
                    // disjoint from every other (slice, digit) run.
                    #[allow(unsafe_code)]
                    unsafe {
                        out.write(*c, k);
                    }
                    *c += 1;
                }
            });
        std::mem::swap(keys, scratch);
    }
}

/// Where one splat can reach alpha ≥ 1/255 in one tile, for all 16 rows at once: each row's
/// x range (tile local, inclusive, as floats) and the half-rows that range touches.
///
/// Pixels outside a span have o·G < 1/255 and would fail the per-pixel test anyway, so spans
/// only save work: the images and gradients are those of the per-pixel tests alone. The tile
/// walks take whole rows ([`RowSpans::reach`], [`RowSpans::of_rows`]: every real column of the
/// half-rows a splat reaches, no square root); the exact per-row solve (`solve`, 16 rows in two
/// 8-lane vector steps) is the tests' reference for which pixels those half-rows must hold.
pub(crate) struct RowSpans {
    /// Tile-local first pixel of each row's span (≥ 0; 0 for whole rows): the exact solve's,
    /// which only the tests read (the falloff takes every lane of a half-row).
    #[cfg(test)]
    pub lo: [f32; TILE_SIZE as usize],
    /// Tile-local last pixel of each row's span (≤ tile width − 1; 15 for whole rows); below
    /// `lo` when empty.
    #[cfg(test)]
    pub hi: [f32; TILE_SIZE as usize],
    /// Splat centre minus pixel-row centre, per row.
    pub dy: [f32; TILE_SIZE as usize],
    /// [`RowExponent`]'s k₂ and k₃ per row, solved here for all rows at once so the falloff's
    /// half-row loop only loads them.
    pub k2: [f32; TILE_SIZE as usize],
    /// See `k2`.
    pub k3: [f32; TILE_SIZE as usize],
    /// Bit `2·row + half` set when that half-row has pixels in the span.
    pub mask: u32,
}

impl RowSpans {
    /// Solves the spans of splat `p` in the tile at pixel origin (`x0`, `y0`) of `tw` × `th`
    /// real pixels; with `AVX2` the half-row mask is built with AVX2 compares and bit masks
    /// (the same bits), which only callers compiled with AVX2 may ask for. The tests' exact
    /// spans: the walks take [`Self::reach`]'s half-rows and let the alpha test decide lanes.
    #[cfg(test)]
    pub fn solve<const AVX2: bool>(p: &Projected, x0: i32, y0: i32, tw: i32, th: i32) -> Self {
        const N: usize = TILE_SIZE as usize;
        let [a, b, _] = p.conic;
        let q_max = p.q_max;
        let (x0f, y0f) = (x0 as f32, y0 as f32);
        let last_x = (tw - 1) as f32;
        let mut lo = [0.0_f32; N];
        let mut hi = [0.0_f32; N];
        let mut dy = [0.0_f32; N];
        let mut k2 = [0.0_f32; N];
        let mut k3 = [0.0_f32; N];
        let exponent = RowExponent::coefficients(p.conic);
        let det = conic_det(p.conic);
        let a_q = a * q_max;
        // One division a splat and tile, not two per row: the product's extra rounding
        // (relative 2⁻²⁴ of dx) is far inside `SPAN_MARGIN`.
        let inv_a = 1.0 / a;
        for r in 0..N {
            let d = p.xy[1] - (y0f + r as f32);
            // Solve a·dx² + 2b·dy·dx + c·dy² ≤ q_max for dx (a > 0 for any projected splat):
            // the discriminant (over 4) is b²·d² − a·(c·d² − q_max) = a·q_max − d²·(a·c − b²).
            let disc = a_q - d * d * det;
            let root = disc.max(0.0).sqrt();
            let dx_lo = (-b * d - root) * inv_a;
            let dx_hi = (-b * d + root) * inv_a;
            // dx = px − x, so x ∈ [px − dx_hi, px − dx_lo], widened by `SPAN_MARGIN`.
            let l = ((p.xy[0] - dx_hi - SPAN_MARGIN).ceil() - x0f).max(0.0);
            let h = ((p.xy[0] - dx_lo + SPAN_MARGIN).floor() - x0f).min(last_x);
            // A row without real solutions (or past the tile's real rows) gets an empty span.
            let empty = disc.is_nan() | (disc < 0.0) | (r as i32 >= th);
            lo[r] = l;
            hi[r] = if empty { -1.0 } else { h };
            dy[r] = d;
            (k2[r], k3[r]) = exponent.row(d);
        }
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: only the AVX2 instantiations of the tile walks ask for `AVX2`, and they
            // run only where `has_avx2()` found the feature.
            #[allow(unsafe_code)]
            let mask = unsafe { half_row_mask_avx2(&lo, &hi) };
            return Self {
                lo,
                hi,
                dy,
                k2,
                k3,
                mask,
            };
        }
        let mask = half_row_mask(&lo, &hi);
        Self {
            lo,
            hi,
            dy,
            k2,
            k3,
            mask,
        }
    }
}

/// The conic's determinant a·c − b², from the f32 entries in f64 (their products are exact
/// there): for a long thin splat it is far below the rounding of a·c in f32, so b²·d² − a·c·d²
/// came out wrong by more than itself and rows the splat crosses were found empty.
#[inline(always)]
fn conic_det([a, b, c]: [f32; 3]) -> f32 {
    (f64::from(a) * f64::from(c) - f64::from(b) * f64::from(b)) as f32
}

impl RowSpans {
    /// The half-rows of the tile at pixel origin (`x0`, `y0`), `tw` × `th` real pixels, that
    /// splat `p` can reach, with spans over every real column ([`Self::of_rows`]): the tile
    /// walks evaluate every lane of those half-rows and let the alpha test decide, which every
    /// pixel outside the exact spans fails (`spans_hold_every_pixel_the_lane_test_passes`).
    /// A half-row is kept when its pixels, widened by `SPAN_MARGIN`, meet the ellipse
    /// q ≤ q_max (with a relative 2⁻¹⁰ for rounding): the least q along a row is
    /// a·(dx − dx*)² + (det/a)·dy², at the point of the segment nearest the row's vertex
    /// dx* = −b·dy/a, so no square root and no rounding to pixels (the exact spans' solve cost
    /// a quarter of the compositing walk). The determinant is [`conic_det`]'s. With `AVX2` eight rows a vector (the same operations in the same order, so the
    /// same mask), which only callers compiled with AVX2 may ask for.
    #[inline(always)]
    pub fn reach<const AVX2: bool>(p: &Projected, x0: i32, y0: i32, tw: i32, th: i32) -> Self {
        let [a, b, _] = p.conic;
        let det = conic_det(p.conic);
        let inv_a = 1.0 / a;
        let det_a = det * inv_a;
        let bound = p.q_max * (1.0 + 1.0 / 1024.0);
        let x0f = x0 as f32;
        let last_l = 7.min(tw - 1) as f32;
        let last_r = 15.min(tw - 1) as f32;
        let seg = [
            (
                p.xy[0] - (x0f + last_l) - SPAN_MARGIN,
                p.xy[0] - x0f + SPAN_MARGIN,
            ),
            (
                p.xy[0] - (x0f + last_r) - SPAN_MARGIN,
                p.xy[0] - (x0f + 8.0) + SPAN_MARGIN,
            ),
        ];
        // The portable rows: here LLVM vectorises them as well as the intrinsics do (and a
        // little better, by callgrind), unlike in the backward walk.
        let mut spans = Self::of_rows::<false>(p, 0, y0);
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            use std::arch::x86_64::{
                _CMP_LE_OQ, _CMP_LT_OQ, _mm256_add_ps, _mm256_and_ps, _mm256_cmp_ps,
                _mm256_loadu_ps, _mm256_max_ps, _mm256_min_ps, _mm256_movemask_ps, _mm256_mul_ps,
                _mm256_set1_ps, _mm256_setr_ps, _mm256_sub_ps,
            };
            // SAFETY: only the AVX2 instantiations of the tile walks ask for `AVX2`, and they
            // run only where `has_avx2()` found the feature; the loads are rows 0..8 and 8..16
            // of the 16-row `dy`.
            #[allow(unsafe_code)]
            unsafe {
                let lane = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
                let (mut first, mut second) = (0_u32, 0_u32);
                for base in [0_usize, 8] {
                    let d = _mm256_loadu_ps(spans.dy.as_ptr().add(base));
                    let r = _mm256_add_ps(_mm256_set1_ps(base as f32), lane);
                    let real = _mm256_cmp_ps::<_CMP_LT_OQ>(r, _mm256_set1_ps(th as f32));
                    let vertex =
                        _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(-b), d), _mm256_set1_ps(inv_a));
                    let bq = _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(det_a), d), d);
                    let bnd = _mm256_set1_ps(bound);
                    // Each half's least q, as the portable loop's closure (a loop, not a
                    // closure: one LLVM left out of line would run without AVX2).
                    let mut reached = [0_u32; 2];
                    for (h, &(lo, hi)) in seg.iter().enumerate() {
                        let x = _mm256_sub_ps(
                            _mm256_min_ps(
                                _mm256_max_ps(vertex, _mm256_set1_ps(lo)),
                                _mm256_set1_ps(hi),
                            ),
                            vertex,
                        );
                        let q = _mm256_add_ps(
                            _mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(a), x), x),
                            bq,
                        );
                        let kept = _mm256_and_ps(real, _mm256_cmp_ps::<_CMP_LE_OQ>(q, bnd));
                        reached[h] = _mm256_movemask_ps(kept).cast_unsigned();
                    }
                    first |= reached[0] << base;
                    second |= reached[1] << base;
                }
                if tw <= 8 {
                    second = 0;
                }
                spans.mask = spread_bits(first) | (spread_bits(second) << 1);
            }
            return spans;
        }
        let (mut first, mut second) = (0_u32, 0_u32);
        for r in 0..TILE_SIZE as usize {
            let d = spans.dy[r];
            let vertex = -b * d * inv_a;
            let bq = det_a * d * d;
            let q = |(lo, hi): (f32, f32)| {
                let x = vertex.max(lo).min(hi) - vertex;
                a * x * x + bq
            };
            let real = (r as i32) < th;
            first |= u32::from(real & (q(seg[0]) <= bound)) << r;
            second |= u32::from(real & (tw > 8) & (q(seg[1]) <= bound)) << r;
        }
        spans.mask = spread_bits(first) | (spread_bits(second) << 1);
        spans
    }

    /// Spans over every real column of the tile in each row, for the half-rows of `mask` (a
    /// mask [`Self::reach`] gave for the same splat and tile, or the part of it the forward
    /// pass blended the splat into): the lanes outside the exact
    /// spans are evaluated too and fail the alpha test, as every pixel outside them does
    /// (`spans_hold_every_pixel_the_lane_test_passes`), and a lane that fails it passes nothing
    /// on in either walk, so a walk over these spans composites and differentiates exactly what
    /// it would over the exact ones. Each row's dy, k₂ and k₃ are the exact solve's.
    /// With `AVX2` the rows go eight to a vector in intrinsics (the same operations, so the
    /// same bits), which only callers compiled with AVX2 may ask for: in the backward walk
    /// LLVM had built the rows' vectors from shuffles and blends, 72 instructions a pair.
    #[inline(always)]
    pub fn of_rows<const AVX2: bool>(p: &Projected, mask: u32, y0: i32) -> Self {
        const N: usize = TILE_SIZE as usize;
        let exponent = RowExponent::coefficients(p.conic);
        let y0f = y0 as f32;
        let mut dy = [0.0_f32; N];
        let mut k2 = [0.0_f32; N];
        let mut k3 = [0.0_f32; N];
        if cfg!(target_arch = "x86_64") && AVX2 {
            #[cfg(target_arch = "x86_64")]
            use std::arch::x86_64::{
                _mm256_add_ps, _mm256_mul_ps, _mm256_set1_ps, _mm256_setr_ps, _mm256_storeu_ps,
                _mm256_sub_ps,
            };
            // SAFETY: only the AVX2 instantiations of the tile walks ask for `AVX2`, and they
            // run only where `has_avx2()` found the feature; the stores are rows 0..8 and
            // 8..16 of the 16-row arrays.
            #[cfg(target_arch = "x86_64")]
            #[allow(unsafe_code)]
            unsafe {
                let lane = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
                let (yc, k2c, k3c) = (
                    _mm256_set1_ps(p.xy[1]),
                    _mm256_set1_ps(exponent.k2),
                    _mm256_set1_ps(exponent.k3),
                );
                for base in [0_usize, 8] {
                    // y0 + r, then the centre minus it, as the portable loop rounds them.
                    let row_y = _mm256_add_ps(
                        _mm256_set1_ps(y0f),
                        _mm256_add_ps(_mm256_set1_ps(base as f32), lane),
                    );
                    let d = _mm256_sub_ps(yc, row_y);
                    _mm256_storeu_ps(dy.as_mut_ptr().add(base), d);
                    _mm256_storeu_ps(k2.as_mut_ptr().add(base), _mm256_mul_ps(k2c, d));
                    _mm256_storeu_ps(
                        k3.as_mut_ptr().add(base),
                        _mm256_mul_ps(_mm256_mul_ps(k3c, d), d),
                    );
                }
            }
        } else {
            for r in 0..N {
                let d = p.xy[1] - (y0f + r as f32);
                dy[r] = d;
                (k2[r], k3[r]) = exponent.row(d);
            }
        }
        Self {
            #[cfg(test)]
            lo: [0.0; N],
            #[cfg(test)]
            hi: [(N - 1) as f32; N],
            dy,
            k2,
            k3,
            mask,
        }
    }
}

/// Bit `2·row + half` set when that half-row of the tile has pixels in the row's span
/// [`lo`, `hi`] (tile-local pixels).
#[cfg(test)]
fn half_row_mask(lo: &[f32; TILE_SIZE as usize], hi: &[f32; TILE_SIZE as usize]) -> u32 {
    let half = (LANES - 1) as f32;
    let mut mask = 0_u32;
    for r in 0..TILE_SIZE as usize {
        let first = u32::from((lo[r] <= hi[r]) & (lo[r] <= half));
        let second = u32::from((lo[r] <= hi[r]) & (hi[r] > half));
        mask |= (first | (second << 1)) << (2 * r);
    }
    mask
}

/// [`half_row_mask`] from four 8-lane compares and their sign masks, the two 16-bit masks of
/// first and second halves then interleaved. LLVM compiles the loop above into per-row scalar
/// code (about 70 instructions of a span's 150) and does not find this form itself.
#[cfg(all(test, target_arch = "x86_64"))]
#[target_feature(enable = "avx2")]
fn half_row_mask_avx2(lo: &[f32; TILE_SIZE as usize], hi: &[f32; TILE_SIZE as usize]) -> u32 {
    use std::arch::x86_64::{
        _CMP_GT_OQ, _CMP_LE_OQ, _mm256_and_ps, _mm256_cmp_ps, _mm256_loadu_ps, _mm256_movemask_ps,
        _mm256_set1_ps,
    };
    let half = _mm256_set1_ps((LANES - 1) as f32);
    let (mut first, mut second) = (0_u32, 0_u32);
    for j in 0..2 {
        // SAFETY: rows 8·j .. 8·j + 8 of 16-element arrays.
        #[allow(unsafe_code)]
        let (l, h) = unsafe {
            (
                _mm256_loadu_ps(lo.as_ptr().add(8 * j)),
                _mm256_loadu_ps(hi.as_ptr().add(8 * j)),
            )
        };
        let nonempty = _mm256_cmp_ps::<_CMP_LE_OQ>(l, h);
        let f = _mm256_and_ps(nonempty, _mm256_cmp_ps::<_CMP_LE_OQ>(l, half));
        let s = _mm256_and_ps(nonempty, _mm256_cmp_ps::<_CMP_GT_OQ>(h, half));
        first |= _mm256_movemask_ps(f).cast_unsigned() << (8 * j);
        second |= _mm256_movemask_ps(s).cast_unsigned() << (8 * j);
    }
    spread_bits(first) | (spread_bits(second) << 1)
}

/// Moves bit i of the low 16 bits of `x` to bit 2·i.
#[inline(always)]
fn spread_bits(x: u32) -> u32 {
    let mut x = x & 0xffff;
    x = (x | (x << 8)) & 0x00ff_00ff;
    x = (x | (x << 4)) & 0x0f0f_0f0f;
    x = (x | (x << 2)) & 0x3333_3333;
    (x | (x << 1)) & 0x5555_5555
}

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

/// A splat's Gaussian falloff over the half-rows of a tile it is to be drawn in, computed in a
/// pass of its own before the compositing that uses it.
///
/// The falloff (quadratic form, exponential) is the long chain of dependent operations of each
/// half-row; computed in the compositing loop, a half-row's instructions nearly filled the CPU's
/// reorder window, so the core waited on one chain at a time. In a pass of their own the
/// half-rows are short and independent and their chains overlap, and the compositing pass that
/// follows has a short chain per half-row.
pub(crate) struct Falloff {
    /// The half-rows, ascending.
    pub hr: [HalfRowId; HALF_ROWS],
    /// G = 2^t per lane of each half-row ([`RowExponent`]), or 0 where t > 0; about 2⁻¹²⁶
    /// where t is below the least exponent (o·G fails the alpha ≥ 1/255 test there either way).
    pub gauss: [[f32; LANES]; HALF_ROWS],
    /// Number of half-rows filled.
    pub n: usize,
}

impl Falloff {
    /// Returns an empty buffer.
    pub fn new() -> Self {
        Self {
            hr: [HalfRowId::default(); HALF_ROWS],
            gauss: [[0.0; LANES]; HALF_ROWS],
            n: 0,
        }
    }

    /// Fills the buffer with splat `p`'s falloff over the half-rows of `todo` (bits of
    /// `spans.mask`) in the tile whose pixel origin has x = `x0`, all 8 lanes of each (the
    /// walks' alpha test and per-pixel state reject the lanes past a partial tile's last
    /// column: no pixel there is open in the forward or has a contributor in the backward).
    /// With `AVX2` the lanes are written in AVX2 intrinsics (the same IEEE operations in the
    /// same order, so the same bits), which only callers compiled with AVX2 may ask for.
    #[inline(always)]
    pub fn compute<const AVX2: bool>(
        &mut self,
        p: &Projected,
        spans: &RowSpans,
        todo: u32,
        x0: i32,
    ) {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            // SAFETY: only the AVX2 instantiations of the tile walks ask for `AVX2`, and they
            // run only where `has_avx2()` found the feature.
            #[allow(unsafe_code)]
            unsafe {
                self.compute_avx2(p, spans, todo, x0);
            }
            return;
        }
        self.compute_portable(p, spans, todo, x0);
    }

    /// [`Self::compute`] lane by lane.
    #[inline(always)]
    fn compute_portable(&mut self, p: &Projected, spans: &RowSpans, mut todo: u32, x0: i32) {
        let k1 = RowExponent::coefficients(p.conic).k1;
        // A local count: through `self.n` every half-row's stores waited on a reload of it.
        let mut n = 0;
        while todo != 0 {
            let hr = HalfRowId::lowest(todo);
            todo &= todo - 1;
            let ly = hr.row();
            let row = RowExponent {
                k1,
                k2: spans.k2[ly],
                k3: spans.k3[ly],
            };
            let xb = half_row_dx(p.xy[0], x0, hr.index());
            for (l, g) in self.gauss[n].iter_mut().enumerate() {
                let t = row.at(xb - l as f32);
                let gauss = fast_exp2(t);
                *g = if t <= 0.0 { gauss } else { 0.0 };
            }
            self.hr[n] = hr;
            n += 1;
        }
        self.n = n;
    }

    /// [`Self::compute_portable`] in AVX2 intrinsics: written out because LLVM's vectoriser
    /// packed the row's scalar coefficients into lanes with a dozen shuffles and blends a
    /// half-row.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    fn compute_avx2(&mut self, p: &Projected, spans: &RowSpans, mut todo: u32, x0: i32) {
        use std::arch::x86_64::{
            _CMP_LE_OQ, _MM_FROUND_NO_EXC, _MM_FROUND_TO_NEAREST_INT, _mm256_add_epi32,
            _mm256_add_ps, _mm256_and_ps, _mm256_castps_si256, _mm256_castsi256_ps, _mm256_cmp_ps,
            _mm256_max_ps, _mm256_mul_ps, _mm256_round_ps, _mm256_set1_epi32, _mm256_set1_ps,
            _mm256_setr_ps, _mm256_slli_epi32, _mm256_storeu_ps, _mm256_sub_ps,
        };
        let lane = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
        let min_t = _mm256_set1_ps(EXP2_MIN);
        let zero = _mm256_set1_ps(0.0);
        let one = _mm256_set1_ps(1.0);
        let round = _mm256_set1_ps(ROUND_TO_INTEGER);
        let [c3, c2, c1, c0] = EXP2_POLY;
        let [c3, c2, c1, c0] = [
            _mm256_set1_ps(c3),
            _mm256_set1_ps(c2),
            _mm256_set1_ps(c1),
            _mm256_set1_ps(c0),
        ];
        let bias = _mm256_set1_epi32(EXP2_BIAS.cast_signed());
        let k1 = _mm256_set1_ps(RowExponent::coefficients(p.conic).k1);
        // Lane offsets dx and k₁·dx of the tile's left and right half-rows, the same for every
        // row: taken out of the half-row loop, whose exponential is a chain of dependent
        // operations that these would lengthen.
        let u_half = [
            _mm256_sub_ps(_mm256_set1_ps(half_row_dx(p.xy[0], x0, 0)), lane),
            _mm256_sub_ps(_mm256_set1_ps(half_row_dx(p.xy[0], x0, 1)), lane),
        ];
        let k1u_half = [_mm256_mul_ps(k1, u_half[0]), _mm256_mul_ps(k1, u_half[1])];
        let mut n = 0;
        while todo != 0 {
            let hr = HalfRowId::lowest(todo);
            todo &= todo - 1;
            let ly = hr.row();
            let (u, k1u) = (u_half[hr.half()], k1u_half[hr.half()]);
            let t = _mm256_add_ps(
                _mm256_mul_ps(u, _mm256_add_ps(k1u, _mm256_set1_ps(spans.k2[ly]))),
                _mm256_set1_ps(spans.k3[ly]),
            );
            // fast_exp2, lane by lane. The rounding is `vroundps` (to nearest, ties to even, as
            // `fast_exp2`'s addition of 1.5·2²³ does), a step shorter than removing the addend
            // again.
            let t_raw = t;
            let t = _mm256_max_ps(t_raw, min_t);
            let shifted = _mm256_add_ps(t, round);
            let f = _mm256_sub_ps(
                t,
                _mm256_round_ps::<{ _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC }>(t),
            );
            let mut poly = _mm256_add_ps(_mm256_mul_ps(c3, f), c2);
            poly = _mm256_add_ps(_mm256_mul_ps(poly, f), c1);
            poly = _mm256_add_ps(_mm256_mul_ps(poly, f), c0);
            let scale = _mm256_castsi256_ps(_mm256_slli_epi32::<23>(_mm256_add_epi32(
                _mm256_castps_si256(shifted),
                bias,
            )));
            let gauss = _mm256_mul_ps(_mm256_add_ps(one, _mm256_mul_ps(poly, f)), scale);
            // t ≤ 0 (a rounding above 0 could only come of a conic that is not quite positive
            // definite, whose falloff would not fall).
            let keep = _mm256_cmp_ps::<_CMP_LE_OQ>(t_raw, zero);
            debug_assert!(n < HALF_ROWS);
            // SAFETY: `n` < HALF_ROWS, one per set bit of the 32-bit `todo` (so unchecked: the
            // check was a compare and a branch a half-row).
            #[allow(unsafe_code)]
            unsafe {
                _mm256_storeu_ps(
                    self.gauss.get_unchecked_mut(n).as_mut_ptr(),
                    _mm256_and_ps(keep, gauss),
                );
                *self.hr.get_unchecked_mut(n) = hr;
            }
            n += 1;
        }
        self.n = n;
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

/// A splat's Gaussian falloff along one pixel row, as the exponent in base 2: for the conic
/// (a, b, c) and the row's dy = centre − pixel row, log₂e·(−½(a·dx² + c·dy²) − b·dx·dy) at the
/// offset dx = centre − pixel is dx·(k₁·dx + k₂) + k₃, with k₁ = −½·log₂e·a, k₂ = −log₂e·b·dy
/// and k₃ = −½·log₂e·c·dy². Per lane that is two multiplications and two additions, against
/// seven for the symmetric form and the exponential's scaling by log₂e (the tile walks'
/// compositing 7–10 % faster, the backward walk 2–6 %, on the bench torus). The grouping rounds
/// differently from the symmetric form's by an ulp of the terms, which the forward and backward
/// passes share.
#[derive(Clone, Copy)]
pub(crate) struct RowExponent {
    k1: f32,
    k2: f32,
    k3: f32,
}

impl RowExponent {
    /// The row at `dy` of the splat whose conic is `conic`.
    #[cfg(test)]
    pub(crate) fn new(conic: [f32; 3], dy: f32) -> Self {
        let exponent = RowExponent::coefficients(conic);
        let (k2, k3) = exponent.row(dy);
        Self {
            k1: exponent.k1,
            k2,
            k3,
        }
    }

    /// The splat's own factors: k₁, and in place of k₂ and k₃ the factors −log₂e·b and
    /// −½·log₂e·c that [`Self::row`] multiplies by the row's dy.
    #[inline(always)]
    pub(crate) fn coefficients([a, b, c]: [f32; 3]) -> Self {
        use std::f32::consts::LOG2_E;
        Self {
            k1: (-0.5 * LOG2_E) * a,
            k2: -LOG2_E * b,
            k3: (-0.5 * LOG2_E) * c,
        }
    }

    /// k₂ and k₃ of the row at `dy`, from [`Self::coefficients`].
    #[inline(always)]
    pub(crate) fn row(self, dy: f32) -> (f32, f32) {
        (self.k2 * dy, self.k3 * dy * dy)
    }

    /// The exponent at offset `dx`.
    #[inline(always)]
    pub(crate) fn at(self, dx: f32) -> f32 {
        dx * (self.k1 * dx + self.k2) + self.k3
    }
}

/// 2^t for the Gaussian falloff, with a degree-3 polynomial for 2^f (relative error below 3.5e-6
/// for t in [−15, 0], where alphas reach 1/255), written branch-free (no library calls) for the
/// per-lane loops. Inputs below −126 give 2⁻¹²⁶'s value (about 1.2e-38, far below any alpha
/// that passes the 1/255 test): a clamp, one vector operation, where a test and a mask were
/// two.
/// The forward and backward passes both use it, so they see identical alphas.
#[inline(always)]
pub(crate) fn fast_exp2(t: f32) -> f32 {
    let clamped = t.max(EXP2_MIN);
    // Round to nearest by adding and removing 1.5·2²³ (plain adds: `floor` is a library call
    // on the x86-64 baseline).
    let shifted = clamped + ROUND_TO_INTEGER;
    let n = shifted - ROUND_TO_INTEGER;
    let f = clamped - n;
    let [c3, c2, c1, c0] = EXP2_POLY;
    let p = ((c3 * f + c2) * f + c1) * f + c0;
    // 2ⁿ from the bits of `shifted`, whose low mantissa bits hold n (two's complement): a
    // saturating `n as i32` would not vectorise. Exact for the clamped range n ∈ [−126, 128).
    let scale = f32::from_bits(shifted.to_bits().wrapping_add(EXP2_BIAS) << 23);
    (1.0 + p * f) * scale
}

/// The least exponent [`fast_exp2`] builds 2ⁿ for (the least normal f32 is 2⁻¹²⁶).
const EXP2_MIN: f32 = -126.0;
/// 127 − bits(`ROUND_TO_INTEGER`), wrapping: added to the bits of t + `ROUND_TO_INTEGER`, it
/// leaves n + 127 in the bits that become the exponent of 2ⁿ.
const EXP2_BIAS: u32 = 127_u32.wrapping_sub(ROUND_TO_INTEGER.to_bits());
/// 2^f on [−½, ½] as 1 + f·P(f), P of degree 3 (highest term first) fitted for least maximum
/// relative error: 2.9e-6 in f32 arithmetic, two terms shorter than Cephes' degree-5 P at
/// 1.2e-7. An alpha that far off moves a pixel by under 1e-5 of its range, and the term saves
/// a multiply and an add in every half-row of both tile walks (the degree-4 P was 1.9e-7).
/// Its constant term is the fit's, not ln 2.
#[allow(clippy::approx_constant)]
const EXP2_POLY: [f32; 4] = [9.582_83e-3, 5.590_64e-2, 2.402_41e-1, 6.931_242e-1];

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};

    use super::{
        Bins, EXP2_MIN, Falloff, HALF_ROWS, HalfRowId, LANES, RowExponent, RowSpans, SCAN_BLOCK,
        TILE_PIXELS, TILE_SIZE, fast_exp2, half_row_dx, half_row_mask, half_row_x, owned_bits,
    };
    #[cfg(target_arch = "x86_64")]
    use super::{half_row_mask_avx2, owned_bits_avx2};
    use crate::projected::{Projected, footprint, quad_bound, random_footprint};

    /// The spans only skip work if every pixel they leave out has o·G < 1/255: checked in f64
    /// against random rotated, stretched splats around full and partial tiles.
    #[test]
    fn spans_contain_every_pixel_that_can_reach_the_alpha_threshold() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let ts = TILE_SIZE as i32;
        let mut inside = 0;
        for case in 0..20_000 {
            let (_, conic) = random_footprint(&mut rng, 40.0);
            let opacity: f32 = rng.random_range(0.004..1.0);
            let (x0, y0) = (ts * rng.random_range(0..8), ts * rng.random_range(0..8));
            let centre = [
                x0 as f32 + rng.random_range(-60.0..76.0),
                y0 as f32 + rng.random_range(-60.0..76.0),
            ];
            // Every tenth case is a partial tile at the image's right or bottom edge.
            let (tw, th) = if case % 10 == 0 {
                (rng.random_range(1..=ts), rng.random_range(1..=ts))
            } else {
                (ts, ts)
            };
            let p = Projected {
                xy: centre,
                conic: conic.map(|v| v as f32),
                opacity,
                q_max: quad_bound(opacity),
                ..Projected::default()
            };
            let spans = RowSpans::solve::<false>(&p, x0, y0, tw, th);
            let reach = RowSpans::reach::<false>(&p, x0, y0, tw, th).mask;
            for ly in 0..th {
                for lx in 0..tw {
                    let dx = f64::from(p.xy[0]) - f64::from(x0 + lx);
                    let dy = f64::from(p.xy[1]) - f64::from(y0 + ly);
                    let [a, b, cc] = p.conic.map(f64::from);
                    let power = -0.5 * (a * dx * dx + cc * dy * dy) - b * dx * dy;
                    let alpha = f64::from(opacity) * power.exp();
                    if alpha < 1.0 / 255.0 {
                        continue;
                    }
                    inside += 1;
                    let (row, x) = (ly as usize, lx as f32);
                    let half = (lx as usize) / LANES;
                    assert!(
                        spans.lo[row] <= x && x <= spans.hi[row],
                        "case {case}: pixel ({lx}, {ly}) with alpha {alpha} outside the span \
                         [{}, {}]",
                        spans.lo[row],
                        spans.hi[row]
                    );
                    let bit = 2 * row + half;
                    assert!(bit < HALF_ROWS && spans.mask & (1 << bit) != 0);
                    assert!(
                        reach & (1 << bit) != 0,
                        "case {case}: ({lx}, {ly}) not reached"
                    );
                }
            }
        }
        assert!(
            inside > 100_000,
            "the cases must reach many pixels: {inside}"
        );
    }

    /// A splat from a fifth of a pixel to thousands of pixels across (long thin ones at every
    /// angle), of any opacity, and a tile it may reach: centred inside it or far outside, and
    /// every tenth `case` a partial tile at the image's right or bottom edge.
    fn random_splat_and_tile(rng: &mut rand_pcg::Pcg64, case: usize) -> RandomPair {
        let ts = TILE_SIZE as i32;
        let axis = |rng: &mut rand_pcg::Pcg64| 0.2 * 25_000.0_f64.powf(rng.random_range(0.0..1.0));
        let (s1, s2) = (axis(rng), axis(rng));
        let (_, conic64) = footprint([s1, s2], rng.random_range(0.0..std::f64::consts::PI));
        let opacity: f32 = rng.random_range(0.004..1.0);
        let (x0, y0) = (ts * rng.random_range(0..64), ts * rng.random_range(0..64));
        let reach = 3.0 * s1.max(s2) as f32;
        let centre = [
            x0 as f32 + rng.random_range(-reach..reach + 16.0),
            y0 as f32 + rng.random_range(-reach..reach + 16.0),
        ];
        let (tw, th) = if case.is_multiple_of(10) {
            (rng.random_range(1..=ts), rng.random_range(1..=ts))
        } else {
            (ts, ts)
        };
        let p = Projected {
            xy: centre,
            conic: conic64.map(|v| v as f32),
            opacity,
            q_max: quad_bound(opacity),
            ..Projected::default()
        };
        RandomPair {
            p,
            conic64,
            axes: (s1, s2),
            tile: (x0, y0, tw, th),
        }
    }

    /// A splat and a tile from [`random_splat_and_tile`].
    struct RandomPair {
        p: Projected,
        /// The splat's conic in f64, before rounding to the f32 of `p`.
        conic64: [f64; 3],
        /// Its standard deviations, pixels.
        axes: (f64, f64),
        /// The tile's origin and real size (x0, y0, tw, th).
        tile: (i32, i32, i32, i32),
    }

    /// The spans leave out only pixels where the tile loops' own f32 test, o·G ≥ 1/255 with G
    /// from `RowExponent` and `fast_exp2`, fails (or passes on rounding noise alone, below): so
    /// the half-pixel margin the spans keep is enough for the images. Splats from a fifth of a
    /// pixel to thousands of pixels across (long thin ones at every angle), centred inside and
    /// far outside the tile.
    #[test]
    fn spans_hold_every_pixel_the_lane_test_passes() {
        // Also the half-rows of `RowSpans::reach`, which the tile walks take.
        use crate::constants::{MAX_ALPHA, MIN_ALPHA};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(23);
        let mut passed = 0_u64;
        for case in 0..400_000 {
            let RandomPair {
                p,
                conic64,
                axes: (s1, s2),
                tile: (x0, y0, tw, th),
            } = random_splat_and_tile(&mut rng, case);
            let (conic, opacity, centre) = (p.conic, p.opacity, p.xy);
            let spans = RowSpans::solve::<false>(&p, x0, y0, tw, th);
            // The half-rows the walks take: the same from both instantiations.
            let reach = RowSpans::reach::<false>(&p, x0, y0, tw, th).mask;
            #[cfg(target_arch = "x86_64")]
            if crate::has_avx2() {
                assert_eq!(
                    RowSpans::reach::<true>(&p, x0, y0, tw, th).mask,
                    reach,
                    "case {case}"
                );
            }
            for ly in 0..th {
                for lx in 0..tw {
                    // The tile loops' arithmetic: dx from the half-row's origin, dy per row.
                    let first = (lx as usize / LANES * LANES) as f32;
                    let xb = p.xy[0] - (x0 as f32 + first);
                    let dx = xb - (lx as f32 - first);
                    let dy = spans.dy[ly as usize];
                    let power = RowExponent::new(conic, dy).at(dx);
                    let alpha = (opacity * fast_exp2(power)).min(MAX_ALPHA);
                    // Far out along a splat thousands of pixels long, a·dx², c·dy² and b·dx·dy
                    // are large and nearly cancel, and the f32 power is rounding noise (it can
                    // come out 0 where the splat's true alpha is 10⁻⁴); the spans, solved per
                    // row, rightly leave such pixels out. Required: every pixel whose true
                    // alpha clears the threshold by 1 %, and on splats up to 100 px across
                    // (where that noise is far below the margins) every pixel the lane test
                    // passes.
                    let [a64, b64, c64] = conic64;
                    let (dx64, dy64) = (
                        f64::from(centre[0]) - f64::from(x0 + lx),
                        f64::from(centre[1]) - f64::from(y0 + ly),
                    );
                    let q = a64 * dx64 * dx64 + 2.0 * b64 * dx64 * dy64 + c64 * dy64 * dy64;
                    let true_alpha = f64::from(opacity) * (-0.5 * q).exp();
                    let lane_passes = power <= 0.0 && alpha >= MIN_ALPHA;
                    let required =
                        true_alpha >= 1.01 / 255.0 || (lane_passes && s1.max(s2) <= 100.0);
                    if !required {
                        continue;
                    }
                    passed += 1;
                    let (row, x) = (ly as usize, lx as f32);
                    assert!(
                        spans.lo[row] <= x && x <= spans.hi[row],
                        "case {case}: axes {s1:.1} × {s2:.1} px, pixel ({lx}, {ly}) with alpha \
                         {alpha} (true {true_alpha}) outside the span [{}, {}]",
                        spans.lo[row],
                        spans.hi[row]
                    );
                    let bit = 2 * row + lx as usize / LANES;
                    assert!(spans.mask & (1 << bit) != 0);
                    assert!(
                        reach & (1 << bit) != 0,
                        "case {case}: axes {s1:.1} × {s2:.1} px, pixel ({lx}, {ly}) with alpha \
                         {alpha} (true {true_alpha}) in a half-row `reach` leaves out"
                    );
                }
            }
        }
        assert!(
            passed > 500_000,
            "the cases must reach many pixels: {passed}"
        );
    }

    /// `n` splats to bin: depths from `depth`, random tile rectangles (some reaching the
    /// grid's edges), three in four visible.
    fn random_splats_to_bin(
        rng: &mut rand_pcg::Pcg64,
        n: usize,
        [tiles_x, tiles_y]: [u32; 2],
        depth: impl Fn(&mut rand_pcg::Pcg64) -> f32,
    ) -> (Vec<Projected>, Vec<[u32; 4]>, Vec<bool>) {
        let mut proj = vec![Projected::default(); n];
        let mut rects = vec![[0_u32; 4]; n];
        let mut visible = vec![false; n];
        for i in 0..n {
            proj[i].depth = depth(rng);
            let (x0, y0) = (rng.random_range(0..tiles_x), rng.random_range(0..tiles_y));
            rects[i] = [
                x0,
                rng.random_range(x0..=tiles_x),
                y0,
                rng.random_range(y0..=tiles_y),
            ];
            visible[i] = rng.random_range(0..4) != 0;
        }
        (proj, rects, visible)
    }

    /// The per-splat reduction must add each splat's records in list order, as a plain serial
    /// scan of the list does, bit for bit and for any number of threads; hidden splats (whose
    /// stale rectangles must not be listed) get nothing.
    #[test]
    fn per_splat_sums_follow_the_list_order_for_any_thread_count() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let (tiles_x, tiles_y) = (9_u32, 7_u32);
        let n = 3_000;
        let (proj, rects, visible) = random_splats_to_bin(&mut rng, n, [tiles_x, tiles_y], |rng| {
            rng.random_range(0.5..9.0)
        });
        let mut bins = Bins::default();
        bins.build(&proj, &rects, &visible, tiles_x, tiles_y);
        assert!(
            bins.pairs() > 3 * n,
            "rectangles must overlap: {}",
            bins.pairs()
        );
        // Values of mixed magnitudes, so that another order of the adds would round otherwise.
        let records: Vec<f32> = (0..bins.pairs())
            .map(|_| rng.random_range(-1.0_f32..1.0) * 10f32.powi(rng.random_range(-4..4)))
            .collect();
        let mut expected = vec![0.0_f32; n];
        let mut entries = vec![Vec::new(); n];
        for (p, &sid) in bins.list.iter().enumerate() {
            expected[sid as usize] += records[p];
            entries[sid as usize].push(p);
        }
        for threads in [1, 3, 7, 16] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for avx2 in [false, crate::has_avx2()] {
                let mut sums = vec![0.0_f32; n];
                pool.install(|| bins.reduce_per_splat(&mut sums, &records, |s, r| *s += r, avx2));
                for i in 0..n {
                    assert_eq!(
                        sums[i].to_bits(),
                        expected[i].to_bits(),
                        "splat {i}, {threads} threads, AVX2 {avx2}"
                    );
                }
            }
            // Which records reach a splat, and in which order: exactly its own, in list order.
            let positions: Vec<usize> = (0..bins.pairs()).collect();
            for avx2 in [false, crate::has_avx2()] {
                let mut seen = vec![Vec::new(); n];
                pool.install(|| {
                    bins.reduce_per_splat(&mut seen, &positions, |s, &p| s.push(p), avx2);
                });
                assert_eq!(seen, entries, "{threads} threads, AVX2 {avx2}");
            }
        }
        for i in (0..n).filter(|&i| !visible[i]) {
            assert!(entries[i].is_empty(), "hidden splat {i} is listed");
        }
    }

    /// The AVX2 block mask must be the scalar one: ranges at either end of the u32 indices,
    /// one splat wide and all of them wide, ids below, inside and above.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn vector_and_scalar_block_masks_agree() {
        if !crate::has_avx2() {
            return;
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let ranges = [
            (0, 1),
            (0, u32::MAX),
            (5, 3),
            (u32::MAX - 1, 1),
            (1 << 31, 1 << 30),
        ];
        for (first, count) in ranges {
            for _ in 0..200 {
                let ids: [u32; SCAN_BLOCK] =
                    std::array::from_fn(|_| match rng.random_range(0..4) {
                        0 => first.wrapping_add(rng.random_range(0..count.min(4))),
                        1 => first.wrapping_sub(rng.random_range(1..3)),
                        2 => first
                            .wrapping_add(count)
                            .wrapping_add(rng.random_range(0..2)),
                        _ => rng.random(),
                    });
                // SAFETY: the CPU has AVX2 (checked above).
                #[allow(unsafe_code)]
                let vector = unsafe { owned_bits_avx2(&ids, first, count) };
                assert_eq!(
                    vector,
                    owned_bits(&ids, first, count),
                    "first {first}, count {count}"
                );
            }
        }
    }

    /// The AVX2 half-row mask must be the loop's: spans empty (`hi` below `lo`, `hi` = −1),
    /// within either half, across the middle, touching lanes 7 and 8, NaN bounds.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn vector_and_scalar_half_row_masks_agree() {
        if !crate::has_avx2() {
            return;
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(12);
        const N: usize = TILE_SIZE as usize;
        let bound = |rng: &mut rand_pcg::Pcg64| match rng.random_range(0..8) {
            0 => f32::NAN,
            1 => -1.0,
            2 => 7.0,
            3 => 8.0,
            _ => rng.random_range(-2..18) as f32,
        };
        let mut seen = std::collections::HashSet::new();
        for _ in 0..20_000 {
            let lo: [f32; N] = std::array::from_fn(|_| bound(&mut rng));
            let hi: [f32; N] = std::array::from_fn(|_| bound(&mut rng));
            let scalar = half_row_mask(&lo, &hi);
            // SAFETY: the CPU has AVX2 (checked above).
            #[allow(unsafe_code)]
            let vector = unsafe { half_row_mask_avx2(&lo, &hi) };
            assert_eq!(vector, scalar, "lo {lo:?}, hi {hi:?}");
            for r in 0..N {
                seen.insert((scalar >> (2 * r)) & 3);
            }
        }
        // Every row state occurs: empty, first half, second half, both.
        assert_eq!(seen.len(), 4);
    }

    /// The AVX2 falloff must store the portable one's bits: it takes the lane offsets, k₁·dx
    /// and the span's columns per tile half, rounds with `vroundps` and leaves lanes below the
    /// least exponent (no clamp there) to its keep mask. Splats from a fraction of a pixel to
    /// thousands of pixels across, at every angle, centred inside and far outside partial and
    /// whole tiles, over random subsets of their half-rows. The cases must include lanes kept
    /// and lanes below the least exponent (far outside the splat, where the unclamped
    /// arithmetic gives no valid 2ⁿ and only the mask may decide what is stored).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn vector_and_scalar_falloffs_agree() {
        if !crate::has_avx2() {
            return;
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(31);
        let (mut below_least, mut kept) = (0_u64, 0_u64);
        for case in 0..200_000 {
            let RandomPair {
                p,
                tile: (x0, y0, tw, th),
                ..
            } = random_splat_and_tile(&mut rng, case);
            let conic = p.conic;
            let spans = RowSpans::solve::<false>(&p, x0, y0, tw, th);
            let todo = if case.is_multiple_of(2) {
                spans.mask
            } else {
                spans.mask & rng.random::<u32>()
            };
            let (mut scalar, mut vector) = (Falloff::new(), Falloff::new());
            scalar.compute::<false>(&p, &spans, todo, x0);
            vector.compute::<true>(&p, &spans, todo, x0);
            // The evaluation count from the mask: each half-row's real columns.
            let real_columns: u64 = (0..HALF_ROWS)
                .filter(|&hr| todo & (1 << hr) != 0)
                .map(|hr| {
                    (0..LANES)
                        .filter(|&l| half_row_x(hr) + (l as f32) < tw as f32)
                        .count() as u64
                })
                .sum();
            assert_eq!(
                super::evaluated_pixels(todo, tw),
                real_columns,
                "case {case}"
            );
            assert_eq!(vector.n, scalar.n, "case {case}");
            assert_eq!(vector.hr[..scalar.n], scalar.hr[..scalar.n], "case {case}");
            for (i, (v, s)) in vector
                .gauss
                .iter()
                .zip(&scalar.gauss)
                .take(scalar.n)
                .enumerate()
            {
                assert_eq!(
                    v.map(f32::to_bits),
                    s.map(f32::to_bits),
                    "case {case}, half-row {i}"
                );
                let hr = scalar.hr[i].index();
                let row = RowExponent::new(conic, spans.dy[hr / 2]);
                let xb = half_row_dx(p.xy[0], x0, hr);
                for (l, &g) in s.iter().enumerate() {
                    let t = row.at(xb - l as f32);
                    if t < EXP2_MIN {
                        // Clamped to the least exponent's value, not 0.
                        below_least += 1;
                        assert!(g > 0.0 && g < 1.2e-38, "case {case}: {g} below the least");
                    } else {
                        kept += u64::from(g > 0.0);
                    }
                }
            }
        }
        assert!(
            below_least > 1_000,
            "{below_least} lanes below the least exponent"
        );
        assert!(kept > 100_000, "{kept} lanes kept");
    }

    /// The walks' falloff takes every lane of the half-rows it is given ([`RowSpans::of_rows`]
    /// for whole rows, the exact solve's dy, k₂ and k₃): every lane outside the exact solved
    /// span of its row must fail the alpha test (or lie past a partial tile's last column,
    /// where no pixel is open in the forward nor has a contributor in the backward), so the
    /// walks composite and differentiate exactly what they would over the exact spans.
    /// Portable and AVX2 falloffs, splats of every size and angle around partial and whole
    /// tiles.
    #[test]
    fn lanes_outside_the_exact_spans_fail_the_alpha_test() {
        use crate::constants::{MAX_ALPHA, MIN_ALPHA};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(37);
        let (mut inside, mut outside) = (0_u64, 0_u64);
        for case in 0..100_000 {
            let RandomPair {
                p,
                tile: (x0, y0, tw, th),
                ..
            } = random_splat_and_tile(&mut rng, case);
            let solved = RowSpans::solve::<false>(&p, x0, y0, tw, th);
            let whole = RowSpans::of_rows::<false>(&p, solved.mask, y0);
            for r in 0..TILE_SIZE as usize {
                assert_eq!(whole.dy[r].to_bits(), solved.dy[r].to_bits());
                assert_eq!(whole.k2[r].to_bits(), solved.k2[r].to_bits());
                assert_eq!(whole.k3[r].to_bits(), solved.k3[r].to_bits());
            }
            let mut paths = vec![false];
            #[cfg(target_arch = "x86_64")]
            if crate::has_avx2() {
                paths.push(true);
            }
            for avx2 in paths {
                let mut f = Falloff::new();
                if avx2 {
                    f.compute::<true>(&p, &whole, solved.mask, x0);
                } else {
                    f.compute::<false>(&p, &whole, solved.mask, x0);
                }
                assert_eq!(f.n, solved.mask.count_ones() as usize);
                for (&hr, g) in f.hr.iter().zip(&f.gauss).take(f.n) {
                    let hr = hr.index();
                    let row = hr / 2;
                    for (l, &gauss) in g.iter().enumerate() {
                        let column = half_row_x(hr) + l as f32;
                        if solved.lo[row] <= column && column <= solved.hi[row] {
                            inside += 1;
                            continue;
                        }
                        outside += 1;
                        let alpha = (p.opacity * gauss).min(MAX_ALPHA);
                        assert!(
                            alpha < MIN_ALPHA || column >= tw as f32,
                            "case {case}: column {column} of row {row} outside the span \
                             [{}, {}] with alpha {alpha}",
                            solved.lo[row],
                            solved.hi[row]
                        );
                    }
                }
            }
        }
        assert!(
            inside > 1_000_000 && outside > 100_000,
            "{inside} lanes inside the spans, {outside} outside"
        );
    }

    /// The radix sort must give the order of a plain sort of the keys, for any thread count:
    /// depths of few distinct values (many ties, some passes with one digit only), of all
    /// magnitudes, and sizes around the slices' split.
    #[test]
    fn depth_sort_matches_a_plain_sort() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(23);
        for n in [0, 1, 2, 15, 16, 17, 1000, 40_001] {
            for few in [true, false] {
                let keys: Vec<u64> = (0..n)
                    .map(|i| {
                        let depth: f32 = if few {
                            [0.5, 1.0, 3.0][rng.random_range(0..3)]
                        } else {
                            rng.random_range(1e-3_f32..1e4)
                        };
                        (u64::from(depth.to_bits()) << 32) | i as u64
                    })
                    .collect();
                let mut want = keys.clone();
                want.sort_unstable();
                for threads in [1, 3] {
                    let pool = rayon::ThreadPoolBuilder::new()
                        .num_threads(threads)
                        .build()
                        .unwrap();
                    let mut got = keys.clone();
                    pool.install(|| {
                        super::sort_by_depth(&mut got, &mut Vec::new(), &mut Vec::new())
                    });
                    assert_eq!(got, want, "{n} keys, few depths {few}, {threads} threads");
                }
            }
        }
    }

    /// Every tile's list must hold exactly the visible splats whose rectangle covers it, front
    /// to back with equal depths in index order, for any thread count: checked against a
    /// brute-force listing, with depths drawn from a few values so that ties are common.
    #[test]
    fn tile_lists_are_ordered_by_depth_then_index() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(17);
        let (tiles_x, tiles_y) = (11_u32, 6_u32);
        let n = 4_000;
        let (proj, rects, visible) = random_splats_to_bin(&mut rng, n, [tiles_x, tiles_y], |rng| {
            [0.5_f32, 1.0, 1.0 + f32::EPSILON, 2.5, 7.0][rng.random_range(0..5)]
        });
        let mut expected = Vec::new();
        for t in 0..tiles_x * tiles_y {
            let (tx, ty) = (t % tiles_x, t / tiles_x);
            let mut listed: Vec<usize> = (0..n)
                .filter(|&i| {
                    let [x0, x1, y0, y1] = rects[i];
                    visible[i] && (x0..x1).contains(&tx) && (y0..y1).contains(&ty)
                })
                .collect();
            listed.sort_by(|&a, &b| proj[a].depth.total_cmp(&proj[b].depth).then(a.cmp(&b)));
            expected.push(listed);
        }
        for threads in [1, 4] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            let mut bins = Bins::default();
            pool.install(|| bins.build(&proj, &rects, &visible, tiles_x, tiles_y));
            for (t, want) in expected.iter().enumerate() {
                let got: Vec<usize> = bins.list[bins.offsets[t]..bins.offsets[t + 1]]
                    .iter()
                    .map(|&i| i as usize)
                    .collect();
                assert_eq!(&got, want, "tile {t}, {threads} threads");
            }
        }
    }

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

    #[test]
    fn fast_exp2_is_accurate_over_the_falloff_range() {
        // Alpha can reach 1/255 only for t ≥ −log₂ 255 ≈ −8; the polynomial's relative error
        // does not grow with |t|, since 2ⁿ is exact.
        for (lo, tol) in [(-15.0, 3.5e-6), (-126.0, 3.5e-6)] {
            let mut worst = 0.0_f64;
            for i in 0..=200_000 {
                let t = (lo * f64::from(i) / 200_000.0) as f32;
                let got = f64::from(fast_exp2(t));
                let want = f64::from(t).exp2();
                worst = worst.max((got - want).abs() / want);
            }
            assert!(worst < tol, "worst relative error {worst} on [{lo}, 0]");
        }
        // Below the least exponent: 2⁻¹²⁶'s value, to the polynomial's rounding.
        for t in [-127.0, -1e4, f32::NEG_INFINITY, f32::NAN] {
            assert!((fast_exp2(t) / f32::MIN_POSITIVE - 1.0).abs() < 1e-6, "{t}");
        }
        assert_eq!(fast_exp2(0.0), 1.0);
        assert_eq!(fast_exp2(-3.0), 0.125);
    }

    /// The row form of the exponent is the Gaussian's, log₂e·(−½(a·dx² + c·dy²) − b·dx·dy),
    /// to f32 rounding of its terms, checked in f64 on random conics and offsets.
    #[test]
    fn row_exponent_is_the_gaussian_s_in_base_two() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        for _ in 0..100_000 {
            let (_, conic64) = footprint(
                [rng.random_range(0.2..50.0), rng.random_range(0.2..50.0)],
                rng.random_range(0.0..std::f64::consts::PI),
            );
            let conic = conic64.map(|v| v as f32);
            let (dx, dy): (f32, f32) =
                (rng.random_range(-40.0..40.0), rng.random_range(-40.0..40.0));
            let got = f64::from(RowExponent::new(conic, dy).at(dx));
            let [a, b, c] = conic.map(f64::from);
            let (dx, dy) = (f64::from(dx), f64::from(dy));
            let terms = [a * dx * dx, c * dy * dy, 2.0 * (b * dx * dy).abs()];
            let want = std::f64::consts::LOG2_E * (-0.5 * (terms[0] + terms[1]) - b * dx * dy);
            let scale = std::f64::consts::LOG2_E * terms.iter().sum::<f64>();
            assert!(
                (got - want).abs() <= 4e-7 * scale + 1e-30,
                "{got} against {want} (terms {scale})"
            );
        }
    }
}
