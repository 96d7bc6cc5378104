//! Structural similarity (SSIM) of interleaved RGB images and its exact gradient.
//!
//! Follows the 3DGS reference (`utils/loss_utils.py` of Inria's trainer): an 11×11 Gaussian window
//! with σ = 1.5, applied per channel as a zero-padded "same" convolution, C1 = 0.01², C2 = 0.03²,
//! and the mean of the SSIM map over all pixels and channels. The window is separable, so every
//! filter is a horizontal then a vertical 11-tap pass.
//!
//! Only where the images differ: where x and y are equal over a pixel's whole window, that
//! pixel's SSIM is exactly 1 (μx = μy and σx² = σy² = σxy make both factors equal their
//! denominators) and it adds exactly nothing to the gradient (∂SSIM/∂μx = 0, and the
//! σ terms, −2x/B₂ + 2y/B₂, cancel wherever x = y). A render and its reference agree exactly on
//! the background a splat never touches (both are the background colour), which is most of a
//! view of a single object, so every pass runs only over each row's span of pixels that can
//! matter, worked out from where the images differ. Inside the spans the arithmetic is the
//! dense filter's; outside them the value is the exact 1 and the gradient the exact 0 that the
//! dense filter approaches up to rounding.

use std::ops::Range;
use std::sync::{Mutex, PoisonError};

use rayon::prelude::*;

/// Half-width of the Gaussian window (11 taps), as in Inria's `create_window(11, ...)`.
pub const RADIUS: usize = 5;
/// Standard deviation of the Gaussian window in pixels (Inria: `gaussian(window_size, 1.5)`).
pub const SIGMA: f32 = 1.5;
/// Stabiliser of the luminance term, (0.01 · L)² with dynamic range L = 1.
pub const C1: f32 = 0.01 * 0.01;
/// Stabiliser of the contrast-structure term, (0.03 · L)² with L = 1.
pub const C2: f32 = 0.03 * 0.03;

const TAPS: usize = 2 * RADIUS + 1;

/// The normalised 1D Gaussian taps of the window.
#[must_use]
pub fn gaussian_taps() -> [f32; TAPS] {
    let mut g = [0.0f64; TAPS];
    for (i, v) in g.iter_mut().enumerate() {
        let d = i as f64 - RADIUS as f64;
        *v = (-d * d / (2.0 * f64::from(SIGMA) * f64::from(SIGMA))).exp();
    }
    let sum: f64 = g.iter().sum();
    g.map(|v| (v / sum) as f32)
}

/// A half-open range of pixel columns in one row; empty when `lo >= hi`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Span {
    lo: usize,
    hi: usize,
}

impl Span {
    const EMPTY: Self = Self { lo: 0, hi: 0 };

    fn is_empty(self) -> bool {
        self.lo >= self.hi
    }

    fn len(self) -> usize {
        self.hi.saturating_sub(self.lo)
    }

    /// The smallest span holding both.
    fn union(self, other: Self) -> Self {
        match (self.is_empty(), other.is_empty()) {
            (true, _) => other,
            (_, true) => self,
            _ => Self {
                lo: self.lo.min(other.lo),
                hi: self.hi.max(other.hi),
            },
        }
    }

    fn intersect(self, other: Self) -> Self {
        Self {
            lo: self.lo.max(other.lo),
            hi: self.hi.min(other.hi),
        }
    }

    /// Widened by `r` columns each way, within a row of `w` pixels.
    fn widen(self, r: usize, w: usize) -> Self {
        if self.is_empty() {
            return self;
        }
        Self {
            lo: self.lo.saturating_sub(r),
            hi: (self.hi + r).min(w),
        }
    }
}

/// For every row, the union of `spans` over the rows at most `RADIUS` away, widened by `widen`.
fn spread(spans: &[Span], widen: usize, w: usize, out: &mut Vec<Span>) {
    let h = spans.len();
    out.clear();
    out.extend((0..h).map(|y| {
        spans[y.saturating_sub(RADIUS)..(y + RADIUS + 1).min(h)]
            .iter()
            .fold(Span::EMPTY, |a, &s| a.union(s))
            .widen(widen, w)
    }));
}

/// Per row, where each pass works (see the module docs for why nothing outside matters).
#[derive(Debug, Default)]
struct Spans {
    /// Pixels where x and y differ in some channel.
    differ: Vec<Span>,
    /// Pixels whose window holds a differing pixel: where the SSIM map is computed.
    map: Vec<Span>,
    /// Where horizontal window sums of the images are needed (the map spans of the rows
    /// within reach of the vertical pass).
    sums: Vec<Span>,
    /// Where horizontal window sums of the map's partial derivatives are nonzero.
    partial_sums: Vec<Span>,
    /// Pixels that receive gradient.
    grad: Vec<Span>,
}

/// Reusable buffers for SSIM at one image size: no allocation per evaluation once warm.
///
/// The passes run band by band: each band of rows streams its horizontal window sums, its map
/// rows and their partials' horizontal sums through rings of 11 rows (the window's height), so
/// that what the vertical passes read was written a few rows earlier and is still in cache
/// (whole-image buffers of the eight quantities, 100 MB at 1024², were written out and read
/// back from memory, and the vertical pass waited on each newly read row). A band also works
/// out the rows just outside it that its own rows' windows reach, which its neighbours work out
/// too: the same operations on the same values, so every value, and the result, is the same
/// bit for bit whatever the bands.
#[derive(Debug)]
pub struct Ssim {
    width: usize,
    height: usize,
    taps: [f32; TAPS],
    spans: Spans,
    /// Bands' buffers not in use, for the next evaluation's bands.
    scratch: Mutex<Vec<BandScratch>>,
    row_sums: Vec<f64>,
}

/// One band's buffers at a row width of `row` floats (3 a pixel).
#[derive(Debug)]
struct BandScratch {
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
    fn new(row: usize) -> Self {
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
const BANDS_PER_THREAD: usize = 3;

/// Fewest rows of a band (past the image's first and last): a band works out up to
/// `2 · RADIUS` rows beyond each end, so narrower bands would repeat much of their work.
const MIN_BAND_ROWS: usize = 64;

/// What every band of one evaluation reads.
struct Pass<'a> {
    x: &'a [f32],
    y: &'a [f32],
    w: usize,
    h: usize,
    taps: &'a [f32; TAPS],
    spans: &'a Spans,
    avx2: bool,
}

impl Ssim {
    /// Buffers for `width × height` RGB images.
    #[must_use]
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width: width as usize,
            height: height as usize,
            taps: gaussian_taps(),
            spans: Spans::default(),
            scratch: Mutex::new(Vec::new()),
            row_sums: Vec::with_capacity(height as usize),
        }
    }

    /// Image width these buffers serve.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.width as u32
    }

    /// Image height these buffers serve.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.height as u32
    }

    /// Mean SSIM of `x` against `y` (both RGB, 3·W·H).
    ///
    /// # Panics
    /// If the image sizes do not match the buffers (a caller bug).
    pub fn value(&mut self, x: &[f32], y: &[f32]) -> f64 {
        self.evaluate(x, y, None)
    }

    /// Mean SSIM of `x` against `y` (both RGB, 3·W·H); when `grad` is given as `(scale, out)`,
    /// adds `scale · ∂SSIM/∂x` into `out`.
    ///
    /// # Panics
    /// If the image sizes do not match the buffers (a caller bug).
    pub fn evaluate(&mut self, x: &[f32], y: &[f32], grad: Option<(f32, &mut [f32])>) -> f64 {
        let n = 3 * self.width * self.height;
        assert!(
            x.len() == n && y.len() == n,
            "image size does not match SSIM buffers"
        );
        if n == 0 {
            return f64::NAN;
        }
        self.find_spans(x, y);
        let bands = plan_bands(
            &self.spans.map,
            BANDS_PER_THREAD * rayon::current_num_threads(),
            MIN_BAND_ROWS,
        );
        self.evaluate_in_bands(x, y, grad, &bands)
    }

    /// [`Ssim::evaluate`] over the given bands of rows (consecutive, covering the image), the
    /// spans already found.
    fn evaluate_in_bands(
        &mut self,
        x: &[f32],
        y: &[f32],
        grad: Option<(f32, &mut [f32])>,
        bands: &[Range<usize>],
    ) -> f64 {
        let (w, h) = (self.width, self.height);
        let n = 3 * w * h;
        let pass = Pass {
            x,
            y,
            w,
            h,
            taps: &self.taps,
            spans: &self.spans,
            avx2: splat_core::has_avx2(),
        };
        let lengths: Vec<usize> = bands.iter().map(ExactSizeIterator::len).collect();
        self.row_sums.clear();
        self.row_sums.resize(h, 0.0);
        let values = split_by_lengths(&mut self.row_sums, lengths.iter().copied());
        let k = grad.as_ref().map(|(scale, _)| scale / n as f32);
        let outs: Vec<Option<&mut [f32]>> = match grad {
            Some((_, out)) => {
                assert_eq!(
                    out.len(),
                    n,
                    "gradient buffer size does not match SSIM buffers"
                );
                split_by_lengths(out, lengths.iter().map(|&len| 3 * w * len))
                    .into_iter()
                    .map(Some)
                    .collect()
            }
            None => bands.iter().map(|_| None).collect(),
        };
        let pool = &self.scratch;
        bands
            .par_iter()
            .zip(values)
            .zip(outs)
            .with_max_len(1)
            .for_each(|((band, values), out)| {
                let taken = pool.lock().unwrap_or_else(PoisonError::into_inner).pop();
                let mut scratch = taken.unwrap_or_else(|| BandScratch::new(3 * w));
                let grad = k.zip(out);
                pass.band(band.clone(), values, grad, &mut scratch);
                pool.lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .push(scratch);
            });
        // Per-row sums added in row order: the value is the same bits whatever the bands.
        let sum: f64 = self.row_sums.iter().sum();
        sum / n as f64
    }

    /// Fills the per-row spans for images `x` and `y`.
    fn find_spans(&mut self, x: &[f32], y: &[f32]) {
        let w = self.width;
        let sp = &mut self.spans;
        x.par_chunks(3 * w)
            .zip(y.par_chunks(3 * w))
            .map(|(xr, yr)| {
                let differs = |p: usize| xr[3 * p..3 * p + 3] != yr[3 * p..3 * p + 3];
                match (0..w).find(|&p| differs(p)) {
                    Some(lo) => {
                        let hi = (lo..w).rev().find(|&p| differs(p)).map_or(lo, |p| p) + 1;
                        Span { lo, hi }
                    }
                    None => Span::EMPTY,
                }
            })
            .collect_into_vec(&mut sp.differ);
        spread(&sp.differ, RADIUS, w, &mut sp.map);
        spread(&sp.map, 0, w, &mut sp.sums);
        sp.partial_sums.clear();
        sp.partial_sums
            .extend(sp.map.iter().map(|s| s.widen(RADIUS, w)));
        spread(&sp.partial_sums, 0, w, &mut sp.grad);
    }
}

/// Splits `rows` into bands of consecutive rows for [`Ssim::evaluate`]: about `bands` of them
/// with equal work (the length of each row's map span; rows without one cost nothing), none
/// narrower than `min_rows` unless the image is, covering every row.
fn plan_bands(map: &[Span], bands: usize, min_rows: usize) -> Vec<Range<usize>> {
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
fn split_by_lengths<T>(data: &mut [T], lengths: impl Iterator<Item = usize>) -> Vec<&mut [T]> {
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
    fn band(
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

/// Lanes of the per-row sums of the SSIM map.
const LANES: usize = 8;

/// The products x², y², xy of one row's values, into `dst`. The AVX2 instantiation where the
/// CPU has it (as each kernel here: the same operations, so the same values).
fn square_products(x: &[f32], y: &[f32], dst: [&mut [f32]; 3], avx2: bool) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { square_products_avx2(x, y, dst) };
    }
    let _ = avx2;
    square_products_impl(x, y, dst);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn square_products_avx2(x: &[f32], y: &[f32], dst: [&mut [f32]; 3]) {
    square_products_impl(x, y, dst);
}

#[inline(always)]
fn square_products_impl(x: &[f32], y: &[f32], [xx, yy, xy]: [&mut [f32]; 3]) {
    for ((((xx, yy), xy), &x), &y) in xx.iter_mut().zip(yy).zip(xy).zip(x).zip(y) {
        *xx = x * x;
        *yy = y * y;
        *xy = x * y;
    }
}

/// The SSIM map over one row's span from its window means `[μx, μy, E[x²], E[y²], E[xy]]`;
/// with `grads`, also writes the map's partials ∂/∂μx (with the chain through σx² and σxy),
/// ∂/∂E[x²] and ∂/∂E[xy]. Returns the map's sum in f64, kept per lane and the lanes added in
/// order (one running sum was a chain of dependent additions that kept the loop scalar).
fn map_row(means: [&[f32]; 5], grads: Option<[&mut [f32]; 3]>, avx2: bool) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { map_row_avx2(means, grads) };
    }
    let _ = avx2;
    map_row_impl(means, grads)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn map_row_avx2(means: [&[f32]; 5], grads: Option<[&mut [f32]; 3]>) -> f64 {
    map_row_impl(means, grads)
}

#[inline(always)]
fn map_row_impl(means: [&[f32]; 5], mut grads: Option<[&mut [f32]; 3]>) -> f64 {
    let n = means.iter().map(|m| m.len()).min().unwrap_or(0);
    let mut lanes = [0.0_f64; LANES];
    // Whole groups of lanes through fixed-size copies (vectorised), then the rest one by one.
    let mut j0 = 0;
    while j0 < n {
        let len = LANES.min(n - j0);
        let mut m = [[0.0_f32; LANES]; 5];
        for (m, src) in m.iter_mut().zip(&means) {
            m[..len].copy_from_slice(&src[j0..j0 + len]);
        }
        let mut map = [0.0_f32; LANES];
        let mut partials = [[0.0_f32; LANES]; 3];
        for l in 0..LANES {
            let t = MapTerms::new([m[0][l], m[1][l], m[2][l], m[3][l], m[4][l]]);
            map[l] = t.map;
            [partials[0][l], partials[1][l], partials[2][l]] = t.partials();
        }
        for l in 0..len {
            lanes[l] += f64::from(map[l]);
        }
        if let Some(grads) = grads.as_mut() {
            for (g, p) in grads.iter_mut().zip(&partials) {
                g[j0..j0 + len].copy_from_slice(&p[..len]);
            }
        }
        j0 += LANES;
    }
    lanes.iter().sum()
}

/// The terms of the SSIM map at one value: SSIM = A1·A2 / (B1·B2) with A1 = 2μxμy + C1,
/// A2 = 2σxy + C2, B1 = μx² + μy² + C1, B2 = σx² + σy² + C2, σx² = E[x²] − μx²,
/// σxy = E[xy] − μxμy.
struct MapTerms {
    mu_x: f32,
    mu_y: f32,
    a1: f32,
    a2: f32,
    b1: f32,
    b2: f32,
    map: f32,
}

impl MapTerms {
    /// The terms from the window means `[μx, μy, E[x²], E[y²], E[xy]]`.
    #[inline(always)]
    fn new([mu_x, mu_y, exx, eyy, exy]: [f32; 5]) -> Self {
        let sxx = exx - mu_x * mu_x;
        let syy = eyy - mu_y * mu_y;
        let sxy = exy - mu_x * mu_y;
        let a1 = 2.0 * mu_x * mu_y + C1;
        let a2 = 2.0 * sxy + C2;
        let b1 = mu_x * mu_x + mu_y * mu_y + C1;
        let b2 = sxx + syy + C2;
        Self {
            mu_x,
            mu_y,
            a1,
            a2,
            b1,
            b2,
            map: (a1 * a2) / (b1 * b2),
        }
    }

    /// The map's partials ∂/∂μx (with the chain through σx² and σxy), ∂/∂E[x²], ∂/∂E[xy].
    #[inline(always)]
    fn partials(&self) -> [f32; 3] {
        let Self {
            mu_x,
            mu_y,
            a1,
            a2,
            b1,
            b2,
            map,
        } = *self;
        let inv = 1.0 / (b1 * b2);
        let g_sxx = -map / b2;
        let g_sxy = 2.0 * a1 * inv;
        let g_mu = 2.0 * mu_y * a2 * inv - map * 2.0 * mu_x / b1;
        [g_mu - 2.0 * mu_x * g_sxx - mu_y * g_sxy, g_sxx, g_sxy]
    }
}

/// Adds `k` times the gradient of one row's span into `out`: from the blurred partials
/// `[∂/∂μx, ∂/∂E[x²], ∂/∂E[xy]]` and the images `[x, y]`.
fn add_gradient_row(
    out: &mut [f32],
    images: [&[f32]; 2],
    partials: [&[f32]; 3],
    k: f32,
    avx2: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { add_gradient_row_avx2(out, images, partials, k) };
    }
    let _ = avx2;
    add_gradient_row_impl(out, images, partials, k);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_gradient_row_avx2(out: &mut [f32], images: [&[f32]; 2], partials: [&[f32]; 3], k: f32) {
    add_gradient_row_impl(out, images, partials, k);
}

#[inline(always)]
fn add_gradient_row_impl(
    out: &mut [f32],
    [x, y]: [&[f32]; 2],
    [dm, dxx, dxy]: [&[f32]; 3],
    k: f32,
) {
    for (((((o, &x), &y), &dm), &dxx), &dxy) in
        out.iter_mut().zip(x).zip(y).zip(dm).zip(dxx).zip(dxy)
    {
        *o += k * (dm + 2.0 * x * dxx + y * dxy);
    }
}

/// Horizontal pass over the columns of `out` in one interleaved RGB row: `dst[c] = Σₜ gₜ ·
/// src[c + t − R]` per channel, with `src` taken as zero outside `valid` (and the row). Along a
/// row, neighbouring pixels of a channel are 3 floats apart, so each tap is one shifted,
/// contiguous multiply-add (vectorisable).
fn horizontal(
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
struct RowSums<'a> {
    src: &'a [f32],
    slots: usize,
    h: usize,
    row: usize,
    filled: &'a [Span],
}

/// Vertical pass for row `r` over the columns of `out`: the weighted sum of the rows of
/// `sums` up to `RADIUS` away, each taken as zero outside the image and outside its own span.
/// `dst` holds the span's 3·len floats.
fn vertical(
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
    use rand::{RngExt, SeedableRng};

    /// Direct 2D SSIM in f64, the window summed in full (not separable) with explicit zero padding.
    fn reference_ssim(x: &[f64], y: &[f64], w: usize, h: usize) -> f64 {
        let g: Vec<f64> = (0..TAPS)
            .map(|i| {
                let d = i as f64 - RADIUS as f64;
                (-d * d / (2.0 * 1.5 * 1.5)).exp()
            })
            .collect();
        let gs: f64 = g.iter().sum();
        let c1 = 0.01f64.powi(2);
        let c2 = 0.03f64.powi(2);
        let mut total = 0.0;
        for py in 0..h {
            for px in 0..w {
                for c in 0..3 {
                    let (mut mx, mut my, mut exx, mut eyy, mut exy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for ky in 0..TAPS {
                        for kx in 0..TAPS {
                            let sx = px as isize + kx as isize - RADIUS as isize;
                            let sy = py as isize + ky as isize - RADIUS as isize;
                            if sx < 0 || sy < 0 || sx >= w as isize || sy >= h as isize {
                                continue;
                            }
                            let wgt = g[kx] * g[ky] / (gs * gs);
                            let i = (sy as usize * w + sx as usize) * 3 + c;
                            mx += wgt * x[i];
                            my += wgt * y[i];
                            exx += wgt * x[i] * x[i];
                            eyy += wgt * y[i] * y[i];
                            exy += wgt * x[i] * y[i];
                        }
                    }
                    let sxx = exx - mx * mx;
                    let syy = eyy - my * my;
                    let sxy = exy - mx * my;
                    total += ((2.0 * mx * my + c1) * (2.0 * sxy + c2))
                        / ((mx * mx + my * my + c1) * (sxx + syy + c2));
                }
            }
        }
        total / (3 * w * h) as f64
    }

    fn f64s(v: &[f32]) -> Vec<f64> {
        v.iter().map(|&x| f64::from(x)).collect()
    }

    /// Asserts that `ours` (the SSIM of `x` against `y`) is within 2e-6 of the f64 direct
    /// window sum, and returns that reference value.
    fn checked_against_reference(ours: f64, x: &[f32], y: &[f32], w: usize, h: usize) -> f64 {
        let reference = reference_ssim(&f64s(x), &f64s(y), w, h);
        assert!(
            (ours - reference).abs() < 2e-6,
            "ours {ours} reference {reference}"
        );
        reference
    }

    fn random_pair(w: usize, h: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let y: Vec<f32> = (0..3 * w * h).map(|_| rng.random::<f32>()).collect();
        let x: Vec<f32> = y
            .iter()
            .map(|&v| (v + 0.3 * (rng.random::<f32>() - 0.5)).clamp(0.0, 1.0))
            .collect();
        (x, y)
    }

    /// The AVX2 and portable window passes must give the same sums bit for bit (the tests
    /// against references exercise only the one this machine picks).
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

    /// The bands change where the work is done, never a value: the SSIM and its gradient are
    /// the same bits for one band, bands of one row each (every row worked out by up to 21
    /// bands), random cuts and the planned bands, on an image with a differing region that
    /// starts and ends mid-image and a band boundary inside it. Also the value alone (its
    /// bands reach only R rows out).
    #[test]
    fn bands_give_the_same_bits_however_the_rows_are_cut() {
        let (w, h) = (41, 67);
        let (mut x, y) = random_pair(w, h, 21);
        // Rows 0..9 and 50.. equal in both images: empty spans at both ends.
        for r in (0..9).chain(50..h) {
            let row = 3 * w * r..3 * w * (r + 1);
            x[row.clone()].copy_from_slice(&y[row]);
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(22);
        let mut cuts: Vec<Vec<Range<usize>>> = vec![
            vec![0..h],
            (0..h).map(|r| r..r + 1).collect(),
            vec![0..20, 20..21, 21..h],
        ];
        for _ in 0..4 {
            let mut ends: Vec<usize> = (0..5).map(|_| rng.random_range(1..h)).collect();
            ends.sort_unstable();
            ends.dedup();
            let mut start = 0;
            let mut bands: Vec<Range<usize>> = ends
                .iter()
                .map(|&e| {
                    let band = start..e;
                    start = e;
                    band
                })
                .collect();
            bands.push(start..h);
            cuts.push(bands);
        }
        let mut s = Ssim::new(w as u32, h as u32);
        s.find_spans(&x, &y);
        cuts.push(plan_bands(&s.spans.map, 3, 4));
        let run = |s: &mut Ssim, bands: &[Range<usize>]| {
            let mut grad = vec![0.25_f32; 3 * w * h];
            let value = s.evaluate_in_bands(&x, &y, Some((-0.5, &mut grad)), bands);
            let alone = s.evaluate_in_bands(&x, &y, None, bands);
            assert_eq!(value.to_bits(), alone.to_bits(), "{bands:?}");
            (
                value.to_bits(),
                grad.iter().map(|g| g.to_bits()).collect::<Vec<_>>(),
            )
        };
        let whole = run(&mut s, &cuts[0]);
        assert!(whole.1.iter().any(|&g| g != 0.25_f32.to_bits()));
        for bands in &cuts[1..] {
            assert_eq!(run(&mut s, bands), whole, "{bands:?}");
        }
        // The public call, planning its own bands, agrees as well.
        let mut grad = vec![0.25_f32; 3 * w * h];
        let value = Ssim::new(w as u32, h as u32).evaluate(&x, &y, Some((-0.5, &mut grad)));
        assert_eq!(value.to_bits(), whole.0);
        checked_against_reference(value, &x, &y, w, h);
    }

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

    #[test]
    fn identical_images_have_ssim_one() {
        let (_, y) = random_pair(20, 17, 1);
        let mut s = Ssim::new(20, 17);
        assert!((s.value(&y, &y) - 1.0).abs() < 1e-6);
    }

    #[test]
    fn separable_value_matches_direct_window_sum() {
        let (w, h) = (23, 14);
        let (x, y) = random_pair(w, h, 2);
        let mut s = Ssim::new(w as u32, h as u32);
        let ours = s.value(&x, &y);
        let reference = checked_against_reference(ours, &x, &y, w, h);
        assert!(reference < 0.99, "test images must differ");
    }

    #[test]
    fn gradient_matches_finite_differences_of_direct_ssim() {
        let (w, h) = (13, 9);
        let (x, y) = random_pair(w, h, 3);
        let mut s = Ssim::new(w as u32, h as u32);
        let mut grad = vec![0.0f32; x.len()];
        s.evaluate(&x, &y, Some((1.0, &mut grad)));
        let xd = f64s(&x);
        let yd = f64s(&y);
        let n = x.len() as f64;
        let eps = 1e-5;
        let mut max_rel = 0.0f64;
        for i in (0..x.len()).step_by(7) {
            let mut xp = xd.clone();
            xp[i] += eps;
            let mut xm = xd.clone();
            xm[i] -= eps;
            let fd =
                (reference_ssim(&xp, &yd, w, h) - reference_ssim(&xm, &yd, w, h)) / (2.0 * eps);
            // Compare per-pixel contributions (× N) so that the tolerance is not swamped by 1/N.
            let err = (f64::from(grad[i]) * n - fd * n).abs() / (fd.abs() * n).max(0.05);
            max_rel = max_rel.max(err);
        }
        assert!(max_rel < 2e-3, "max relative error {max_rel}");
    }

    #[test]
    fn gradient_scale_and_accumulation() {
        let (w, h) = (12, 12);
        let (x, y) = random_pair(w, h, 4);
        let mut s = Ssim::new(w as u32, h as u32);
        let mut g1 = vec![0.0f32; x.len()];
        s.evaluate(&x, &y, Some((1.0, &mut g1)));
        let mut g2 = vec![1.0f32; x.len()];
        s.evaluate(&x, &y, Some((-0.5, &mut g2)));
        for (a, b) in g1.iter().zip(&g2) {
            assert!((1.0 - 0.5 * a - b).abs() < 1e-6);
        }
    }

    /// The exact gradient of [`reference_ssim`] with respect to x, in f64, from direct 2D
    /// window sums over the whole image (no spans, no separable passes).
    fn reference_grad(x: &[f64], y: &[f64], w: usize, h: usize) -> Vec<f64> {
        let g: Vec<f64> = (0..TAPS)
            .map(|i| {
                let d = i as f64 - RADIUS as f64;
                (-d * d / (2.0 * 1.5 * 1.5)).exp()
            })
            .collect();
        let gs: f64 = g.iter().sum();
        let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
        let n = (3 * w * h) as f64;
        let mut grad = vec![0.0; x.len()];
        let g = &g;
        let window = |px: usize, py: usize| {
            (0..TAPS * TAPS).filter_map(move |k| {
                let sx = (px + k % TAPS).checked_sub(RADIUS)?;
                let sy = (py + k / TAPS).checked_sub(RADIUS)?;
                (sx < w && sy < h).then(|| (sy * w + sx, g[k % TAPS] * g[k / TAPS] / (gs * gs)))
            })
        };
        for py in 0..h {
            for px in 0..w {
                for c in 0..3 {
                    let (mut mx, mut my, mut exx, mut eyy, mut exy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                    for (p, wt) in window(px, py) {
                        let (a, b) = (x[3 * p + c], y[3 * p + c]);
                        mx += wt * a;
                        my += wt * b;
                        exx += wt * a * a;
                        eyy += wt * b * b;
                        exy += wt * a * b;
                    }
                    let (sxx, syy, sxy) = (exx - mx * mx, eyy - my * my, exy - mx * my);
                    let (a1, a2) = (2.0 * mx * my + c1, 2.0 * sxy + c2);
                    let (b1, b2) = (mx * mx + my * my + c1, sxx + syy + c2);
                    let map = a1 * a2 / (b1 * b2);
                    // ∂map/∂μx, ∂map/∂σx², ∂map/∂σxy, then chained to each window pixel's x.
                    let d_mu = 2.0 * my * a2 / (b1 * b2) - map * 2.0 * mx / b1;
                    let d_sxx = -map / b2;
                    let d_sxy = 2.0 * a1 / (b1 * b2);
                    for (p, wt) in window(px, py) {
                        let (a, b) = (x[3 * p + c], y[3 * p + c]);
                        let dx = d_mu + d_sxx * (2.0 * a - 2.0 * mx) + d_sxy * (b - my);
                        grad[3 * p + c] += wt * dx / n;
                    }
                }
            }
        }
        grad
    }

    /// Images equal on a flat, non-black background except for a patch at the right border and
    /// one pixel in the top-left corner: the spans skip most of the image, and the value and
    /// every pixel's gradient still match the dense f64 computation.
    #[test]
    fn images_equal_outside_small_regions_match_the_dense_computation() {
        let (w, h) = (41, 33);
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let y: Vec<f32> = (0..3 * w * h).map(|i| [0.7, 0.2, 0.45][i % 3]).collect();
        let mut x = y.clone();
        for py in 12..20 {
            for px in 35..41 {
                for c in 0..3 {
                    x[3 * (py * w + px) + c] = rng.random::<f32>();
                }
            }
        }
        x[1] = 0.9;
        let mut s = Ssim::new(w as u32, h as u32);
        let mut grad = vec![0.0f32; x.len()];
        let ours = s.evaluate(&x, &y, Some((1.0, &mut grad)));
        let reference = checked_against_reference(ours, &x, &y, w, h);
        assert!(reference < 0.995, "the images must differ");
        let (xd, yd) = (f64s(&x), f64s(&y));
        let truth = reference_grad(&xd, &yd, w, h);
        let n = x.len() as f64;
        let scale = truth.iter().fold(0.0f64, |m, g| m.max(g.abs())) * n;
        for (i, (&ours, &t)) in grad.iter().zip(&truth).enumerate() {
            let err = (f64::from(ours) - t).abs() * n;
            assert!(err < 1e-4 * scale, "value {i}: ours {ours} truth {t}");
        }
        // Far from both regions the gradient is exactly zero, not rounding noise.
        let (px, py) = (15, 28);
        assert_eq!(grad[3 * (py * w + px)], 0.0);
        // The spans left most of the image out.
        let mapped: usize = s.spans.map.iter().map(|sp| sp.len()).sum();
        assert!(mapped < w * h / 2, "{mapped} of {} pixels mapped", w * h);
    }

    /// The f64 gradient reference agrees with finite differences of the f64 value.
    #[test]
    fn reference_gradient_matches_finite_differences() {
        let (w, h) = (9, 8);
        let (x, y) = random_pair(w, h, 6);
        let xd = f64s(&x);
        let yd = f64s(&y);
        let g = reference_grad(&xd, &yd, w, h);
        let eps = 1e-6;
        for i in (0..xd.len()).step_by(5) {
            let (mut p, mut m) = (xd.clone(), xd.clone());
            p[i] += eps;
            m[i] -= eps;
            let fd = (reference_ssim(&p, &yd, w, h) - reference_ssim(&m, &yd, w, h)) / (2.0 * eps);
            assert!(
                (fd - g[i]).abs() < 1e-7,
                "value {i}: fd {fd} analytic {}",
                g[i]
            );
        }
    }

    #[test]
    fn identical_images_do_no_work_and_give_zero_gradient() {
        let (_, y) = random_pair(20, 17, 7);
        let mut s = Ssim::new(20, 17);
        let mut grad = vec![0.0f32; y.len()];
        assert_eq!(s.evaluate(&y, &y, Some((1.0, &mut grad))), 1.0);
        assert!(grad.iter().all(|&g| g == 0.0));
        assert!(s.spans.map.iter().all(|sp| sp.is_empty()));
    }
}
