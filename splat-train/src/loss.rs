//! The photometric training loss (1 − λ)·L1 + λ·(1 − SSIM) (3DGS paper Eq. 7), or with the
//! root mean squared error in place of L1 ([`Photometric`]), and its gradient.

use rayon::prelude::*;

use crate::config::Photometric;
use crate::ssim::Ssim;

/// Value of one evaluation of the loss, with its parts.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct LossValue {
    /// The weighted total that is minimised.
    pub total: f64,
    /// Mean absolute error over all pixels and channels.
    pub l1: f64,
    /// Mean SSIM over all pixels and channels.
    pub ssim: f64,
    /// Mean squared error (for PSNR; its root is the objective's photometric term under
    /// [`Photometric::L2`]).
    pub mse: f64,
}

/// Lanes of the photometric passes' partial sums.
const LANES: usize = 8;

/// The L1 pass over one chunk: writes ∂L1/∂render (±`k`, 0 where equal) into `d` and returns
/// Σ|r − g| and Σ(r − g)² in f64. The AVX2 instantiation where the CPU has it: the same
/// operations in the same order, so the same values.
fn l1_chunk(d: &mut [f32], r: &[f32], g: &[f32], k: f32, avx2: bool) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { l1_chunk_avx2(d, r, g, k) };
    }
    let _ = avx2;
    l1_chunk_impl(d, r, g, k)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn l1_chunk_avx2(d: &mut [f32], r: &[f32], g: &[f32], k: f32) -> (f64, f64) {
    l1_chunk_impl(d, r, g, k)
}

/// The sums are kept per lane (value `i` in lane `i mod 8`) and the lanes added in order at
/// the end: one running sum was a chain of dependent f64 additions, one value at a time.
#[inline(always)]
fn l1_chunk_impl(d: &mut [f32], r: &[f32], g: &[f32], k: f32) -> (f64, f64) {
    error_sums(d, r, g, |e| {
        // Branch-free sign: k, −k or 0 (also for NaN, as the comparisons fail).
        (if e > 0.0 { k } else { 0.0 }) - if e < 0.0 { k } else { 0.0 }
    })
}

/// The squared-error pass over one chunk: writes the error r − g into `d` (scaled into the
/// RMSE's gradient once the whole image's sum is known) and returns the sums of
/// [`l1_chunk`]. The AVX2 instantiation where the CPU has it.
fn error_chunk(d: &mut [f32], r: &[f32], g: &[f32], avx2: bool) -> (f64, f64) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { error_chunk_avx2(d, r, g) };
    }
    let _ = avx2;
    error_sums(d, r, g, |e| e)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn error_chunk_avx2(d: &mut [f32], r: &[f32], g: &[f32]) -> (f64, f64) {
    error_sums(d, r, g, |e| e)
}

/// Σ|r − g| and Σ(r − g)² over one chunk in f64, writing `grad(r − g)` into `d`.
#[inline(always)]
fn error_sums(d: &mut [f32], r: &[f32], g: &[f32], grad: impl Fn(f32) -> f32) -> (f64, f64) {
    let n = d.len().min(r.len()).min(g.len());
    let (mut a, mut s) = ([0.0_f64; LANES], [0.0_f64; LANES]);
    let whole = n - n % LANES;
    let step = |d: &mut f32, r: f32, g: f32, a: &mut f64, s: &mut f64| {
        let e = r - g;
        *a += f64::from(e.abs());
        *s += f64::from(e * e);
        *d = grad(e);
    };
    for ((d, r), g) in d[..whole]
        .chunks_exact_mut(LANES)
        .zip(r[..whole].chunks_exact(LANES))
        .zip(g[..whole].chunks_exact(LANES))
    {
        for l in 0..LANES {
            step(&mut d[l], r[l], g[l], &mut a[l], &mut s[l]);
        }
    }
    for i in whole..n {
        step(&mut d[i], r[i], g[i], &mut a[i - whole], &mut s[i - whole]);
    }
    (a.iter().sum(), s.iter().sum())
}

/// Values per parallel task of the photometric pass.
const CHUNK: usize = 4096;

/// Reusable buffers for the loss at one image size.
#[derive(Debug)]
pub struct Loss {
    ssim: Ssim,
    d_rgb: Vec<f32>,
    partials: Vec<(f64, f64)>,
}

impl Loss {
    /// Buffers for `width × height` RGB images.
    #[must_use]
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            ssim: Ssim::new(width, height),
            d_rgb: vec![0.0; 3 * width as usize * height as usize],
            partials: Vec::new(),
        }
    }

    /// Image width these buffers serve.
    #[must_use]
    pub fn width(&self) -> u32 {
        self.ssim.width()
    }

    /// Image height these buffers serve.
    #[must_use]
    pub fn height(&self) -> u32 {
        self.ssim.height()
    }

    /// Evaluates the loss of `render` against `image`, (1 − `lambda`)·`photometric` +
    /// `lambda`·D-SSIM, and leaves ∂loss/∂render in [`Loss::d_rgb`].
    ///
    /// # Panics
    /// If the image sizes do not match the buffers (a caller bug).
    pub fn evaluate(
        &mut self,
        render: &[f32],
        image: &[f32],
        photometric: Photometric,
        lambda: f32,
    ) -> LossValue {
        let n = render.len();
        let k = (1.0 - lambda) / n as f32;
        // Partial sums per chunk, added in order so the value does not depend on scheduling.
        let avx2 = splat_core::has_avx2();
        let chunks = self
            .d_rgb
            .par_chunks_mut(CHUNK)
            .zip(render.par_chunks(CHUNK).zip(image.par_chunks(CHUNK)));
        match photometric {
            // d|r − g|/dr = sign(r − g), 0 at equality (PyTorch's subgradient).
            Photometric::L1 => chunks
                .map(|(d, (r, g))| l1_chunk(d, r, g, k, avx2))
                .collect_into_vec(&mut self.partials),
            Photometric::L2 => chunks
                .map(|(d, (r, g))| error_chunk(d, r, g, avx2))
                .collect_into_vec(&mut self.partials),
        }
        let (abs_sum, sq_sum) = self
            .partials
            .iter()
            .fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
        let (l1, mse) = (abs_sum / n as f64, sq_sum / n as f64);
        let term = match photometric {
            Photometric::L1 => l1,
            Photometric::L2 => {
                // d√(mean e²)/dr = e / (n·RMSE); at RMSE 0 every error is 0 and so is the
                // gradient (the subgradient 0 of the norm at its minimum).
                let rmse = mse.sqrt();
                let scale = if rmse > 0.0 { k / rmse as f32 } else { 0.0 };
                self.d_rgb.par_chunks_mut(CHUNK).for_each(|d| {
                    for v in d {
                        *v *= scale;
                    }
                });
                rmse
            }
        };
        let ssim = self
            .ssim
            .evaluate(render, image, Some((-lambda, &mut self.d_rgb)));
        LossValue {
            total: f64::from(1.0 - lambda) * term + f64::from(lambda) * (1.0 - ssim),
            l1,
            ssim,
            mse,
        }
    }

    /// ∂loss/∂render of the last [`Loss::evaluate`].
    #[must_use]
    pub fn d_rgb(&self) -> &[f32] {
        &self.d_rgb
    }
}

/// Pixels per parallel task of [`alpha_l1`].
const ALPHA_CHUNK: usize = 4096;

/// Mean absolute error of an alpha map against a target mask (16-bit fractions of one, as a
/// [`View`](crate::View) holds it); writes `weight · ∂/∂alpha` into `d_alpha` and returns the
/// unweighted error. Each chunk's mask is expanded to f32 and run through the colour's L1
/// kernel (`l1_chunk`: the same sign rule, its sums in lanes and vectorised), where a scalar
/// loop with one running f64 sum and two branches a pixel took 0.7 ms of every 1024² step.
pub fn alpha_l1(alpha: &[f32], mask: &[u16], weight: f32, d_alpha: &mut [f32]) -> f64 {
    let n = alpha.len();
    let k = weight / n as f32;
    let avx2 = splat_core::has_avx2();
    // Partial sums per chunk, added in order so the value does not depend on scheduling.
    let partials: Vec<f64> = d_alpha
        .par_chunks_mut(ALPHA_CHUNK)
        .zip(
            alpha
                .par_chunks(ALPHA_CHUNK)
                .zip(mask.par_chunks(ALPHA_CHUNK)),
        )
        .map(|(d, (a, m))| {
            let mut target = [0.0_f32; ALPHA_CHUNK];
            for (t, &m) in target.iter_mut().zip(m) {
                *t = crate::view::from_unorm16(m);
            }
            l1_chunk(d, a, &target[..m.len()], k, avx2).0
        })
        .collect();
    partials.iter().sum::<f64>() / n as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// A 16 × 11 reference and a render within ±0.1 of it, from `seed`.
    fn image_and_render(seed: u64) -> (Vec<f32>, Vec<f32>) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let image: Vec<f32> = (0..3 * 16 * 11).map(|_| rng.random::<f32>()).collect();
        let render = image
            .iter()
            .map(|&v| v + 0.2 * (rng.random::<f32>() - 0.5))
            .collect();
        (image, render)
    }

    /// The loss's central difference in value `i` of the render, over 2·`eps`.
    fn central_difference(
        loss: &mut Loss,
        render: &[f32],
        image: &[f32],
        photometric: Photometric,
        i: usize,
        eps: f32,
    ) -> f64 {
        let mut p = render.to_vec();
        p[i] += eps;
        let fp = loss.evaluate(&p, image, photometric, 0.2).total;
        p[i] -= 2.0 * eps;
        let fm = loss.evaluate(&p, image, photometric, 0.2).total;
        (fp - fm) / f64::from(2.0 * eps)
    }

    /// The mean of `f(r − g)` over the values, in f64.
    fn mean_of(render: &[f32], image: &[f32], f: impl Fn(f32) -> f64) -> f64 {
        let sum: f64 = render.iter().zip(image).map(|(a, b)| f(a - b)).sum();
        sum / render.len() as f64
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let (image, render) = image_and_render(9);
        let n = image.len();
        let mut loss = Loss::new(16, 11);
        let v = loss.evaluate(&render, &image, Photometric::L1, 0.2);
        let grad = loss.d_rgb().to_vec();
        let l1 = mean_of(&render, &image, |e| f64::from(e.abs()));
        assert!((v.l1 - l1).abs() < 1e-9);
        let eps = 5e-3f32;
        for i in (0..n).step_by(13) {
            if (render[i] - image[i]).abs() < 2.0 * eps {
                continue; // the L1 kink lies inside the difference interval
            }
            let fd = central_difference(&mut loss, &render, &image, Photometric::L1, i, eps);
            let err = (fd - f64::from(grad[i])).abs() * n as f64;
            assert!(err < 0.05, "pixel {i}: fd {fd} analytic {}", grad[i]);
        }
    }

    /// The root-mean-squared term: its value against an f64 sum, its gradient (with the
    /// D-SSIM's) against central differences at every pixel (no kink away from zero error).
    #[test]
    fn squared_error_gradient_matches_finite_differences() {
        let (image, render) = image_and_render(21);
        let n = image.len();
        let mut loss = Loss::new(16, 11);
        let v = loss.evaluate(&render, &image, Photometric::L2, 0.2);
        let grad = loss.d_rgb().to_vec();
        let mse = mean_of(&render, &image, |e| f64::from(e * e));
        assert!((v.mse - mse).abs() < 1e-12 * mse, "{} against {mse}", v.mse);
        let want = 0.8 * mse.sqrt() + 0.2 * (1.0 - v.ssim);
        assert!((v.total - want).abs() < 1e-9, "{} against {want}", v.total);
        for (i, &g) in grad.iter().enumerate() {
            let fd = central_difference(&mut loss, &render, &image, Photometric::L2, i, 1e-3);
            let err = (fd - f64::from(g)).abs() * n as f64;
            assert!(err < 0.02, "pixel {i}: fd {fd} analytic {g}");
        }
    }

    /// Where the render is the image, the squared term's gradient is 0, not 0/0.
    #[test]
    fn squared_error_of_a_perfect_render_has_no_gradient() {
        let image: Vec<f32> = (0..3 * 8 * 8).map(|i| (i % 7) as f32 / 7.0).collect();
        let mut loss = Loss::new(8, 8);
        let v = loss.evaluate(&image, &image, Photometric::L2, 0.0);
        assert_eq!(v.total, 0.0);
        assert!(loss.d_rgb().iter().all(|&d| d == 0.0));
    }

    #[test]
    fn alpha_loss_value_and_sign() {
        // The mask as a view holds it: 16-bit fractions (32768 is the alpha of the third pixel).
        let alpha = [0.2, 0.9, crate::view::from_unorm16(32768)];
        let mask = [0, u16::MAX, 32768];
        let mut d = [9.0; 3];
        let e = alpha_l1(&alpha, &mask, 3.0, &mut d);
        assert!((e - 0.1).abs() < 1e-7);
        assert_eq!(d, [1.0, -1.0, 0.0]);
    }

    /// Over several chunks and a partial last one (the vector loops and their tails): the
    /// value is the f64 mean of |alpha − mask| and each gradient is exactly ±k or 0.
    #[test]
    fn alpha_loss_over_many_chunks_matches_a_scalar_reference() {
        let n = 3 * ALPHA_CHUNK + 1234;
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let mask: Vec<u16> = (0..n)
            .map(|i| if i % 5 == 0 { 0 } else { rng.random() })
            .collect();
        let alpha: Vec<f32> = (0..n)
            .map(|i| match i % 3 {
                0 => crate::view::from_unorm16(mask[i]),
                _ => rng.random(),
            })
            .collect();
        let (weight, mut d) = (0.1_f32, vec![9.0_f32; n]);
        let e = alpha_l1(&alpha, &mask, weight, &mut d);
        let k = weight / n as f32;
        let mut sum = 0.0_f64;
        for i in 0..n {
            let err = alpha[i] - crate::view::from_unorm16(mask[i]);
            sum += f64::from(err.abs());
            let want = if err > 0.0 {
                k
            } else if err < 0.0 {
                -k
            } else {
                0.0
            };
            assert_eq!(d[i].to_bits(), want.to_bits(), "pixel {i}");
        }
        assert!(
            (e - sum / n as f64).abs() <= 1e-12 * e,
            "{e} {}",
            sum / n as f64
        );
        assert!(d.iter().filter(|&&g| g == 0.0).count() >= n / 3);
    }
}
