//! Errors of camera conversions that can be refused.

/// Why a camera could not be converted or built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// The camera cannot be expressed as a PccAppRenderer viewport (what is wrong is named).
    #[error("camera is not a symmetric-frustum OpenGL viewport: {0}")]
    NotAViewport(String),
    /// An input value is out of its valid range (what is wrong is named).
    #[error("invalid camera parameter: {0}")]
    InvalidParameter(String),
}
