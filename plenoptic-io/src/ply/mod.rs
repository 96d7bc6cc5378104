//! PLY point clouds and meshes: header, fast binary path, general path, writer.

mod header;

pub use header::{Element, Header, PlyFormat, Property, PropertyKind, ScalarType, parse_header};

use std::path::Path;

use crate::{Error, Mesh, Model, PlenopticCloud};

/// Reads a PLY point cloud.
pub(crate) fn read_cloud(path: &Path) -> Result<PlenopticCloud, Error> {
    Err(Error::Content {
        path: path.to_path_buf(),
        message: "PLY reader not built yet".into(),
    })
}

/// Reads a PLY mesh.
pub(crate) fn read_mesh(path: &Path) -> Result<Mesh, Error> {
    Err(Error::Content {
        path: path.to_path_buf(),
        message: "PLY reader not built yet".into(),
    })
}

/// Reads a PLY as mesh or cloud.
pub(crate) fn load(path: &Path) -> Result<Model, Error> {
    read_cloud(path).map(Model::Cloud)
}

/// Writes a PLY point cloud.
pub(crate) fn write_cloud(path: &Path, _cloud: &PlenopticCloud) -> Result<(), Error> {
    Err(Error::Write {
        path: path.to_path_buf(),
        message: "PLY writer not built yet".into(),
    })
}
