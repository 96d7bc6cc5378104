//! Structural similarity (SSIM) of interleaved RGB images and its exact gradient.
//!
//! Follows the 3DGS reference (`utils/loss_utils.py` of Inria's trainer): an 11×11 Gaussian window
//! with σ = 1.5, applied per channel as a zero-padded "same" convolution, C1 = 0.01², C2 = 0.03²,
//! and the mean of the SSIM map over all pixels and channels. The window is separable, so every
//! filter is a horizontal then a vertical 11-tap pass.

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

/// Windowed mean and variance of a fixed target image, computed once and reused every step.
#[derive(Debug, Clone)]
pub struct SsimTarget {
    width: u32,
    height: u32,
    mu: Vec<f32>,
    sigma2: Vec<f32>,
}

/// Reusable buffers for SSIM at one image size: no allocation per evaluation.
#[derive(Debug)]
pub struct Ssim {
    width: usize,
    height: usize,
    taps: [f32; TAPS],
    tmp: Vec<f32>,
    mu_x: Vec<f32>,
    e_xx: Vec<f32>,
    e_xy: Vec<f32>,
    prod: Vec<f32>,
    row_sums: Vec<f64>,
}

impl Ssim {
    /// Buffers for `width × height` RGB images.
    #[must_use]
    pub fn new(width: u32, height: u32) -> Self {
        let n = 3 * width as usize * height as usize;
        Self {
            width: width as usize,
            height: height as usize,
            taps: gaussian_taps(),
            tmp: vec![0.0; n],
            mu_x: vec![0.0; n],
            e_xx: vec![0.0; n],
            e_xy: vec![0.0; n],
            prod: vec![0.0; n],
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

    /// Precomputes the windowed statistics of a target image `y` (RGB, 3·W·H).
    ///
    /// # Panics
    /// If `y` does not hold 3·W·H values (a caller bug, not an input condition).
    #[must_use]
    pub fn target(&mut self, y: &[f32]) -> SsimTarget {
        assert_eq!(
            y.len(),
            self.mu_x.len(),
            "target size does not match SSIM buffers"
        );
        let mut mu = vec![0.0; y.len()];
        let mut sigma2 = vec![0.0; y.len()];
        blur(
            y,
            &mut mu,
            &mut self.tmp,
            self.width,
            self.height,
            &self.taps,
        );
        self.prod
            .par_iter_mut()
            .zip(y.par_iter())
            .for_each(|(p, &v)| *p = v * v);
        blur(
            &self.prod,
            &mut sigma2,
            &mut self.tmp,
            self.width,
            self.height,
            &self.taps,
        );
        sigma2
            .par_iter_mut()
            .zip(mu.par_iter())
            .for_each(|(s, &m)| *s -= m * m);
        SsimTarget {
            width: self.width as u32,
            height: self.height as u32,
            mu,
            sigma2,
        }
    }

    /// Mean SSIM of `x` against `y` (both RGB, 3·W·H).
    ///
    /// # Panics
    /// If the image sizes do not match the buffers (a caller bug).
    pub fn value(&mut self, x: &[f32], y: &[f32]) -> f64 {
        let target = self.target(y);
        self.evaluate(x, y, &target, None)
    }

    /// Mean SSIM of `x` against the target `y` whose statistics are `target`; when `grad` is
    /// given as `(scale, out)`, adds `scale · ∂SSIM/∂x` into `out`.
    ///
    /// # Panics
    /// If the image sizes do not match the buffers (a caller bug).
    pub fn evaluate(
        &mut self,
        x: &[f32],
        y: &[f32],
        target: &SsimTarget,
        grad: Option<(f32, &mut [f32])>,
    ) -> f64 {
        let n = self.mu_x.len();
        assert!(
            x.len() == n && y.len() == n,
            "image size does not match SSIM buffers"
        );
        assert!(
            target.width as usize == self.width && target.height as usize == self.height,
            "SSIM target statistics are for another image size"
        );
        let (w, h, taps) = (self.width, self.height, self.taps);
        blur(x, &mut self.mu_x, &mut self.tmp, w, h, &taps);
        self.prod
            .par_iter_mut()
            .zip(x.par_iter())
            .for_each(|(p, &v)| *p = v * v);
        blur(&self.prod, &mut self.e_xx, &mut self.tmp, w, h, &taps);
        self.prod
            .par_iter_mut()
            .zip(x.par_iter().zip(y.par_iter()))
            .for_each(|(p, (&a, &b))| *p = a * b);
        blur(&self.prod, &mut self.e_xy, &mut self.tmp, w, h, &taps);

        // Per pixel, SSIM = A1·A2 / (B1·B2) with A1 = 2μxμy + C1, A2 = 2σxy + C2,
        // B1 = μx² + μy² + C1, B2 = σx² + σy² + C2, σx² = E[x²] − μx², σxy = E[xy] − μxμy.
        // With a gradient, the three buffers are overwritten by ∂SSIM/∂μx, ∂SSIM/∂E[x²] and
        // ∂SSIM/∂E[xy] (the chain through σx² and σxy folded into the first).
        let want_grad = grad.is_some();
        let row = 3 * w;
        // Per-row partial sums, added in row order afterwards: rayon's reduction tree depends on
        // scheduling, and a fixed order keeps the value bit-identical from run to run.
        self.mu_x
            .par_chunks_mut(row)
            .zip(self.e_xx.par_chunks_mut(row))
            .zip(self.e_xy.par_chunks_mut(row))
            .zip(target.mu.par_chunks(row).zip(target.sigma2.par_chunks(row)))
            .map(|(((mx, exx), exy), (my, syy))| {
                let mut s = 0.0f64;
                for i in 0..mx.len() {
                    let (mu_x, mu_y) = (mx[i], my[i]);
                    let sxx = exx[i] - mu_x * mu_x;
                    let sxy = exy[i] - mu_x * mu_y;
                    let a1 = 2.0 * mu_x * mu_y + C1;
                    let a2 = 2.0 * sxy + C2;
                    let b1 = mu_x * mu_x + mu_y * mu_y + C1;
                    let b2 = sxx + syy[i] + C2;
                    let map = (a1 * a2) / (b1 * b2);
                    s += f64::from(map);
                    if want_grad {
                        let inv = 1.0 / (b1 * b2);
                        let d_sxx = -map / b2;
                        let d_sxy = 2.0 * a1 * inv;
                        let d_mu = 2.0 * mu_y * a2 * inv - map * 2.0 * mu_x / b1;
                        mx[i] = d_mu - 2.0 * mu_x * d_sxx - mu_y * d_sxy;
                        exx[i] = d_sxx;
                        exy[i] = d_sxy;
                    }
                }
                s
            })
            .collect_into_vec(&mut self.row_sums);
        let sum: f64 = self.row_sums.iter().sum();
        if let Some((scale, out)) = grad {
            assert_eq!(
                out.len(),
                n,
                "gradient buffer size does not match SSIM buffers"
            );
            // The adjoint of a zero-padded "same" convolution with a symmetric kernel is the
            // same convolution, so each partial is blurred back onto the pixels of x.
            blur_in_place(&mut self.mu_x, &mut self.tmp, w, h, &taps);
            blur_in_place(&mut self.e_xx, &mut self.tmp, w, h, &taps);
            blur_in_place(&mut self.e_xy, &mut self.tmp, w, h, &taps);
            let k = scale / n as f32;
            out.par_chunks_mut(row)
                .zip(x.par_chunks(row).zip(y.par_chunks(row)))
                .zip(self.mu_x.par_chunks(row))
                .zip(self.e_xx.par_chunks(row).zip(self.e_xy.par_chunks(row)))
                .for_each(|(((o, (xr, yr)), dm), (dxx, dxy))| {
                    for i in 0..o.len() {
                        o[i] += k * (dm[i] + 2.0 * xr[i] * dxx[i] + yr[i] * dxy[i]);
                    }
                });
        }
        sum / n as f64
    }
}

/// Zero-padded separable Gaussian blur of an interleaved RGB image: `src` → `dst`, `tmp` scratch.
fn blur(src: &[f32], dst: &mut [f32], tmp: &mut [f32], w: usize, h: usize, taps: &[f32; TAPS]) {
    horizontal(src, tmp, w, taps);
    vertical(tmp, dst, w, h, taps);
}

/// [`blur`] whose result replaces its input.
fn blur_in_place(buf: &mut [f32], tmp: &mut [f32], w: usize, h: usize, taps: &[f32; TAPS]) {
    horizontal(buf, tmp, w, taps);
    vertical(tmp, buf, w, h, taps);
}

/// Horizontal pass: along a row, neighbouring pixels of the same channel are 3 floats apart, so
/// each tap is one shifted, contiguous multiply-add over the row (vectorisable); samples beyond
/// the border are zero.
fn horizontal(src: &[f32], dst: &mut [f32], w: usize, taps: &[f32; TAPS]) {
    let row = 3 * w;
    dst.par_chunks_mut(row)
        .zip(src.par_chunks(row))
        .for_each(|(d, s)| {
            d.fill(0.0);
            for (k, &g) in taps.iter().enumerate() {
                let off = 3 * k as isize - 3 * RADIUS as isize;
                let lo = (-off).max(0) as usize;
                let hi = (row as isize - off).min(row as isize).max(0) as usize;
                if lo >= hi {
                    continue;
                }
                let src_lo = (lo as isize + off) as usize;
                let src_hi = (hi as isize + off) as usize;
                for (o, &v) in d[lo..hi].iter_mut().zip(&s[src_lo..src_hi]) {
                    *o += g * v;
                }
            }
        });
}

/// Vertical pass: each output row is the weighted sum of up to 11 input rows.
fn vertical(src: &[f32], dst: &mut [f32], w: usize, h: usize, taps: &[f32; TAPS]) {
    let row = 3 * w;
    dst.par_chunks_mut(row).enumerate().for_each(|(y, d)| {
        d.fill(0.0);
        for (k, &g) in taps.iter().enumerate() {
            let yy = y as isize + k as isize - RADIUS as isize;
            if yy < 0 || yy >= h as isize {
                continue;
            }
            let s = &src[yy as usize * row..(yy as usize + 1) * row];
            for (o, &v) in d.iter_mut().zip(s) {
                *o += g * v;
            }
        }
    });
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

    fn random_pair(w: usize, h: usize, seed: u64) -> (Vec<f32>, Vec<f32>) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let y: Vec<f32> = (0..3 * w * h).map(|_| rng.random::<f32>()).collect();
        let x: Vec<f32> = y
            .iter()
            .map(|&v| (v + 0.3 * (rng.random::<f32>() - 0.5)).clamp(0.0, 1.0))
            .collect();
        (x, y)
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
        let xd: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        let yd: Vec<f64> = y.iter().map(|&v| f64::from(v)).collect();
        let reference = reference_ssim(&xd, &yd, w, h);
        assert!(
            (ours - reference).abs() < 2e-6,
            "ours {ours} reference {reference}"
        );
        assert!(reference < 0.99, "test images must differ");
    }

    #[test]
    fn gradient_matches_finite_differences_of_direct_ssim() {
        let (w, h) = (13, 9);
        let (x, y) = random_pair(w, h, 3);
        let mut s = Ssim::new(w as u32, h as u32);
        let target = s.target(&y);
        let mut grad = vec![0.0f32; x.len()];
        s.evaluate(&x, &y, &target, Some((1.0, &mut grad)));
        let xd: Vec<f64> = x.iter().map(|&v| f64::from(v)).collect();
        let yd: Vec<f64> = y.iter().map(|&v| f64::from(v)).collect();
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
        let t = s.target(&y);
        let mut g1 = vec![0.0f32; x.len()];
        s.evaluate(&x, &y, &t, Some((1.0, &mut g1)));
        let mut g2 = vec![1.0f32; x.len()];
        s.evaluate(&x, &y, &t, Some((-0.5, &mut g2)));
        for (a, b) in g1.iter().zip(&g2) {
            assert!((1.0 - 0.5 * a - b).abs() < 1e-6);
        }
    }
}
