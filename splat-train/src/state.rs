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

    /// Gives splat `group[0]` the mean of the moments of the splats in `group`, weighted by
    /// `shares` (one a member, summing to 1): the splat a merge leaves in the group's place.
    ///
    /// Zeroed moments would not be a fresh start late in a run: Adam's bias correction follows
    /// the run's step count, so a splat whose moments restart mid-run steps by about
    /// m / √v = (1 − β₁) / √(1 − β₂) ≈ 3 times its rate at first and stays above its rate for
    /// hundreds of steps, until v has caught up. The members' moments carry the scale of their
    /// gradients, so the merged splat goes on at its rate.
    pub fn blend_moments(&mut self, group: &[usize], shares: &[f32]) {
        let k = self.splats.coeffs_per_splat();
        let m = &mut self.moments;
        m.means.blend(WIDTHS[0], group, shares);
        m.log_scales.blend(WIDTHS[1], group, shares);
        m.rotations.blend(WIDTHS[2], group, shares);
        m.opacity_logits.blend(WIDTHS[3], group, shares);
        m.sh.blend(3 * k, group, shares);
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

    /// Sets the `stride`-long record `group[0]` to the `shares`-weighted mean of the records
    /// `group`, both moments.
    pub fn blend(&mut self, stride: usize, group: &[usize], shares: &[f32]) {
        for moment in [&mut self.m, &mut self.v] {
            let mut mean = vec![0.0_f32; stride];
            for (&j, &w) in group.iter().zip(shares) {
                for (a, &x) in mean.iter_mut().zip(&moment[j * stride..(j + 1) * stride]) {
                    *a += w * x;
                }
            }
            moment[group[0] * stride..(group[0] + 1) * stride].copy_from_slice(&mean);
        }
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

    #[test]
    fn blended_moments_are_the_members_weighted_means() {
        let mut st = ParamState::new(model());
        let fill = |m: &mut Moments, stride: usize| {
            for (i, (a, b)) in m.m.iter_mut().zip(m.v.iter_mut()).enumerate() {
                *a = (i / stride) as f32 + 0.5;
                *b = 10.0 * ((i / stride) as f32 + 1.0);
            }
        };
        fill(&mut st.moments.means, 3);
        fill(&mut st.moments.log_scales, 3);
        fill(&mut st.moments.rotations, 4);
        fill(&mut st.moments.opacity_logits, 1);
        fill(&mut st.moments.sh, 12);
        let before = st.moments.clone();
        st.blend_moments(&[3, 1], &[0.25, 0.75]);
        // Splat 3 now holds 0.25·(splat 3) + 0.75·(splat 1) in every record: m = 0.25·3.5 +
        // 0.75·1.5 = 2, v = 0.25·40 + 0.75·20 = 25; the other splats are untouched.
        for (after, old, stride) in [
            (&st.moments.means, &before.means, 3),
            (&st.moments.log_scales, &before.log_scales, 3),
            (&st.moments.rotations, &before.rotations, 4),
            (&st.moments.opacity_logits, &before.opacity_logits, 1),
            (&st.moments.sh, &before.sh, 12),
        ] {
            assert_eq!(after.m[3 * stride..4 * stride], vec![2.0; stride][..]);
            assert_eq!(after.v[3 * stride..4 * stride], vec![25.0; stride][..]);
            assert_eq!(after.m[..3 * stride], old.m[..3 * stride]);
            assert_eq!(after.v[..3 * stride], old.v[..3 * stride]);
        }
    }
}
