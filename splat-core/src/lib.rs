//! 3D Gaussian splats: spherical harmonics, EWA projection, tile rasteriser with exact gradients, 3DGS PLY.
//!
//! Conventions follow Inria's `diff-gaussian-rasterization` and gsplat so that models render the
//! same in their viewers (see `ARCHITECTURE.md`): COLMAP camera axes, pixel (0, 0)'s centre at
//! (0.5, 0.5), Inria's SH basis and signs, +0.3 px² dilation, alpha = min(0.99, o·G), skip alpha
//! below 1/255, stop when transmittance falls below 1e-4, 16×16 tiles, 3σ extent (narrowed to the
//! tiles that pixels above 1/255 can lie in, which changes no image).
//!
//! - [`Splats`]: the model in structure-of-arrays form, with activations ([`sigmoid`], [`logit`]).
//! - [`sh`]: real spherical harmonics of degree 0–3 with their gradients.
//! - [`RenderCamera`], [`RenderOptions`], [`RenderOutput`], [`SplatGrads`] (and [`SplatGradsMut`], a range
//!   of it for chunked work): rasteriser inputs/outputs.
//! - [`Rasterizer`]: forward and backward passes (projection, tile binning, compositing; the
//!   backward also in two steps, `backward_sums` then `chain_into` range by range), and each
//!   splat's summed blending weight over a view (`accumulate_contributions`).
//! - [`ply`]: the Inria 3DGS PLY, read and write; [`export`]: the antimatter15 `.splat` layout,
//!   read and write; [`spz`]: Niantic's compressed SPZ, read and write; [`glb`]: binary glTF with
//!   `KHR_gaussian_splatting`, read and write; [`frame`]: the change to their y-up frame;
//!   [`model_file`]: any of the four by its extension, with whether the file says the model is
//!   drawn antialiased (a PLY header comment, SPZ's flag).
//! - [`Error`]: inconsistent models, oversized views and file errors.
//!
//! ```
//! use camera_model::{Camera, Intrinsics, Pose};
//! use glam::{DVec3, Vec3};
//! use splat_core::{Rasterizer, RenderCamera, RenderOptions, Splats};
//!
//! // One orange splat at the origin, seen from 5 units away.
//! let splats = Splats::from_points(
//!     &[Vec3::ZERO], &[[1.0, 0.5, 0.0]], &[Vec3::splat(0.5)], None, 0.9, 0,
//! )?;
//! let camera = Camera::new(
//!     Intrinsics::from_fov_y(32, 32, 40.0),
//!     Pose::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y),
//! );
//! let mut rasterizer = Rasterizer::new();
//! let camera = RenderCamera::try_from(&camera)?; // refuses a skewed camera
//! let out = rasterizer.try_forward(&splats, &camera, &RenderOptions::default())?;
//! let centre = 16 * 32 + 16;
//! assert!(out.alpha[centre] > 0.8);
//! assert!(out.rgb[3 * centre] > out.rgb[3 * centre + 2]); // more red than blue
//! # Ok::<(), splat_core::Error>(())
//! ```

mod bins;
mod camera;
mod contribution;
mod disjoint;
mod error;
pub mod export;
mod falloff;
pub mod frame;
pub mod glb;
mod lanes;
pub mod model_file;
pub mod ply;
mod prefetch;
mod project;
mod project_backward;
mod projected;
mod rasterize;
mod rasterize_backward;
mod render;
pub mod sh;
mod spans;
mod splats;
pub mod spz;
mod tiles;

pub use camera::RenderCamera;
pub use error::Error;
pub use rasterize::{MAX_PIXELS, RasterPhases, Rasterizer, RenderStats, has_avx2};
pub use render::{RenderOptions, RenderOutput, SplatGrads, SplatGradsMut};
pub use sh::num_sh_coeffs;
pub use splats::{
    MIN_QUAT_NORM, Splats, all_finite, logit, normalize_quat, rgb_to_sh_dc, sh_dc_to_rgb, sigmoid,
};
pub use tiles::TILE_SIZE;

/// Rasteriser constants shared by the forward and backward passes (Inria/gsplat values).
pub mod constants {
    /// Added to the 2D covariance diagonal so every splat is at least about a pixel wide
    /// (Inria `forward.cu`: "every Gaussian should be at least one pixel wide").
    pub const DILATION: f32 = 0.3;
    /// Upper clamp of a splat's alpha (Inria/gsplat).
    pub const MAX_ALPHA: f32 = 0.99;
    /// Contributions with alpha below this are skipped (Inria/gsplat).
    pub const MIN_ALPHA: f32 = 1.0 / 255.0;
    /// A pixel stops compositing when its transmittance would fall below this (Inria/gsplat).
    pub const MIN_TRANSMITTANCE: f32 = 1e-4;
    /// Splats whose camera-space depth is at or below this are culled (gsplat and Brush use 0.01;
    /// Inria 0.2, which would cull too much in scenes measured in small units).
    pub const NEAR_PLANE: f32 = 0.01;
    /// The extent of a splat in standard deviations of its largest 2D axis (Inria's 3σ radius).
    pub const EXTENT_SIGMAS: f32 = 3.0;
    /// The projection Jacobian is evaluated with x/z clamped to 1.3·tan(fov/2) (Inria; gsplat
    /// writes the margin as 0.3·tan(fov/2) beyond each image edge).
    pub const FOV_CLAMP_MARGIN: f32 = 0.3;
}
