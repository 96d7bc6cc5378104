//! The PLY header model (format line, elements, properties, comments) and its parser.

use crate::{HeaderError, HeaderProblem, ScalarType};

/// Longest header we accept; real headers (8iVSLF with 13 rig matrices) are ~3.5 KB.
pub const MAX_HEADER_BYTES: usize = 1 << 20;

/// How the PLY body is encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PlyFormat {
    /// `format ascii 1.0`: one element per line, whitespace-separated numbers.
    Ascii,
    /// `format binary_little_endian 1.0`.
    BinaryLittleEndian,
    /// `format binary_big_endian 1.0`.
    BinaryBigEndian,
}

impl PlyFormat {
    /// The keyword used on the `format` line.
    #[must_use]
    pub fn keyword(self) -> &'static str {
        match self {
            PlyFormat::Ascii => "ascii",
            PlyFormat::BinaryLittleEndian => "binary_little_endian",
            PlyFormat::BinaryBigEndian => "binary_big_endian",
        }
    }
}

/// The kind of a property: one scalar, or a list with a count type and an item type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PropertyKind {
    /// `property TYPE name`.
    Scalar(ScalarType),
    /// `property list COUNT_TYPE ITEM_TYPE name`.
    List {
        /// Type of the leading count.
        count: ScalarType,
        /// Type of each item.
        item: ScalarType,
    },
}

/// One property of an element.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Property {
    /// Its name.
    pub name: String,
    /// Scalar or list.
    pub kind: PropertyKind,
}

/// One element declaration (`element vertex 1234`) with its properties.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Element {
    /// Its name.
    pub name: String,
    /// How many rows the header promises.
    pub count: u64,
    /// Its properties in order.
    pub properties: Vec<Property>,
}

impl Element {
    /// Byte size of one row when every property is a scalar (binary formats), else `None`.
    #[must_use]
    pub fn fixed_stride(&self) -> Option<usize> {
        self.properties
            .iter()
            .map(|p| match p.kind {
                PropertyKind::Scalar(t) => Some(t.size()),
                PropertyKind::List { .. } => None,
            })
            .sum()
    }

    /// Fewest bytes one row can take in the given format (lists may be empty).
    #[must_use]
    pub fn min_row_bytes(&self, format: PlyFormat) -> u64 {
        match format {
            // Every value needs at least one digit and one separator (space or newline).
            PlyFormat::Ascii => 2 * self.properties.len() as u64,
            _ => self
                .properties
                .iter()
                .map(|p| match p.kind {
                    PropertyKind::Scalar(t) => t.size() as u64,
                    PropertyKind::List { count, .. } => count.size() as u64,
                })
                .sum(),
        }
    }

    /// Index of the property called `name`.
    #[must_use]
    pub fn property_index(&self, name: &str) -> Option<usize> {
        self.properties.iter().position(|p| p.name == name)
    }
}

/// A parsed PLY header.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// Body encoding.
    pub format: PlyFormat,
    /// Elements in file order.
    pub elements: Vec<Element>,
    /// `comment` lines (text after `comment `), in order, with their 1-based line numbers.
    pub comments: Vec<(usize, String)>,
    /// `obj_info` lines.
    pub obj_info: Vec<String>,
    /// Byte offset of the body (just after `end_header\n`).
    pub body_offset: usize,
}

impl Header {
    /// The element called `name`, with its index.
    #[must_use]
    pub fn element(&self, name: &str) -> Option<(usize, &Element)> {
        self.elements
            .iter()
            .enumerate()
            .find(|(_, e)| e.name == name)
    }

    /// Whether the vertices carry 3D Gaussian Splatting's properties
    /// ([`GAUSSIAN_SPLAT_PROPERTIES`]): a splat model rather than a point cloud or a mesh.
    #[must_use]
    pub fn holds_gaussian_splats(&self) -> bool {
        self.element("vertex").is_some_and(|(_, v)| {
            GAUSSIAN_SPLAT_PROPERTIES
                .iter()
                .all(|n| v.properties.iter().any(|p| p.name == *n))
        })
    }
}

/// The vertex properties that mark a PLY as a 3D Gaussian Splatting model, one of each kind
/// (colour, opacity, scale, rotation): a point cloud or a mesh has none of them.
pub const GAUSSIAN_SPLAT_PROPERTIES: [&str; 4] = ["f_dc_0", "opacity", "scale_0", "rot_0"];

/// Parses the header at the start of `bytes` (the whole file, or at least its header).
///
/// Accepts the classic and the sized type names, CRLF header lines, blank lines, `comment` and
/// `obj_info` lines; refuses anything else with the 1-based line and the problem.
///
/// # Errors
/// [`HeaderError`] for an empty input, a missing `ply` magic line, a header that is not UTF-8,
/// longer than [`MAX_HEADER_BYTES`] or without `end_header`, an unknown format, version, type
/// or keyword, and elements or properties that are malformed or declared twice.
pub fn parse_header(bytes: &[u8]) -> Result<Header, HeaderError> {
    if bytes.is_empty() {
        return Err(HeaderError {
            line: 1,
            problem: HeaderProblem::Empty,
        });
    }
    let mut lines = HeaderLines {
        bytes,
        pos: 0,
        line: 0,
    };
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    let mut comments = Vec::new();
    let mut obj_info = Vec::new();
    loop {
        let text = lines.next_line()?;
        let line = lines.line;
        let at = |problem| HeaderError { line, problem };
        if line == 1 {
            if text.trim_end() != "ply" {
                return Err(at(HeaderProblem::NotPly {
                    found: text.to_string(),
                }));
            }
            continue;
        }
        let mut words = text.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        match keyword {
            "format" => {
                if format.is_some() {
                    return Err(at(HeaderProblem::SecondFormat));
                }
                format = Some(format_line(words).map_err(at)?);
            }
            "comment" => comments.push((line, text_after(text, "comment"))),
            "obj_info" => obj_info.push(text_after(text, "obj_info")),
            "element" => {
                let element = element_line(words).map_err(at)?;
                if elements.iter().any(|e| e.name == element.name) {
                    return Err(at(HeaderProblem::DuplicateElement { name: element.name }));
                }
                elements.push(element);
            }
            "property" => {
                let Some(element) = elements.last_mut() else {
                    return Err(at(HeaderProblem::PropertyBeforeElement));
                };
                let property = property_line(words, text).map_err(at)?;
                if element.property_index(&property.name).is_some() {
                    return Err(at(HeaderProblem::DuplicateProperty {
                        element: element.name.clone(),
                        property: property.name,
                    }));
                }
                element.properties.push(property);
            }
            "end_header" => break,
            other => {
                return Err(at(HeaderProblem::UnknownKeyword {
                    found: other.to_string(),
                }));
            }
        }
    }
    let Some(format) = format else {
        return Err(HeaderError {
            line: 2,
            problem: HeaderProblem::NoFormat,
        });
    };
    Ok(Header {
        format,
        elements,
        comments,
        obj_info,
        body_offset: lines.pos,
    })
}

/// The header's lines one by one, numbered from 1, within [`MAX_HEADER_BYTES`].
struct HeaderLines<'a> {
    bytes: &'a [u8],
    /// Byte offset of the next line.
    pos: usize,
    /// 1-based number of the line last returned.
    line: usize,
}

impl<'a> HeaderLines<'a> {
    /// The next line's text, without its line ending (LF, or CRLF as some Windows tools write
    /// headers; the body is unaffected).
    fn next_line(&mut self) -> Result<&'a str, HeaderError> {
        let (bytes, pos) = (self.bytes, self.pos);
        let at = |line, problem| HeaderError { line, problem };
        if pos >= bytes.len() {
            return Err(at(self.line, HeaderProblem::NoEndHeader));
        }
        if pos > MAX_HEADER_BYTES {
            return Err(at(
                self.line,
                HeaderProblem::TooLong {
                    limit: MAX_HEADER_BYTES,
                },
            ));
        }
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |i| pos + i);
        self.line += 1;
        self.pos = (end + 1).min(bytes.len());
        let text = std::str::from_utf8(&bytes[pos..end])
            .map_err(|_| at(self.line, HeaderProblem::NotUtf8))?;
        Ok(text.strip_suffix('\r').unwrap_or(text))
    }
}

/// The text of a `comment` or `obj_info` line after its keyword, trimmed.
fn text_after(text: &str, keyword: &str) -> String {
    text.trim_start()[keyword.len()..].trim().to_string()
}

/// The words after `format`: the body's encoding and version 1.0.
fn format_line<'a>(mut words: impl Iterator<Item = &'a str>) -> Result<PlyFormat, HeaderProblem> {
    let kind = words.next().unwrap_or("");
    let format = match kind {
        "ascii" => PlyFormat::Ascii,
        "binary_little_endian" => PlyFormat::BinaryLittleEndian,
        "binary_big_endian" => PlyFormat::BinaryBigEndian,
        _ => {
            return Err(HeaderProblem::UnknownFormat {
                found: kind.to_string(),
            });
        }
    };
    match words.next() {
        Some("1.0" | "1") => Ok(format),
        v => Err(HeaderProblem::UnsupportedVersion {
            found: v.unwrap_or("").to_string(),
        }),
    }
}

/// The words after `element`: its name and row count, with no properties yet.
fn element_line<'a>(mut words: impl Iterator<Item = &'a str>) -> Result<Element, HeaderProblem> {
    let (Some(name), Some(count)) = (words.next(), words.next()) else {
        return Err(HeaderProblem::MalformedElement);
    };
    let count: u64 = count.parse().map_err(|_| HeaderProblem::BadElementCount {
        found: count.to_string(),
    })?;
    Ok(Element {
        name: name.to_string(),
        count,
        properties: Vec::new(),
    })
}

/// The words after `property` (`TYPE name` or `list COUNT_TYPE ITEM_TYPE name`); `text` is the
/// whole line, for the error.
fn property_line<'a>(
    words: impl Iterator<Item = &'a str>,
    text: &str,
) -> Result<Property, HeaderProblem> {
    let ty = |s: &str| {
        ScalarType::parse(s).ok_or_else(|| HeaderProblem::UnknownType {
            found: s.to_string(),
        })
    };
    let parts: Vec<&str> = words.collect();
    match parts.as_slice() {
        ["list", count, item, name] => {
            let count = ty(count)?;
            if count.is_float() {
                return Err(HeaderProblem::FloatListCount { found: count });
            }
            Ok(Property {
                name: (*name).to_string(),
                kind: PropertyKind::List {
                    count,
                    item: ty(item)?,
                },
            })
        }
        [t, name] => Ok(Property {
            name: (*name).to_string(),
            kind: PropertyKind::Scalar(ty(t)?),
        }),
        _ => Err(HeaderProblem::MalformedProperty {
            found: text.to_string(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Header, HeaderError> {
        parse_header(text.as_bytes())
    }

    #[test]
    fn parses_elements_lists_and_comments() {
        let text = "ply\nformat binary_big_endian 1.0\ncomment width 1023\nobj_info made by hand\n\
                    element vertex 3\nproperty float x\nproperty uint8 red\nelement face 1\n\
                    property list uchar int vertex_indices\nend_header\n";
        let h = parse(&format!("{text}XYZ")).unwrap();
        assert_eq!(h.format, PlyFormat::BinaryBigEndian);
        assert_eq!(h.comments, vec![(3, "width 1023".to_string())]);
        assert_eq!(h.obj_info, vec!["made by hand".to_string()]);
        assert_eq!(h.elements[0].fixed_stride(), Some(5));
        assert_eq!(h.elements[0].property_index("red"), Some(1));
        assert_eq!(h.elements[1].fixed_stride(), None);
        assert_eq!(h.elements[1].min_row_bytes(h.format), 1);
        assert_eq!(h.elements[1].min_row_bytes(PlyFormat::Ascii), 2);
        assert_eq!(h.element("face").map(|(i, _)| i), Some(1));
        assert_eq!(h.body_offset, text.len());
    }

    #[test]
    fn accepts_crlf_and_sized_type_names() {
        let h = parse(
            "ply\r\nformat ascii 1.0\r\nelement vertex 1\r\nproperty float64 x\r\nend_header\r\n",
        )
        .unwrap();
        assert_eq!(h.format, PlyFormat::Ascii);
        assert_eq!(
            h.elements[0].properties[0].kind,
            PropertyKind::Scalar(ScalarType::F64)
        );
    }

    #[test]
    fn rejects_bad_headers_with_line_numbers() {
        let e = parse("ply\nformat ascii 1.0\nelement vertex -3\nend_header\n").unwrap_err();
        assert_eq!(e.line, 3, "{e}");
        assert!(
            matches!(e.problem, HeaderProblem::BadElementCount { .. }),
            "{e}"
        );
        let e = parse("ply\nformat ascii 1.0\nelement vertex 3\nproperty flot x\nend_header\n")
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "PLY header line 4: unknown property type \"flot\""
        );
        let e = parse("ply\nformat ascii 1.0\nelement vertex 3\n").unwrap_err();
        assert!(e.to_string().contains("end_header"), "{e}");
        let e = parse("plx\n").unwrap_err();
        assert_eq!(e.line, 1, "{e}");
        assert!(e.to_string().contains("not a PLY file"), "{e}");
        let e = parse("").unwrap_err();
        assert_eq!((e.line, e.problem), (1, HeaderProblem::Empty));
        let e = parse("ply\nelement vertex 1\nend_header\n").unwrap_err();
        assert_eq!((e.line, e.problem), (2, HeaderProblem::NoFormat));
        let e = parse("ply\nformat ascii 2.0\nend_header\n").unwrap_err();
        assert_eq!(e.line, 2, "{e}");
        let e =
            parse("ply\nformat ascii 1.0\nelement v 1\nproperty list float int i\nend_header\n")
                .unwrap_err();
        assert!(e.to_string().contains("found float"), "{e}");
        let e = parse(
            "ply\nformat ascii 1.0\nelement v 1\nproperty int a\nproperty int a\nend_header\n",
        )
        .unwrap_err();
        assert_eq!(e.line, 5, "{e}");
        let e = parse("ply\nformat ascii 1.0\nbogus\nend_header\n").unwrap_err();
        assert_eq!(e.line, 3, "{e}");
    }

    #[test]
    fn refuses_an_endless_header() {
        let mut text = String::from("ply\nformat ascii 1.0\n");
        while text.len() <= MAX_HEADER_BYTES + 100 {
            text.push_str("comment padding padding padding padding padding padding\n");
        }
        let e = parse(&text).unwrap_err();
        assert!(matches!(e.problem, HeaderProblem::TooLong { .. }), "{e}");
    }
}
