//! The change between this crate's frame and the y-up frames of web formats.
//!
//! Splats here live in COLMAP's right-down-forward frame (x right, y down, z forward), like the
//! input they were trained on. SPZ stores right-up-back (three.js, OpenGL) and glTF is y-up with
//! the front of an asset facing +z, the same axes. The two frames differ by a half turn about x,
//! (x, y, z) → (x, −y, −z): a proper rotation, so it needs no change of handedness, and its own
//! inverse, so one function converts both ways.

use glam::Vec3;

use crate::Splats;

/// SH sign of each coefficient (Inria's order, DC first) under the half turn about x: the basis
/// polynomials with an odd number of y and z factors change sign.
const HALF_TURN_X_SH_SIGN: [f32; 16] = [
    1.0, // 1
    -1.0, -1.0, 1.0, // y, z, x
    -1.0, 1.0, 1.0, -1.0, 1.0, // xy, yz, 2z²−x²−y², xz, x²−y²
    -1.0, 1.0, -1.0, -1.0, 1.0, -1.0,
    1.0, // y(3x²−y²), xyz, y(…), z(…), x(…), z(x²−y²), x(…)
];

/// Turns splats half a turn about x, between right-down-forward and right-up-back (either way):
/// position (x, −y, −z), quaternion (w, x, −y, −z), SH coefficients re-signed so every splat
/// shows the same colour towards the same (turned) direction.
#[must_use]
pub fn y_up_frame(splats: &Splats) -> Splats {
    let k = splats.coeffs_per_splat();
    let mut out = splats.clone();
    for m in &mut out.means {
        *m = Vec3::new(m.x, -m.y, -m.z);
    }
    for q in &mut out.rotations {
        *q = [q[0], q[1], -q[2], -q[3]];
    }
    for (j, c) in out.sh.iter_mut().enumerate() {
        let s = HALF_TURN_X_SH_SIGN[j % k];
        *c = c.map(|v| v * s);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sh_signs_match_the_basis_under_a_half_turn_about_x() {
        // Independent check of the table: the basis at (x, −y, −z) against the basis at (x, y, z).
        let mut a = [0.0; 16];
        let mut b = [0.0; 16];
        for d in [
            Vec3::new(0.3, -0.5, 0.81),
            Vec3::new(-0.7, 0.2, 0.4),
            Vec3::new(0.1, 0.9, -0.3),
        ] {
            let d = d.normalize();
            crate::sh::basis(3, d, &mut a);
            crate::sh::basis(3, Vec3::new(d.x, -d.y, -d.z), &mut b);
            for j in 0..16 {
                assert!(
                    (b[j] - HALF_TURN_X_SH_SIGN[j] * a[j]).abs() < 1e-6,
                    "coefficient {j}: {} vs {}",
                    b[j],
                    a[j]
                );
            }
        }
    }

    #[test]
    fn a_turned_model_renders_the_same_from_a_turned_camera() {
        // The colour of splat 0 towards a direction d, before the turn, equals the turned
        // splat's colour towards the turned direction.
        let mut s = Splats::new(3);
        let sh: Vec<[f32; 3]> = (0..16)
            .map(|k| [0.1 * k as f32 - 0.7, 0.05 * k as f32, -0.03 * k as f32])
            .collect();
        s.push(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::ZERO,
            [0.9, 0.1, -0.3, 0.2],
            0.0,
            &sh,
        );
        let t = y_up_frame(&s);
        let d = Vec3::new(0.2, -0.6, 0.77).normalize();
        let a = crate::sh::eval(3, d, s.sh_of(0));
        let b = crate::sh::eval(3, Vec3::new(d.x, -d.y, -d.z), t.sh_of(0));
        assert!((a - b).abs().max_element() < 1e-6, "{a} vs {b}");
        // The turned splat's covariance R·S²·Rᵀ is the turned covariance T·Σ·Tᵀ (its axes turn
        // up to sign, which an ellipsoid does not see).
        let t_mat = glam::Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0));
        let scales = glam::Mat3::from_diagonal(Vec3::new(0.5, 2.0, 0.1));
        let cov = |q: glam::Quat| {
            let r = glam::Mat3::from_quat(q);
            r * scales * scales * r.transpose()
        };
        let want = t_mat * cov(s.rotation(0)) * t_mat;
        let got = cov(t.rotation(0));
        assert!((want - got).abs().to_cols_array().iter().all(|d| *d < 1e-5));
        assert_eq!(y_up_frame(&t), s);
    }
}
