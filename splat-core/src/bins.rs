//! Binning: every visible splat is listed in each 16×16 tile its 3σ square touches within the
//! box of its alpha ≥ 1/255 ellipse (`project::within_reach`), each tile's list front to back;
//! and the per-splat sums of records kept per (tile, splat) pair, in list order.
//!
//! This is Inria's single sort of (tile, depth) keys done as the two passes of an LSD radix sort:
//! one sort of the visible splats by (depth, index), then a stable counting sort by tile. The
//! index in the key makes the order total, so binning is identical for any thread count.

use rayon::prelude::*;

use crate::disjoint::DisjointWrites;
use crate::projected::Projected;

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
    ///
    /// The counting sort runs in parallel over a fixed number of slices of the depth order:
    /// each slice counts its pairs per tile, every (tile, slice) gets the next run of its
    /// tile's list, and each slice fills its runs in its own (depth) order. The result is the
    /// one stable order, whatever the thread count.
    pub fn build(
        &mut self,
        proj: &[Projected],
        rects: &[[u32; 4]],
        visible: &[bool],
        tiles_x: u32,
        tiles_y: u32,
    ) {
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
        let slice_len = self.order.len().div_ceil(BIN_SLICES).max(1);
        self.count_pairs(slice_len, tiles_x, tiles_y);
        let pairs = self.lay_out_runs((tiles_x * tiles_y) as usize);
        self.scatter(slice_len, pairs, tiles_x);
    }

    /// Counts each slice's pairs per tile into `slice_counts` (slice-major).
    fn count_pairs(&mut self, slice_len: usize, tiles_x: u32, tiles_y: u32) {
        let n_tiles = (tiles_x * tiles_y) as usize;
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
    }

    /// Turns the counts into each (tile, slice) run's start, tile-major then slice order: each
    /// tile's total, the tiles' starts (`offsets`), then each slice's start within its tile
    /// (in place of its count in `slice_counts`). Returns the number of pairs.
    fn lay_out_runs(&mut self, n_tiles: usize) -> usize {
        // Every pass runs along one slice's counts (tile by tile down the slices, the loop read
        // 16 strided cache lines a tile).
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
        next
    }

    /// Writes each slice's splats into its runs of `list`, in depth order.
    fn scatter(&mut self, slice_len: usize, pairs: usize, tiles_x: u32) {
        let n_tiles = self.offsets.len() - 1;
        // Not cleared: the scatter writes every position.
        self.list.resize(pairs, 0);
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

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};

    #[cfg(target_arch = "x86_64")]
    use super::owned_bits_avx2;
    use super::{Bins, SCAN_BLOCK, owned_bits};
    use crate::projected::Projected;

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
}
