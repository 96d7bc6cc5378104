//! The renderer's camera: single precision, checked, with pixel rays as linear functions of the pixel.

use camera_model::{Camera, CameraF32, Intrinsics};
use glam::Vec3;

use crate::Error;

/// The largest image side the renderer accepts (per axis, after supersampling).
const MAX_SIDE: u32 = 32_768;

/// The most pixels one render may have (after supersampling): 2^27 pixels already take 1 GiB of
/// z-buffer and 2.5 GiB of colour, alpha and depth.
const MAX_PIXELS: u64 = 1 << 27;

/// A camera in single precision (camera-model's [`CameraF32`], reachable through `Deref`), with
/// the pixel-ray directions as linear functions of the pixel.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ViewCamera {
    /// The camera's intrinsics and world→camera pose in single precision.
    cam: CameraF32,
    /// Camera centre in world coordinates.
    pub center: Vec3,
    /// World direction (camera z = 1) of the ray through pixel position (u, v) is
    /// `ray_base + u·ray_du + v·ray_dv`.
    pub ray_base: Vec3,
    pub ray_du: Vec3,
    pub ray_dv: Vec3,
}

impl std::ops::Deref for ViewCamera {
    type Target = CameraF32;

    fn deref(&self) -> &CameraF32 {
        &self.cam
    }
}

impl ViewCamera {
    /// Single-precision view of `camera`, checked for a usable size and finite parameters.
    pub fn new(camera: &Camera) -> Result<Self, Error> {
        let k = &camera.intrinsics;
        if k.width == 0 || k.height == 0 || k.width > MAX_SIDE || k.height > MAX_SIDE {
            return Err(Error::InvalidCamera(format!(
                "image size {}×{} is outside 1..={MAX_SIDE}",
                k.width, k.height
            )));
        }
        if u64::from(k.width) * u64::from(k.height) > MAX_PIXELS {
            return Err(Error::InvalidCamera(format!(
                "image size {}×{} exceeds the renderer's limit of {MAX_PIXELS} pixels (lower the resolution or supersampling)",
                k.width, k.height
            )));
        }
        let finite = [k.fx, k.fy, k.cx, k.cy, k.skew]
            .iter()
            .all(|v| v.is_finite())
            && k.fx != 0.0
            && k.fy != 0.0;
        let center = camera.center();
        if !finite || !center.is_finite() || !camera.pose.translation.is_finite() {
            return Err(Error::InvalidCamera(format!(
                "non-finite or zero parameters: fx {} fy {} cx {} cy {} skew {}, centre {center}",
                k.fx, k.fy, k.cx, k.cy, k.skew
            )));
        }
        let r = camera.pose.rotation_matrix();
        let rt = r.transpose();
        // Intrinsics::unproject: v = (py − cy)/fy, u = (px − cx − skew·v)/fx, direction (u, v, 1).
        let du = rt * glam::DVec3::new(1.0 / k.fx, 0.0, 0.0);
        let dv = rt * glam::DVec3::new(-k.skew / (k.fx * k.fy), 1.0 / k.fy, 0.0);
        let base = rt * glam::DVec3::new((-k.cx + k.skew * k.cy / k.fy) / k.fx, -k.cy / k.fy, 1.0);
        Ok(Self {
            cam: camera.to_f32(),
            center: center.as_vec3(),
            ray_base: base.as_vec3(),
            ray_du: du.as_vec3(),
            ray_dv: dv.as_vec3(),
        })
    }

    /// Number of pixels.
    pub fn pixels(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// World direction with camera z = 1 of the ray through the centre of pixel (x, y).
    #[inline]
    pub fn world_ray(&self, x: u32, y: u32) -> Vec3 {
        self.ray_base + (x as f32 + 0.5) * self.ray_du + (y as f32 + 0.5) * self.ray_dv
    }

    /// Camera-space direction with z = 1 of the ray through the centre of pixel (x, y).
    #[inline]
    pub fn camera_ray(&self, x: u32, y: u32) -> Vec3 {
        let v = (y as f32 + 0.5 - self.cy) / self.fy;
        let u = (x as f32 + 0.5 - self.cx - self.skew * v) / self.fx;
        Vec3::new(u, v, 1.0)
    }

    /// Pixel-index ranges (inclusive) whose centres can fall inside the camera-space box
    /// [lo, hi] (lo.z > 0), or `None` when none can.
    #[inline]
    pub fn pixel_range(&self, lo: Vec3, hi: Vec3) -> Option<(u32, u32, u32, u32)> {
        if lo.z <= 0.0 {
            return None;
        }
        // Extremes of x/z and y/z over the box: the divisor that makes the ratio extreme depends on the sign.
        let ratio = |a: f32, b: f32| -> (f32, f32) {
            let min = if a < 0.0 { a / lo.z } else { a / hi.z };
            let max = if b > 0.0 { b / lo.z } else { b / hi.z };
            (min, max)
        };
        let (xa, xb) = ratio(lo.x, hi.x);
        let (ya, yb) = ratio(lo.y, hi.y);
        let (sa, sb) = if self.skew >= 0.0 {
            (self.skew * ya, self.skew * yb)
        } else {
            (self.skew * yb, self.skew * ya)
        };
        let (fxa, fxb) = if self.fx >= 0.0 { (xa, xb) } else { (xb, xa) };
        let (fya, fyb) = if self.fy >= 0.0 { (ya, yb) } else { (yb, ya) };
        let umin = self.fx * fxa + sa + self.cx;
        let umax = self.fx * fxb + sb + self.cx;
        let vmin = self.fy * fya + self.cy;
        let vmax = self.fy * fyb + self.cy;
        // Pixel i's centre is i + 0.5: the covered indices are ceil(min − 0.5) ..= floor(max − 0.5).
        let x0 = (umin - 0.5).ceil().max(0.0);
        let x1 = (umax - 0.5).floor().min(self.width as f32 - 1.0);
        let y0 = (vmin - 0.5).ceil().max(0.0);
        let y1 = (vmax - 0.5).floor().min(self.height as f32 - 1.0);
        // NaN fails both comparisons and is refused here too.
        if x0 <= x1 && y0 <= y1 {
            Some((x0 as u32, x1 as u32, y0 as u32, y1 as u32))
        } else {
            None
        }
    }
}

/// `camera` with its image `k` times larger in each direction (same field of view).
pub(crate) fn scaled_camera(camera: &Camera, k: u32) -> Camera {
    let s = f64::from(k);
    let i = &camera.intrinsics;
    Camera::new(
        Intrinsics {
            width: i.width * k,
            height: i.height * k,
            fx: i.fx * s,
            fy: i.fy * s,
            cx: i.cx * s,
            cy: i.cy * s,
            skew: i.skew * s,
        },
        camera.pose,
    )
}
