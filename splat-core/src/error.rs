//! Typed errors of this crate; each names the file and the place of the problem.

use std::path::{Path, PathBuf};

/// Errors from reading, writing or validating splats.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An operating-system error on a file.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The PLY header is malformed or lacks what a 3DGS model needs.
    #[error("{}: PLY header{}: {message}", path.display(), at_line(*line))]
    Header {
        /// The file.
        path: PathBuf,
        /// One-based header line number (0 when the problem is the header as a whole).
        line: usize,
        /// What is wrong.
        message: String,
    },
    /// The PLY body is malformed (truncated, wrong size, unparsable values).
    #[error("{path}: byte offset {offset} (vertex {index}): {message}")]
    Body {
        /// The file.
        path: PathBuf,
        /// Byte offset in the file where the problem starts.
        offset: u64,
        /// Vertex index being read.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// An SPZ file that is not what its header says, or of a version this crate does not read.
    #[error("{path}: SPZ: {message}")]
    Spz {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A `.glb` file that is not a binary glTF container, or whose splat primitive is missing or
    /// broken (a chunk cut short, an accessor outside its buffer, counts that disagree).
    #[error("{path}: glTF: {place}: {message}")]
    Glb {
        /// The file.
        path: PathBuf,
        /// Where in the file: the header, a chunk, or an accessor and its attribute.
        place: String,
        /// What is wrong.
        message: String,
    },
    /// A `.splat` file that is not whole 32-byte records.
    #[error("{path}: .splat: {message}")]
    DotSplat {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An attribute of a splat is NaN or infinite (or a double beyond the f32 range).
    #[error("{path}: vertex {index}, property {property}: {value:?}")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// 0-based vertex index.
        index: usize,
        /// The property name (`x`, `f_rest_17`, `opacity`…).
        property: String,
        /// The value as read from the file.
        value: f64,
    },
    /// Splats that the output file's format cannot hold (a linear scale that overflows or
    /// vanishes in f32, an empty model where the format needs a record).
    #[error("{path}: cannot be written: {message}")]
    Unwritable {
        /// The file.
        path: PathBuf,
        /// What cannot be stored, naming the splat.
        message: String,
    },
    /// A [`crate::Splats`] value whose arrays disagree in length or whose degree is unsupported.
    #[error("inconsistent splats: {0}")]
    Inconsistent(String),
    /// A view larger than the rasteriser's per-pixel buffers may be ([`crate::MAX_PIXELS`]).
    #[error(
        "a {width}×{height} view needs {pixels} pixels of buffers (padded to 16×16 tiles), over \
         the rasteriser's limit of {limit} pixels ({limit_mib} MiB); render it at a lower resolution"
    )]
    ViewTooLarge {
        /// Image width in pixels.
        width: u32,
        /// Image height in pixels.
        height: u32,
        /// Pixels the buffers would need.
        pixels: u64,
        /// The limit, [`crate::MAX_PIXELS`].
        limit: u64,
        /// The memory the limit stands for, in MiB.
        limit_mib: u64,
    },
    /// A model file whose extension names no splat format this crate reads.
    #[error(
        "{path}: unknown splat format {extension}; .ply (3DGS), .spz, .splat and .glb are read \
         and written"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// Its extension as written (`` `.obj` ``), or `(no extension)`.
        extension: String,
    },
    /// A camera with skew: the 3DGS projection has no skew term.
    #[error(
        "the camera has skew {skew}; 3D Gaussian splats are rendered with skew-free pinhole cameras (resample the image to remove the skew)"
    )]
    Skewed {
        /// The camera's skew, in pixels.
        skew: f64,
    },
}

impl Error {
    /// Wraps an I/O error with its file.
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        Error::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// " line N" for a header line, nothing for the header as a whole (line 0).
fn at_line(line: usize) -> String {
    if line == 0 {
        String::new()
    } else {
        format!(" line {line}")
    }
}
