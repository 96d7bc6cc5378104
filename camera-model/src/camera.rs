//! A pinhole camera: intrinsics and a world→camera pose.

use glam::{DVec2, DVec3, Mat3, Vec3};

use crate::{Intrinsics, Pose};

/// A pinhole camera: what it sees (intrinsics) and where it is (world→camera pose).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Camera {
    /// Image size, focal lengths, principal point and skew.
    pub intrinsics: Intrinsics,
    /// World→camera pose.
    pub pose: Pose,
}

/// A ray in world coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start of the ray (the camera centre).
    pub origin: DVec3,
    /// Unit direction of the ray.
    pub direction: DVec3,
}

impl Ray {
    /// The point `origin + s·direction`.
    #[must_use]
    pub fn at(&self, s: f64) -> DVec3 {
        self.origin + s * self.direction
    }
}

impl Camera {
    /// Camera from intrinsics and pose.
    #[must_use]
    pub fn new(intrinsics: Intrinsics, pose: Pose) -> Self {
        Self { intrinsics, pose }
    }

    /// Pixel coordinates of a world point (pixel (0, 0)'s centre at (0.5, 0.5)); `None` when the
    /// point is not in front of the camera. Points outside the image are still returned; use
    /// [`Intrinsics::contains`] to test visibility.
    #[must_use]
    pub fn project(&self, world: DVec3) -> Option<DVec2> {
        self.intrinsics.project(self.pose.world_to_camera(world))
    }

    /// Camera centre in world coordinates.
    #[must_use]
    pub fn center(&self) -> DVec3 {
        self.pose.center()
    }

    /// Depth of a world point along the viewing axis (camera z).
    #[must_use]
    pub fn depth(&self, world: DVec3) -> f64 {
        self.pose.world_to_camera(world).z
    }

    /// The world ray through a pixel position: the inverse of [`Self::project`].
    #[must_use]
    pub fn ray(&self, pixel: DVec2) -> Ray {
        let r = self.pose.rotation_matrix();
        let dir_cam = self.intrinsics.unproject(pixel);
        Ray {
            origin: self.center(),
            direction: (r.transpose() * dir_cam).normalize(),
        }
    }

    /// Single-precision copy for hot loops (rasterisers); the rotation is converted from the
    /// double-precision matrix so it stays orthonormal to f32 rounding.
    #[must_use]
    pub fn to_f32(&self) -> CameraF32 {
        let k = &self.intrinsics;
        CameraF32 {
            width: k.width,
            height: k.height,
            fx: k.fx as f32,
            fy: k.fy as f32,
            cx: k.cx as f32,
            cy: k.cy as f32,
            skew: k.skew as f32,
            rotation: self.pose.rotation_matrix().as_mat3(),
            translation: self.pose.translation.as_vec3(),
        }
    }
}

/// Single-precision pinhole camera for hot loops (see [`Camera::to_f32`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraF32 {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, in pixels.
    pub fx: f32,
    /// Focal length along y, in pixels.
    pub fy: f32,
    /// Principal point x, in pixels.
    pub cx: f32,
    /// Principal point y, in pixels.
    pub cy: f32,
    /// Skew (camera y to pixel x).
    pub skew: f32,
    /// World→camera rotation matrix.
    pub rotation: Mat3,
    /// World→camera translation.
    pub translation: Vec3,
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn camera() -> Camera {
        Camera::new(
            Intrinsics::from_fov_y(800, 600, 20.0),
            Pose::look_at(
                DVec3::new(3000.0, 800.0, 2500.0),
                DVec3::splat(512.0),
                DVec3::Y,
            ),
        )
    }

    #[test]
    fn target_projects_to_principal_point() {
        let c = camera();
        assert_relative_eq!(
            c.project(DVec3::splat(512.0)).unwrap(),
            DVec2::new(400.0, 300.0),
            epsilon = 1e-9
        );
        assert_relative_eq!(
            c.center(),
            DVec3::new(3000.0, 800.0, 2500.0),
            epsilon = 1e-9
        );
    }

    #[test]
    fn ray_inverts_projection() {
        let c = camera();
        for pixel in [
            DVec2::new(0.5, 0.5),
            DVec2::new(799.5, 10.25),
            DVec2::new(400.0, 300.0),
        ] {
            let ray = c.ray(pixel);
            assert_relative_eq!(ray.direction.length(), 1.0, epsilon = 1e-14);
            for s in [1.0, 100.0, 5000.0] {
                assert_relative_eq!(c.project(ray.at(s)).unwrap(), pixel, epsilon = 1e-8);
                assert_relative_eq!(c.depth(ray.at(s)) / s, c.depth(ray.at(1.0)), epsilon = 1e-9);
            }
        }
    }

    #[test]
    fn f32_copy_projects_like_f64() {
        let c = camera();
        let f = c.to_f32();
        let p = DVec3::new(600.0, 300.0, 700.0);
        let q = f.rotation * p.as_vec3() + f.translation;
        let px = (f.fx * q.x / q.z + f.cx, f.fy * q.y / q.z + f.cy);
        let expected = c.project(p).unwrap();
        assert!((f64::from(px.0) - expected.x).abs() < 0.05);
        assert!((f64::from(px.1) - expected.y).abs() < 0.05);
    }
}
