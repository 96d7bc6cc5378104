//! Errors of the reference renderer and its writers.

use std::path::PathBuf;

/// Errors of the reference renderer and its writers.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A rendering option is out of range.
    #[error("invalid view option: {0}")]
    InvalidOption(String),
    /// The camera cannot be rendered (empty image, too large, or non-finite parameters).
    #[error("cannot render camera: {0}")]
    InvalidCamera(String),
    /// The model's arrays disagree (e.g. a triangle names a vertex that does not exist).
    #[error("inconsistent model: {0}")]
    InvalidModel(String),
    /// The input or its views cannot make a model (see [`crate::degenerate`]).
    #[error(transparent)]
    Degenerate(#[from] crate::degenerate::DegenerateError),
    /// A file could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// Writing the COLMAP dataset failed.
    #[error("cannot write the COLMAP dataset: {0}")]
    Colmap(Box<colmap_io::Error>),
    /// An image could not be encoded.
    #[error("cannot encode {path}: {message}")]
    Encode {
        /// The file.
        path: PathBuf,
        /// What the encoder said.
        message: String,
    },
}

impl From<colmap_io::Error> for Error {
    /// Boxed: colmap-io's error is large and would make every `Result` of this module large.
    fn from(e: colmap_io::Error) -> Self {
        Self::Colmap(Box::new(e))
    }
}
