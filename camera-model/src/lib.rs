//! Pinhole cameras, poses, look-at, camera rigs and the PccAppRenderer-to-COLMAP transform.
//!
//! Conventions (see `docs/cameras.md`): COLMAP/OpenCV camera axes (x right, y down, z forward),
//! poses are world→camera (`x_cam = R·x_world + t`) with a Hamilton unit quaternion written
//! w first, the camera centre is `−Rᵀt`, and pixel (0, 0)'s centre is at (0.5, 0.5).
//! Poses are `f64` because inputs come in voxel units with cameras thousands of units away;
//! [`CameraF32`] is the cheap single-precision copy for hot loops.

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
