//! The separable Gaussian window: its horizontal and vertical passes over spans of rows.

use super::spans::Span;
use super::{RADIUS, TAPS};

/// Horizontal pass over the columns of `out` in one interleaved RGB row: `dst[c] = Σₜ gₜ ·
/// src[c + t − R]` per channel, with `src` taken as zero outside `valid` (and the row). Along a
/// row, neighbouring pixels of a channel are 3 floats apart, so each tap is one shifted,
/// contiguous multiply-add (vectorisable).
pub(super) fn horizontal(
    src: &[f32],
    valid: Span,
    dst: &mut [f32],
    out: Span,
    taps: &[f32; TAPS],
    avx2: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { horizontal_avx2(src, valid, dst, out, taps) };
    }
    let _ = avx2;
    horizontal_impl(src, valid, dst, out, taps);
}

/// [`horizontal_impl`] compiled with AVX2: 8 floats a multiply-add instead of 4 (the same
/// IEEE operations, so the same sums).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn horizontal_avx2(src: &[f32], valid: Span, dst: &mut [f32], out: Span, taps: &[f32; TAPS]) {
    horizontal_impl(src, valid, dst, out, taps);
}

#[inline(always)]
fn horizontal_impl(src: &[f32], valid: Span, dst: &mut [f32], out: Span, taps: &[f32; TAPS]) {
    // Output value q (of the span's 3·len) reads source value 3·out.lo + q + 3(t − R), which
    // must lie in `valid`.
    let first = 3 * out.lo as isize;
    let rows = std::array::from_fn(|t| {
        let shift = first + 3 * (t as isize - RADIUS as isize);
        TapRow {
            src,
            shift,
            lo: (3 * valid.lo as isize - shift).max(0) as usize,
            hi: (3 * valid.hi as isize - shift).max(0) as usize,
            weight: taps[t],
        }
    });
    weighted_sums(&mut dst[3 * out.lo..3 * out.hi], &rows);
}

/// One tap of [`weighted_sums`]: output value `q` adds `weight · src[q + shift]` where
/// `lo ≤ q < hi` (the source is taken as zero elsewhere).
#[derive(Clone, Copy)]
struct TapRow<'a> {
    src: &'a [f32],
    shift: isize,
    lo: usize,
    hi: usize,
    weight: f32,
}

/// Values of `weighted_sums`'s blocks: four AVX2 registers, so four independent chains of
/// additions per tap.
const BLOCK: usize = 32;

/// `dst[q] = Σₜ` (tap t's term at q), the taps added in order for each value, as a loop over
/// taps each adding into the whole of `dst` would; but a block of `dst` stays in registers over
/// all the taps instead of being loaded, added to and stored once per tap.
#[inline(always)]
fn weighted_sums(dst: &mut [f32], rows: &[TapRow<'_>; TAPS]) {
    let n = dst.len();
    let whole = n - n % BLOCK;
    // The blocks every tap covers whole (most of a span) go through a loop with no per-tap
    // range test: each tap's source sliced once to their extent.
    let (lo, hi) = rows
        .iter()
        .fold((0, whole), |(a, b), r| (a.max(r.lo), b.min(r.hi)));
    let (full_lo, full_hi) = (lo.div_ceil(BLOCK) * BLOCK, hi / BLOCK * BLOCK);
    let full = if full_lo < full_hi {
        let srcs: [&[f32]; TAPS] =
            std::array::from_fn(|t| &rows[t].src[rows[t].at(full_lo)..rows[t].at(full_hi)]);
        let weights: [f32; TAPS] = std::array::from_fn(|t| rows[t].weight);
        for (k, out) in dst[full_lo..full_hi].chunks_exact_mut(BLOCK).enumerate() {
            let mut acc = [0.0_f32; BLOCK];
            for (src, &w) in srcs.iter().zip(&weights) {
                let s: &[f32; BLOCK] = src[k * BLOCK..(k + 1) * BLOCK]
                    .try_into()
                    .expect("a block's length");
                add_block(&mut acc, w, s);
            }
            out.copy_from_slice(&acc);
        }
        full_lo..full_hi
    } else {
        0..0
    };
    for (b, out) in dst[..whole].chunks_exact_mut(BLOCK).enumerate() {
        let q0 = b * BLOCK;
        if full.contains(&q0) {
            continue;
        }
        let mut acc = [0.0_f32; BLOCK];
        for row in rows {
            let (lo, hi) = (row.lo.max(q0), row.hi.min(q0 + BLOCK));
            if lo >= hi {
                continue;
            }
            if lo == q0 && hi == q0 + BLOCK {
                add_block(&mut acc, row.weight, row.block(q0));
            } else {
                add_block(&mut acc, row.weight, &row.part(q0, lo, hi));
            }
        }
        out.copy_from_slice(&acc);
    }
    // The last values as one block padded with zeros (which add +0, as in `TapRow::part`).
    if whole < n {
        let mut acc = [0.0_f32; BLOCK];
        for row in rows {
            let (lo, hi) = (row.lo.max(whole), row.hi.min(n));
            if lo < hi {
                add_block(&mut acc, row.weight, &row.part(whole, lo, hi));
            }
        }
        dst[whole..].copy_from_slice(&acc[..n - whole]);
    }
}

/// `acc += w · s`, lane by lane.
#[inline(always)]
fn add_block(acc: &mut [f32; BLOCK], w: f32, s: &[f32; BLOCK]) {
    for (a, &v) in acc.iter_mut().zip(s) {
        *a += w * v;
    }
}

impl TapRow<'_> {
    /// Position in `src` of output value `q`.
    #[inline(always)]
    fn at(&self, q: usize) -> usize {
        (q as isize + self.shift) as usize
    }

    /// The source of the block of outputs at `q0`, all inside the tap's range.
    #[inline(always)]
    fn block(&self, q0: usize) -> &[f32; BLOCK] {
        self.src[self.at(q0)..self.at(q0) + BLOCK]
            .try_into()
            .expect("a block's length")
    }

    /// The source of the block at `q0` where only `lo..hi` is inside the tap's range, zero
    /// elsewhere: adding w·0 = +0 leaves a sum as it was (a sum that starts at +0 is never −0),
    /// so the block gives the sums that skipping those values would.
    #[inline(always)]
    fn part(&self, q0: usize, lo: usize, hi: usize) -> [f32; BLOCK] {
        let mut part = [0.0_f32; BLOCK];
        part[lo - q0..hi - q0].copy_from_slice(&self.src[self.at(lo)..self.at(hi)]);
        part
    }
}

/// Horizontal window sums of an image's `h` rows, read by the vertical pass: row `rr` is held
/// in slot `rr % slots` of `src` (`row` floats a slot: the whole image when `slots` is `h`, a
/// ring of the last rows when it is [`TAPS`]), valid only over its span in `filled`.
#[derive(Clone, Copy)]
pub(super) struct RowSums<'a> {
    pub(super) src: &'a [f32],
    pub(super) slots: usize,
    pub(super) h: usize,
    pub(super) row: usize,
    pub(super) filled: &'a [Span],
}

/// Vertical pass for row `r` over the columns of `out`: the weighted sum of the rows of
/// `sums` up to `RADIUS` away, each taken as zero outside the image and outside its own span.
/// `dst` holds the span's 3·len floats.
pub(super) fn vertical(
    sums: RowSums<'_>,
    r: usize,
    out: Span,
    dst: &mut [f32],
    taps: &[f32; TAPS],
    avx2: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { vertical_avx2(sums, r, out, dst, taps) };
    }
    let _ = avx2;
    vertical_impl(sums, r, out, dst, taps);
}

/// [`vertical_impl`] compiled with AVX2 (as [`horizontal_avx2`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn vertical_avx2(sums: RowSums<'_>, r: usize, out: Span, dst: &mut [f32], taps: &[f32; TAPS]) {
    vertical_impl(sums, r, out, dst, taps);
}

#[inline(always)]
fn vertical_impl(sums: RowSums<'_>, r: usize, out: Span, dst: &mut [f32], taps: &[f32; TAPS]) {
    let RowSums {
        src,
        slots,
        h,
        row,
        filled,
    } = sums;
    let rows = std::array::from_fn(|t| {
        // Rows outside the image, and columns outside a row's span, read as zero.
        let (rr, cols) = match (r + t).checked_sub(RADIUS).filter(|&rr| rr < h) {
            Some(rr) => (rr, out.intersect(filled[rr])),
            None => (0, Span::EMPTY),
        };
        let first = (rr % slots) * row + 3 * out.lo;
        TapRow {
            src,
            shift: first as isize,
            lo: 3 * cols.lo.saturating_sub(out.lo),
            hi: if cols.is_empty() {
                0
            } else {
                3 * (cols.hi - out.lo)
            },
            weight: taps[t],
        }
    });
    weighted_sums(dst, &rows);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ssim::gaussian_taps;
    use crate::ssim::tests::random_pair;
    use rand::{RngExt, SeedableRng};

    /// `weighted_sums` against one value at a time, the taps in order, bit for bit: taps whose
    /// ranges start and end anywhere (so blocks wholly inside every tap, blocks cut by some,
    /// and the last values that fill no block), and ranges that leave no block whole.
    #[test]
    fn weighted_sums_add_each_value_s_taps_in_order() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let taps = gaussian_taps();
        let src: Vec<f32> = (0..4096).map(|_| rng.random::<f32>()).collect();
        for case in 0..200 {
            let n = rng.random_range(1..700usize);
            let rows: [TapRow<'_>; TAPS] = std::array::from_fn(|t| {
                let (a, b) = if case % 3 == 0 {
                    // Nearly whole: every tap covers the middle blocks.
                    (rng.random_range(0..40), n - rng.random_range(0..40.min(n)))
                } else {
                    let a = rng.random_range(0..n);
                    (a, rng.random_range(a..=n))
                };
                TapRow {
                    src: &src,
                    shift: rng.random_range(0..3000) as isize,
                    lo: a.min(n),
                    hi: b.max(a).min(n),
                    weight: taps[t],
                }
            });
            let mut dst = vec![f32::NAN; n];
            weighted_sums(&mut dst, &rows);
            for (q, &got) in dst.iter().enumerate() {
                let mut acc = 0.0_f32;
                for r in rows.iter().filter(|r| (r.lo..r.hi).contains(&q)) {
                    acc += r.weight * r.src[r.at(q)];
                }
                assert_eq!(
                    got.to_bits(),
                    acc.to_bits(),
                    "case {case}, value {q} of {n}"
                );
            }
        }
    }

    /// The AVX2 and portable window passes must give the same sums bit for bit (the tests
    /// against references exercise only the one this machine picks).
    #[test]
    fn both_instantiations_of_the_window_passes_agree_bit_for_bit() {
        let (w, h) = (37, 9);
        let row = 3 * w;
        let (x, _) = random_pair(w, h, 4);
        let taps = gaussian_taps();
        let valid = Span { lo: 3, hi: 30 };
        let out = Span { lo: 1, hi: 35 };
        let run = |avx2: bool| {
            let mut across = vec![0.0_f32; row * h];
            for r in 0..h {
                let dst = &mut across[r * row..(r + 1) * row];
                horizontal(&x[r * row..(r + 1) * row], valid, dst, out, &taps, avx2);
            }
            let filled = vec![out; h];
            let mut down = vec![0.0_f32; 3 * out.len()];
            let mut all = Vec::new();
            let rows = RowSums {
                src: &across,
                slots: h,
                h,
                row,
                filled: &filled,
            };
            for r in 0..h {
                vertical(rows, r, out, &mut down, &taps, avx2);
                all.extend(down.iter().map(|v| v.to_bits()));
            }
            (across.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), all)
        };
        let portable = run(false);
        assert!(
            portable.1.iter().any(|&b| b != 0),
            "the passes must produce sums"
        );
        assert_eq!(portable, run(splat_core::has_avx2()));
    }

    /// The window passes keep a block of sums in registers over all the taps; each sum must
    /// still be the taps' products added in tap order, skipping the taps outside the source's
    /// span, bit for bit: checked against that loop written out, with spans that start and
    /// end inside blocks, reach the row's ends, or are empty.
    #[test]
    fn window_passes_add_the_taps_in_order_bit_for_bit() {
        let (w, h) = (90, 12);
        let row = 3 * w;
        let (x, _) = random_pair(w, h, 9);
        let taps = gaussian_taps();
        let spans = [
            (0, 90),
            (3, 61),
            (11, 12),
            (40, 40),
            (0, 7),
            (85, 90),
            (29, 77),
        ];
        let sum_of = |terms: &mut dyn Iterator<Item = (f32, f32)>| {
            terms.fold(0.0_f32, |acc, (g, v)| acc + g * v)
        };
        for avx2 in [false, splat_core::has_avx2()] {
            for &(vlo, vhi) in &spans {
                for &(olo, ohi) in &spans {
                    let (valid, out) = (Span { lo: vlo, hi: vhi }, Span { lo: olo, hi: ohi });
                    let mut dst = vec![f32::NAN; row];
                    horizontal(&x[..row], valid, &mut dst, out, &taps, avx2);
                    for c in out.lo..out.hi {
                        for ch in 0..3 {
                            let want = sum_of(&mut (0..TAPS).filter_map(|t| {
                                let sc = (c + t).checked_sub(RADIUS)?;
                                (valid.lo..valid.hi)
                                    .contains(&sc)
                                    .then(|| (taps[t], x[3 * sc + ch]))
                            }));
                            assert_eq!(
                                dst[3 * c + ch].to_bits(),
                                want.to_bits(),
                                "{valid:?} {out:?}"
                            );
                        }
                    }
                }
            }
            // Rows with spans of their own, some empty, read through the vertical pass.
            let filled: Vec<Span> = (0..h)
                .map(|r| {
                    let (lo, hi) = spans[r % spans.len()];
                    Span { lo, hi }
                })
                .collect();
            for &(olo, ohi) in &spans {
                let out = Span { lo: olo, hi: ohi };
                let mut dst = vec![f32::NAN; 3 * out.len()];
                let rows = RowSums {
                    src: &x,
                    slots: h,
                    h,
                    row,
                    filled: &filled,
                };
                for r in 0..h {
                    vertical(rows, r, out, &mut dst, &taps, avx2);
                    for c in out.lo..out.hi {
                        for ch in 0..3 {
                            let want = sum_of(&mut (0..TAPS).filter_map(|t| {
                                let rr = (r + t).checked_sub(RADIUS).filter(|&rr| rr < h)?;
                                let span = filled[rr];
                                (span.lo..span.hi)
                                    .contains(&c)
                                    .then(|| (taps[t], x[rr * row + 3 * c + ch]))
                            }));
                            let got = dst[3 * (c - out.lo) + ch];
                            assert_eq!(got.to_bits(), want.to_bits(), "row {r}, {out:?}");
                        }
                    }
                }
            }
        }
    }
}
