//! The passes band by band: each band of rows streams its window sums, map rows and
//! partials through rings of [`TAPS`] rows (see [`super::Ssim`]).

use std::ops::Range;

use super::spans::{Span, Spans};
use super::terms::{add_gradient_row, map_row, square_products};
use super::window::{RowSums, horizontal, vertical};
use super::{RADIUS, TAPS};

/// One band's buffers at a row width of `row` floats (3 a pixel).
#[derive(Debug)]
pub(super) struct BandScratch {
    /// x², y² and xy of one row.
    products: Vec<f32>,
    /// Rings of the horizontal window sums of x, y, x², y² and xy: row k in slot k % TAPS.
    sums: [Vec<f32>; 5],
    /// One row's window means μx, μy, E[x²], E[y²], E[xy].
    means: Vec<f32>,
    /// One row's map partials ∂SSIM/∂μx (with the chain through σx² and σxy folded in),
    /// ∂SSIM/∂E[x²] and ∂SSIM/∂E[xy].
    partials: Vec<f32>,
    /// Rings of the partials' horizontal window sums.
    partial_sums: [Vec<f32>; 3],
    /// One row's partials blurred vertically too.
    blurred: Vec<f32>,
}

impl BandScratch {
    pub(super) fn new(row: usize) -> Self {
        Self {
            products: vec![0.0; 3 * row],
            sums: std::array::from_fn(|_| vec![0.0; TAPS * row]),
            means: vec![0.0; 5 * row],
            partials: vec![0.0; 3 * row],
            partial_sums: std::array::from_fn(|_| vec![0.0; TAPS * row]),
            blurred: vec![0.0; 3 * row],
        }
    }
}

/// Bands each thread gets about, so that a thread that finishes early finds work.
pub(super) const BANDS_PER_THREAD: usize = 3;

/// Fewest rows of a band (past the image's first and last): a band works out up to
/// `2 · RADIUS` rows beyond each end, so narrower bands would repeat much of their work.
pub(super) const MIN_BAND_ROWS: usize = 64;

/// What every band of one evaluation reads.
pub(super) struct Pass<'a> {
    pub(super) x: &'a [f32],
    pub(super) y: &'a [f32],
    pub(super) w: usize,
    pub(super) h: usize,
    pub(super) taps: &'a [f32; TAPS],
    pub(super) spans: &'a Spans,
    pub(super) avx2: bool,
}

/// Splits `rows` into bands of consecutive rows for [`super::Ssim::evaluate`]: about `bands`
/// of them with equal work (the length of each row's map span; rows without one cost
/// nothing), none narrower than `min_rows` unless the image is, covering every row.
pub(super) fn plan_bands(map: &[Span], bands: usize, min_rows: usize) -> Vec<Range<usize>> {
    let h = map.len();
    let bands = bands.max(1);
    let total: usize = map.iter().map(|s| s.len()).sum();
    let mut out = Vec::new();
    let (mut start, mut work) = (0, 0);
    for (r, span) in map.iter().enumerate() {
        work += span.len();
        // A band ends once the work so far reaches its share of the whole, unless it is too
        // narrow, too near the end, or the last one.
        let share = (out.len() + 1) * total / bands;
        if out.len() + 1 < bands
            && work >= share.max(1)
            && r + 1 - start >= min_rows
            && h - (r + 1) >= min_rows
        {
            out.push(start..r + 1);
            start = r + 1;
        }
    }
    out.push(start..h);
    out
}

/// `data` cut into consecutive pieces of the given lengths (which must add up to its length).
pub(super) fn split_by_lengths<T>(
    data: &mut [T],
    lengths: impl Iterator<Item = usize>,
) -> Vec<&mut [T]> {
    let mut rest = data;
    let mut pieces = Vec::new();
    for len in lengths {
        let (piece, tail) = rest.split_at_mut(len);
        pieces.push(piece);
        rest = tail;
    }
    debug_assert!(rest.is_empty(), "the lengths cover the data");
    pieces
}

impl Pass<'_> {
    /// The band `rows`: each row's SSIM map sum into `values` and, with `grad` as `(k, out)`,
    /// `k` times the gradient added into `out` (the band's rows of the gradient image).
    ///
    /// Row k's horizontal sums go into the rings at step k, the map of row k − R (whose window
    /// reaches rows k − 2R ..= k) and its partials' horizontal sums at the same step, and the
    /// gradient of row k − 2R (whose window reaches the partials of rows k − 3R ..= k − R) too:
    /// each ring of TAPS rows holds exactly the rows its readers need. The band starts 2R rows
    /// early (R without a gradient) so that its first rows see whole windows.
    pub(super) fn band(
        &self,
        rows: Range<usize>,
        values: &mut [f64],
        mut grad: Option<(f32, &mut [f32])>,
        scratch: &mut BandScratch,
    ) {
        let (a, b, h) = (rows.start, rows.end, self.h);
        let reach = if grad.is_some() { 2 * RADIUS } else { RADIUS };
        // The map rows the band needs: its own, and R more each way for the gradient's window.
        let maps = if grad.is_some() {
            a.saturating_sub(RADIUS)..(b + RADIUS).min(h)
        } else {
            rows.clone()
        };
        for k in a.saturating_sub(reach)..b + reach {
            if k < h {
                self.sums_row(k, scratch);
            }
            if let Some(m) = k.checked_sub(RADIUS).filter(|m| maps.contains(m)) {
                let value = self.map_row(m, grad.is_some(), scratch);
                if rows.contains(&m) {
                    values[m - a] = value;
                }
            }
            if let Some((k_grad, out)) = grad.as_mut()
                && let Some(g) = k.checked_sub(2 * RADIUS).filter(|g| rows.contains(g))
            {
                let row = 3 * self.w;
                let out = &mut out[(g - a) * row..(g - a + 1) * row];
                self.gradient_row(g, *k_grad, out, scratch);
            }
        }
    }

    /// The vertical window sums of row `r` over `span` from each of `rings` (rings of
    /// [`TAPS`] rows, valid over `filled`), into the matching row of `dst` (`N` rows of 3·W
    /// floats); returns each one's values over the span.
    fn vertical_rings<'d, const N: usize>(
        &self,
        rings: &[Vec<f32>; N],
        filled: &[Span],
        r: usize,
        span: Span,
        dst: &'d mut [f32],
    ) -> [&'d [f32]; N] {
        let row = 3 * self.w;
        let cols = 3 * span.lo..3 * span.hi;
        for (ring, out) in rings.iter().zip(dst.chunks_exact_mut(row)) {
            let rows = RowSums {
                src: ring,
                slots: TAPS,
                h: self.h,
                row,
                filled,
            };
            vertical(rows, r, span, &mut out[cols.clone()], self.taps, self.avx2);
        }
        let dst = &*dst;
        std::array::from_fn(|q| &dst[q * row + cols.start..q * row + cols.end])
    }

    /// Horizontal window sums of x, y, x², y², xy of row `r` over its `sums` span, into the
    /// rings.
    fn sums_row(&self, r: usize, scratch: &mut BandScratch) {
        let (w, avx2, taps) = (self.w, self.avx2, self.taps);
        let row = 3 * w;
        let out = self.spans.sums[r];
        if out.is_empty() {
            return;
        }
        let (xr, yr) = (
            &self.x[r * row..(r + 1) * row],
            &self.y[r * row..(r + 1) * row],
        );
        // The products are only needed where the sums read them.
        let need = out.widen(RADIUS, w);
        let (pxx, rest) = scratch.products.split_at_mut(row);
        let (pyy, pxy) = rest.split_at_mut(row);
        let cols = 3 * need.lo..3 * need.hi;
        let dst = [
            &mut pxx[cols.clone()],
            &mut pyy[cols.clone()],
            &mut pxy[cols.clone()],
        ];
        square_products(&xr[cols.clone()], &yr[cols], dst, avx2);
        let slot = (r % TAPS) * row..(r % TAPS + 1) * row;
        let [ox, oy, oxx, oyy, oxy] = scratch.sums.each_mut().map(|s| &mut s[slot.clone()]);
        let whole = Span { lo: 0, hi: w };
        horizontal(xr, whole, ox, out, taps, avx2);
        horizontal(yr, whole, oy, out, taps, avx2);
        horizontal(pxx, need, oxx, out, taps, avx2);
        horizontal(pyy, need, oyy, out, taps, avx2);
        horizontal(pxy, need, oxy, out, taps, avx2);
    }

    /// The SSIM map of row `r` over its `map` span, returned as the row's sum (every pixel
    /// outside the span has SSIM exactly 1); with `want_grad`, also the horizontal sums of its
    /// partials, into the rings. Per SSIM = A1·A2 / (B1·B2) with A1 = 2μxμy + C1,
    /// A2 = 2σxy + C2, B1 = μx² + μy² + C1, B2 = σx² + σy² + C2, σx² = E[x²] − μx²,
    /// σxy = E[xy] − μxμy. The adjoint of a zero-padded "same" convolution with a symmetric
    /// kernel is the same convolution, so each partial is blurred back onto the pixels of x.
    fn map_row(&self, r: usize, want_grad: bool, scratch: &mut BandScratch) -> f64 {
        let (w, avx2, taps) = (self.w, self.avx2, self.taps);
        let row = 3 * w;
        let span = self.spans.map[r];
        let s = (3 * (w - span.len())) as f64;
        if span.is_empty() {
            return s;
        }
        let cols = 3 * span.lo..3 * span.hi;
        let means =
            self.vertical_rings(&scratch.sums, &self.spans.sums, r, span, &mut scratch.means);
        if !want_grad {
            return s + map_row(means, None, avx2);
        }
        let (d_mu, rest) = scratch.partials.split_at_mut(row);
        let (d_xx, d_xy) = rest.split_at_mut(row);
        let grads = [
            &mut d_mu[cols.clone()],
            &mut d_xx[cols.clone()],
            &mut d_xy[cols.clone()],
        ];
        let value = s + map_row(means, Some(grads), avx2);
        // The partials are valid over the map's span only; the blur reads nothing outside it.
        let out = self.spans.partial_sums[r];
        let slot = (r % TAPS) * row..(r % TAPS + 1) * row;
        let [o_mu, o_xx, o_xy] = scratch
            .partial_sums
            .each_mut()
            .map(|s| &mut s[slot.clone()]);
        horizontal(d_mu, span, o_mu, out, taps, avx2);
        horizontal(d_xx, span, o_xx, out, taps, avx2);
        horizontal(d_xy, span, o_xy, out, taps, avx2);
        value
    }

    /// Adds `k` times the gradient of row `r` into `out` (that row of the gradient image), from
    /// its partials' window sums: the vertical pass over the rings of their horizontal sums.
    fn gradient_row(&self, r: usize, k: f32, out: &mut [f32], scratch: &mut BandScratch) {
        let row = 3 * self.w;
        let span = self.spans.grad[r];
        if span.is_empty() {
            return;
        }
        let cols = 3 * span.lo..3 * span.hi;
        let partials = self.vertical_rings(
            &scratch.partial_sums,
            &self.spans.partial_sums,
            r,
            span,
            &mut scratch.blurred,
        );
        let (xr, yr) = (
            &self.x[r * row..(r + 1) * row],
            &self.y[r * row..(r + 1) * row],
        );
        let images = [&xr[cols.clone()], &yr[cols.clone()]];
        add_gradient_row(&mut out[cols], images, partials, k, self.avx2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bands hold at least the rows asked for (but the image's), cover the rows in order and
    /// share the work about evenly.
    #[test]
    fn planned_bands_cover_the_rows_with_even_work() {
        let h = 1000;
        let map: Vec<Span> = (0..h)
            .map(|r| {
                if (300..700).contains(&r) {
                    Span {
                        lo: 10,
                        hi: 10 + r % 50 + 1,
                    }
                } else {
                    Span::EMPTY
                }
            })
            .collect();
        for (bands, min_rows) in [(1, 64), (6, 64), (6, 10), (50, 64), (3, 2000)] {
            let plan = plan_bands(&map, bands, min_rows);
            assert_eq!(plan.first().map(|b| b.start), Some(0));
            assert_eq!(plan.last().map(|b| b.end), Some(h));
            assert!(plan.windows(2).all(|p| p[0].end == p[1].start));
            assert!(plan.iter().all(|b| b.len() >= min_rows.min(h)), "{plan:?}");
            assert!(plan.len() <= bands.max(1), "{plan:?}");
            if bands == 6 && min_rows == 10 {
                assert_eq!(plan.len(), 6, "{plan:?}");
                let work = |b: &Range<usize>| map[b.clone()].iter().map(|s| s.len()).sum::<usize>();
                let total: usize = plan.iter().map(work).sum();
                assert!(plan.iter().all(|b| work(b) <= total / 6 + 60), "{plan:?}");
            }
        }
        assert_eq!(plan_bands(&[], 4, 64), vec![0..0]);
    }
}
