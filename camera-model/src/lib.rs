//! Pinhole cameras, poses, look-at, camera rigs and the PccAppRenderer-to-COLMAP transform.
//!
//! Conventions (see `docs/cameras.md`): COLMAP/OpenCV camera axes (x right, y down, z forward),
//! poses are world→camera (`x_cam = R·x_world + t`) with a Hamilton unit quaternion written
//! w first, the camera centre is `−Rᵀt`, and pixel (0, 0)'s centre is at (0.5, 0.5).
//! Poses are `f64` because inputs come in voxel units with cameras thousands of units away;
//! [`CameraF32`] is the cheap single-precision copy for hot loops.
//!
//! - [`Intrinsics`] ([`focal_from_fov`], [`fov_from_focal`]), [`Pose`] and [`Camera`]
//!   (projection, depth, [`Ray`]s through pixels), with the `f32` copy [`CameraF32`].
//! - [`rig`]: PccAppRenderer capture rigs and their transform into COLMAP's frame.
//! - [`rotation`]: rotation-matrix and quaternion conversions.
//! - [`GlViewport`]: the OpenGL viewport and field of view ([`DEFAULT_FOV_Y_DEG`]) of the
//!   reference renderer; [`Error`]: what the constructors refuse.
//!
//! ```
//! use camera_model::{Camera, Intrinsics, Pose};
//! use glam::DVec3;
//!
//! // 10 units up the z axis, looking at the origin.
//! let camera = Camera::new(
//!     Intrinsics::from_fov_y(640, 480, 60.0),
//!     Pose::look_at(DVec3::new(0.0, 0.0, 10.0), DVec3::ZERO, DVec3::Y),
//! );
//! assert!((camera.center() - DVec3::new(0.0, 0.0, 10.0)).length() < 1e-9);
//! assert!((camera.depth(DVec3::ZERO) - 10.0).abs() < 1e-9);
//! // The point looked at lands on the image centre.
//! let pixel = camera.project(DVec3::ZERO).unwrap();
//! assert!((pixel.x - 320.0).abs() < 1e-9 && (pixel.y - 240.0).abs() < 1e-9);
//! ```

mod camera;
mod error;
mod intrinsics;
mod pose;
pub mod rig;
pub mod rotation;
mod viewport;

pub use camera::{Camera, CameraF32, Ray};
pub use error::Error;
pub use intrinsics::{Intrinsics, focal_from_fov, fov_from_focal};
pub use pose::Pose;
pub use viewport::{DEFAULT_FOV_Y_DEG, GlViewport};
