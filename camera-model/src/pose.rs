//! World→camera poses and the look-at construction.

use glam::{DMat3, DQuat, DVec3};

use crate::rotation::{matrix_from_quat, quat_from_matrix};

/// World→camera rigid transform: `x_cam = R·x_world + t` (COLMAP convention).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// World→camera rotation as a unit Hamilton quaternion.
    pub rotation: DQuat,
    /// World→camera translation (the world origin in camera coordinates).
    pub translation: DVec3,
}

impl Default for Pose {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose {
    /// The camera at the world origin looking down world +z.
    pub const IDENTITY: Self = Self {
        rotation: DQuat::IDENTITY,
        translation: DVec3::ZERO,
    };

    /// Pose from a quaternion written w first (as in COLMAP files), normalised, and a translation.
    #[must_use]
    pub fn from_wxyz(q: [f64; 4], t: [f64; 3]) -> Self {
        Self {
            rotation: DQuat::from_xyzw(q[1], q[2], q[3], q[0]).normalize(),
            translation: DVec3::from_array(t),
        }
    }

    /// Pose from a world→camera rotation matrix and translation.
    #[must_use]
    pub fn from_rotation_matrix(r: &DMat3, t: DVec3) -> Self {
        Self {
            rotation: quat_from_matrix(r),
            translation: t,
        }
    }

    /// Pose of a camera with world→camera rotation `r` whose centre is `center` (t = −R·c).
    #[must_use]
    pub fn from_rotation_and_center(r: &DMat3, center: DVec3) -> Self {
        Self::from_rotation_matrix(r, -(*r * center))
    }

    /// The rotation quaternion as `[w, x, y, z]`.
    #[must_use]
    pub fn wxyz(&self) -> [f64; 4] {
        let q = self.rotation;
        [q.w, q.x, q.y, q.z]
    }

    /// The world→camera rotation matrix R.
    #[must_use]
    pub fn rotation_matrix(&self) -> DMat3 {
        matrix_from_quat(self.rotation)
    }

    /// Camera centre in world coordinates: −Rᵀt.
    #[must_use]
    pub fn center(&self) -> DVec3 {
        -(self.rotation_matrix().transpose() * self.translation)
    }

    /// A world point in camera coordinates: R·p + t.
    #[must_use]
    pub fn world_to_camera(&self, p: DVec3) -> DVec3 {
        self.rotation_matrix() * p + self.translation
    }

    /// A camera-frame point in world coordinates: Rᵀ·(p − t).
    #[must_use]
    pub fn camera_to_world(&self, p: DVec3) -> DVec3 {
        self.rotation_matrix().transpose() * (p - self.translation)
    }

    /// Viewing direction (camera +z) in world coordinates.
    #[must_use]
    pub fn forward(&self) -> DVec3 {
        self.rotation_matrix().row(2)
    }

    /// Image-down direction (camera +y) in world coordinates.
    #[must_use]
    pub fn down(&self) -> DVec3 {
        self.rotation_matrix().row(1)
    }

    /// Image-right direction (camera +x) in world coordinates.
    #[must_use]
    pub fn right(&self) -> DVec3 {
        self.rotation_matrix().row(0)
    }

    /// Camera at `eye` looking at `target` with `up` pointing up in the image
    /// (COLMAP axes: x right, y down, z forward).
    ///
    /// Robust at the poles: when `up` is parallel to the viewing direction (or zero), the world
    /// axis least aligned with the viewing direction (first of x, y, z on ties) is used as up
    /// instead. When `eye == target` the camera looks down world −z.
    #[must_use]
    pub fn look_at(eye: DVec3, target: DVec3, up: DVec3) -> Self {
        let (right, down, forward) = look_frame(eye, target, up);
        let r = DMat3::from_cols(right, down, forward).transpose();
        Self::from_rotation_and_center(&r, eye)
    }
}

/// Orthonormal (right, down, forward) world directions of a camera at `eye` looking at
/// `target` with image-up `up`; the single place where the look-at basis is computed
/// (used by [`Pose::look_at`] and the OpenGL view matrix).
pub(crate) fn look_frame(eye: DVec3, target: DVec3, up: DVec3) -> (DVec3, DVec3, DVec3) {
    let forward = (target - eye).try_normalize().unwrap_or(DVec3::NEG_Z);
    // |f × up| below this (relative to |up|) means up is parallel to the view: use a fallback.
    const PARALLEL: f64 = 1e-9;
    let right = match forward.cross(up).try_normalize() {
        Some(r) if forward.cross(up).length() > PARALLEL * up.length() => r,
        _ => {
            let fallback = [DVec3::X, DVec3::Y, DVec3::Z]
                .into_iter()
                .fold((DVec3::X, f64::INFINITY), |best, axis| {
                    let a = forward.dot(axis).abs();
                    if a < best.1 { (axis, a) } else { best }
                })
                .0;
            forward.cross(fallback).normalize()
        }
    };
    // Just above the threshold the cross product is the small difference of products near 1,
    // so its rounding (~1e-16) is up to 1e-7 of its length: remove the part along forward that
    // this leaves, or the basis is orthogonal only to ~1e-7.
    let right = (right - forward * forward.dot(right)).normalize();
    let down = forward.cross(right);
    (right, down, forward)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn look_at_axes_follow_colmap() {
        // Camera on +z looking at the origin with y up: right = +x, down = −y, forward = −z.
        let p = Pose::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y);
        assert_relative_eq!(p.right(), DVec3::X, epsilon = 1e-15);
        assert_relative_eq!(p.down(), DVec3::NEG_Y, epsilon = 1e-15);
        assert_relative_eq!(p.forward(), DVec3::NEG_Z, epsilon = 1e-15);
        assert_relative_eq!(p.center(), DVec3::new(0.0, 0.0, 5.0), epsilon = 1e-14);
        assert_relative_eq!(
            p.world_to_camera(DVec3::ZERO),
            DVec3::new(0.0, 0.0, 5.0),
            epsilon = 1e-14
        );
        // A point above the target is above the image centre (negative camera y).
        assert!(p.world_to_camera(DVec3::Y).y < 0.0);
    }

    #[test]
    fn look_at_is_robust_at_the_poles() {
        for (eye, up) in [
            (DVec3::new(0.0, 7.0, 0.0), DVec3::Y),
            (DVec3::new(0.0, -7.0, 0.0), DVec3::Y),
            (DVec3::new(0.0, 0.0, 3.0), DVec3::Z),
            (DVec3::new(2.0, 0.0, 0.0), DVec3::ZERO),
            (DVec3::new(0.0, 1e6, 0.0), DVec3::new(1e-12, 1.0, 0.0)),
        ] {
            let p = Pose::look_at(eye, DVec3::ZERO, up);
            let r = p.rotation_matrix();
            assert!(r.is_finite(), "{eye} {up}");
            assert_relative_eq!(r * r.transpose(), DMat3::IDENTITY, epsilon = 1e-12);
            assert_relative_eq!(r.determinant(), 1.0, epsilon = 1e-12);
            assert_relative_eq!(p.forward(), -eye.normalize(), epsilon = 1e-12);
            assert_relative_eq!(p.center(), eye, epsilon = 1e-9 * eye.length());
        }
        // Eye at the target: a valid pose looking down −z rather than NaN.
        let p = Pose::look_at(DVec3::ONE, DVec3::ONE, DVec3::Y);
        assert_relative_eq!(p.forward(), DVec3::NEG_Z, epsilon = 1e-15);
    }

    /// Straight up and down with an up vector parallel or nearly parallel to the view (within
    /// 10⁻¹³ to 10⁻³ rad, on both sides of the fallback's threshold), for oblique view directions:
    /// the rotation is orthonormal with det +1 and its forward axis is the view direction, checked
    /// on the pose's matrix and on the (right, down, forward) basis the pose was built from.
    #[test]
    fn look_at_with_up_nearly_parallel_to_the_view() {
        let dirs = [
            DVec3::Y,
            DVec3::NEG_Y,
            DVec3::new(0.3, 0.9, -0.2).normalize(),
            DVec3::new(-0.577, 0.01, 0.8166).normalize(),
        ];
        for f in dirs {
            let perp = f.any_orthonormal_vector();
            for angle in [0.0_f64, 1e-13, 1e-11, 1e-10, 1e-9, 3e-9, 1e-8, 1e-6, 1e-3] {
                for sign in [1.0, -1.0] {
                    let up = sign * (f * angle.cos() + perp * angle.sin()) * 2.5;
                    let eye = DVec3::new(1.0, -2.0, 3.0);
                    let target = eye + 7.0 * f;
                    let (right, down, forward) = look_frame(eye, target, up);
                    let basis = DMat3::from_cols(right, down, forward);
                    let ctx = format!("forward {f}, angle {angle}, sign {sign}");
                    assert!(
                        (basis.transpose() * basis - DMat3::IDENTITY)
                            .to_cols_array()
                            .iter()
                            .all(|v| v.abs() < 1e-14),
                        "basis not orthonormal: {ctx}"
                    );
                    assert!((basis.determinant() - 1.0).abs() < 1e-14, "{ctx}");
                    assert!((forward - f).length() < 1e-15, "{ctx}");
                    let p = Pose::look_at(eye, target, up);
                    let r = p.rotation_matrix();
                    assert_relative_eq!(r * r.transpose(), DMat3::IDENTITY, epsilon = 1e-14);
                    assert_relative_eq!(r.determinant(), 1.0, epsilon = 1e-14);
                    assert!((p.forward() - f).length() < 1e-14, "{ctx}: {}", p.forward());
                }
            }
        }
    }

    #[test]
    fn far_cameras_keep_double_precision() {
        // Voxel coordinates up to 4095 with a camera thousands of units away.
        let eye = DVec3::new(9000.0, 3000.0, -7000.0);
        let target = DVec3::new(2047.5, 2047.5, 2047.5);
        let p = Pose::look_at(eye, target, DVec3::Y);
        let c = p.world_to_camera(target);
        assert_relative_eq!(c.x, 0.0, epsilon = 1e-9);
        assert_relative_eq!(c.y, 0.0, epsilon = 1e-9);
        assert_relative_eq!(c.z, (target - eye).length(), epsilon = 1e-9);
        let q = p.camera_to_world(DVec3::new(1.0, 2.0, 3.0));
        assert_relative_eq!(
            p.world_to_camera(q),
            DVec3::new(1.0, 2.0, 3.0),
            epsilon = 1e-9
        );
    }

    #[test]
    fn wxyz_round_trip_normalises() {
        let p = Pose::from_wxyz([2.0, 0.0, 0.0, 0.0], [1.0, 2.0, 3.0]);
        assert_eq!(p.wxyz(), [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(p.center(), DVec3::new(-1.0, -2.0, -3.0));
    }
}
