//! The MPEG PccAppRenderer viewport (an OpenGL look-at camera) and its COLMAP equivalent.
//!
//! PccAppRenderer builds its view with `glm::lookAt(eye, center, up)` (camera looks down −Z, +Y
//! up) and a symmetric perspective frustum with a 20° vertical field of view
//! (`reference/formats.md` §2.4). COLMAP cameras look down +z with y down, so the same camera in
//! COLMAP is R = diag(1, −1, −1)·R_gl, t = diag(1, −1, −1)·t_gl with fx = fy = H / (2·tan(fov_y/2))
//! and the principal point at (W/2, H/2).

use glam::{DMat3, DMat4, DVec3, DVec4};

use crate::pose::look_frame;
use crate::{Camera, Error, Intrinsics, Pose};

/// PccAppRenderer's default vertical field of view in degrees (`m_fFov = 20.f`).
pub const DEFAULT_FOV_Y_DEG: f64 = 20.0;

/// An OpenGL look-at viewport with a symmetric perspective frustum.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GlViewport {
    /// Position of the viewer.
    pub eye: DVec3,
    /// Point looked at (PccAppRenderer's "view" / "center").
    pub center: DVec3,
    /// Up direction of the image.
    pub up: DVec3,
    /// Vertical field of view in degrees.
    pub fov_y_deg: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

/// diag(1, −1, −1): flips OpenGL camera axes (y up, looking down −z) to COLMAP's (y down, +z).
const GL_TO_COLMAP: DMat3 = DMat3::from_cols(DVec3::X, DVec3::NEG_Y, DVec3::NEG_Z);

impl GlViewport {
    /// Viewport with PccAppRenderer's default 20° vertical field of view.
    #[must_use]
    pub fn new(eye: DVec3, center: DVec3, up: DVec3, width: u32, height: u32) -> Self {
        Self {
            eye,
            center,
            up,
            fov_y_deg: DEFAULT_FOV_Y_DEG,
            width,
            height,
        }
    }

    /// The OpenGL view matrix, as `glm::lookAt(eye, center, up)` builds it (world→eye, column
    /// major); made robust at the poles like [`Pose::look_at`].
    #[must_use]
    pub fn view_matrix(&self) -> DMat4 {
        let (s, down, f) = look_frame(self.eye, self.center, self.up);
        let u = -down; // glm: u = s × f
        DMat4::from_cols(
            DVec4::new(s.x, u.x, -f.x, 0.0),
            DVec4::new(s.y, u.y, -f.y, 0.0),
            DVec4::new(s.z, u.z, -f.z, 0.0),
            DVec4::new(-s.dot(self.eye), -u.dot(self.eye), f.dot(self.eye), 1.0),
        )
    }

    /// The OpenGL projection matrix, as `glm::perspective(fov_y, W/H, near, far)` builds it.
    #[must_use]
    pub fn projection_matrix(&self, near: f64, far: f64) -> DMat4 {
        let aspect = f64::from(self.width) / f64::from(self.height);
        let g = 1.0 / (0.5 * self.fov_y_deg.to_radians()).tan();
        DMat4::from_cols(
            DVec4::new(g / aspect, 0.0, 0.0, 0.0),
            DVec4::new(0.0, g, 0.0, 0.0),
            DVec4::new(0.0, 0.0, (far + near) / (near - far), -1.0),
            DVec4::new(0.0, 0.0, 2.0 * far * near / (near - far), 0.0),
        )
    }

    /// Intrinsics of the viewport: fx = fy = H / (2·tan(fov_y/2)), principal point (W/2, H/2).
    #[must_use]
    pub fn intrinsics(&self) -> Intrinsics {
        Intrinsics::from_fov_y(self.width, self.height, self.fov_y_deg)
    }

    /// The same camera in COLMAP convention: R = diag(1, −1, −1)·R_gl, t = diag(1, −1, −1)·t_gl.
    #[must_use]
    pub fn to_colmap(&self) -> Camera {
        let v = self.view_matrix();
        let r_gl = DMat3::from_mat4(v);
        let t_gl = v.w_axis.truncate();
        let pose = Pose::from_rotation_matrix(&(GL_TO_COLMAP * r_gl), GL_TO_COLMAP * t_gl);
        Camera::new(self.intrinsics(), pose)
    }

    /// The viewport of a COLMAP camera, looking at the point `target_distance` ahead of it.
    ///
    /// Refused unless the camera has square pixels, no skew and its principal point at the image
    /// centre (a symmetric frustum), within a relative tolerance of 1e-9.
    pub fn from_colmap(camera: &Camera, target_distance: f64) -> Result<Self, Error> {
        let k = &camera.intrinsics;
        let tol = 1e-9 * f64::from(k.width.max(k.height)).max(1.0);
        if (k.fx - k.fy).abs() > 1e-9 * k.fx.abs() {
            return Err(Error::NotAViewport(format!(
                "fx = {} differs from fy = {}",
                k.fx, k.fy
            )));
        }
        if (k.cx - 0.5 * f64::from(k.width)).abs() > tol
            || (k.cy - 0.5 * f64::from(k.height)).abs() > tol
        {
            return Err(Error::NotAViewport(format!(
                "principal point ({}, {}) is not the image centre ({}, {})",
                k.cx,
                k.cy,
                0.5 * f64::from(k.width),
                0.5 * f64::from(k.height)
            )));
        }
        if k.skew != 0.0 {
            return Err(Error::NotAViewport(format!("skew is {}", k.skew)));
        }
        if !(target_distance > 0.0 && target_distance.is_finite()) {
            return Err(Error::InvalidParameter(format!(
                "target distance must be positive and finite, got {target_distance}"
            )));
        }
        let eye = camera.center();
        Ok(Self {
            eye,
            center: eye + target_distance * camera.pose.forward(),
            up: -camera.pose.down(),
            fov_y_deg: k.fov_y().to_degrees(),
            width: k.width,
            height: k.height,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use glam::DVec2;
    use rand::{RngExt, SeedableRng};

    /// Pixel position of a world point through the OpenGL pipeline: clip = P·V·p, NDC = clip/w,
    /// window x = (ndc.x + 1)/2·W, and rows counted from the top as PccAppRenderer writes them
    /// (it flips glReadPixels' bottom-up rows): y = (1 − ndc.y)/2·H.
    fn project_gl(vp: &GlViewport, p: DVec3) -> Option<DVec2> {
        let clip = vp.projection_matrix(0.1, 1e5) * vp.view_matrix() * p.extend(1.0);
        if clip.w <= 0.0 {
            return None;
        }
        let ndc = clip.truncate() / clip.w;
        Some(DVec2::new(
            (ndc.x + 1.0) * 0.5 * f64::from(vp.width),
            (1.0 - ndc.y) * 0.5 * f64::from(vp.height),
        ))
    }

    fn random_viewport(rng: &mut rand_pcg::Pcg64) -> GlViewport {
        let mut v3 = |s: f64| {
            DVec3::new(
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
                rng.random::<f64>() - 0.5,
            ) * s
        };
        let center = v3(4096.0) + DVec3::splat(2048.0);
        let eye = center + v3(8000.0);
        let up = v3(2.0);
        GlViewport {
            eye,
            center,
            up,
            fov_y_deg: 5.0 + 80.0 * rng.random::<f64>(),
            width: 64 + rng.random_range(0..2000u32),
            height: 64 + rng.random_range(0..2000u32),
        }
    }

    #[test]
    fn gl_and_colmap_project_random_points_to_the_same_pixel() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let mut checked = 0;
        for _ in 0..2_000 {
            let vp = random_viewport(&mut rng);
            let cam = vp.to_colmap();
            // Independent construction of the same camera from the look-at definition.
            let direct = Pose::look_at(vp.eye, vp.center, vp.up);
            assert_relative_eq!(
                cam.pose.rotation_matrix(),
                direct.rotation_matrix(),
                epsilon = 1e-12
            );
            for _ in 0..10 {
                // A random pixel and depth in front of the viewer, as a world point.
                let px = DVec2::new(
                    rng.random::<f64>() * f64::from(vp.width),
                    rng.random::<f64>() * f64::from(vp.height),
                );
                let p = cam.ray(px).at(1.0 + 10_000.0 * rng.random::<f64>());
                let gl = project_gl(&vp, p).unwrap();
                let colmap = cam.project(p).unwrap();
                assert!((gl - colmap).length() < 1e-6, "{gl} vs {colmap}");
                assert!((colmap - px).length() < 1e-6);
                checked += 1;
            }
            // Behind the viewer neither projects.
            let behind = vp.eye + (vp.eye - vp.center);
            assert!(project_gl(&vp, behind).is_none() && cam.project(behind).is_none());
        }
        assert_eq!(checked, 20_000);
    }

    #[test]
    fn colmap_to_viewport_and_back() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        for _ in 0..1_000 {
            let vp = random_viewport(&mut rng);
            let cam = vp.to_colmap();
            let back = GlViewport::from_colmap(&cam, (vp.center - vp.eye).length()).unwrap();
            assert_relative_eq!(back.eye, vp.eye, epsilon = 1e-8);
            assert_relative_eq!(back.center, vp.center, epsilon = 1e-8);
            assert_relative_eq!(back.fov_y_deg, vp.fov_y_deg, epsilon = 1e-10);
            // up comes back orthogonalised but in the same half-plane.
            assert!(back.up.dot(vp.up) > 0.0);
            assert_relative_eq!(
                back.to_colmap().pose.rotation_matrix(),
                cam.pose.rotation_matrix(),
                epsilon = 1e-12
            );
        }
    }

    #[test]
    fn pcc_default_focal_and_refusals() {
        let vp = GlViewport::new(
            DVec3::new(0.0, 0.0, 3000.0),
            DVec3::ZERO,
            DVec3::Y,
            1920,
            1080,
        );
        let cam = vp.to_colmap();
        assert_relative_eq!(cam.intrinsics.fy, 3062.4925, epsilon = 1e-3);
        assert_eq!((cam.intrinsics.cx, cam.intrinsics.cy), (960.0, 540.0));
        let mut off = cam;
        off.intrinsics.cx += 1.0;
        assert!(matches!(
            GlViewport::from_colmap(&off, 1.0),
            Err(Error::NotAViewport(_))
        ));
        let mut aniso = cam;
        aniso.intrinsics.fx *= 1.01;
        assert!(GlViewport::from_colmap(&aniso, 1.0).is_err());
        assert!(GlViewport::from_colmap(&cam, 0.0).is_err());
    }
}
