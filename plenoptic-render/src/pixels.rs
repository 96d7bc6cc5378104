//! From primitives to pixels, shared by the cloud and mesh renderers: shading a resolved z-buffer
//! into a [`ViewImage`], and supersampling with a box or Gaussian pixel filter.

use std::ops::{Range, RangeInclusive};

use camera_model::Camera;
use rayon::prelude::*;

use crate::camera::{ViewCamera, scaled_camera};
use crate::zbuffer::ZBuffer;
use crate::{Error, PIXEL_FILTER_VARIANCE, PixelFilter, ViewImage, ViewOptions};

/// Validates `opts` and renders with `render` from `camera` scaled `opts.supersample` times in
/// each direction; `render` ends with [`resolve`], which filters the sub-pixels down.
pub(crate) fn render_supersampled<F>(
    camera: &Camera,
    opts: &ViewOptions,
    render: F,
) -> Result<ViewImage, Error>
where
    F: Fn(&Camera) -> Result<ViewImage, Error>,
{
    opts.validate()?;
    match opts.supersample {
        1 => render(camera),
        k => render(&scaled_camera(camera, k)),
    }
}

/// Output rows per parallel work item of [`filter_down`]. Each item shades the sub-pixel rows
/// its own rows' filter reaches, so the rows the filter shares with the next item (six at k = 3:
/// nine taps less the pixel's own three) are shaded twice: an eighth more than the 48 sub-rows
/// of 16 output rows at k = 3.
const BAND_ROWS: usize = 16;

/// The image of a resolved z-buffer of `view` (`opts.supersample` times the output's size in
/// each direction), with `shade(id, x, y)` the colour of primitive `id` at sub-pixel (x, y):
/// colour (composited on the background) and alpha filtered down with `opts.pixel_filter`,
/// depth the mean over the pixel's own covered sub-pixels. The sub-pixels are shaded a band of
/// rows at a time and never stored whole: at 1024² and k = 3 the full-size colour, alpha and
/// depth took 190 MB a view in flight.
pub(crate) fn resolve<F>(
    view: &ViewCamera,
    zbuf: &ZBuffer,
    opts: &ViewOptions,
    shade: F,
) -> ViewImage
where
    F: Fn(u32, u32, u32) -> [f32; 3] + Sync,
{
    let k = opts.supersample as usize;
    if k == 1 {
        // One sample a pixel: the depth is written in the same loop as the colour, at no
        // cost worth a second loop without it.
        let mut image = shade_pixels(view, zbuf, opts.background, shade);
        if !opts.depth {
            image.depth = Vec::new();
        }
        return image;
    }
    let (bw, bh) = (view.width as usize, view.height as usize);
    let [r, g, b] = opts.background;
    let taps = filter_taps(opts.pixel_filter, k);
    let (rgb, alpha) = filter_down(bw, bh, k, &taps, [r, g, b, 0.0], |sy, row| {
        let span = zbuf.row_span(sy)?;
        for sx in span.clone() {
            if let Some((_, id)) = zbuf.get(sx, sy) {
                let [r, g, b] = shade(id, sx as u32, sy as u32);
                row[sx] = [r, g, b, 1.0];
            }
        }
        Some(span)
    });
    ViewImage {
        width: (bw / k) as u32,
        height: (bh / k) as u32,
        rgb,
        alpha,
        depth: if opts.depth {
            own_pixel_depth(zbuf, k)
        } else {
            Vec::new()
        },
    }
}

/// The 1-D taps of `filter` for k× sub-pixels: `(offset, weight)` with `offset` in sub-pixels
/// from the first sub-pixel of an output pixel (negative before it). The box's weights are 1
/// (sums of coverage stay exact until the one division).
fn filter_taps(filter: PixelFilter, k: usize) -> Vec<(i64, f32)> {
    match filter {
        PixelFilter::Box => (0..k as i64).map(|j| (j, 1.0)).collect(),
        PixelFilter::Gaussian => gaussian_taps(k as u32),
    }
}

/// Weights of the Gaussian pixel filter along one axis, for the sub-pixels of a k×-supersampled
/// row relative to the first sub-pixel of an output pixel: `(offset, weight)` with `offset` in
/// sub-pixels (negative before the pixel), normalised to sum to 1, truncated at 3σ.
fn gaussian_taps(k: u32) -> Vec<(i64, f32)> {
    let sigma = PIXEL_FILTER_VARIANCE.sqrt();
    let k = i64::from(k);
    let reach = (3.0 * sigma * k as f32).ceil() as i64;
    let mut taps: Vec<(i64, f32)> = (-reach..k + reach)
        .filter_map(|j| {
            // Distance in output pixels from the sub-pixel's centre to the pixel's centre.
            let d = (j as f32 + 0.5) / k as f32 - 0.5;
            (d.abs() <= 3.0 * sigma).then(|| (j, (-d * d / (2.0 * PIXEL_FILTER_VARIANCE)).exp()))
        })
        .collect();
    let sum: f32 = taps.iter().map(|t| t.1).sum();
    for t in &mut taps {
        t.1 /= sum;
    }
    taps
}

/// Separable filtering of a `bw`×`bh` image of k× sub-pixels, RGBA, down to its (bw/k)×(bh/k)
/// pixels with the 1-D `taps`, in parallel over bands of [`BAND_ROWS`] output rows. The image is
/// never stored: `fill_row(sy, row)` writes sub-pixel row `sy` when a band needs it. The row
/// comes holding `blank` in every sub-pixel, and `fill_row` writes only inside the span it
/// returns (`None`: nowhere). At the image's border the taps that fall outside are dropped and
/// the rest renormalised, so a constant image stays constant. Returns interleaved RGB and alpha.
///
/// A pixel whose taps all fall on blank sub-pixels is the filter of a blank image there, which
/// is one value a row (the border's renormalisation aside): it is computed once, by the same
/// operations in the same order, so skipping the pixels outside the spans changes no bit of the
/// result. A reference view of a paper-scale frame is about four-fifths such pixels.
fn filter_down<F>(
    bw: usize,
    bh: usize,
    k: usize,
    taps: &[(i64, f32)],
    blank: [f32; 4],
    fill_row: F,
) -> (Vec<f32>, Vec<f32>)
where
    F: Fn(usize, &mut [[f32; 4]]) -> Option<RangeInclusive<usize>> + Sync,
{
    filter_down_using(bw, bh, k, taps, blank, fill_row, crate::cpu::has_avx2())
}

/// [`filter_down`] with the AVX2 instantiation of its band loops or without it.
fn filter_down_using<F>(
    bw: usize,
    bh: usize,
    k: usize,
    taps: &[(i64, f32)],
    blank: [f32; 4],
    fill_row: F,
    avx2: bool,
) -> (Vec<f32>, Vec<f32>)
where
    F: Fn(usize, &mut [[f32; 4]]) -> Option<RangeInclusive<usize>> + Sync,
{
    let (w, h) = (bw / k, bh / k);
    let mut rgb = vec![0.0f32; 3 * w * h];
    let mut alpha = vec![0.0f32; w * h];
    let band = Band::new(bw, bh, k, taps, blank);
    rgb.par_chunks_mut(3 * w * BAND_ROWS)
        .zip(alpha.par_chunks_mut(w * BAND_ROWS))
        .enumerate()
        .for_each(|(i, (rgb, alpha))| band.filter(i, rgb, alpha, &fill_row, avx2));
    (rgb, alpha)
}

/// What every band of one [`filter_down`] shares.
struct Band<'a> {
    bw: usize,
    bh: usize,
    k: usize,
    taps: &'a [(i64, f32)],
    first: i64,
    last: i64,
    full_norm: f32,
    blank: [f32; 4],
    /// The row pass of a blank sub-row at an output pixel whose taps all fall inside the row.
    blank_row: [f32; 4],
    /// The output pixels whose row taps all fall inside a sub-row: `x` with
    /// `x·k + first ≥ 0` and `x·k + last < bw` (empty when the row is narrower than the taps).
    interior: Range<usize>,
}

impl<'a> Band<'a> {
    /// The filter of a `bw`×`bh` image of k× sub-pixels with the 1-D `taps`, whose sub-pixels
    /// outside the filled spans hold `blank`.
    fn new(bw: usize, bh: usize, k: usize, taps: &'a [(i64, f32)], blank: [f32; 4]) -> Self {
        let (first, last) = taps
            .iter()
            .fold((i64::MAX, i64::MIN), |(a, b), t| (a.min(t.0), b.max(t.0)));
        // The weights' sum, added in the same order as the border case adds them, so that an
        // interior pixel of a constant image comes out exactly that constant.
        let full_norm = taps.iter().fold(0.0f32, |n, t| n + t.1);
        // What the row pass computes for an interior pixel over blank sub-pixels, operation for
        // operation.
        let mut acc = [0.0f32; 4];
        for &(_, wt) in taps {
            add_weighted(&mut acc, wt, blank);
        }
        let w = bw / k;
        let lo = (0..w).find(|&x| (x * k) as i64 + first >= 0).unwrap_or(w);
        let hi = (0..w)
            .rev()
            .find(|&x| (x * k) as i64 + last < bw as i64)
            .map_or(0, |x| x + 1);
        Self {
            bw,
            bh,
            k,
            taps,
            first,
            last,
            full_norm,
            blank,
            blank_row: acc.map(|a| a / full_norm),
            interior: lo..hi.max(lo),
        }
    }

    /// Filters band `band` into its `rgb` and `alpha` rows: the AVX2 instantiation where the
    /// CPU has it, else the portable one (the same operations, so the same bits).
    fn filter<F>(&self, band: usize, rgb: &mut [f32], alpha: &mut [f32], fill_row: &F, avx2: bool)
    where
        F: Fn(usize, &mut [[f32; 4]]) -> Option<RangeInclusive<usize>> + Sync,
    {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU has AVX2.
            #[allow(unsafe_code)]
            return unsafe { self.filter_avx2(band, rgb, alpha, fill_row) };
        }
        let _ = avx2;
        self.filter_portable(band, rgb, alpha, fill_row);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn filter_avx2<F>(&self, band: usize, rgb: &mut [f32], alpha: &mut [f32], fill_row: &F)
    where
        F: Fn(usize, &mut [[f32; 4]]) -> Option<RangeInclusive<usize>> + Sync,
    {
        self.filter_portable(band, rgb, alpha, fill_row);
    }

    #[inline(always)]
    fn filter_portable<F>(&self, band: usize, rgb: &mut [f32], alpha: &mut [f32], fill_row: &F)
    where
        F: Fn(usize, &mut [[f32; 4]]) -> Option<RangeInclusive<usize>> + Sync,
    {
        let (bw, bh, k, taps) = (self.bw, self.bh, self.k, self.taps);
        let (first, last, full_norm) = (self.first, self.last, self.full_norm);
        let w = bw / k;
        let interior = self.interior.clone();
        let y0 = band * BAND_ROWS;
        let rows_out = alpha.len() / w;
        let sy0 = ((y0 * k) as i64 + first).max(0) as usize;
        let sy1 = (((y0 + rows_out - 1) * k) as i64 + last + 1).min(bh as i64) as usize;
        let mut sub = vec![self.blank; bw];
        // Row-filtered sub-rows sy0..sy1, w pixels each, and for each the output pixels whose
        // taps reach its filled span (every other interior pixel of it is `blank_row`).
        let mut rows = vec![[0.0f32; 4]; (sy1 - sy0) * w];
        let mut reached: Vec<Option<(usize, usize)>> = Vec::with_capacity(sy1 - sy0);
        for (sy, out) in (sy0..sy1).zip(rows.chunks_mut(w)) {
            let span = fill_row(sy, &mut sub);
            let (lo, hi) = span.as_ref().map_or((i64::MAX, i64::MIN), |s| {
                (*s.start() as i64, *s.end() as i64)
            });
            let mut reach: Option<(usize, usize)> = None;
            for (x, o) in out.iter_mut().enumerate() {
                let start = (x * k) as i64;
                if start + last >= lo && start + first <= hi {
                    reach = Some(reach.map_or((x, x), |(a, _)| (a, x)));
                } else if interior.contains(&x) {
                    *o = self.blank_row;
                    continue;
                }
                let mut acc = [0.0f32; 4];
                let norm = if interior.contains(&x) {
                    let s = &sub[(start + first) as usize..];
                    for &(off, wt) in taps {
                        add_weighted(&mut acc, wt, s[(off - first) as usize]);
                    }
                    full_norm
                } else {
                    let mut norm = 0.0f32;
                    for (sx, wt) in taps_within(taps, x * k, bw) {
                        norm += wt;
                        add_weighted(&mut acc, wt, sub[sx]);
                    }
                    norm
                };
                *o = acc.map(|a| a / norm);
            }
            reached.push(reach);
            if let Some(span) = span {
                sub[span].fill(self.blank);
            }
        }
        // Then columns, from the row-filtered sub-rows: the pixels at the row's borders and
        // those some tap's sub-row reached; every other pixel of an output row is the column
        // pass over `blank_row`, computed once for the row.
        let mut acc = vec![[0.0f32; 4]; w];
        for r in 0..rows_out {
            let y = y0 + r;
            let mut norm = 0.0f32;
            let mut blank_acc = [0.0f32; 4];
            let mut reach: Option<(usize, usize)> = None;
            for (sy, wt) in taps_within(taps, y * k, bh) {
                norm += wt;
                add_weighted(&mut blank_acc, wt, self.blank_row);
                if let Some((a, b)) = reached[sy - sy0] {
                    reach = Some(reach.map_or((a, b), |(c, d)| (c.min(a), d.max(b))));
                }
            }
            let blank_pixel = blank_acc.map(|a| a / norm);
            let spans = [
                Some((0, interior.start)),
                reach.map(|(a, b)| (a, b + 1)),
                Some((interior.end, w)),
            ];
            for x in 0..w {
                let i = r * w + x;
                rgb[3 * i..3 * i + 3].copy_from_slice(&blank_pixel[..3]);
                alpha[i] = blank_pixel[3];
            }
            for (a, b) in spans.into_iter().flatten().filter(|(a, b)| a < b) {
                let acc = &mut acc[a..b];
                acc.fill([0.0; 4]);
                for (sy, wt) in taps_within(taps, y * k, bh) {
                    let src = &rows[(sy - sy0) * w..][a..b];
                    for (a, &v) in acc.iter_mut().zip(src) {
                        add_weighted(a, wt, v);
                    }
                }
                for (x, a) in (a..b).zip(acc.iter()) {
                    let i = r * w + x;
                    for c in 0..3 {
                        rgb[3 * i + c] = a[c] / norm;
                    }
                    alpha[i] = a[3] / norm;
                }
            }
        }
    }
}

/// The taps of the output pixel whose first sub-pixel is `start` that fall inside a row (or
/// column) of `len` sub-pixels, as (sub-pixel index, weight), in tap order.
fn taps_within(
    taps: &[(i64, f32)],
    start: usize,
    len: usize,
) -> impl Iterator<Item = (usize, f32)> + '_ {
    taps.iter().filter_map(move |&(off, wt)| {
        let i = start as i64 + off;
        (0..len as i64).contains(&i).then_some((i as usize, wt))
    })
}

/// `acc += wt · v`, channel by channel.
#[inline]
fn add_weighted(acc: &mut [f32; 4], wt: f32, v: [f32; 4]) {
    for (a, v) in acc.iter_mut().zip(v) {
        *a += wt * v;
    }
}

/// Depth of each pixel of a k×-supersampled z-buffer: the mean over its own k×k sub-pixels
/// that something covers (0 where none is). Each pixel adds its sub-pixels' depths row by row,
/// left to right, and reads only the rows' written spans.
fn own_pixel_depth(zbuf: &ZBuffer, k: usize) -> Vec<f32> {
    let (w, h) = (zbuf.width() / k, zbuf.height() / k);
    let mut depth = vec![0.0f32; w * h];
    depth.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let mut covered = vec![0u32; w];
        for sy in y * k..(y + 1) * k {
            for sx in zbuf.row_span(sy).into_iter().flatten() {
                if let (Some((z, _)), true) = (zbuf.get(sx, sy), sx / k < w) {
                    row[sx / k] += z;
                    covered[sx / k] += 1;
                }
            }
        }
        for (d, &n) in row.iter_mut().zip(&covered) {
            if n > 0 {
                *d /= n as f32;
            }
        }
    });
    depth
}

/// Fills colour, alpha and depth from a resolved z-buffer of one sample a pixel, with
/// `shade(id, x, y)` giving the colour of primitive `id` at pixel (x, y).
fn shade_pixels<F>(view: &ViewCamera, zbuf: &ZBuffer, background: [f32; 3], shade: F) -> ViewImage
where
    F: Fn(u32, u32, u32) -> [f32; 3] + Sync,
{
    let w = view.width as usize;
    let n = view.pixels();
    let mut rgb = vec![0.0f32; 3 * n];
    let mut alpha = vec![0.0f32; n];
    let mut depth = vec![0.0f32; n];
    rgb.par_chunks_mut(3 * w)
        .zip(alpha.par_chunks_mut(w))
        .zip(depth.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((rgb_row, alpha_row), depth_row))| {
            for c in rgb_row.chunks_mut(3) {
                c.copy_from_slice(&background);
            }
            for x in zbuf.row_span(y).into_iter().flatten() {
                if let Some((z, id)) = zbuf.get(x, y) {
                    alpha_row[x] = 1.0;
                    depth_row[x] = z;
                    rgb_row[3 * x..3 * x + 3].copy_from_slice(&shade(id, x as u32, y as u32));
                }
            }
        });
    ViewImage {
        width: view.width,
        height: view.height,
        rgb,
        alpha,
        depth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A random k×-supersampled RGBA image of `bw`×`bh` sub-pixels.
    fn random_image(bw: usize, bh: usize, seed: u64) -> Vec<[f32; 4]> {
        let mut seed = seed;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        (0..bw * bh)
            .map(|_| [next(), next(), next(), next()])
            .collect()
    }

    /// [`filter_down`] of a stored image.
    fn filter_image(
        big: &[[f32; 4]],
        bw: usize,
        bh: usize,
        k: usize,
        taps: &[(i64, f32)],
    ) -> (Vec<f32>, Vec<f32>) {
        filter_down(bw, bh, k, taps, [0.0; 4], |sy, row| {
            row.copy_from_slice(&big[sy * bw..(sy + 1) * bw]);
            Some(0..=bw - 1)
        })
    }

    #[test]
    fn avx2_and_portable_filters_agree_bit_for_bit() {
        // Sizes that are not multiples of the band height, so the last band is short, and both
        // filters (their border taps renormalised).
        for (k, filter, bw, bh) in [
            (3, PixelFilter::Gaussian, 3 * 37, 3 * 21),
            (2, PixelFilter::Box, 2 * 19, 2 * 40),
        ] {
            let taps = filter_taps(filter, k);
            let big = random_image(bw, bh, 7);
            let run = |avx2| {
                filter_down_using(
                    bw,
                    bh,
                    k,
                    &taps,
                    [0.0; 4],
                    |sy, row| {
                        row.copy_from_slice(&big[sy * bw..(sy + 1) * bw]);
                        Some(0..=bw - 1)
                    },
                    avx2,
                )
            };
            let bits = |(rgb, alpha): (Vec<f32>, Vec<f32>)| {
                rgb.iter()
                    .chain(&alpha)
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            };
            assert_eq!(
                bits(run(false)),
                bits(run(crate::cpu::has_avx2())),
                "k = {k}"
            );
        }
    }

    /// The banded separable filter against a direct 2-D weighted sum in f64 (border pixels
    /// renormalised over the sub-pixels inside the image), on a random image tall enough for
    /// several bands, for odd and even k, with the Gaussian and the box.
    #[test]
    fn banded_filter_matches_the_direct_sum() {
        let sigma2 = f64::from(PIXEL_FILTER_VARIANCE);
        for k in [2usize, 3, 4] {
            for filter in [PixelFilter::Gaussian, PixelFilter::Box] {
                let (w, h) = (5usize, 2 * BAND_ROWS + 3);
                let (bw, bh) = (w * k, h * k);
                let big = random_image(bw, bh, 7 + k as u64);
                let (rgb, alpha) = filter_image(&big, bw, bh, k, &filter_taps(filter, k));
                for y in 0..h {
                    for x in 0..w {
                        let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                        let mut acc = [0.0f64; 4];
                        let mut norm = 0.0;
                        for sy in 0..bh {
                            for sx in 0..bw {
                                let dx = (sx as f64 + 0.5) / k as f64 - cx;
                                let dy = (sy as f64 + 0.5) / k as f64 - cy;
                                let wt = match filter {
                                    PixelFilter::Gaussian => {
                                        let reach = 3.0 * sigma2.sqrt();
                                        if dx.abs() > reach || dy.abs() > reach {
                                            continue;
                                        }
                                        (-(dx * dx + dy * dy) / (2.0 * sigma2)).exp()
                                    }
                                    PixelFilter::Box => {
                                        if sx / k != x || sy / k != y {
                                            continue;
                                        }
                                        1.0
                                    }
                                };
                                norm += wt;
                                for c in 0..4 {
                                    acc[c] += wt * f64::from(big[sy * bw + sx][c]);
                                }
                            }
                        }
                        let got = [
                            rgb[3 * (y * w + x)],
                            rgb[3 * (y * w + x) + 1],
                            rgb[3 * (y * w + x) + 2],
                            alpha[y * w + x],
                        ];
                        for c in 0..4 {
                            let direct = acc[c] / norm;
                            assert!(
                                (f64::from(got[c]) - direct).abs() < 1e-5,
                                "k {k} {filter:?} ({x}, {y}) channel {c}: {} vs {direct}",
                                got[c]
                            );
                        }
                    }
                }
            }
        }
    }

    /// Each band asks for every sub-row its rows' filter reaches, and only those, in order.
    #[test]
    fn bands_shade_the_rows_their_filter_reaches() {
        let k = 3;
        let (w, h) = (4usize, 2 * BAND_ROWS + 5);
        let (bw, bh) = (w * k, h * k);
        let taps = filter_taps(PixelFilter::Gaussian, k);
        let asked = std::sync::Mutex::new(vec![0u32; bh]);
        filter_down(bw, bh, k, &taps, [0.0; 4], |sy, row| {
            asked.lock().unwrap()[sy] += 1;
            row.fill([0.5; 4]);
            Some(0..=bw - 1)
        });
        let asked = asked.into_inner().unwrap();
        // Every sub-row is shaded, the rows near a band's edge at most twice.
        assert!(asked.iter().all(|&n| (1..=2).contains(&n)), "{asked:?}");
        let twice = asked.iter().filter(|&&n| n == 2).count();
        let (first, last) = (taps[0].0, taps[taps.len() - 1].0);
        let per_seam = (last - first + 1) as usize - k;
        assert_eq!(
            twice,
            2 * per_seam,
            "two seams of {per_seam} sub-rows: {asked:?}"
        );
    }

    /// A constant image stays exactly constant, borders included; the Gaussian's taps sum to
    /// 1 and, for odd k, are symmetric about the pixel's centre sub-pixel.
    #[test]
    fn filters_keep_constants_and_the_gaussian_is_centred() {
        let taps = gaussian_taps(3);
        assert!((taps.iter().map(|t| t.1).sum::<f32>() - 1.0).abs() < 1e-6);
        for &(off, wt) in &taps {
            let mirror = taps.iter().find(|t| t.0 == 2 - off).unwrap();
            assert!((mirror.1 - wt).abs() < 1e-7);
        }
        for filter in [PixelFilter::Gaussian, PixelFilter::Box] {
            let big = vec![[0.25f32, 1.0, 0.0, 1.0]; 12 * 9];
            let (rgb, alpha) = filter_image(&big, 12, 9, 3, &filter_taps(filter, 3));
            assert_eq!(alpha.len(), 4 * 3);
            assert!(alpha.iter().all(|&a| a == 1.0), "{filter:?} {alpha:?}");
            assert!(
                rgb.chunks(3).all(|c| c == [0.25, 1.0, 0.0]),
                "{filter:?} {rgb:?}"
            );
        }
    }

    /// Filling only the spans that hold something (the rest left blank, some rows empty) gives
    /// the same bits as filling every sub-pixel of every row, for both filters, odd and even k,
    /// spans at the borders and in the middle, a non-black blank, and both instantiations.
    #[test]
    fn skipping_blank_pixels_changes_no_bit() {
        let blank = [0.3f32, 0.7, 0.1, 0.0];
        for (k, filter) in [
            (3, PixelFilter::Gaussian),
            (2, PixelFilter::Gaussian),
            (4, PixelFilter::Box),
        ] {
            let taps = filter_taps(filter, k);
            let (w, h) = (23usize, 2 * BAND_ROWS + 7);
            let (bw, bh) = (w * k, h * k);
            let noise = random_image(bw, bh, 11 + k as u64);
            // Row sy holds noise over its span, blank elsewhere; a third of the rows are empty.
            let span_of = |sy: usize| match sy % 6 {
                0 | 3 => None,
                1 => Some(0..=2),
                2 => Some(bw - 4..=bw - 1),
                4 => Some(sy % bw / 2..=sy % bw / 2 + 5),
                _ => Some(bw / 3..=bw / 3),
            };
            let pixel = |sx: usize, sy: usize| match span_of(sy) {
                Some(s) if s.contains(&sx) => noise[sy * bw + sx],
                _ => blank,
            };
            let bits = |(rgb, alpha): (Vec<f32>, Vec<f32>)| {
                rgb.iter()
                    .chain(&alpha)
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            };
            for avx2 in [false, crate::cpu::has_avx2()] {
                let whole = filter_down_using(
                    bw,
                    bh,
                    k,
                    &taps,
                    blank,
                    |sy, row| {
                        for (sx, p) in row.iter_mut().enumerate() {
                            *p = pixel(sx, sy);
                        }
                        Some(0..=bw - 1)
                    },
                    avx2,
                );
                let spans = filter_down_using(
                    bw,
                    bh,
                    k,
                    &taps,
                    blank,
                    |sy, row| {
                        assert!(row.iter().all(|&p| p == blank), "row {sy} not blank");
                        let span = span_of(sy)?;
                        for sx in span.clone() {
                            row[sx] = pixel(sx, sy);
                        }
                        Some(span)
                    },
                    avx2,
                );
                assert_eq!(bits(whole), bits(spans), "k = {k}, {filter:?}, avx2 {avx2}");
            }
        }
    }
}
