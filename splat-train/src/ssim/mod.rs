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
//!
//! [`Ssim`] holds the buffers and runs the passes; `spans` works out where they run, `bands`
//! runs them band by band of rows, `window` is the separable Gaussian window's two passes and
//! `terms` the per-pixel SSIM map and its partials.

mod bands;
mod spans;
mod terms;
mod window;

use std::ops::Range;
use std::sync::{Mutex, PoisonError};

use rayon::prelude::*;

use bands::{BANDS_PER_THREAD, BandScratch, MIN_BAND_ROWS, Pass, plan_bands, split_by_lengths};
use spans::Spans;

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
        self.spans.find(x, y, self.width);
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
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The window's 1D Gaussian taps in f64, written out from σ = 1.5 (not from [`SIGMA`] or
    /// [`gaussian_taps`], which they check), and their sum.
    fn reference_window() -> (Vec<f64>, f64) {
        let g: Vec<f64> = (0..TAPS)
            .map(|i| {
                let d = i as f64 - RADIUS as f64;
                (-d * d / (2.0 * 1.5 * 1.5)).exp()
            })
            .collect();
        let sum = g.iter().sum();
        (g, sum)
    }

    /// Direct 2D SSIM in f64, the window summed in full (not separable) with explicit zero padding.
    fn reference_ssim(x: &[f64], y: &[f64], w: usize, h: usize) -> f64 {
        let (g, gs) = reference_window();
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

    pub(super) fn random_pair(w: usize, h: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let y: Vec<f32> = (0..3 * w * h).map(|_| rng.random::<f32>()).collect();
        let x: Vec<f32> = y
            .iter()
            .map(|&v| (v + 0.3 * (rng.random::<f32>() - 0.5)).clamp(0.0, 1.0))
            .collect();
        (x, y)
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
        s.spans.find(&x, &y, w);
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
        let (g, gs) = reference_window();
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
