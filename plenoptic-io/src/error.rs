//! The one error type of the crate: every variant names the file and the place of the problem.

use std::path::PathBuf;

/// Why a file could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The operating system refused to open, map, read or write the file.
    #[error("{}: {error}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error (shown in the message, so not repeated as a `source`).
        error: std::io::Error,
    },
    /// The extension is not one of ply, obj, gltf, glb.
    #[error("{}: unsupported file type '{extension}' (expected .ply, .obj, .gltf or .glb)", path.display())]
    UnsupportedFormat {
        /// The file.
        path: PathBuf,
        /// Its extension.
        extension: String,
    },
    /// The PLY header is malformed or uses something this reader does not support.
    #[error("{}: PLY header line {line}: {message}", path.display())]
    Header {
        /// The file.
        path: PathBuf,
        /// 1-based header line.
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The header promises more data than the file holds (checked before allocating).
    #[error(
        "{}: the header promises {count} {element} element(s) needing at least {needed} bytes after the header, but the file holds only {available}",
        path.display()
    )]
    Truncated {
        /// The file.
        path: PathBuf,
        /// The element name (e.g. `vertex`).
        element: String,
        /// How many elements the header promises.
        count: u64,
        /// Minimum bytes the promised elements need.
        needed: u64,
        /// Bytes actually present.
        available: u64,
    },
    /// A value in the PLY body could not be parsed, or the body ended early.
    #[error("{}: {element} {index} ({location}): {message}", path.display())]
    Body {
        /// The file.
        path: PathBuf,
        /// The element name.
        element: String,
        /// 0-based index of the element row.
        index: u64,
        /// `line N` for ASCII, `byte N` for binary.
        location: String,
        /// What is wrong.
        message: String,
    },
    /// The file's content is well-formed but not usable as asked (missing x/y/z, bad roles…).
    #[error("{}: {message}", path.display())]
    Content {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A position is NaN or infinite.
    #[error("{}: {what} {index} has a non-finite coordinate ({value:?})", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// What holds the coordinate (`vertex`, `glTF POSITION of mesh 0 primitive 0`…).
        what: String,
        /// Index of the first offending entry.
        index: u64,
        /// Its value.
        value: [f32; 3],
    },
    /// The capture-rig comments disagree with the colour properties, or a camera lacks its matrix.
    #[error("{}: capture rig: {message}", path.display())]
    Rig {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A face refers to a vertex that does not exist.
    #[error("{}: {what} {index} refers to vertex {vertex} but there are only {count} vertices", path.display())]
    IndexOutOfRange {
        /// The file.
        path: PathBuf,
        /// What holds the index (`face`, `OBJ face`, `glTF primitive`…).
        what: String,
        /// Index of the face/triangle.
        index: u64,
        /// The offending vertex index.
        vertex: i64,
        /// Number of vertices.
        count: u64,
    },
    /// The OBJ loader (tobj) rejected the file.
    #[error("{}: OBJ: {message}", path.display())]
    Obj {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The glTF loader rejected the file, or it uses something unsupported.
    #[error("{}: glTF: {message}", path.display())]
    Gltf {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A texture image could not be read or decoded.
    #[error("{}: texture {}: {message}", path.display(), texture.display())]
    Texture {
        /// The model file.
        path: PathBuf,
        /// The texture file (or embedded image name).
        texture: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The data to write is inconsistent (e.g. the layout names cameras the cloud lacks).
    #[error("{}: cannot write: {message}", path.display())]
    Write {
        /// The destination.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

impl Error {
    /// Wraps an I/O error with its file.
    pub(crate) fn io(path: &std::path::Path, error: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            error,
        }
    }

    /// Refuses a path that is not an existing regular file, before a reader library sees it.
    pub(crate) fn require_file(path: &std::path::Path) -> Result<(), Self> {
        if path.is_file() {
            return Ok(());
        }
        Err(Self::io(
            path,
            std::io::Error::new(std::io::ErrorKind::NotFound, "no such file"),
        ))
    }
}

/// Reports the first non-finite position (in parallel) as [`Error::NonFinite`].
pub(crate) fn check_finite(
    path: &std::path::Path,
    what: &str,
    positions: &[glam::Vec3],
) -> Result<(), Error> {
    use rayon::prelude::*;
    match positions.par_iter().position_first(|p| !p.is_finite()) {
        Some(index) => Err(Error::NonFinite {
            path: path.to_path_buf(),
            what: what.to_string(),
            index: index as u64,
            value: positions[index].to_array(),
        }),
        None => Ok(()),
    }
}
