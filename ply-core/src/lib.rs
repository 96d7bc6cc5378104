//! The PLY header model, header parser and scalar codec shared by every PLY reader and writer of
//! the transcoder (`plenoptic-io` for point clouds and meshes, `splat-core` for 3DGS models).
//!
//! - Header model: [`PlyFormat`], [`ScalarType`], [`PropertyKind`], [`Property`], [`Element`],
//!   [`Header`] (with its comments and their line numbers).
//! - [`parse_header`]: the header at the start of a file, refused with a [`HeaderError`] (the
//!   1-based line and a [`HeaderProblem`]) when malformed; at most [`MAX_HEADER_BYTES`] long.
//! - Scalar codec, every value through `f64`: [`read_binary`] / [`write_binary`] (either
//!   endianness), [`parse_ascii`] / [`write_ascii`].
//!
//! The crate knows nothing about what properties mean, and nothing about files: readers hand it
//! bytes and wrap its errors with their path.
//!
//! ```
//! use ply_core::{PlyFormat, PropertyKind, ScalarType, parse_header, read_binary};
//!
//! let mut file = b"ply\nformat binary_big_endian 1.0\ncomment made by hand\n\
//!     element vertex 1\nproperty float x\nproperty ushort id\nend_header\n"
//!     .to_vec();
//! file.extend(2.5f32.to_be_bytes());
//! file.extend(7u16.to_be_bytes());
//!
//! let header = parse_header(&file)?;
//! assert_eq!(header.format, PlyFormat::BinaryBigEndian);
//! assert_eq!(header.comments, [(3, "made by hand".to_string())]);
//! let (_, vertex) = header.element("vertex").unwrap();
//! assert_eq!(vertex.fixed_stride(), Some(6));
//! assert_eq!(vertex.properties[1].kind, PropertyKind::Scalar(ScalarType::U16));
//!
//! let record = &file[header.body_offset..];
//! assert_eq!(read_binary(record, ScalarType::F32, true), 2.5);
//! assert_eq!(read_binary(&record[4..], ScalarType::U16, true), 7.0);
//!
//! let e = parse_header(b"ply\nformat ascii 1.0\nelement vertex x\nend_header\n").unwrap_err();
//! assert_eq!(e.line, 3);
//! assert_eq!(
//!     e.to_string(),
//!     "PLY header line 3: element count \"x\" is not a non-negative integer"
//! );
//! # Ok::<(), ply_core::HeaderError>(())
//! ```

mod codec;
mod error;
mod header;
mod scalar;

pub use codec::{parse_ascii, read_binary, write_ascii, write_binary};
pub use error::{HeaderError, HeaderProblem};
pub use header::{
    Element, GAUSSIAN_SPLAT_PROPERTIES, Header, MAX_HEADER_BYTES, PlyFormat, Property,
    PropertyKind, parse_header,
};
pub use scalar::ScalarType;
