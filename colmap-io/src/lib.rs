//! Read and write COLMAP sparse models (cameras, images, points3D) in text and binary.
//!
//! The layout follows COLMAP's `doc/format.rst` and `reconstruction_io_{text,binary}.cc`: poses
//! are world→camera (quaternion w first, then translation), pixel (0, 0)'s centre is at
//! (0.5, 0.5), every camera model is known by id, name and parameter count. Text ↔ binary
//! conversions are exact. [`dataset`] writes the `images/` + `sparse/0/` folder that COLMAP,
//! gsplat, Inria's gaussian-splatting, nerfstudio and Brush load.
//!
//! - [`read_model`], [`read_model_as`], [`write_model`] ([`Format`], [`detect_format`]): a
//!   `sparse/0` folder as a [`Reconstruction`] of [`CameraRecord`]s, [`ImageRecord`]s and
//!   [`Point3D`]s.
//! - [`CameraModel`]: every COLMAP camera model; [`Reconstruction::camera_of`] gives an image's
//!   `camera_model::Camera` (pinhole models only).
//! - [`dataset`]: the dataset folder of images and model.
//! - [`Error`] ([`Location`], [`Problem`]): the file, the place in it and what is wrong.
//!
//! ```
//! use camera_model::{Intrinsics, Pose};
//! use colmap_io::{CameraRecord, Format, ImageRecord, Reconstruction};
//! use glam::DVec3;
//!
//! // One camera and one image, written as binary and read back exactly.
//! let mut rec = Reconstruction::default();
//! rec.cameras.insert(1, CameraRecord::from_intrinsics(1, &Intrinsics::from_fov_y(64, 48, 50.0))?);
//! let pose = Pose::look_at(DVec3::new(0.0, 0.0, 4.0), DVec3::ZERO, DVec3::Y);
//! rec.images.insert(1, ImageRecord::new(1, 1, "view.png", &pose));
//!
//! let dir = tempfile::tempdir()?;
//! colmap_io::write_model(dir.path(), &rec, Format::Binary)?;
//! let back = colmap_io::read_model(dir.path())?;
//! assert_eq!(back, rec);
//! let camera = back.camera_of(1)?; // a camera_model::Camera
//! assert!((camera.center() - DVec3::new(0.0, 0.0, 4.0)).length() < 1e-9);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod binary;
mod camera_models;
pub mod dataset;
mod error;
mod io;
mod located;
mod reconstruction;
mod text;

pub use camera_models::CameraModel;
pub use error::{Error, Location, Problem};
pub use io::{Format, detect_format, read_model, read_model_as, write_model};
pub use reconstruction::{
    CameraRecord, ImageRecord, Point2D, Point3D, Reconstruction, TrackElement,
};
