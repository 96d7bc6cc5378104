//! Adam (Kingma & Ba) as PyTorch implements it, the optimiser of Inria's 3DGS trainer.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Adam hyper-parameters shared by all parameter groups.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct AdamParams {
    /// Decay of the first moment.
    pub beta1: f32,
    /// Decay of the second moment.
    pub beta2: f32,
    /// Denominator guard; Inria's trainer sets 1e-15.
    pub eps: f32,
}

impl Default for AdamParams {
    fn default() -> Self {
        Self {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        }
    }
}

/// First and second moments of one flat parameter array.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Moments {
    /// First moment (mean of gradients).
    pub m: Vec<f32>,
    /// Second moment (mean of squared gradients).
    pub v: Vec<f32>,
}

impl Moments {
    /// Zeroed moments for `n` values.
    #[must_use]
    pub fn zeros(n: usize) -> Self {
        Self {
            m: vec![0.0; n],
            v: vec![0.0; n],
        }
    }

    /// Number of values tracked.
    #[must_use]
    pub fn len(&self) -> usize {
        self.m.len()
    }

    /// Whether no values are tracked.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.m.is_empty()
    }

    /// Zeroes the moments of values `range` (a reset parameter starts afresh, as Inria's
    /// `replace_tensor_to_optimizer`).
    pub fn reset(&mut self, range: std::ops::Range<usize>) {
        self.m[range.clone()].fill(0.0);
        self.v[range].fill(0.0);
    }

    /// Applies one Adam step at 1-based `step` to `params` with gradients `grads`, the rate of
    /// value `i` being `lr(i)` (a rate of 0 leaves the value and its moments untouched).
    ///
    /// # Panics
    /// If the slices differ in length (a caller bug).
    pub fn step(
        &mut self,
        hp: &AdamParams,
        step: u64,
        params: &mut [f32],
        grads: &[f32],
        lr: impl Fn(usize) -> f32 + Sync,
    ) {
        assert!(
            params.len() == grads.len() && params.len() == self.m.len(),
            "Adam size mismatch"
        );
        let t = i32::try_from(step.max(1)).unwrap_or(i32::MAX);
        // Bias corrections in f64 (β^t underflows gracefully), the per-value update in f32 as
        // PyTorch does.
        let inv_bc1 = (1.0 / (1.0 - f64::from(hp.beta1).powi(t))) as f32;
        let inv_bc2_sqrt = (1.0 / (1.0 - f64::from(hp.beta2).powi(t)).sqrt()) as f32;
        let (b1, b2, eps) = (hp.beta1, hp.beta2, hp.eps);
        const CHUNK: usize = 8192;
        params
            .par_chunks_mut(CHUNK)
            .zip(grads.par_chunks(CHUNK))
            .zip(
                self.m
                    .par_chunks_mut(CHUNK)
                    .zip(self.v.par_chunks_mut(CHUNK)),
            )
            .enumerate()
            .for_each(|(c, ((p, g), (m, v)))| {
                let base = c * CHUNK;
                for i in 0..p.len() {
                    let rate = lr(base + i);
                    if rate == 0.0 {
                        continue;
                    }
                    m[i] = b1 * m[i] + (1.0 - b1) * g[i];
                    v[i] = b2 * v[i] + (1.0 - b2) * g[i] * g[i];
                    // PyTorch: p −= lr/bc1 · m / (√v/√bc2 + eps).
                    p[i] -= rate * inv_bc1 * m[i] / (v[i].sqrt() * inv_bc2_sqrt + eps);
                }
            });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_lr_times_sign() {
        // After one step with bias correction, m̂ = g and v̂ = g², so Δp = −lr·g/|g|.
        let hp = AdamParams::default();
        let mut mo = Moments::zeros(3);
        let mut p = [1.0f32, 2.0, 3.0];
        mo.step(&hp, 1, &mut p, &[0.5, -3.0, 0.0], |_| 0.1);
        assert!((p[0] - 0.9).abs() < 1e-6);
        assert!((p[1] - 2.1).abs() < 1e-6);
        assert_eq!(p[2], 3.0);
    }

    #[test]
    fn matches_hand_written_second_step() {
        let hp = AdamParams {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        };
        let mut mo = Moments::zeros(1);
        let mut p = [0.0f32];
        mo.step(&hp, 1, &mut p, &[1.0], |_| 0.01);
        mo.step(&hp, 2, &mut p, &[2.0], |_| 0.01);
        let m: f64 = 0.9 * 0.1 + 0.1 * 2.0;
        let v: f64 = 0.999 * 0.001 + 0.001 * 4.0;
        let m_hat = m / (1.0 - 0.81);
        let v_hat = v / (1.0 - 0.999f64.powi(2));
        let expect = -0.01 - 0.01 * m_hat / (v_hat.sqrt() + 1e-8);
        assert!(
            (f64::from(p[0]) - expect).abs() < 1e-6,
            "{} vs {expect}",
            p[0]
        );
    }

    #[test]
    fn zero_rate_freezes_value_and_moments() {
        let hp = AdamParams::default();
        let mut mo = Moments::zeros(2);
        let mut p = [1.0f32, 1.0];
        mo.step(
            &hp,
            1,
            &mut p,
            &[1.0, 1.0],
            |i| if i == 0 { 0.0 } else { 0.1 },
        );
        assert_eq!(p[0].to_bits(), 1.0f32.to_bits());
        assert_eq!(mo.m[0], 0.0);
        assert!(p[1] < 1.0);
    }
}
