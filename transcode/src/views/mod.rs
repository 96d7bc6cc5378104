//! Reference renderer: plenoptic clouds and meshes to RGB, alpha and depth images per camera.
//!
//! It draws what MPEG's PccAppRenderer draws by default (`docs/reference/formats.md` §2):
//! every point an axis-aligned cube one voxel wide (or a view-aligned disc), z-buffered, coloured
//! towards the viewer with [`plenoptic_io::view_color::interpolate`]; meshes are rasterised with
//! perspective-correct attributes, bilinear textures, vertex colours and per-vertex plenoptic
//! colours (interpolated at the vertices, then across the triangle, as the surface shader does).
//!
//! Rendering is two passes per view: a visibility pass writes (depth, primitive id) into an atomic
//! z-buffer in parallel over primitives, then a shading pass colours only the winning primitive of
//! each pixel. Colour is constant per point, so this equals shading every fragment, and the view
//! interpolation (the expensive part) runs once per pixel instead of once per point.
//! Cameras follow COLMAP: pixel (0, 0)'s centre is at (0.5, 0.5), x right, y down, z forward.

mod cloud;
mod dataset;
mod mesh;
mod output;
mod rig;
mod zbuffer;

pub use cloud::render_cloud;
pub use dataset::{DatasetOptions, dataset_image_name, write_dataset};
pub(crate) use mesh::check_mesh;
pub use mesh::{albedo_at, render_mesh, sample_bilinear};
pub use output::{
    BitDepth, ViewFiles, write_alpha_png, write_depth_exr, write_rgb_png, write_view_images,
};
pub use rig::{bounding_sphere, fibonacci_rig};

use std::path::PathBuf;

use camera_model::{Camera, CameraF32, Intrinsics};
use glam::Vec3;
use plenoptic_io::Model;
use rayon::prelude::*;

/// How a point of a cloud is drawn (PccAppRenderer `--type`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PointShape {
    /// Axis-aligned cube of side `point_size` voxels centred on the point (`--type 0`, the default).
    Cube,
    /// View-aligned disc of radius √ln 2 · `point_size` (`--type 1`: a quad of half-size
    /// `point_size` whose fragments with exp(−|c|²) < 0.5 are discarded).
    Disc,
}

/// Options of the reference renderer.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewOptions {
    /// Shape of a point.
    pub point_shape: PointShape,
    /// Point size in voxel (file) units: the cube side, or the disc's quad half-size.
    pub point_size: f32,
    /// Exponent n of the view interpolation weight max(0, cos)^n.
    pub exponent: i32,
    /// Background colour of pixels no primitive covers.
    pub background: [f32; 3],
    /// Supersampling factor k: render at k×k the resolution and box-filter down (1 = off).
    pub supersample: u32,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            point_shape: PointShape::Cube,
            point_size: 1.0,
            exponent: plenoptic_io::view_color::DEFAULT_EXPONENT,
            background: [0.0; 3],
            supersample: 1,
        }
    }
}

impl ViewOptions {
    /// Checks the options, naming the first bad one.
    pub fn validate(&self) -> Result<(), Error> {
        if !(self.point_size > 0.0 && self.point_size.is_finite()) {
            return Err(Error::InvalidOption(format!(
                "point_size must be positive and finite, got {}",
                self.point_size
            )));
        }
        if !(1..=8).contains(&self.supersample) {
            return Err(Error::InvalidOption(format!(
                "supersample must be in 1..=8, got {}",
                self.supersample
            )));
        }
        if self.exponent < 0 {
            return Err(Error::InvalidOption(format!(
                "exponent must be non-negative, got {}",
                self.exponent
            )));
        }
        if self.background.iter().any(|c| !c.is_finite()) {
            return Err(Error::InvalidOption(format!(
                "background must be finite, got {:?}",
                self.background
            )));
        }
        Ok(())
    }
}

/// One rendered view: colour, coverage and depth for the same camera.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewImage {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Interleaved RGB in [0, 1], row-major, top row first (3·W·H), composited on the background.
    pub rgb: Vec<f32>,
    /// Coverage in [0, 1] (W·H): 1 where the object is, fractional at edges when supersampled.
    pub alpha: Vec<f32>,
    /// Camera-space z of the visible surface (W·H); 0 where nothing is seen.
    pub depth: Vec<f32>,
}

impl ViewImage {
    /// RGB of pixel (x, y).
    #[must_use]
    pub fn rgb_at(&self, x: u32, y: u32) -> [f32; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Alpha of pixel (x, y).
    #[must_use]
    pub fn alpha_at(&self, x: u32, y: u32) -> f32 {
        self.alpha[y as usize * self.width as usize + x as usize]
    }

    /// Depth of pixel (x, y) (0 where nothing is seen).
    #[must_use]
    pub fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.depth[y as usize * self.width as usize + x as usize]
    }
}

/// Errors of the reference renderer and its writers.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A rendering option is out of range.
    #[error("invalid view option: {0}")]
    InvalidOption(String),
    /// The camera cannot be rendered (empty image, too large, or non-finite parameters).
    #[error("cannot render camera: {0}")]
    InvalidCamera(String),
    /// The model's arrays disagree (e.g. a triangle names a vertex that does not exist).
    #[error("inconsistent model: {0}")]
    InvalidModel(String),
    /// The input or its views cannot make a model (see [`crate::degenerate`]).
    #[error(transparent)]
    Degenerate(#[from] crate::degenerate::DegenerateError),
    /// A file could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Writing the COLMAP dataset failed.
    #[error("cannot write the COLMAP dataset: {0}")]
    Colmap(Box<colmap_io::Error>),
    /// An image could not be encoded.
    #[error("cannot encode {path}: {message}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// What the encoder said.
        message: String,
    },
}

impl From<colmap_io::Error> for Error {
    /// Boxed: colmap-io's error is large and would make every `Result` of this module large.
    fn from(e: colmap_io::Error) -> Self {
        Self::Colmap(Box::new(e))
    }
}

/// Renders a cloud or a mesh (see [`render_cloud`] and [`render_mesh`]).
pub fn render_model(
    model: &Model,
    camera: &Camera,
    opts: &ViewOptions,
) -> Result<ViewImage, Error> {
    match model {
        Model::Cloud(cloud) => render_cloud(cloud, camera, opts),
        Model::Mesh(mesh) => render_mesh(mesh, camera, opts),
    }
}

/// Renders `model` from every camera, in parallel over views, handing each finished view to
/// `sink` (view index, image) as soon as it is done, so that callers can write and drop it.
pub fn render_each<F>(
    model: &Model,
    cameras: &[Camera],
    opts: &ViewOptions,
    sink: F,
) -> Result<(), Error>
where
    F: Fn(usize, ViewImage) -> Result<(), Error> + Sync + Send,
{
    cameras
        .par_iter()
        .enumerate()
        .try_for_each(|(i, camera)| sink(i, render_model(model, camera, opts)?))
}

/// Renders `model` from every camera, in parallel over views, and returns the images in order.
pub fn render_views(
    model: &Model,
    cameras: &[Camera],
    opts: &ViewOptions,
) -> Result<Vec<ViewImage>, Error> {
    cameras
        .par_iter()
        .map(|camera| render_model(model, camera, opts))
        .collect()
}

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

/// Renders at `opts.supersample`× and box-filters down: colour and alpha are averaged over the
/// k×k sub-pixels, depth over the covered ones.
pub(crate) fn render_supersampled<F>(
    camera: &Camera,
    opts: &ViewOptions,
    render: F,
) -> Result<ViewImage, Error>
where
    F: Fn(&Camera) -> Result<ViewImage, Error>,
{
    opts.validate()?;
    let k = opts.supersample;
    if k == 1 {
        return render(camera);
    }
    let big = render(&scaled_camera(camera, k))?;
    Ok(downsample(&big, k))
}

/// Box filter of a k×-supersampled image.
fn downsample(big: &ViewImage, k: u32) -> ViewImage {
    let (w, h) = (big.width / k, big.height / k);
    let n = (k * k) as f32;
    let mut rgb = vec![0.0f32; 3 * w as usize * h as usize];
    let mut alpha = vec![0.0f32; w as usize * h as usize];
    let mut depth = vec![0.0f32; w as usize * h as usize];
    rgb.par_chunks_mut(3 * w as usize)
        .zip(alpha.par_chunks_mut(w as usize))
        .zip(depth.par_chunks_mut(w as usize))
        .enumerate()
        .for_each(|(y, ((rgb_row, alpha_row), depth_row))| {
            for x in 0..w as usize {
                let mut c = [0.0f32; 3];
                let (mut a, mut d, mut covered) = (0.0f32, 0.0f32, 0u32);
                for sy in 0..k as usize {
                    for sx in 0..k as usize {
                        let j = (y * k as usize + sy) * big.width as usize + x * k as usize + sx;
                        for (sum, v) in c.iter_mut().zip(&big.rgb[3 * j..3 * j + 3]) {
                            *sum += v;
                        }
                        a += big.alpha[j];
                        if big.depth[j] > 0.0 {
                            d += big.depth[j];
                            covered += 1;
                        }
                    }
                }
                for (out, sum) in rgb_row[3 * x..3 * x + 3].iter_mut().zip(c) {
                    *out = sum / n;
                }
                alpha_row[x] = a / n;
                depth_row[x] = if covered > 0 { d / covered as f32 } else { 0.0 };
            }
        });
    ViewImage {
        width: w,
        height: h,
        rgb,
        alpha,
        depth,
    }
}

/// Fills colour, alpha and depth from a resolved z-buffer with `shade(id, x, y)` giving the
/// colour of primitive `id` at pixel (x, y).
pub(crate) fn shade_pixels<F>(
    view: &ViewCamera,
    zbuf: &zbuffer::ZBuffer,
    background: [f32; 3],
    shade: F,
) -> ViewImage
where
    F: Fn(u32, u32, u32) -> [f32; 3] + Sync,
{
    let w = view.width as usize;
    let n = view.pixels();
    let mut rgb = vec![0.0f32; 3 * n];
    let mut alpha = vec![0.0f32; n];
    let mut depth = vec![0.0f32; n];
    rgb.par_chunks_mut(3 * w)
        .zip(alpha.par_chunks_mut(w))
        .zip(depth.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((rgb_row, alpha_row), depth_row))| {
            for x in 0..w {
                let c = match zbuf.get(y * w + x) {
                    Some((z, id)) => {
                        alpha_row[x] = 1.0;
                        depth_row[x] = z;
                        shade(id, x as u32, y as u32)
                    }
                    None => background,
                };
                rgb_row[3 * x..3 * x + 3].copy_from_slice(&c);
            }
        });
    ViewImage {
        width: view.width,
        height: view.height,
        rgb,
        alpha,
        depth,
    }
}
