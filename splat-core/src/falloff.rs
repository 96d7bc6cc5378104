//! A splat's Gaussian falloff over the half-rows of a tile, computed the same way by both tile
//! walks: 2^t of the exponent in row form ([`RowExponent`]) through a branch-free [`fast_exp2`].

use crate::projected::Projected;
use crate::spans::{RowExponent, RowSpans};
use crate::splats::ROUND_TO_INTEGER;
use crate::tiles::{HALF_ROWS, HalfRowId, LANES, half_row_dx};

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

    use super::{EXP2_MIN, Falloff, fast_exp2};
    use crate::spans::tests::{RandomPair, random_splat_and_tile};
    use crate::spans::{RowExponent, RowSpans};
    use crate::tiles::{HALF_ROWS, LANES, TILE_SIZE, evaluated_pixels, half_row_dx, half_row_x};

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
            assert_eq!(evaluated_pixels(todo, tw), real_columns, "case {case}");
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
}
