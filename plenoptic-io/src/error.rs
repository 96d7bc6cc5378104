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
    /// A value that becomes a position, normal, colour or texture coordinate is NaN or infinite.
    #[error("{}: {what} {index}, property {property}: {value}", path.display())]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// What holds the value (`vertex`, `glTF mesh 0 primitive 0 vertex`, `line 12: v`…).
        what: String,
        /// 0-based index of the first offending entry.
        index: u64,
        /// The property or attribute component (`x`, `red3`, `POSITION.y`…).
        property: String,
        /// The value as read (`NaN`, `inf`, `-inf`), with a note when it overflowed a conversion.
        value: String,
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

    /// Wraps a header error of [`ply_core::parse_header`] with its file.
    pub(crate) fn header(path: &std::path::Path, error: ply_core::HeaderError) -> Self {
        Error::Header {
            path: path.to_path_buf(),
            line: error.line,
            message: error.problem.to_string(),
        }
    }

    /// Refuses a path that is not an existing regular file, before a reader library sees it.
    pub(crate) fn require_file(path: &std::path::Path) -> Result<(), Self> {
        use std::io::{Error as IoError, ErrorKind};
        let problem = match std::fs::metadata(path) {
            Ok(m) if m.is_file() => return Ok(()),
            Ok(m) if m.is_dir() => IoError::new(ErrorKind::InvalidInput, "a folder, not a file"),
            // A pipe or a device cannot be mapped ("No such device").
            Ok(_) => IoError::new(
                ErrorKind::InvalidInput,
                "not a regular file (a pipe or a device): give the file itself",
            ),
            Err(e) if e.kind() == ErrorKind::NotFound => {
                IoError::new(ErrorKind::NotFound, "no such file")
            }
            Err(e) => e,
        };
        Err(Self::io(path, problem))
    }
}

/// Reports the first entry (in parallel) of `values`, `N` components each named by
/// `components`, that holds a NaN or an infinity, as [`Error::NonFinite`].
pub(crate) fn check_finite<const N: usize>(
    path: &std::path::Path,
    what: &str,
    components: [&str; N],
    values: &[[f32; N]],
) -> Result<(), Error> {
    use rayon::prelude::*;
    let Some(index) = values
        .par_iter()
        .position_first(|v| v.iter().any(|x| !x.is_finite()))
    else {
        return Ok(());
    };
    let c = values[index]
        .iter()
        .position(|x| !x.is_finite())
        .unwrap_or(0);
    Err(Error::NonFinite {
        path: path.to_path_buf(),
        what: what.to_string(),
        index: index as u64,
        property: components[c].to_string(),
        value: values[index][c].to_string(),
    })
}

#[cfg(test)]
mod tests {
    /// A folder named like a model said "No such device" (the PLY reader mapped it), and a pipe
    /// likewise; each is now named for what it is, through every reader.
    #[test]
    fn what_is_not_a_file_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let folder = dir.path().join("model.ply");
        std::fs::create_dir(&folder).unwrap();
        for read in [crate::load, |p: &std::path::Path| {
            crate::read_cloud(p).map(crate::Model::Cloud)
        }] {
            let e = read(&folder).unwrap_err().to_string();
            assert!(e.ends_with("model.ply: a folder, not a file"), "{e}");
        }
        let missing = dir.path().join("none.obj");
        let e = crate::load(&missing).unwrap_err().to_string();
        assert!(e.ends_with("none.obj: no such file"), "{e}");
        let fifo = dir.path().join("pipe.ply");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        assert!(made.unwrap().success(), "mkfifo (coreutils) failed");
        let e = crate::load(&fifo).unwrap_err().to_string();
        assert!(
            e.contains("pipe.ply: not a regular file (a pipe or a device)"),
            "{e}"
        );
    }
}
