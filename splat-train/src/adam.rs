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

    /// Applies one Adam step at 1-based `step` to `params` with gradients `grads` at the
    /// learning `rates` (a rate of 0 leaves its values and their moments untouched).
    ///
    /// Runs in parallel over chunks of whole records; within a record each run of one rate is a
    /// branch-free loop that the compiler vectorises (where the CPU has AVX2, 8 lanes, chosen at
    /// run time). Every value is updated by the same IEEE operations in the same order either
    /// way, so the result does not depend on the thread count or the CPU.
    ///
    /// # Panics
    /// If the slices differ in length (a caller bug).
    pub fn step(
        &mut self,
        hp: &AdamParams,
        step: u64,
        params: &mut [f32],
        grads: &[f32],
        rates: Rates,
    ) {
        assert!(
            params.len() == grads.len() && params.len() == self.m.len(),
            "Adam size mismatch"
        );
        let k = AdamStep::new(hp, step);
        let stride = rates.stride();
        // About 8k values a chunk, in whole records so each chunk starts at a record.
        let chunk = (8192 / stride).max(1) * stride;
        params
            .par_chunks_mut(chunk)
            .zip(grads.par_chunks(chunk))
            .zip(
                self.m
                    .par_chunks_mut(chunk)
                    .zip(self.v.par_chunks_mut(chunk)),
            )
            .for_each(|((p, g), (m, v))| k.update(p, g, m, v, rates));
    }
}

/// The learning rates of a parameter group's values.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rates {
    /// One rate for every value.
    All(f32),
    /// Values come in records of `stride` (one per splat); the first `head` values of each
    /// take `head_rate` and the others `tail_rate` (the SH: DC, then the higher bands).
    Split {
        /// Values per record.
        stride: usize,
        /// Values at the head of a record.
        head: usize,
        /// Rate of the head values.
        head_rate: f32,
        /// Rate of the others.
        tail_rate: f32,
    },
}

impl Rates {
    /// Values per record (1 for [`Rates::All`]).
    fn stride(self) -> usize {
        match self {
            Self::All(_) => 1,
            Self::Split { stride, .. } => stride.max(1),
        }
    }

    /// The rate of value `i`.
    #[must_use]
    pub fn at(self, i: usize) -> f32 {
        match self {
            Self::All(r) => r,
            Self::Split {
                stride,
                head,
                head_rate,
                tail_rate,
            } => {
                if i % stride.max(1) < head {
                    head_rate
                } else {
                    tail_rate
                }
            }
        }
    }
}

/// The widest record [`AdamStep::run_pattern`] takes: a splat's SH at degree 3.
const MAX_PATTERN_STRIDE: usize = 48;
/// Records a block of [`AdamStep::run_pattern`] (8, so a block is whole vectors of 8 lanes).
const PATTERN_RECORDS: usize = 8;

/// One Adam step's constants, shared by every value it updates.
#[derive(Clone, Copy)]
pub(crate) struct AdamStep {
    b1: f32,
    b2: f32,
    eps: f32,
    inv_bc1: f32,
    inv_bc2_sqrt: f32,
    avx2: bool,
}

impl AdamStep {
    /// The constants of 1-based step `step`.
    pub(crate) fn new(hp: &AdamParams, step: u64) -> Self {
        let t = i32::try_from(step.max(1)).unwrap_or(i32::MAX);
        // Bias corrections in f64 (β^t underflows gracefully), the per-value update in f32 as
        // PyTorch does.
        Self {
            b1: hp.beta1,
            b2: hp.beta2,
            eps: hp.eps,
            inv_bc1: (1.0 / (1.0 - f64::from(hp.beta1).powi(t))) as f32,
            inv_bc2_sqrt: (1.0 / (1.0 - f64::from(hp.beta2).powi(t)).sqrt()) as f32,
            avx2: splat_core::has_avx2(),
        }
    }

    /// Whether this step's loops run their AVX2 instantiations (decided once, when the step's
    /// constants are made).
    pub(crate) fn uses_avx2(&self) -> bool {
        self.avx2
    }

    /// Updates `p` (with its moments `m`, `v`) by the gradients `g`: whole records of
    /// `rates` (the slices start at a record), the AVX2 instantiation where the CPU has it.
    pub(crate) fn update(
        &self,
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        rates: Rates,
    ) {
        #[cfg(target_arch = "x86_64")]
        if self.avx2 {
            // SAFETY: `avx2` is only true when the CPU reports AVX2 (`splat_core::has_avx2`).
            #[allow(unsafe_code)]
            unsafe {
                self.chunk_avx2(p, g, m, v, rates);
            }
            return;
        }
        self.chunk_impl(p, g, m, v, rates);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn chunk_avx2(&self, p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], rates: Rates) {
        self.chunk_impl(p, g, m, v, rates);
    }

    #[inline(always)]
    fn chunk_impl(&self, p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], rates: Rates) {
        match rates {
            Rates::All(rate) => self.run(p, g, m, v, rate),
            Rates::Split {
                stride,
                head,
                head_rate,
                tail_rate,
            } => {
                let stride = stride.max(1);
                let head = head.min(stride);
                if stride <= MAX_PATTERN_STRIDE && head_rate != 0.0 && tail_rate != 0.0 {
                    self.run_pattern(p, g, m, v, stride, head, head_rate, tail_rate);
                    return;
                }
                for (((p, g), m), v) in p
                    .chunks_mut(stride)
                    .zip(g.chunks(stride))
                    .zip(m.chunks_mut(stride))
                    .zip(v.chunks_mut(stride))
                {
                    let h = head.min(p.len());
                    let (ph, pt) = p.split_at_mut(h);
                    let (mh, mt) = m.split_at_mut(h);
                    let (vh, vt) = v.split_at_mut(h);
                    self.run(ph, &g[..h], mh, vh, head_rate);
                    self.run(pt, &g[h..], mt, vt, tail_rate);
                }
            }
        }
    }

    /// The update of whole records of `stride` values whose first `head` take `head_rate` and
    /// the others `tail_rate`, both non-zero: eight records at a time against a table of the
    /// eight records' rates, so the loop runs the length of the block in full vectors instead
    /// of a short run per record (the SH's 3 + 45 values a splat at degree 3 were 8 scalar
    /// updates and 5 vector ones). Each value goes through [`AdamStep::run`]'s operations, so
    /// the result is the same bit for bit.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn run_pattern(
        &self,
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        stride: usize,
        head: usize,
        head_rate: f32,
        tail_rate: f32,
    ) {
        let mut table = [0.0_f32; PATTERN_RECORDS * MAX_PATTERN_STRIDE];
        let block = PATTERN_RECORDS * stride;
        for (i, r) in table[..block].iter_mut().enumerate() {
            *r = if i % stride < head {
                head_rate
            } else {
                tail_rate
            };
        }
        let n = p.len().min(g.len()).min(m.len()).min(v.len());
        for start in (0..n).step_by(block) {
            let len = block.min(n - start);
            let range = start..start + len;
            let (p, g) = (&mut p[range.clone()], &g[range.clone()]);
            let (m, v, rates) = (&mut m[range.clone()], &mut v[range], &table[..len]);
            for i in 0..len {
                self.value(&mut p[i], g[i], &mut m[i], &mut v[i], rates[i]);
            }
        }
    }

    /// The update of a run of values sharing one rate (PyTorch's, in its order).
    #[inline(always)]
    fn run(&self, p: &mut [f32], g: &[f32], m: &mut [f32], v: &mut [f32], rate: f32) {
        if rate == 0.0 {
            return;
        }
        let n = p.len().min(g.len()).min(m.len()).min(v.len());
        let (p, g, m, v) = (&mut p[..n], &g[..n], &mut m[..n], &mut v[..n]);
        for i in 0..n {
            self.value(&mut p[i], g[i], &mut m[i], &mut v[i], rate);
        }
    }

    /// The update of one value `p` with its moments `m`, `v` by its gradient `g` at `rate`:
    /// the one place of Adam's formula (PyTorch's, in its order).
    #[inline(always)]
    fn value(&self, p: &mut f32, g: f32, m: &mut f32, v: &mut f32, rate: f32) {
        *m = self.b1 * *m + (1.0 - self.b1) * g;
        *v = self.b2 * *v + (1.0 - self.b2) * g * g;
        // PyTorch: p −= lr/bc1 · m / (√v/√bc2 + eps).
        *p -= rate * self.inv_bc1 * *m / (v.sqrt() * self.inv_bc2_sqrt + self.eps);
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
        mo.step(&hp, 1, &mut p, &[0.5, -3.0, 0.0], Rates::All(0.1));
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
        mo.step(&hp, 1, &mut p, &[1.0], Rates::All(0.01));
        mo.step(&hp, 2, &mut p, &[2.0], Rates::All(0.01));
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
        let rates = Rates::Split {
            stride: 2,
            head: 1,
            head_rate: 0.0,
            tail_rate: 0.1,
        };
        mo.step(&hp, 1, &mut p, &[1.0, 1.0], rates);
        assert_eq!(p[0].to_bits(), 1.0f32.to_bits());
        assert_eq!(mo.m[0], 0.0);
        assert!(p[1] < 1.0);
    }

    /// The update of value `i` written out on its own, as the reference for the chunked,
    /// split and vectorised loops.
    fn reference_step(
        hp: &AdamParams,
        t: i32,
        p: &mut [f32],
        g: &[f32],
        m: &mut [f32],
        v: &mut [f32],
        rates: Rates,
    ) {
        let inv_bc1 = (1.0 / (1.0 - f64::from(hp.beta1).powi(t))) as f32;
        let inv_bc2_sqrt = (1.0 / (1.0 - f64::from(hp.beta2).powi(t)).sqrt()) as f32;
        for i in 0..p.len() {
            let rate = rates.at(i);
            if rate == 0.0 {
                continue;
            }
            m[i] = hp.beta1 * m[i] + (1.0 - hp.beta1) * g[i];
            v[i] = hp.beta2 * v[i] + (1.0 - hp.beta2) * g[i] * g[i];
            p[i] -= rate * inv_bc1 * m[i] / (v[i].sqrt() * inv_bc2_sqrt + hp.eps);
        }
    }

    #[test]
    fn chunked_split_steps_are_bit_identical_to_the_plain_loop_at_any_thread_count() {
        // Records of the SH at each degree (48, 27, 12, 3 values; a head of 3 for the DC) and
        // two odd shapes, over more than one chunk, with a ragged end: 401 records, so the
        // chunks' last blocks of eight records are partial.
        for (stride, head) in [(48, 3), (27, 3), (12, 3), (3, 3), (5, 2), (7, 0)] {
            let n = stride * 401;
            let mut rng = 0x2545_f491_4f6c_dd1d_u64;
            let mut next = || {
                rng ^= rng << 13;
                rng ^= rng >> 7;
                rng ^= rng << 17;
                (rng >> 40) as f32 / (1u64 << 24) as f32 - 0.5
            };
            let p0: Vec<f32> = (0..n).map(|_| next()).collect();
            let grads: Vec<Vec<f32>> = (0..3)
                .map(|_| (0..n).map(|_| 1e-2 * next()).collect())
                .collect();
            let hp = AdamParams::default();
            let rates = Rates::Split {
                stride,
                head,
                head_rate: 2.5e-3,
                tail_rate: 1.25e-4,
            };
            let (mut p_ref, mut m_ref, mut v_ref) = (p0.clone(), vec![0.0; n], vec![0.0; n]);
            for (t, g) in grads.iter().enumerate() {
                reference_step(
                    &hp,
                    t as i32 + 1,
                    &mut p_ref,
                    g,
                    &mut m_ref,
                    &mut v_ref,
                    rates,
                );
            }
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let (p, mo) = pool.install(|| {
                    let mut p = p0.clone();
                    let mut mo = Moments::zeros(n);
                    for (t, g) in grads.iter().enumerate() {
                        mo.step(&hp, t as u64 + 1, &mut p, g, rates);
                    }
                    (p, mo)
                });
                let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                let case = format!("stride {stride}, head {head}, {threads} threads");
                assert_eq!(bits(&p), bits(&p_ref), "{case}");
                assert_eq!(bits(&mo.m), bits(&m_ref), "{case}");
                assert_eq!(bits(&mo.v), bits(&v_ref), "{case}");
            }
        }
    }
}
