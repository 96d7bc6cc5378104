//! Finding non-finite parameters and gradients: a whole-buffer check each step, and the
//! per-splat search it almost never has to make.

use glam::Vec3;
use rayon::prelude::*;
use splat_core::{SplatGrads, Splats};

/// Whether every parameter of splat `i` is finite.
pub(super) fn splat_is_finite(s: &Splats, i: usize) -> bool {
    let k = s.coeffs_per_splat();
    values_finite(
        s.means[i],
        s.log_scales[i],
        &s.rotations[i],
        s.opacity_logits[i],
        &s.sh[i * k..(i + 1) * k],
    )
}

/// Whether one splat's values are all finite: its parameters, or their gradients (the same
/// fields in [`Splats`] and [`SplatGrads`]).
fn values_finite(
    mean: Vec3,
    log_scale: Vec3,
    rotation: &[f32; 4],
    opacity_logit: f32,
    sh: &[[f32; 3]],
) -> bool {
    mean.is_finite()
        && log_scale.is_finite()
        && rotation.iter().all(|v| v.is_finite())
        && opacity_logit.is_finite()
        && sh.iter().flatten().all(|v| v.is_finite())
}

/// Whether every value of the buffers is finite: the check each step makes of all parameters
/// and gradients before it looks for the splats at fault, which it almost never has to.
/// [`splat_core::all_finite`] over chunks in parallel (a per-splat test with early exits took
/// about 4 % of a step at paper scale).
pub(super) fn all_finite(buffers: &[&[f32]]) -> bool {
    buffers
        .iter()
        .all(|values| values.par_chunks(1 << 14).all(splat_core::all_finite))
}

/// Index of the first splat with a non-finite parameter.
pub(super) fn first_non_finite(s: &Splats) -> Option<usize> {
    (0..s.len()).find(|&i| !splat_is_finite(s, i))
}

/// Zeroes the gradients of splats with any non-finite gradient; returns how many.
pub(crate) fn zero_non_finite_grads(g: &mut SplatGrads) -> u64 {
    let n = g.means.len();
    let k = g.sh.len().checked_div(n).unwrap_or(0);
    if all_finite(&g.float_arrays()) {
        return 0;
    }
    // The search reads every gradient in parallel; the rare repair is serial.
    let grads = &*g;
    let bad: Vec<usize> = (0..n)
        .into_par_iter()
        .filter(|&i| {
            !(values_finite(
                grads.means[i],
                grads.log_scales[i],
                &grads.rotations[i],
                grads.opacity_logits[i],
                &grads.sh[i * k..(i + 1) * k],
            ) && grads.screen_grad_norm[i].is_finite())
        })
        .collect();
    let count = bad.len() as u64;
    for i in bad {
        g.means[i] = Vec3::ZERO;
        g.log_scales[i] = Vec3::ZERO;
        g.rotations[i] = [0.0; 4];
        g.opacity_logits[i] = 0.0;
        g.sh[i * k..(i + 1) * k].fill([0.0; 3]);
        g.screen_grad_norm[i] = 0.0;
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The whole-buffer check must pass finite gradients untouched, and send any non-finite
    /// value (NaN or ±∞, in any group, in a chunk past the first) to the per-splat repair.
    #[test]
    fn non_finite_gradients_are_found_in_every_group_and_zeroed_per_splat() {
        let n = 40_000;
        let k = 16;
        let filled = |n: usize| SplatGrads {
            means: vec![Vec3::splat(0.5); n],
            log_scales: vec![Vec3::splat(-0.25); n],
            rotations: vec![[0.1, 0.2, 0.3, 0.4]; n],
            opacity_logits: vec![1.5; n],
            sh: vec![[0.01, 0.02, 0.03]; n * k],
            screen_grad_norm: vec![2.0; n],
        };
        let mut g = filled(n);
        assert_eq!(zero_non_finite_grads(&mut g), 0);
        assert_eq!(g, filled(n), "finite gradients are left as they were");
        g.sh[33_333 * k + 7][2] = f32::NAN;
        g.rotations[20_001][3] = f32::INFINITY;
        g.screen_grad_norm[5] = f32::NEG_INFINITY;
        g.means[39_999].y = f32::NAN;
        assert_eq!(zero_non_finite_grads(&mut g), 4);
        for i in [5, 20_001, 33_333, 39_999] {
            assert_eq!(g.means[i], Vec3::ZERO);
            assert_eq!(g.rotations[i], [0.0; 4]);
            assert_eq!(g.opacity_logits[i], 0.0);
            assert!(g.sh[i * k..(i + 1) * k].iter().all(|c| *c == [0.0; 3]));
            assert_eq!(g.screen_grad_norm[i], 0.0);
        }
        assert_eq!(
            g.means[6],
            Vec3::splat(0.5),
            "other splats keep their gradients"
        );
        assert!(all_finite(&[g.sh.as_flattened(), &g.screen_grad_norm]));
    }
}
