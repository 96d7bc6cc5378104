//! Image quality metrics: PSNR and SSIM on colours in [0, 1].

use crate::ssim::Ssim;

/// Peak signal-to-noise ratio in dB of `a` against `b` (peak 1); infinite when they are equal.
#[must_use]
pub fn psnr(a: &[f32], b: &[f32]) -> f64 {
    psnr_from_mse(mse(a, b))
}

/// Mean squared error of `a` against `b`.
#[must_use]
pub fn mse(a: &[f32], b: &[f32]) -> f64 {
    let n = a.len().min(b.len());
    if n == 0 {
        return 0.0;
    }
    let s: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| f64::from(x - y) * f64::from(x - y))
        .sum();
    s / n as f64
}

/// PSNR in dB (peak 1) from a mean squared error.
#[must_use]
pub fn psnr_from_mse(mse: f64) -> f64 {
    -10.0 * mse.log10()
}

/// Mean SSIM (11×11 Gaussian window, σ 1.5, as in 3DGS) of RGB images `a` and `b` of size w × h.
///
/// # Panics
/// If `a` or `b` does not hold 3·w·h values.
#[must_use]
pub fn ssim(a: &[f32], b: &[f32], w: u32, h: u32) -> f64 {
    Ssim::new(w, h).value(a, b)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn psnr_closed_form() {
        let a = [0.5f32; 12];
        let b = [0.6f32; 12];
        // MSE = 0.01 → 20 dB.
        assert!((psnr(&a, &b) - 20.0).abs() < 1e-4);
        assert!(psnr(&a, &a).is_infinite());
    }

    #[test]
    fn ssim_of_identical_and_inverted_images() {
        let a: Vec<f32> = (0..3 * 30 * 30)
            .map(|i| ((i * 37) % 101) as f32 / 100.0)
            .collect();
        assert!((ssim(&a, &a, 30, 30) - 1.0).abs() < 1e-6);
        let inv: Vec<f32> = a.iter().map(|v| 1.0 - v).collect();
        assert!(
            ssim(&a, &inv, 30, 30) < 0.0,
            "anti-correlated structure gives negative SSIM"
        );
    }
}
