//! Row spans: where one splat can reach alpha ≥ 1/255 in one tile, for all 16 rows at once,
//! and the half-rows that takes; with each row's terms of the falloff's exponent in row form
//! ([`RowExponent`]).

use crate::projected::Projected;
use crate::tiles::TILE_SIZE;

/// How far beyond the exact solution of its row a span reaches, in pixels: room for the
/// rounding of the row's solution and of the tile loops' own falloff (it was one to two
/// pixels, which around the small splats of a paper-scale frame drew many lanes and half-rows
/// that could not pass the alpha test).
/// `spans_hold_every_pixel_the_lane_test_passes` finds 0.1 px too little for splats thousands
/// of pixels long and 0.3 px enough.
const SPAN_MARGIN: f32 = 0.5;

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
        #[allow(unsafe_code)]
        let mask = if AVX2 {
            // SAFETY: only the AVX2 instantiations of the tile walks ask for `AVX2`, and they
            // run only where `has_avx2()` found the feature.
            unsafe { half_row_mask_avx2(&lo, &hi) }
        } else {
            half_row_mask(&lo, &hi)
        };
        #[cfg(not(target_arch = "x86_64"))]
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
    pub(crate) k1: f32,
    pub(crate) k2: f32,
    pub(crate) k3: f32,
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

/// Bit `2·row + half` set when that half-row of the tile has pixels in the row's span
/// [`lo`, `hi`] (tile-local pixels).
#[cfg(test)]
fn half_row_mask(lo: &[f32; TILE_SIZE as usize], hi: &[f32; TILE_SIZE as usize]) -> u32 {
    let half = (crate::tiles::LANES - 1) as f32;
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
    let half = _mm256_set1_ps((crate::tiles::LANES - 1) as f32);
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

#[cfg(test)]
pub(crate) mod tests {
    use rand::{RngExt, SeedableRng};

    use super::RowExponent;
    #[cfg(target_arch = "x86_64")]
    use super::half_row_mask_avx2;
    use super::{RowSpans, half_row_mask};
    use crate::falloff::fast_exp2;
    use crate::projected::{Projected, footprint, quad_bound, random_footprint};
    use crate::tiles::{HALF_ROWS, LANES, TILE_SIZE};

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
            let (tw, th) = random_tile_size(&mut rng, case);
            let p = splat_at(centre, conic, opacity);
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

    /// A tile's real size: every tenth `case` a partial tile at the image's right or bottom
    /// edge, else a whole one.
    fn random_tile_size(rng: &mut rand_pcg::Pcg64, case: usize) -> (i32, i32) {
        let ts = TILE_SIZE as i32;
        if case.is_multiple_of(10) {
            (rng.random_range(1..=ts), rng.random_range(1..=ts))
        } else {
            (ts, ts)
        }
    }

    /// A projected splat at `centre` of f64 conic `conic` (rounded to f32) and opacity
    /// `opacity`, with its alpha bound.
    fn splat_at(centre: [f32; 2], conic: [f64; 3], opacity: f32) -> Projected {
        Projected {
            xy: centre,
            conic: conic.map(|v| v as f32),
            opacity,
            q_max: quad_bound(opacity),
            ..Projected::default()
        }
    }

    /// A splat from a fifth of a pixel to thousands of pixels across (long thin ones at every
    /// angle), of any opacity, and a tile it may reach: centred inside it or far outside, and
    /// every tenth `case` a partial tile at the image's right or bottom edge.
    pub(crate) fn random_splat_and_tile(rng: &mut rand_pcg::Pcg64, case: usize) -> RandomPair {
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
        let (tw, th) = random_tile_size(rng, case);
        RandomPair {
            p: splat_at(centre, conic64, opacity),
            conic64,
            axes: (s1, s2),
            tile: (x0, y0, tw, th),
        }
    }

    /// A splat and a tile from [`random_splat_and_tile`].
    pub(crate) struct RandomPair {
        pub(crate) p: Projected,
        /// The splat's conic in f64, before rounding to the f32 of `p`.
        pub(crate) conic64: [f64; 3],
        /// Its standard deviations, pixels.
        pub(crate) axes: (f64, f64),
        /// The tile's origin and real size (x0, y0, tw, th).
        pub(crate) tile: (i32, i32, i32, i32),
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
