//! Errors of the trainer.

use std::path::PathBuf;

/// What can go wrong when setting up, checkpointing or resuming a training run.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The configuration is inconsistent or out of range.
    #[error("invalid training configuration: {0}")]
    Config(String),
    /// A view does not fit its camera or the others.
    #[error("view {index} ({name}): {problem}")]
    View {
        /// Index of the view in the list given to the trainer.
        index: usize,
        /// Name of the view.
        name: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The initial splats are unusable.
    #[error("initial splats: {0}")]
    Splats(String),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// An image file cannot be decoded or does not fit its camera.
    #[error("{path}: {problem}")]
    Image {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// A checkpoint file is malformed or does not match the run it should resume.
    #[error("checkpoint {path}: {problem} (at byte {offset})")]
    Checkpoint {
        /// The file.
        path: PathBuf,
        /// Byte offset where the problem was found.
        offset: u64,
        /// What is wrong.
        problem: String,
    },
}
