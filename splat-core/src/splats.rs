//! The splat model in structure-of-arrays form, with Inria's activations and their inverses.

use glam::{Quat, Vec3};

use crate::Error;
use crate::sh::{C0, num_sh_coeffs};

/// Gaussian splats with Inria's parameterisation.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Splats {
    /// Centres, in world units.
    pub means: Vec<Vec3>,
    /// Natural logarithms of the per-axis standard deviations.
    pub log_scales: Vec<Vec3>,
    /// Rotations as quaternions (w, x, y, z), unnormalised in storage, normalised on use.
    pub rotations: Vec<[f32; 4]>,
    /// Opacities before the sigmoid.
    pub opacity_logits: Vec<f32>,
    /// Spherical-harmonics degree of the coefficients stored (0..=3).
    pub sh_degree: u32,
    /// SH coefficients, splat-major: `sh[i * num_sh_coeffs(sh_degree) + k]`, k = 0 is DC.
    pub sh: Vec<[f32; 3]>,
}

/// Returns the logistic function 1 / (1 + e^(−x)) (Inria's opacity activation).
#[must_use]
#[inline]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

/// 1.5·2²³: added to an f32 of magnitude below 2²² and removed again, it rounds it to an integer
/// (to nearest, ties to even), and the sum's low mantissa bits hold that integer; [`exp`] and
/// the tile walks' `fast_exp2` build their powers of two this way.
pub(crate) const ROUND_TO_INTEGER: f32 = 12_582_912.0;

/// e^x within 2 ulp (1.18 at worst in its test; the C library's `expf` is within 0.502),
/// branch-free and without a library call, so that the projection computes its eight lanes'
/// opacities and scales as vectors instead of 32 calls a group of eight splats. Below about
/// −87.3 the result is subnormal or 0 and above about 88.7 infinite, as `expf` gives; NaN stays
/// NaN.
///
/// e^x = 2ᵏ·eʳ with k = round(x·log₂e) and r = x − k·ln 2 (ln 2 split in two so that k·ln 2's
/// high part is exact), eʳ on |r| ≤ ½ln 2 by its Taylor series to r⁷ (truncation 6e-9), and
/// 2ᵏ as two exact powers of two, so that subnormal results are rounded once.
#[inline(always)]
pub(crate) fn exp(x: f32) -> f32 {
    use std::f32::consts::LOG2_E;
    /// ln 2 in two parts: the high one has 12 significant bits, so k·`LN2_HI` is exact.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // Beyond these the result is 0 or infinite anyway; the clamp keeps k in [−151, 129].
    let x = x.clamp(-104.0, 89.0);
    // k from the sum's low mantissa bits (two's complement): a saturating `k as i32` would
    // not vectorise.
    let shifted = x * LOG2_E + ROUND_TO_INTEGER;
    let k = shifted - ROUND_TO_INTEGER;
    let ki = shifted
        .to_bits()
        .wrapping_sub(ROUND_TO_INTEGER.to_bits())
        .cast_signed();
    let r = (x - k * LN2_HI) - k * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (1.0 / 2.0
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0
                        + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    // 2ᵏ = 2^(k − h)·2^h with h = ⌊k/2⌋: both halves normal for k in [−151, 129].
    let h = ki >> 1;
    let pow2 = |e: i32| f32::from_bits(((e + 127) as u32) << 23);
    p * pow2(ki - h) * pow2(h)
}

/// Returns the inverse of [`sigmoid`], ln(p / (1 − p)), with p clamped into (1e-6, 1 − 1e-6).
#[must_use]
pub fn logit(p: f32) -> f32 {
    let p = p.clamp(1e-6, 1.0 - 1e-6);
    (p / (1.0 - p)).ln()
}

/// Returns the DC coefficient that renders as colour `rgb` (Inria's `RGB2SH`: (c − 0.5)/C0).
#[must_use]
pub fn rgb_to_sh_dc(rgb: [f32; 3]) -> [f32; 3] {
    rgb.map(|c| (c - 0.5) / C0)
}

/// Returns the colour a DC coefficient renders as (Inria's `SH2RGB`: dc·C0 + 0.5, unclamped).
#[must_use]
pub fn sh_dc_to_rgb(dc: [f32; 3]) -> [f32; 3] {
    dc.map(|c| c * C0 + 0.5)
}

/// Below this norm a stored quaternion counts as zero: it has no direction to normalise, and the
/// gradient through the normalisation (which grows as 1/|q|) would overflow f32.
pub const MIN_QUAT_NORM: f32 = 1e-30;

/// Whether every value is finite. The test has no early exit, so it compiles to vector compares
/// (an early exit is a branch a value: 48 of them for a degree-3 splat's colour); the
/// projection checks each splat's inputs with it and the trainer each step's parameters and
/// gradients.
#[inline]
#[must_use]
pub fn all_finite(values: &[f32]) -> bool {
    let non_finite = values
        .iter()
        .fold(0_u32, |acc, x| acc | u32::from(!x.is_finite()));
    non_finite == 0
}

/// Normalises a stored quaternion (w, x, y, z); returns it with its norm, or `None` when it is
/// zero (norm below [`MIN_QUAT_NORM`]) or not finite. Zero quaternions render as the identity.
///
/// The components are divided by the largest magnitude first, so the sum of squares neither
/// underflows (|q| ≈ 1e-25 gave 0 and the identity) nor overflows (|q| ≈ 1e20 gave ∞ and a
/// zero quaternion) for any finite input.
#[must_use]
pub fn normalize_quat([w, x, y, z]: [f32; 4]) -> Option<(Quat, f32)> {
    let q = Quat::from_xyzw(x, y, z, w);
    let m = [w, x, y, z].iter().fold(0.0_f32, |m, v| m.max(v.abs()));
    if !(m.is_finite() && m > 0.0) {
        return None;
    }
    let unit = q / m;
    let n = unit.length();
    let norm = m * n;
    (norm > MIN_QUAT_NORM).then(|| (unit / n, norm))
}

impl Splats {
    /// Returns an empty model of the given SH degree (clamped to 3).
    #[must_use]
    pub fn new(sh_degree: u32) -> Self {
        Self {
            sh_degree: sh_degree.min(3),
            ..Self::default()
        }
    }

    /// Returns the number of splats.
    #[must_use]
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// Returns true when there are no splats.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Returns the number of SH coefficients per channel of this model.
    #[must_use]
    pub fn coeffs_per_splat(&self) -> usize {
        num_sh_coeffs(self.sh_degree)
    }

    /// Returns the SH coefficients of splat `i`.
    #[must_use]
    pub fn sh_of(&self, i: usize) -> &[[f32; 3]] {
        let k = self.coeffs_per_splat();
        &self.sh[i * k..(i + 1) * k]
    }

    /// Returns the activated opacity of splat `i`.
    #[must_use]
    pub fn opacity(&self, i: usize) -> f32 {
        sigmoid(self.opacity_logits[i])
    }

    /// Returns the per-axis standard deviations of splat `i`.
    #[must_use]
    pub fn scale(&self, i: usize) -> Vec3 {
        self.log_scales[i].exp()
    }

    /// Returns the normalised rotation of splat `i` (identity for a zero quaternion, see
    /// [`normalize_quat`]).
    #[must_use]
    pub fn rotation(&self, i: usize) -> Quat {
        normalize_quat(self.rotations[i]).map_or(Quat::IDENTITY, |(q, _)| q)
    }

    /// Appends one splat; `sh` must hold `coeffs_per_splat()` coefficients (missing ones are zero,
    /// extra ones are dropped).
    pub fn push(
        &mut self,
        mean: Vec3,
        log_scale: Vec3,
        rotation: [f32; 4],
        opacity_logit: f32,
        sh: &[[f32; 3]],
    ) {
        let k = self.coeffs_per_splat();
        self.means.push(mean);
        self.log_scales.push(log_scale);
        self.rotations.push(rotation);
        self.opacity_logits.push(opacity_logit);
        self.sh
            .extend((0..k).map(|j| sh.get(j).copied().unwrap_or([0.0; 3])));
    }

    /// The splats at the indices of `order`, in that order: a permutation reorders the model, a
    /// shorter list selects from it.
    ///
    /// # Panics
    /// If an index is out of range (a caller bug).
    #[must_use]
    pub fn gather(&self, order: &[u32]) -> Self {
        let k = self.coeffs_per_splat();
        let pick = |i: &u32| *i as usize;
        Self {
            means: order.iter().map(|i| self.means[pick(i)]).collect(),
            log_scales: order.iter().map(|i| self.log_scales[pick(i)]).collect(),
            rotations: order.iter().map(|i| self.rotations[pick(i)]).collect(),
            opacity_logits: order.iter().map(|i| self.opacity_logits[pick(i)]).collect(),
            sh_degree: self.sh_degree,
            sh: order
                .iter()
                .flat_map(|i| &self.sh[pick(i) * k..(pick(i) + 1) * k])
                .copied()
                .collect(),
        }
    }

    /// Builds splats at `points` with colours `colors` (rendered as such from every direction),
    /// per-axis standard deviations `scales` in each splat's own frame, and opacity `opacity`.
    /// With `normals`, each splat's local z axis is turned onto its normal, so a scale with a small
    /// z is a flat disc on the surface; without, rotations are the identity.
    pub fn from_points(
        points: &[Vec3],
        colors: &[[f32; 3]],
        scales: &[Vec3],
        normals: Option<&[Vec3]>,
        opacity: f32,
        sh_degree: u32,
    ) -> Result<Self, Error> {
        let n = points.len();
        if colors.len() != n || scales.len() != n || normals.is_some_and(|v| v.len() != n) {
            return Err(Error::Inconsistent(format!(
                "from_points: {n} points but {} colours, {} scales, {} normals",
                colors.len(),
                scales.len(),
                normals.map_or(n, <[Vec3]>::len)
            )));
        }
        let mut s = Self::new(sh_degree);
        let o = logit(opacity);
        for i in 0..n {
            let q = match normals {
                Some(nv) if nv[i].length_squared() > 0.0 && nv[i].is_finite() => {
                    Quat::from_rotation_arc(Vec3::Z, nv[i].normalize())
                }
                _ => Quat::IDENTITY,
            };
            let ls = scales[i].max(Vec3::splat(f32::MIN_POSITIVE)).ln();
            s.push(
                points[i],
                ls,
                [q.w, q.x, q.y, q.z],
                o,
                &[rgb_to_sh_dc(colors[i])],
            );
        }
        Ok(s)
    }

    /// The first splat whose linear scale (the exponential of its log-scale, in f32) is not a
    /// finite positive number, as `(splat, axis, log-scale)`: formats that store linear scales
    /// (`.splat`, glTF) cannot hold it, and their readers would refuse the zero or infinity.
    #[must_use]
    pub fn first_unstorable_linear_scale(&self) -> Option<(usize, usize, f32)> {
        self.log_scales.iter().enumerate().find_map(|(i, l)| {
            let l = l.to_array();
            (0..3)
                .find(|&axis| {
                    let s = l[axis].exp();
                    !(s.is_finite() && s > 0.0)
                })
                .map(|axis| (i, axis, l[axis]))
        })
    }

    /// Checks that all arrays agree with `len()` and the degree is at most 3.
    pub fn validate(&self) -> Result<(), Error> {
        let n = self.len();
        if self.sh_degree > 3 {
            return Err(Error::Inconsistent(format!(
                "SH degree {} (at most 3 is supported)",
                self.sh_degree
            )));
        }
        if self.log_scales.len() != n
            || self.rotations.len() != n
            || self.opacity_logits.len() != n
            || self.sh.len() != n * self.coeffs_per_splat()
        {
            return Err(Error::Inconsistent(format!(
                "{n} means but {} log-scales, {} rotations, {} opacities, {} SH coefficients \
                 (expected {} per splat)",
                self.log_scales.len(),
                self.rotations.len(),
                self.opacity_logits.len(),
                self.sh.len(),
                self.coeffs_per_splat()
            )));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The test agrees with `f32::is_finite` on every special value at every position.
    #[test]
    fn all_finite_finds_a_nan_or_infinity_anywhere() {
        let finite = [
            0.0,
            -0.0,
            f32::MAX,
            f32::MIN,
            f32::MIN_POSITIVE,
            1e-45,
            -3.5,
        ];
        let non_finite = [f32::NAN, -f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
        assert!(all_finite(&[]));
        for len in [1, 7, 48] {
            let mut v: Vec<f32> = (0..len).map(|k| finite[k % finite.len()]).collect();
            assert!(all_finite(&v));
            for at in 0..len {
                for &bad in &non_finite {
                    let keep = v[at];
                    v[at] = bad;
                    assert!(!all_finite(&v), "{bad} at {at} of {len}");
                    v[at] = keep;
                }
            }
        }
    }

    #[test]
    fn activations_invert() {
        for p in [0.01_f32, 0.1, 0.5, 0.9, 0.99] {
            assert!((sigmoid(logit(p)) - p).abs() < 1e-6);
        }
        let c = [0.2, 0.5, 0.9];
        let back = sh_dc_to_rgb(rgb_to_sh_dc(c));
        for k in 0..3 {
            assert!((back[k] - c[k]).abs() < 1e-6);
        }
        assert_eq!(num_sh_coeffs(0), 1);
        assert_eq!(num_sh_coeffs(3), 16);
    }

    #[test]
    fn from_points_orients_discs_along_normals() {
        let n = Vec3::new(1.0, 2.0, -0.5).normalize();
        let s = Splats::from_points(
            &[Vec3::ZERO],
            &[[0.3, 0.6, 0.9]],
            &[Vec3::new(0.1, 0.1, 0.001)],
            Some(&[n]),
            0.5,
            1,
        )
        .unwrap();
        s.validate().unwrap();
        assert!((s.rotation(0) * Vec3::Z - n).length() < 1e-5);
        assert!((s.opacity(0) - 0.5).abs() < 1e-6);
        assert_eq!(s.sh.len(), 4);
        assert!(Splats::from_points(&[Vec3::ZERO], &[], &[], None, 0.5, 0).is_err());
    }

    /// Gathering moves every attribute of a splat together: each gathered splat is, field by
    /// field, the splat its index names (checked through `push`, which builds the same record).
    #[test]
    fn gather_moves_whole_splats() {
        let mut s = Splats::new(1);
        for i in 0..5 {
            let f = i as f32;
            let sh: Vec<[f32; 3]> = (0..4).map(|k| [f, k as f32, -f]).collect();
            s.push(
                Vec3::splat(f),
                Vec3::splat(-f),
                [1.0, f, 0.0, 0.0],
                0.1 * f,
                &sh,
            );
        }
        let order = [3, 0, 4, 4, 1];
        let g = s.gather(&order);
        g.validate().unwrap();
        let mut expected = Splats::new(1);
        for &i in &order {
            let i = i as usize;
            expected.push(
                s.means[i],
                s.log_scales[i],
                s.rotations[i],
                s.opacity_logits[i],
                s.sh_of(i),
            );
        }
        assert_eq!(g, expected);
        assert_eq!(s.gather(&[]).len(), 0);
    }

    /// `exp` against f64's over the whole range where e^x is a normal f32 (every 37th f32
    /// from −87.3 to 88.7, about 6 million) within 2 ulp, exact where the result is a power of
    /// two or 1, and the C library's answers at and beyond the ends (subnormals rounded once,
    /// 0, infinity, NaN).
    #[test]
    fn exp_is_within_two_ulp_of_the_exact_value() {
        let ulp_err = |x: f32| {
            let got = exp(x);
            let want = f64::from(x).exp();
            let ulp =
                f64::from(f32::from_bits((want as f32).to_bits() + 1)) - f64::from(want as f32);
            (f64::from(got) - want).abs() / ulp.abs()
        };
        let mut worst = (0.0_f64, 0.0_f32);
        for bits in (0..=88.7_f32.to_bits()).step_by(37) {
            let x = f32::from_bits(bits);
            for x in [x, -x].into_iter().filter(|x| *x >= -87.3) {
                let e = ulp_err(x);
                if e > worst.0 {
                    worst = (e, x);
                }
            }
        }
        assert!(worst.0 <= 2.0, "{} ulp at {}", worst.0, worst.1);
        assert_eq!(exp(0.0), 1.0);
        for x in [-100.0_f32, -95.0, -90.0, -88.0] {
            assert_eq!(exp(x), f64::from(x).exp() as f32, "{x}");
        }
        assert_eq!(exp(-200.0), 0.0);
        assert_eq!(exp(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp(89.0), f32::INFINITY);
        assert_eq!(exp(f32::INFINITY), f32::INFINITY);
        assert!(exp(f32::NAN).is_nan());
    }
}
