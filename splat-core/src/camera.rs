//! The single-precision pinhole camera the rasteriser renders from.

use glam::{Mat3, Vec3};

/// A pinhole camera in COLMAP conventions (x right, y down, z forward; world→camera pose;
/// pixel (0, 0)'s centre at (0.5, 0.5)). Skew is not modelled.
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

impl From<&camera_model::Camera> for RenderCamera {
    fn from(c: &camera_model::Camera) -> Self {
        // 3DGS rasterisers have no skew term; rendered rigs and COLMAP's pinhole models have none.
        let f = c.to_f32();
        Self {
            width: f.width,
            height: f.height,
            fx: f.fx,
            fy: f.fy,
            cx: f.cx,
            cy: f.cy,
            rotation: f.rotation,
            translation: f.translation,
        }
    }
}
