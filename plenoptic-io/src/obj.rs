//! OBJ meshes through tobj.

use std::path::Path;

use crate::{Error, Mesh};

/// Reads an OBJ mesh.
pub(crate) fn read_obj(path: &Path) -> Result<Mesh, Error> {
    Err(Error::Obj {
        path: path.to_path_buf(),
        message: "not built yet".into(),
    })
}
