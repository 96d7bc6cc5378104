//! The single-precision pinhole camera the rasteriser renders from.

use glam::{Mat3, Vec3};

/// A pinhole camera in COLMAP conventions (x right, y down, z forward; world→camera pose;
/// pixel (0, 0)'s centre at (0.5, 0.5)). Skew is not modelled: converting a skewed
/// [`camera_model::Camera`] is refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderCamera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, in pixels.
    pub fx: f32,
    /// Focal length along y, in pixels.
    pub fy: f32,
    /// Principal point x, in pixels from the left image edge.
    pub cx: f32,
    /// Principal point y, in pixels from the top image edge.
    pub cy: f32,
    /// World→camera rotation.
    pub rotation: Mat3,
    /// World→camera translation: `x_cam = rotation·x_world + translation`.
    pub translation: Vec3,
}

impl RenderCamera {
    /// Returns the camera centre in world coordinates, −Rᵀt.
    #[must_use]
    pub fn center(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// Returns the camera-space position of a world point.
    #[must_use]
    pub fn to_camera(&self, world: Vec3) -> Vec3 {
        self.rotation * world + self.translation
    }

    /// Returns tan of half the horizontal and vertical fields of view, W/(2·fx) and H/(2·fy).
    #[must_use]
    pub fn tan_half_fov(&self) -> (f32, f32) {
        (
            0.5 * self.width as f32 / self.fx,
            0.5 * self.height as f32 / self.fy,
        )
    }
}

impl TryFrom<&camera_model::Camera> for RenderCamera {
    type Error = crate::Error;

    /// The one conversion from camera-model's camera: to single precision, refusing a skewed
    /// camera ([`crate::Error::Skewed`]) because the 3DGS projection (and every 3DGS viewer) has
    /// no skew term, so dropping it would render a different image without a word.
    fn try_from(c: &camera_model::Camera) -> Result<Self, Self::Error> {
        if c.intrinsics.skew != 0.0 {
            return Err(crate::Error::Skewed {
                skew: c.intrinsics.skew,
            });
        }
        let f = c.to_f32();
        Ok(Self {
            width: f.width,
            height: f.height,
            fx: f.fx,
            fy: f.fy,
            cx: f.cx,
            cy: f.cy,
            rotation: f.rotation,
            translation: f.translation,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::{Camera, Intrinsics, Pose};
    use glam::DVec3;

    #[test]
    fn conversion_keeps_the_pinhole_and_refuses_skew() {
        let pose = Pose::look_at(DVec3::new(1.0, 2.0, 3.0), DVec3::ZERO, DVec3::Y);
        let mut k = Intrinsics::from_fov_y(64, 48, 30.0);
        let cam = RenderCamera::try_from(&Camera::new(k, pose)).unwrap();
        assert_eq!((cam.width, cam.height), (64, 48));
        assert_eq!(cam.fx, k.fx as f32);
        assert!((cam.center().as_dvec3() - DVec3::new(1.0, 2.0, 3.0)).length() < 1e-5);
        k.skew = 0.5;
        let err = RenderCamera::try_from(&Camera::new(k, pose)).unwrap_err();
        assert!(err.to_string().contains("skew"), "{err}");
    }
}
