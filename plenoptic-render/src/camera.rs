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

    /// World direction with camera z = 1 of the ray through the centre of pixel (x, y): one
    /// lane of [`ViewCamera::world_rays`] (the drawing makes rays in lanes; the tests' brute
    /// force one at a time).
    #[cfg(test)]
    pub fn world_ray(&self, x: u32, y: u32) -> Vec3 {
        let [dx, dy, dz] = self.world_rays(&[x], &[y]);
        Vec3::new(dx[0], dy[0], dz[0])
    }

    /// [`ViewCamera::world_ray`] of the `N` pixels (`xs[lane]`, `ys[lane]`), `[axis][lane]`:
    /// `base + (x + ½)·du + (y + ½)·dv`, each axis in that order, written lane by lane so
    /// that a caller compiled for 8-wide vectors makes 8 rays with each vector operation.
    #[inline(always)]
    pub fn world_rays<const N: usize>(&self, xs: &[u32; N], ys: &[u32; N]) -> [[f32; N]; 3] {
        let (base, du, dv) = (self.ray_base, self.ray_du, self.ray_dv);
        // Pixel indices are far below 2³¹, so through i32 they convert exactly, and with one
        // AVX2 instruction (u32 has none before AVX-512).
        let u: [f32; N] = std::array::from_fn(|l| xs[l] as i32 as f32 + 0.5);
        let v: [f32; N] = std::array::from_fn(|l| ys[l] as i32 as f32 + 0.5);
        // Axis by axis, not through an array built by a closure: LLVM left that closure a call.
        let axis = |b: f32, du: f32, dv: f32| std::array::from_fn(|l| b + u[l] * du + v[l] * dv);
        [
            axis(base.x, du.x, dv.x),
            axis(base.y, du.y, dv.y),
            axis(base.z, du.z, dv.z),
        ]
    }

    /// Camera-space direction with z = 1 of the ray through the centre of pixel (x, y).
    #[inline]
    pub fn camera_ray(&self, x: u32, y: u32) -> Vec3 {
        let v = (y as f32 + 0.5 - self.cy) / self.fy;
        let u = (x as f32 + 0.5 - self.cx - self.skew * v) / self.fx;
        Vec3::new(u, v, 1.0)
    }

    /// Camera-space positions of `N` world points, `[axis][lane]`: `rotation * p + translation`
    /// as glam computes it (the same operations in the same order, so the same bits), written
    /// lane by lane so that a caller compiled for 8-wide vectors moves 8 points with each
    /// vector operation.
    #[inline(always)]
    pub fn camera_space_lanes<const N: usize>(&self, points: &[Vec3; N]) -> [[f32; N]; 3] {
        let (r, t) = (self.rotation, self.translation);
        // Axis by axis, not through an array built by a closure: LLVM left that closure a call.
        let axis = |rx: f32, ry: f32, rz: f32, t: f32| {
            std::array::from_fn(|l| {
                let p = points[l];
                rx * p.x + ry * p.y + rz * p.z + t
            })
        };
        [
            axis(r.x_axis.x, r.y_axis.x, r.z_axis.x, t.x),
            axis(r.x_axis.y, r.y_axis.y, r.z_axis.y, t.y),
            axis(r.x_axis.z, r.y_axis.z, r.z_axis.z, t.z),
        ]
    }

    /// Pixel-index ranges (inclusive) whose centres can fall inside the camera-space box
    /// [lo, hi] (lo.z > 0), or `None` when none can: one lane of [`ViewCamera::pixel_ranges`].
    #[inline]
    pub fn pixel_range(&self, lo: Vec3, hi: Vec3) -> Option<(u32, u32, u32, u32)> {
        let [range] = self.pixel_ranges(lo.to_array().map(|v| [v]), hi.to_array().map(|v| [v]));
        range
    }

    /// [`ViewCamera::pixel_range`] of `N` boxes at once, `lo[axis][lane]` and `hi[axis][lane]`
    /// their corners: written as fixed-length loops over the lanes without branches, so a
    /// caller compiled for 8-wide vectors bounds 8 boxes with each vector operation (a
    /// paper-scale frame's cube pass bounded 3 million boxes a view one at a time, four
    /// divisions each, a third of its time).
    #[inline(always)]
    pub fn pixel_ranges<const N: usize>(
        &self,
        lo: [[f32; N]; 3],
        hi: [[f32; N]; 3],
    ) -> [Option<(u32, u32, u32, u32)>; N] {
        let mut bounds = [[0.0f32; N]; 4];
        let mut inside = [false; N];
        for l in 0..N {
            let (lo_z, hi_z) = (lo[2][l], hi[2][l]);
            // Extremes of x/z and y/z over the box: the divisor that makes the ratio extreme
            // depends on the sign.
            let ratio = |a: f32, b: f32| -> (f32, f32) {
                let min = a / if a < 0.0 { lo_z } else { hi_z };
                let max = b / if b > 0.0 { lo_z } else { hi_z };
                (min, max)
            };
            let (xa, xb) = ratio(lo[0][l], hi[0][l]);
            let (ya, yb) = ratio(lo[1][l], hi[1][l]);
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
            bounds[0][l] = x0;
            bounds[1][l] = x1;
            bounds[2][l] = y0;
            bounds[3][l] = y1;
            // NaN fails the comparisons and is refused here too.
            inside[l] = lo_z > 0.0 && x0 <= x1 && y0 <= y1;
        }
        // The bounds are whole numbers, inside the image where the box is inside it. (Loops,
        // not `map`: `map`'s closures were left out of line, compiled without the caller's AVX2.)
        let mut whole = [[0_u32; N]; 4];
        for (w, b) in whole.iter_mut().zip(&bounds) {
            for (w, &b) in w.iter_mut().zip(b) {
                *w = crate::cpu::small_whole(b);
            }
        }
        std::array::from_fn(|l| {
            inside[l].then(|| {
                let [x0, x1, y0, y1] = whole.map(|b| b[l]);
                (x0, x1, y0, y1)
            })
        })
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

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::Pose;
    use glam::DVec3;

    #[test]
    fn camera_space_lanes_are_glams_transform_bit_for_bit() {
        let camera = Camera::new(
            Intrinsics::from_fov_y(640, 480, 35.0),
            Pose::look_at(
                DVec3::new(3100.0, -800.0, 2500.0),
                DVec3::splat(2048.0),
                DVec3::Y,
            ),
        );
        let view = ViewCamera::new(&camera).unwrap();
        let points: [Vec3; 8] = std::array::from_fn(|l| {
            let l = l as f32;
            Vec3::new(2048.0 + 37.3 * l, 1900.0 - 11.9 * l * l, 2200.0 + 0.017 * l)
        });
        let lanes = view.camera_space_lanes(&points);
        for (l, &p) in points.iter().enumerate() {
            let c = view.rotation * p + view.translation;
            let lane = Vec3::new(lanes[0][l], lanes[1][l], lanes[2][l]);
            assert_eq!(
                lane.to_array().map(f32::to_bits),
                c.to_array().map(f32::to_bits)
            );
        }
    }

    #[test]
    fn world_rays_in_lanes_are_the_pixel_rays_bit_for_bit() {
        let mut camera = Camera::new(
            Intrinsics::from_fov_y(3072, 2048, 35.0),
            Pose::look_at(
                DVec3::new(3100.0, -800.0, 2500.0),
                DVec3::splat(2048.0),
                DVec3::Y,
            ),
        );
        camera.intrinsics.skew = 0.3;
        let view = ViewCamera::new(&camera).unwrap();
        let xs: [u32; 8] = std::array::from_fn(|l| [0, 1, 17, 1535, 1536, 2900, 3070, 3071][l]);
        let ys: [u32; 8] = std::array::from_fn(|l| [2047, 0, 1023, 1024, 5, 1999, 77, 2046][l]);
        let rays = view.world_rays(&xs, &ys);
        let rt = camera.pose.rotation_matrix().transpose();
        for l in 0..8 {
            let (x, y) = (xs[l] as f32 + 0.5, ys[l] as f32 + 0.5);
            let lane = Vec3::new(rays[0][l], rays[1][l], rays[2][l]);
            // glam's form of the sum, the same operations in the same order.
            let glam = view.ray_base + x * view.ray_du + y * view.ray_dv;
            assert_eq!(
                lane.to_array().map(f32::to_bits),
                glam.to_array().map(f32::to_bits)
            );
            assert_eq!(lane, view.world_ray(xs[l], ys[l]));
            // The ray through the pixel centre in f64, rotated to world axes.
            let k = &camera.intrinsics;
            let v = (f64::from(y) - k.cy) / k.fy;
            let u = (f64::from(x) - k.cx - k.skew * v) / k.fx;
            let want = rt * DVec3::new(u, v, 1.0);
            assert!(
                (lane.as_dvec3() - want).length() < 1e-6 * want.length(),
                "pixel ({}, {}): {lane} against {want}",
                xs[l],
                ys[l]
            );
        }
    }

    /// The pixels whose centres the projection of each box covers, in f64 from its eight
    /// corners (the extremes of x/z and y/z over a box lie at corners), or `None`.
    fn covered_pixels(view: &ViewCamera, lo: Vec3, hi: Vec3) -> Option<(u32, u32, u32, u32)> {
        if lo.z <= 0.0 {
            return None;
        }
        let (mut u, mut v) = ((f64::MAX, f64::MIN), (f64::MAX, f64::MIN));
        for k in 0..8 {
            let pick =
                |bit: usize, a: f32, b: f32| f64::from(if k >> bit & 1 == 0 { a } else { b });
            let (x, y, z) = (
                pick(0, lo.x, hi.x),
                pick(1, lo.y, hi.y),
                pick(2, lo.z, hi.z),
            );
            let (px, py) = (
                f64::from(view.fx) * x / z + f64::from(view.skew) * y / z + f64::from(view.cx),
                f64::from(view.fy) * y / z + f64::from(view.cy),
            );
            u = (u.0.min(px), u.1.max(px));
            v = (v.0.min(py), v.1.max(py));
        }
        let first = |m: f64| (m - 0.5).ceil().max(0.0);
        let (x0, x1) = (
            first(u.0),
            (u.1 - 0.5).floor().min(f64::from(view.width) - 1.0),
        );
        let (y0, y1) = (
            first(v.0),
            (v.1 - 0.5).floor().min(f64::from(view.height) - 1.0),
        );
        (x0 <= x1 && y0 <= y1).then_some((x0 as u32, x1 as u32, y0 as u32, y1 as u32))
    }

    /// Without skew a box's pixel range is exactly the pixels its projection covers; with skew
    /// it bounds x/z and y/z apart, so it may hold a column more on either side.
    #[test]
    fn pixel_ranges_in_lanes_are_the_pixels_each_box_covers() {
        for skew in [0.0, 0.7] {
            let mut camera = Camera::new(
                Intrinsics::from_fov_y(320, 240, 40.0),
                Pose::look_at(DVec3::new(0.0, 0.0, 50.0), DVec3::ZERO, DVec3::Y),
            );
            camera.intrinsics.skew = skew;
            let checked = check_pixel_ranges(&ViewCamera::new(&camera).unwrap());
            assert!(checked > 200, "only {checked} boxes on the image");
        }
    }

    fn check_pixel_ranges(view: &ViewCamera) -> usize {
        let mut checked = 0;
        for round in 0..64 {
            // Boxes spread over and past the image, some reaching behind the camera, of
            // sizes from a hundredth of a pixel to many pixels.
            let boxes: [(Vec3, Vec3); 8] = std::array::from_fn(|l| {
                let t = (round * 8 + l) as f32;
                let centre = Vec3::new(
                    30.0 * (0.37 * t).sin(),
                    22.0 * (0.23 * t).cos(),
                    50.0 + 48.0 * (0.11 * t).sin(),
                );
                let half = Vec3::new(0.003, 0.005, 0.004) * (1.0 + (t % 13.0) * 90.0);
                (centre - half, centre + half)
            });
            let lo = std::array::from_fn(|axis| boxes.map(|b| b.0[axis]));
            let hi = std::array::from_fn(|axis| boxes.map(|b| b.1[axis]));
            for (l, range) in view.pixel_ranges(lo, hi).into_iter().enumerate() {
                let (lo, hi) = boxes[l];
                assert_eq!(range, view.pixel_range(lo, hi), "box {lo} {hi}");
                let exact = covered_pixels(view, lo, hi);
                if view.skew == 0.0 {
                    assert_eq!(range, exact, "box {lo} {hi}");
                } else if let Some((x0, x1, y0, y1)) = exact {
                    let (a0, a1, b0, b1) = range.expect("a covering box has a range");
                    assert!(
                        a0 <= x0 && x1 <= a1 && (b0, b1) == (y0, y1),
                        "box {lo} {hi}: {range:?} does not hold {exact:?}"
                    );
                }
                checked += usize::from(range.is_some());
            }
        }
        checked
    }
}
