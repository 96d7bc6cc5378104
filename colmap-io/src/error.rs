//! Errors that name the file, the place in it and what was wrong.

use std::fmt;
use std::path::PathBuf;

/// Where in a file a problem was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a text file.
    Line(usize),
    /// Byte offset of the record or field in a binary file.
    Offset(u64),
    /// The whole file (e.g. when it is missing).
    File,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(n) => write!(f, "line {n}"),
            Location::Offset(o) => write!(f, "byte offset {o}"),
            Location::File => write!(f, "file"),
        }
    }
}

/// What was wrong with a COLMAP model.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Problem {
    /// A camera model name or id that COLMAP does not define.
    #[error("unknown camera model `{0}`")]
    UnknownModel(String),
    /// A camera with the wrong number of parameters for its model.
    #[error("camera model {model} takes {expected} parameters, found {found}")]
    ParamCount {
        /// Model name.
        model: &'static str,
        /// Parameters the model takes.
        expected: usize,
        /// Parameters present.
        found: usize,
    },
    /// The file ended inside a record.
    #[error("truncated record: needed {needed} more bytes, {available} left")]
    Truncated {
        /// Bytes the record needed.
        needed: u64,
        /// Bytes left in the file.
        available: u64,
    },
    /// A declared count that the file cannot hold (refused before allocating).
    #[error("{what} count {count} needs at least {needed} bytes but only {available} are left")]
    CountTooLarge {
        /// What is counted.
        what: &'static str,
        /// The declared count.
        count: u64,
        /// Minimum bytes the records would take.
        needed: u128,
        /// Bytes left in the file.
        available: u64,
    },
    /// A field that could not be parsed.
    #[error("cannot parse {field} from `{token}`")]
    Parse {
        /// Name of the field.
        field: &'static str,
        /// The text found.
        token: String,
    },
    /// A number that is NaN or infinite where the model needs a finite one.
    #[error("{record} {id}, {field}: {value} is not a finite number")]
    NonFinite {
        /// What kind of record (`camera`, `image`, `point3D`).
        record: &'static str,
        /// The record's id.
        id: u64,
        /// The field (`PARAMS[0] (f)`, `QW`, `TX`, `X`…).
        field: String,
        /// The value read.
        value: f64,
    },
    /// A camera with no pixels.
    #[error("camera {id}, WIDTH × HEIGHT: {width} × {height} is not an image size")]
    ZeroSize {
        /// The camera's id.
        id: u64,
        /// The width read.
        width: u64,
        /// The height read.
        height: u64,
    },
    /// A camera whose focal length is zero or negative.
    #[error("camera {id}, {field}: {value} is not a focal length; it must be positive")]
    NotPositive {
        /// The camera's id.
        id: u64,
        /// The parameter (`PARAMS[0] (fx)`…).
        field: String,
        /// The value read.
        value: f64,
    },
    /// An image whose rotation quaternion is zero (or too close to it to normalise).
    #[error("image {id}, QW QX QY QZ: {qvec:?} is not a rotation; a pose needs a unit quaternion")]
    ZeroRotation {
        /// The image's id.
        id: u64,
        /// The quaternion read.
        qvec: [f64; 4],
    },
    /// A field that is missing from a text line.
    #[error("missing {0}")]
    Missing(&'static str),
    /// Numbers left over at the end of a line (e.g. a POINTS2D line not made of triples).
    #[error("{0}")]
    Malformed(String),
    /// Two records with the same id.
    #[error("duplicate {what} id {id}")]
    DuplicateId {
        /// What kind of record.
        what: &'static str,
        /// The repeated id.
        id: u64,
    },
    /// Two images with the same file name.
    #[error("image {id} has the name `{name}` of image {first}; each image is its own file")]
    DuplicateName {
        /// The later image's id.
        id: u32,
        /// The earlier image's id.
        first: u32,
        /// The shared name.
        name: String,
    },
    /// An image observation referring to a 3D point that the model does not have.
    #[error(
        "image {image_id} observation {point2d_idx} refers to point3D {point3d_id}, which no point has"
    )]
    MissingPoint3D {
        /// Image holding the observation.
        image_id: u32,
        /// Index of the observation in the image.
        point2d_idx: usize,
        /// The dangling point id.
        point3d_id: u64,
    },
    /// A track element referring to an image or observation that the model does not have.
    #[error(
        "point3D {point3d_id} track refers to image {image_id} observation {point2d_idx}, which does not exist"
    )]
    MissingObservation {
        /// Point holding the track.
        point3d_id: u64,
        /// Image id in the track.
        image_id: u32,
        /// Observation index in the track.
        point2d_idx: u32,
    },
    /// An image referring to a camera that the model does not have.
    #[error("image {image_id} refers to camera {camera_id}, which does not exist")]
    MissingCamera {
        /// The image.
        image_id: u32,
        /// The dangling camera id.
        camera_id: u32,
    },
    /// An image name that the text format cannot hold (it is read up to the first whitespace).
    #[error("image name `{0}` is empty or contains whitespace, which the text format cannot hold")]
    BadName(String),
}

/// Errors of reading and writing COLMAP models.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// An operating-system error on a file or folder.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// A problem in the content of a model file.
    #[error("{path}: {location}: {problem}")]
    Format {
        /// The file.
        path: PathBuf,
        /// Where in the file.
        location: Location,
        /// What was wrong.
        problem: Problem,
    },
    /// A problem in a reconstruction held in memory (found before writing it).
    #[error("invalid reconstruction: {0}")]
    Invalid(Problem),
    /// No complete model (cameras, images, points3D in .bin or .txt) in a folder.
    #[error("{dir}: no COLMAP model (cameras, images and points3D, all .bin or all .txt)")]
    NoModel {
        /// The folder searched.
        dir: PathBuf,
    },
    /// A camera that is needed as a pinhole but has a distortion model.
    #[error(
        "camera {camera_id} uses the {model} model; only SIMPLE_PINHOLE and PINHOLE can be used as pinhole cameras (undistort the images first)"
    )]
    NotPinhole {
        /// The camera.
        camera_id: u32,
        /// Its model name.
        model: &'static str,
    },
    /// A value that cannot be represented in the target type or format.
    #[error("{0}")]
    Unrepresentable(String),
    /// A dataset that cannot be written as asked (what is wrong is named).
    #[error("dataset {path}: {message}")]
    Dataset {
        /// The dataset folder or file.
        path: PathBuf,
        /// What was wrong.
        message: String,
    },
}

impl Error {
    /// An I/O error on `path`.
    pub(crate) fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io {
            path: path.into(),
            source,
        }
    }
}
