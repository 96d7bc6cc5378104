//! Why a PLY header was refused: the line and the problem, without the file (readers add it).

use crate::ScalarType;

/// A malformed or unsupported PLY header: the 1-based header line and what is wrong there.
///
/// It does not know the file; readers wrap it with their path into their own error types, so
/// the message users see names the file, the line and the problem.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("PLY header line {line}: {problem}")]
pub struct HeaderError {
    /// 1-based header line of the problem.
    pub line: usize,
    /// What was expected and what was found.
    pub problem: HeaderProblem,
}

/// What is wrong with a PLY header (the text is the message readers show after the line).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum HeaderProblem {
    /// The input holds no bytes at all.
    #[error("the file is empty (expected the magic line 'ply')")]
    Empty,
    /// The first line is not `ply`.
    #[error("not a PLY file: expected the magic line 'ply', found {found:?}")]
    NotPly {
        /// The first line as found.
        found: String,
    },
    /// A header line is not valid UTF-8.
    #[error("the header line is not valid UTF-8")]
    NotUtf8,
    /// No `end_header` within [`crate::MAX_HEADER_BYTES`].
    #[error("no 'end_header' within the first {limit} bytes")]
    TooLong {
        /// The limit, [`crate::MAX_HEADER_BYTES`].
        limit: usize,
    },
    /// The input ends before `end_header`.
    #[error("the file ends before 'end_header'")]
    NoEndHeader,
    /// A second `format` line.
    #[error("a second 'format' line")]
    SecondFormat,
    /// The `format` line names an unknown encoding.
    #[error("unknown format {found:?}")]
    UnknownFormat {
        /// The encoding as found.
        found: String,
    },
    /// The `format` line has a version other than 1.0 (empty when it has none).
    #[error("unsupported format version {found:?} (expected 1.0)")]
    UnsupportedVersion {
        /// The version as found.
        found: String,
    },
    /// No `format` line before `end_header`.
    #[error("no 'format' line in the header")]
    NoFormat,
    /// An `element` line without a name and a count.
    #[error("expected 'element NAME COUNT'")]
    MalformedElement,
    /// An element count that is not a non-negative integer.
    #[error("element count {found:?} is not a non-negative integer")]
    BadElementCount {
        /// The count as found.
        found: String,
    },
    /// Two elements with one name.
    #[error("element '{name}' is declared twice")]
    DuplicateElement {
        /// The element name.
        name: String,
    },
    /// A `property` line before any `element` line.
    #[error("property before any element")]
    PropertyBeforeElement,
    /// A property type that is not a PLY scalar type.
    #[error("unknown property type {found:?}")]
    UnknownType {
        /// The type as found.
        found: String,
    },
    /// A list whose count type is `float` or `double`.
    #[error("list count type must be an integer, found {}", found.name())]
    FloatListCount {
        /// The count type as found.
        found: ScalarType,
    },
    /// A `property` line that is neither `property TYPE NAME` nor `property list COUNT ITEM NAME`.
    #[error("malformed property line {found:?}")]
    MalformedProperty {
        /// The line as found.
        found: String,
    },
    /// Two properties with one name in one element.
    #[error("element '{element}' declares property '{property}' twice")]
    DuplicateProperty {
        /// The element name.
        element: String,
        /// The property name.
        property: String,
    },
    /// A line starting with a word that is not a PLY header keyword.
    #[error("unknown header keyword {found:?}")]
    UnknownKeyword {
        /// The keyword as found.
        found: String,
    },
}
