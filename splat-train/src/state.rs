//! The optimised parameters with their Adam moments, edited together so they never drift apart.

use glam::Vec3;
use splat_core::Splats;

use crate::adam::Moments;

/// Adam moments of every splat attribute, laid out like the attribute arrays.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SplatMoments {
    /// Moments of the means (3 per splat).
    pub means: Moments,
    /// Moments of the log-scales (3 per splat).
    pub log_scales: Moments,
    /// Moments of the quaternions (4 per splat).
    pub rotations: Moments,
    /// Moments of the opacity logits (1 per splat).
    pub opacity_logits: Moments,
    /// Moments of the SH coefficients (3 per coefficient, splat-major).
    pub sh: Moments,
}

/// Splats and their optimiser state.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ParamState {
    /// The model being trained.
    pub splats: Splats,
    /// Adam moments, one pair per scalar parameter.
    pub moments: SplatMoments,
}

/// Floats per splat of each attribute array: means, log-scales, rotations, opacities.
const WIDTHS: [usize; 4] = [3, 3, 4, 1];

impl ParamState {
    /// Wraps `splats` with zeroed moments.
    #[must_use]
    pub fn new(splats: Splats) -> Self {
        let n = splats.len();
        let k = splats.coeffs_per_splat();
        let moments = SplatMoments {
            means: Moments::zeros(WIDTHS[0] * n),
            log_scales: Moments::zeros(WIDTHS[1] * n),
            rotations: Moments::zeros(WIDTHS[2] * n),
            opacity_logits: Moments::zeros(WIDTHS[3] * n),
            sh: Moments::zeros(3 * k * n),
        };
        Self { splats, moments }
    }

    /// Number of splats.
    #[must_use]
    pub fn len(&self) -> usize {
        self.splats.len()
    }

    /// Whether there are no splats.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.splats.is_empty()
    }

    /// Appends a copy of splat `i` with a new mean and log-scale and zeroed moments (Inria's
    /// `densification_postfix` starts new splats with empty optimiser state).
    pub fn push_copy(&mut self, i: usize, mean: Vec3, log_scale: Vec3) {
        let k = self.splats.coeffs_per_splat();
        let s = &mut self.splats;
        s.means.push(mean);
        s.log_scales.push(log_scale);
        s.rotations.push(s.rotations[i]);
        s.opacity_logits.push(s.opacity_logits[i]);
        s.sh.extend_from_within(i * k..(i + 1) * k);
        let m = &mut self.moments;
        m.means.grow(WIDTHS[0]);
        m.log_scales.grow(WIDTHS[1]);
        m.rotations.grow(WIDTHS[2]);
        m.opacity_logits.grow(WIDTHS[3]);
        m.sh.grow(3 * k);
    }

    /// Keeps the splats whose flag in `keep` is true, in order.
    ///
    /// # Panics
    /// If `keep` is not one flag per splat (a caller bug).
    pub fn retain(&mut self, keep: &[bool]) {
        assert_eq!(keep.len(), self.len(), "retain needs one flag per splat");
        let k = self.splats.coeffs_per_splat();
        let s = &mut self.splats;
        retain_by(&mut s.means, 1, keep);
        retain_by(&mut s.log_scales, 1, keep);
        retain_by(&mut s.rotations, 1, keep);
        retain_by(&mut s.opacity_logits, 1, keep);
        retain_by(&mut s.sh, k, keep);
        let m = &mut self.moments;
        m.means.retain(WIDTHS[0], keep);
        m.log_scales.retain(WIDTHS[1], keep);
        m.rotations.retain(WIDTHS[2], keep);
        m.opacity_logits.retain(WIDTHS[3], keep);
        m.sh.retain(3 * k, keep);
    }

    /// Zeroes every moment of splat `i`.
    pub fn reset_moments(&mut self, i: usize) {
        let k = self.splats.coeffs_per_splat();
        let m = &mut self.moments;
        m.means.reset(i * 3..i * 3 + 3);
        m.log_scales.reset(i * 3..i * 3 + 3);
        m.rotations.reset(i * 4..i * 4 + 4);
        m.opacity_logits.reset(i..i + 1);
        m.sh.reset(i * 3 * k..(i + 1) * 3 * k);
    }
}

/// Keeps the `stride`-long records of `v` whose flag is set.
fn retain_by<T: Copy>(v: &mut Vec<T>, stride: usize, keep: &[bool]) {
    let mut w = 0;
    for (i, &k) in keep.iter().enumerate() {
        if k {
            if w != i {
                v.copy_within(i * stride..(i + 1) * stride, w * stride);
            }
            w += 1;
        }
    }
    v.truncate(w * stride);
}

impl Moments {
    /// Appends `n` zeroed entries.
    pub fn grow(&mut self, n: usize) {
        self.m.resize(self.m.len() + n, 0.0);
        self.v.resize(self.v.len() + n, 0.0);
    }

    /// Keeps the `stride`-long records whose flag in `keep` is set.
    pub fn retain(&mut self, stride: usize, keep: &[bool]) {
        retain_by(&mut self.m, stride, keep);
        retain_by(&mut self.v, stride, keep);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> Splats {
        let mut s = Splats::new(1);
        for i in 0..4 {
            let f = i as f32;
            s.push(
                Vec3::splat(f),
                Vec3::splat(-f),
                [1.0, f, 0.0, 0.0],
                f,
                &[[f; 3]; 4],
            );
        }
        s
    }

    #[test]
    fn push_copy_and_retain_keep_arrays_aligned() {
        let mut st = ParamState::new(model());
        st.moments.sh.m.fill(7.0);
        st.push_copy(2, Vec3::splat(9.0), Vec3::ZERO);
        assert_eq!(st.len(), 5);
        assert_eq!(st.splats.sh_of(4), &[[2.0; 3]; 4]);
        assert_eq!(st.moments.sh.m[4 * 12], 0.0);
        st.retain(&[true, false, true, false, true]);
        st.splats.validate().unwrap();
        assert_eq!(
            st.splats.means,
            vec![Vec3::ZERO, Vec3::splat(2.0), Vec3::splat(9.0)]
        );
        assert_eq!(st.splats.opacity_logits, vec![0.0, 2.0, 2.0]);
        assert_eq!(st.moments.sh.len(), 3 * 12);
        assert_eq!(st.moments.sh.m[12], 7.0);
        assert_eq!(st.moments.rotations.len(), 12);
    }
}
