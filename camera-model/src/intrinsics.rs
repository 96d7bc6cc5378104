//! Pinhole intrinsics and the field-of-view ↔ focal-length relation.

use glam::{DVec2, DVec3};

/// Pinhole intrinsics in pixels; pixel (0, 0)'s centre is at (0.5, 0.5) (COLMAP convention).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Intrinsics {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, in pixels.
    pub fx: f64,
    /// Focal length along y, in pixels.
    pub fy: f64,
    /// Principal point x, in pixels from the left edge of the image.
    pub cx: f64,
    /// Principal point y, in pixels from the top edge of the image.
    pub cy: f64,
    /// Skew: how much camera y moves pixel x (0 for every real and rendered camera here).
    pub skew: f64,
}

/// Focal length in pixels that spans `fov_rad` over `size_px` pixels (symmetric frustum).
#[must_use]
pub fn focal_from_fov(fov_rad: f64, size_px: f64) -> f64 {
    size_px / (2.0 * (0.5 * fov_rad).tan())
}

/// Field of view in radians spanned by `size_px` pixels at focal length `focal_px`.
#[must_use]
pub fn fov_from_focal(focal_px: f64, size_px: f64) -> f64 {
    2.0 * (0.5 * size_px / focal_px).atan()
}

impl Intrinsics {
    /// Square-pixel intrinsics with vertical field of view `fov_y_deg` and the principal point at
    /// the exact image centre (W/2, H/2), as Inria's trainer assumes.
    #[must_use]
    pub fn from_fov_y(width: u32, height: u32, fov_y_deg: f64) -> Self {
        let f = focal_from_fov(fov_y_deg.to_radians(), f64::from(height));
        Self::centered(width, height, f, f)
    }

    /// Intrinsics with the given focal lengths and the principal point at (W/2, H/2).
    #[must_use]
    pub fn centered(width: u32, height: u32, fx: f64, fy: f64) -> Self {
        Self {
            width,
            height,
            fx,
            fy,
            cx: 0.5 * f64::from(width),
            cy: 0.5 * f64::from(height),
            skew: 0.0,
        }
    }

    /// Horizontal field of view in radians.
    #[must_use]
    pub fn fov_x(&self) -> f64 {
        fov_from_focal(self.fx, f64::from(self.width))
    }

    /// Vertical field of view in radians.
    #[must_use]
    pub fn fov_y(&self) -> f64 {
        fov_from_focal(self.fy, f64::from(self.height))
    }

    /// Pixel coordinates of a camera-frame point; `None` when it is not in front (z ≤ 0).
    #[must_use]
    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        if p.z <= 0.0 || !p.z.is_finite() {
            return None;
        }
        let (u, v) = (p.x / p.z, p.y / p.z);
        Some(DVec2::new(
            self.fx * u + self.skew * v + self.cx,
            self.fy * v + self.cy,
        ))
    }

    /// Camera-frame direction (z = 1) that projects to `pixel`: the inverse of [`Self::project`].
    #[must_use]
    pub fn unproject(&self, pixel: DVec2) -> DVec3 {
        let v = (pixel.y - self.cy) / self.fy;
        let u = (pixel.x - self.cx - self.skew * v) / self.fx;
        DVec3::new(u, v, 1.0)
    }

    /// Whether a pixel position lies inside the image rectangle [0, W) × [0, H).
    #[must_use]
    pub fn contains(&self, pixel: DVec2) -> bool {
        pixel.x >= 0.0
            && pixel.y >= 0.0
            && pixel.x < f64::from(self.width)
            && pixel.y < f64::from(self.height)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn fov_focal_round_trip_and_pcc_value() {
        // PccAppRenderer: 20° vertical FoV at 1080 rows gives f = 1080 / (2·tan 10°) ≈ 3062.5 px.
        let f = focal_from_fov(20f64.to_radians(), 1080.0);
        assert_relative_eq!(f, 3062.4925, epsilon = 1e-3);
        assert_relative_eq!(
            fov_from_focal(f, 1080.0),
            20f64.to_radians(),
            epsilon = 1e-15
        );
        let k = Intrinsics::from_fov_y(1920, 1080, 20.0);
        assert_eq!((k.cx, k.cy), (960.0, 540.0));
        assert_relative_eq!(k.fov_y().to_degrees(), 20.0, epsilon = 1e-12);
    }

    #[test]
    fn principal_point_and_pixel_centres() {
        let k = Intrinsics::centered(4, 2, 10.0, 10.0);
        // The optical axis hits the image centre, which is the corner shared by 4 pixels.
        assert_eq!(k.project(DVec3::Z), Some(DVec2::new(2.0, 1.0)));
        assert_eq!(k.project(DVec3::new(0.0, 0.0, -1.0)), None);
        assert!(k.contains(DVec2::new(0.5, 0.5)));
        assert!(!k.contains(DVec2::new(4.0, 0.5)));
    }

    #[test]
    fn unproject_inverts_project_with_skew() {
        let k = Intrinsics {
            width: 640,
            height: 480,
            fx: 500.0,
            fy: 520.0,
            cx: 321.0,
            cy: 239.0,
            skew: 3.5,
        };
        let p = DVec3::new(0.3, -0.2, 2.0);
        let px = k.project(p).unwrap();
        let d = k.unproject(px);
        assert_relative_eq!(d * 2.0, p, epsilon = 1e-12);
    }
}
