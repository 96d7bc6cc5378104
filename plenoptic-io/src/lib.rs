//! Read and write plenoptic point clouds (8iVSLF PLY), coloured point clouds and meshes (OBJ, glTF, PLY).
//!
//! - [`read_cloud`] / [`write_cloud`]: PLY point clouds with any number of per-camera colours
//!   (`red{k}/green{k}/blue{k}`) and the capture-rig header comments read by MPEG's PccAppRenderer.
//! - [`read_mesh`]: OBJ (tobj), glTF 2.0 / GLB (gltf) and PLY meshes.
//! - [`load`]: either of the above, chosen from the file.
//! - [`view_color`]: the PccAppRenderer view-dependent colour interpolation.
//! - [`morton_order`]: points in Morton (Z-curve) order, near in space near in the order.
//! - [`summary`]: counts, bounds, rig and colour statistics of a model (`transcode info`).
//!
//! Formats, conventions and error policy: `docs/formats-input.md`.
//!
//! ```
//! use glam::Vec3;
//! use plenoptic_io::PlenopticCloud;
//!
//! // A plain coloured cloud of two points, written as PLY and read back.
//! let mut cloud = PlenopticCloud::default();
//! cloud.positions = vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)];
//! cloud.colors = vec![[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];
//! let dir = tempfile::tempdir()?;
//! let path = dir.path().join("points.ply");
//! plenoptic_io::write_cloud(&path, &cloud)?;
//! let back = plenoptic_io::read_cloud(&path)?;
//! assert_eq!(back.positions, cloud.positions);
//! assert_eq!(back.num_cameras, 0);
//!
//! // The view-dependent colour: a viewer next to camera 0 sees mostly its colour.
//! let cameras = [Vec3::new(0.0, 0.0, 10.0), Vec3::new(10.0, 0.0, 0.0)];
//! let colors = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
//! let seen = plenoptic_io::view_color::interpolate(
//!     Vec3::ZERO, Vec3::new(0.0, 0.0, 5.0), &cameras, &colors, [0.5; 3], 2,
//! );
//! assert_eq!(seen, [1.0, 0.0, 0.0]);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod cloud;
mod error;
mod gltf_mesh;
mod mesh;
mod morton;
mod obj;
pub mod ply;
pub mod summary;
pub mod view_color;

pub use cloud::{CaptureCamera, ExtraProperty, PlenopticCloud, PlyLayout};
pub use error::Error;
pub use mesh::{Material, Mesh, Texture, barycentric_mix};
pub use morton::morton_order;
pub use ply::{PlyFormat, ScalarType};

use std::path::Path;

/// What [`load`] found in a file: a point cloud or a mesh.
#[derive(Debug, Clone, PartialEq)]
pub enum Model {
    /// A (plenoptic) point cloud.
    Cloud(PlenopticCloud),
    /// A triangle mesh.
    Mesh(Mesh),
}

/// Reads a plenoptic or coloured point cloud from a PLY file.
pub fn read_cloud(path: &Path) -> Result<PlenopticCloud, Error> {
    ply::read_cloud(path)
}

/// Writes a point cloud as PLY (atomically: temp file + rename), in `cloud.layout` when set,
/// else binary little endian with float positions/normals and uchar colours.
pub fn write_cloud(path: &Path, cloud: &PlenopticCloud) -> Result<(), Error> {
    ply::write_cloud(path, cloud)
}

/// Reads a triangle mesh from OBJ, glTF/GLB or PLY (chosen by extension; PLY must have faces).
pub fn read_mesh(path: &Path) -> Result<Mesh, Error> {
    match extension(path).as_str() {
        "obj" => obj::read_obj(path),
        "gltf" | "glb" => gltf_mesh::read_gltf(path),
        "ply" => ply::read_mesh(path),
        other => Err(Error::UnsupportedFormat {
            path: path.to_path_buf(),
            extension: other.to_string(),
        }),
    }
}

/// Reads any supported file: a PLY with a face element holding at least one face is a mesh,
/// a PLY without is a cloud; `.obj`, `.gltf` and `.glb` are meshes.
pub fn load(path: &Path) -> Result<Model, Error> {
    match extension(path).as_str() {
        "ply" => ply::load(path),
        _ => read_mesh(path).map(Model::Mesh),
    }
}

/// Lower-cased extension of `path`, empty when it has none.
fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}
