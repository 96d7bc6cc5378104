//! Read and write COLMAP sparse models (cameras, images, points3D) in text and binary.
//!
//! The layout follows COLMAP's `doc/format.rst` and `reconstruction_io_{text,binary}.cc`: poses
//! are world→camera (quaternion w first, then translation), pixel (0, 0)'s centre is at
//! (0.5, 0.5), every camera model is known by id, name and parameter count. Text ↔ binary
//! conversions are exact. [`dataset`] writes the `images/` + `sparse/0/` folder that COLMAP,
//! gsplat, Inria's gaussian-splatting, nerfstudio and Brush load.
//!
//! ```no_run
//! let rec = colmap_io::read_model(std::path::Path::new("scene/sparse/0"))?;
//! for id in rec.images.keys() {
//!     let camera = rec.camera_of(*id)?; // a camera_model::Camera (pinhole models only)
//!     println!("{id}: centre {}", camera.center());
//! }
//! # Ok::<(), colmap_io::Error>(())
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
