//! The PLY body reader: a zero-copy parallel path for fixed-size binary vertex records and a
//! general row-by-row path (ASCII, lists, faces) sharing one conversion of values to roles.

use std::path::Path;

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use super::schema::{VertexPlan, color_from_stored};
use crate::Error;
use ply_core::{Element, Header, PlyFormat, PropertyKind, ScalarType, parse_ascii, read_binary};

/// Points decoded per parallel task: large enough to amortise scheduling, small enough to balance 2+ cores.
const CHUNK_POINTS: usize = 16 * 1024;

/// Decoded vertex columns.
#[derive(Debug, Default)]
pub(crate) struct VertexData {
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Normals when the plan has them.
    pub normals: Option<Vec<Vec3>>,
    /// Main colours when the plan has them.
    pub colors: Option<Vec<[f32; 3]>>,
    /// Per-camera colours, point-major.
    pub camera_colors: Vec<[f32; 3]>,
    /// Texture coordinates (v flipped to the image convention).
    pub uvs: Option<Vec<Vec2>>,
    /// Extra columns, in plan order.
    pub extras: Vec<Vec<f64>>,
}

/// Mutable views of a run of points in every output column.
struct Out<'a> {
    positions: &'a mut [Vec3],
    normals: Option<&'a mut [Vec3]>,
    colors: Option<&'a mut [[f32; 3]]>,
    cameras: &'a mut [[f32; 3]],
    uvs: Option<&'a mut [Vec2]>,
    extras: Vec<&'a mut [f64]>,
}

impl VertexData {
    /// Zero-initialised columns for `n` points (calloc'd, so untouched pages cost nothing).
    fn zeroed(plan: &VertexPlan, n: usize) -> Self {
        VertexData {
            positions: bytemuck::zeroed_vec(n),
            normals: plan.normal.map(|_| bytemuck::zeroed_vec(n)),
            colors: plan.main.map(|_| bytemuck::zeroed_vec(n)),
            camera_colors: bytemuck::zeroed_vec(n * plan.cameras.len()),
            uvs: plan.uv.map(|_| bytemuck::zeroed_vec(n)),
            extras: plan.extras.iter().map(|_| vec![0.0; n]).collect(),
        }
    }

    /// Splits every column into runs of `chunk` points.
    fn split(&mut self, chunk: usize, num_cameras: usize) -> Vec<Out<'_>> {
        let positions = self.positions.chunks_mut(chunk);
        let mut normals = self.normals.as_mut().map(|v| v.chunks_mut(chunk));
        let mut colors = self.colors.as_mut().map(|v| v.chunks_mut(chunk));
        let mut cameras = self.camera_colors.chunks_mut((chunk * num_cameras).max(1));
        let mut uvs = self.uvs.as_mut().map(|v| v.chunks_mut(chunk));
        let mut extras: Vec<_> = self
            .extras
            .iter_mut()
            .map(|v| v.chunks_mut(chunk))
            .collect();
        let mut outs = Vec::new();
        for p in positions {
            outs.push(Out {
                positions: p,
                normals: normals.as_mut().and_then(Iterator::next),
                colors: colors.as_mut().and_then(Iterator::next),
                cameras: cameras.next().unwrap_or_default(),
                uvs: uvs.as_mut().and_then(Iterator::next),
                extras: extras
                    .iter_mut()
                    .map(|e| e.next().unwrap_or_default())
                    .collect(),
            });
        }
        outs
    }
}

/// Where [`store_row`] takes one row's values from: parsed values (general path) or a binary
/// record in the mapped file (fast path).
trait Row {
    /// The value of scalar property `p`.
    fn value(&self, p: usize) -> f64;

    /// Colour property `p` normalised to [0, 1].
    #[inline(always)]
    fn color(&self, plan: &VertexPlan, p: usize) -> f32 {
        color_from_stored(self.value(p), plan.types[p])
    }

    /// The row's per-camera colours, in camera order.
    #[inline(always)]
    fn cameras(&self, plan: &VertexPlan, out: &mut [[f32; 3]]) {
        for (dst, ix) in out.iter_mut().zip(&plan.cameras) {
            *dst = ix.map(|i| self.color(plan, i));
        }
    }
}

impl Row for [f64] {
    #[inline(always)]
    fn value(&self, p: usize) -> f64 {
        self[p]
    }
}

/// Stores point `j` of `out` from `row`.
/// The one place where file values become positions, colours, UVs (both paths call it).
#[inline(always)]
fn store_row<R: Row + ?Sized>(plan: &VertexPlan, out: &mut Out<'_>, j: usize, row: &R) {
    let p = plan.position;
    let v = |i: usize| row.value(i) as f32;
    out.positions[j] = Vec3::new(v(p[0]), v(p[1]), v(p[2]));
    if let (Some(normals), Some(n)) = (out.normals.as_deref_mut(), plan.normal) {
        normals[j] = Vec3::new(v(n[0]), v(n[1]), v(n[2]));
    }
    if let (Some(colors), Some(m)) = (out.colors.as_deref_mut(), plan.main) {
        colors[j] = m.map(|i| row.color(plan, i));
    }
    let k = plan.cameras.len();
    if k > 0 {
        row.cameras(plan, &mut out.cameras[j * k..(j + 1) * k]);
    }
    if let (Some(uvs), Some(uv)) = (out.uvs.as_deref_mut(), plan.uv) {
        // PLY s/t follow OpenGL (origin bottom-left); the Mesh convention is top-left.
        uvs[j] = Vec2::new(v(uv[0]), 1.0 - v(uv[1]));
    }
    for (e, (_, i)) in plan.extras.iter().enumerate() {
        out.extras[e][j] = row.value(*i);
    }
}

/// What the fast path knows about a fixed-size record layout.
struct FixedLayout<'a> {
    plan: &'a VertexPlan,
    /// Byte offset of every property in the record.
    offsets: Vec<usize>,
    big_endian: bool,
    /// `color_from_stored` of every uchar level, so uchar colours cost a table look-up.
    uchar_colors: [f32; 256],
    /// Offset of the camera colours when they are all uchar and packed as r0 g0 b0 r1 g1 b1 …
    /// (the 8iVSLF layout): then a point's colours are one contiguous run of bytes.
    camera_block: Option<usize>,
}

impl<'a> FixedLayout<'a> {
    fn new(plan: &'a VertexPlan, element: &Element, big_endian: bool) -> Self {
        let mut offsets = Vec::with_capacity(element.properties.len());
        let mut at = 0;
        for p in &element.properties {
            offsets.push(at);
            if let PropertyKind::Scalar(t) = p.kind {
                at += t.size();
            }
        }
        let camera_block = plan
            .cameras
            .first()
            .map(|first| offsets[first[0]])
            .filter(|&base| {
                plan.cameras.iter().enumerate().all(|(k, ix)| {
                    ix.iter().enumerate().all(|(c, &i)| {
                        plan.types[i] == ScalarType::U8 && offsets[i] == base + 3 * k + c
                    })
                })
            });
        FixedLayout {
            plan,
            offsets,
            big_endian,
            uchar_colors: std::array::from_fn(|v| color_from_stored(v as f64, ScalarType::U8)),
            camera_block,
        }
    }
}

/// One binary record seen through its layout.
struct Record<'a> {
    bytes: &'a [u8],
    layout: &'a FixedLayout<'a>,
}

impl Row for Record<'_> {
    #[inline(always)]
    fn value(&self, p: usize) -> f64 {
        read_binary(
            &self.bytes[self.layout.offsets[p]..],
            self.layout.plan.types[p],
            self.layout.big_endian,
        )
    }

    #[inline(always)]
    fn color(&self, plan: &VertexPlan, p: usize) -> f32 {
        if plan.types[p] == ScalarType::U8 {
            self.layout.uchar_colors[usize::from(self.bytes[self.layout.offsets[p]])]
        } else {
            color_from_stored(self.value(p), plan.types[p])
        }
    }

    #[inline(always)]
    fn cameras(&self, plan: &VertexPlan, out: &mut [[f32; 3]]) {
        let Some(base) = self.layout.camera_block else {
            for (dst, ix) in out.iter_mut().zip(&plan.cameras) {
                *dst = ix.map(|i| self.color(plan, i));
            }
            return;
        };
        let lut = &self.layout.uchar_colors;
        let block = &self.bytes[base..base + 3 * out.len()];
        for (dst, src) in out.iter_mut().zip(block.chunks_exact(3)) {
            *dst = [
                lut[usize::from(src[0])],
                lut[usize::from(src[1])],
                lut[usize::from(src[2])],
            ];
        }
    }
}

/// What the body reader should collect besides vertices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Want {
    /// Vertices only (faces are skipped).
    Points,
    /// Vertices and the triangles of the face element.
    Triangles,
}

/// The decoded content of a PLY body.
#[derive(Debug)]
pub(crate) struct Body {
    /// The vertex element's plan.
    pub plan: VertexPlan,
    /// The vertices.
    pub vertices: VertexData,
    /// Fan-triangulated faces (empty unless asked for).
    pub triangles: Vec<[u32; 3]>,
}

/// Refuses a header whose elements cannot fit in the bytes after it, before anything is allocated.
pub(crate) fn check_sizes(path: &Path, header: &Header, available: u64) -> Result<(), Error> {
    // The last ASCII row may lack its final newline.
    let slack = u64::from(header.format == PlyFormat::Ascii);
    let mut needed = 0u64;
    for e in &header.elements {
        let row = match header.format {
            // At least a newline per row even when an element has no properties.
            PlyFormat::Ascii => e.min_row_bytes(header.format).max(1),
            _ => e.min_row_bytes(header.format),
        };
        needed = needed.saturating_add(e.count.saturating_mul(row));
        if needed > available + slack {
            return Err(Error::Truncated {
                path: path.to_path_buf(),
                element: e.name.clone(),
                count: e.count,
                needed,
                available,
            });
        }
    }
    Ok(())
}

/// A position in the body, for error messages and the row reader.
struct Cursor<'a> {
    path: &'a Path,
    bytes: &'a [u8],
    pos: usize,
    /// 1-based line of the next ASCII line.
    line: usize,
    format: PlyFormat,
}

impl Cursor<'_> {
    fn error(&self, element: &Element, index: u64, message: String) -> Error {
        let location = match self.format {
            PlyFormat::Ascii => format!("line {}", self.line.saturating_sub(1)),
            _ => format!("byte {}", self.pos),
        };
        Error::Body {
            path: self.path.to_path_buf(),
            element: element.name.clone(),
            index,
            location,
            message,
        }
    }

    /// Reads the next row of `element` into `scalars` (one value per property, NaN for lists);
    /// the items of the list property `keep_list`, if any, go to `list`.
    fn row(
        &mut self,
        element: &Element,
        index: u64,
        scalars: &mut [f64],
        keep_list: Option<usize>,
        list: &mut Vec<f64>,
    ) -> Result<(), Error> {
        list.clear();
        match self.format {
            PlyFormat::Ascii => self.ascii_row(element, index, scalars, keep_list, list),
            f => self.binary_row(
                element,
                index,
                scalars,
                keep_list,
                list,
                f == PlyFormat::BinaryBigEndian,
            ),
        }
    }

    fn binary_row(
        &mut self,
        element: &Element,
        index: u64,
        scalars: &mut [f64],
        keep_list: Option<usize>,
        list: &mut Vec<f64>,
        big: bool,
    ) -> Result<(), Error> {
        for (i, p) in element.properties.iter().enumerate() {
            let runs_out = |c: &Self, what: String| {
                c.error(
                    element,
                    index,
                    format!("the data runs out in property '{}' ({what})", p.name),
                )
            };
            match p.kind {
                PropertyKind::Scalar(t) => {
                    let Some(b) = self.bytes.get(self.pos..self.pos + t.size()) else {
                        return Err(runs_out(self, format!("needs {} bytes", t.size())));
                    };
                    scalars[i] = read_binary(b, t, big);
                    self.pos += t.size();
                }
                PropertyKind::List { count, item } => {
                    let Some(b) = self.bytes.get(self.pos..self.pos + count.size()) else {
                        return Err(runs_out(self, "list count".into()));
                    };
                    let n = read_binary(b, count, big);
                    if n < 0.0 {
                        return Err(self.error(
                            element,
                            index,
                            format!("list '{}' has negative length {n}", p.name),
                        ));
                    }
                    self.pos += count.size();
                    let len = (n as usize).saturating_mul(item.size());
                    let Some(items) = self.bytes.get(self.pos..self.pos.saturating_add(len)) else {
                        return Err(runs_out(self, format!("list of {n} items")));
                    };
                    if keep_list == Some(i) {
                        list.extend(
                            items
                                .chunks_exact(item.size())
                                .map(|b| read_binary(b, item, big)),
                        );
                    }
                    self.pos += len;
                    scalars[i] = f64::NAN;
                }
            }
        }
        Ok(())
    }

    fn ascii_row(
        &mut self,
        element: &Element,
        index: u64,
        scalars: &mut [f64],
        keep_list: Option<usize>,
        list: &mut Vec<f64>,
    ) -> Result<(), Error> {
        // One element per line (PLY spec); blank lines between rows are tolerated.
        let text = loop {
            if self.pos >= self.bytes.len() {
                self.line += 1;
                return Err(self.error(element, index, "the data runs out (end of file)".into()));
            }
            let end = self.bytes[self.pos..]
                .iter()
                .position(|&b| b == b'\n')
                .map_or(self.bytes.len(), |i| self.pos + i);
            let raw = &self.bytes[self.pos..end];
            self.pos = (end + 1).min(self.bytes.len());
            self.line += 1;
            let text = std::str::from_utf8(raw)
                .map_err(|_| self.error(element, index, "the line is not valid UTF-8".into()))?;
            if !text.trim().is_empty() {
                break text;
            }
        };
        let mut tokens = text.split_ascii_whitespace();
        let mut next = |c: &Self, what: &str, ty: ScalarType| -> Result<f64, Error> {
            let token = tokens
                .next()
                .ok_or_else(|| c.error(element, index, format!("the line ends before {what}")))?;
            parse_ascii(token, ty).ok_or_else(|| {
                c.error(
                    element,
                    index,
                    format!("{what}: {token:?} is not a valid {}", ty.name()),
                )
            })
        };
        for (i, p) in element.properties.iter().enumerate() {
            match p.kind {
                PropertyKind::Scalar(t) => {
                    scalars[i] = next(self, &format!("property '{}'", p.name), t)?
                }
                PropertyKind::List { count, item } => {
                    let n = next(self, &format!("the length of list '{}'", p.name), count)?;
                    if n < 0.0 {
                        return Err(self.error(
                            element,
                            index,
                            format!("list '{}' has negative length {n}", p.name),
                        ));
                    }
                    for _ in 0..n as u64 {
                        let v = next(self, &format!("an item of list '{}'", p.name), item)?;
                        if keep_list == Some(i) {
                            list.push(v);
                        }
                    }
                    scalars[i] = f64::NAN;
                }
            }
        }
        if let Some(extra) = tokens.next() {
            return Err(self.error(
                element,
                index,
                format!("unexpected value {extra:?} after the last property"),
            ));
        }
        Ok(())
    }
}

/// Decodes the whole body: vertices (fast path when possible), faces when wanted, other elements skipped.
pub(crate) fn read_body(
    path: &Path,
    bytes: &[u8],
    header: &Header,
    with_uv: bool,
    want: Want,
) -> Result<Body, Error> {
    let available = (bytes.len() - header.body_offset) as u64;
    check_sizes(path, header, available)?;
    let Some((vertex_index, vertex_element)) = header.element("vertex") else {
        return Err(Error::Content {
            path: path.to_path_buf(),
            message: "the file has no 'vertex' element".into(),
        });
    };
    let plan = VertexPlan::new(path, vertex_element, with_uv)?;
    let header_lines = bytes[..header.body_offset]
        .iter()
        .filter(|&&b| b == b'\n')
        .count();
    let mut cursor = Cursor {
        path,
        bytes,
        pos: header.body_offset,
        line: header_lines + 1,
        format: header.format,
    };
    let mut vertices = None;
    let mut triangles = Vec::new();
    let big = header.format == PlyFormat::BinaryBigEndian;
    for (ei, element) in header.elements.iter().enumerate() {
        let stride = element
            .fixed_stride()
            .filter(|_| header.format != PlyFormat::Ascii);
        if ei == vertex_index {
            let n = usize::try_from(element.count).map_err(|_| Error::Content {
                path: path.to_path_buf(),
                message: format!("{} vertices do not fit in memory", element.count),
            })?;
            let mut data = VertexData::zeroed(&plan, n);
            if let Some(stride) = stride {
                // check_sizes bounds the minimum; list elements before this one may have used more.
                let records = records(path, bytes, cursor.pos, element, stride)?;
                decode_fixed(&plan, element, records, stride, big, &mut data);
                cursor.pos += records.len();
            } else {
                decode_rows(&plan, element, &mut cursor, &mut data)?;
            }
            vertices = Some(data);
        } else if want == Want::Triangles && element.name == "face" {
            let vertex_count = vertices.as_ref().map(|v| v.positions.len() as u64);
            read_faces(path, element, vertex_count, &mut cursor, &mut triangles)?;
        } else if let Some(stride) = stride {
            cursor.pos += records(path, bytes, cursor.pos, element, stride)?.len();
        } else {
            let mut scalars = vec![0.0; element.properties.len()];
            let mut list = Vec::new();
            for i in 0..element.count {
                cursor.row(element, i, &mut scalars, None, &mut list)?;
            }
        }
    }
    let vertices = vertices.unwrap_or_default();
    check_finite(path, vertex_element, &plan, &vertices)?;
    let count = vertices.positions.len() as u64;
    if let Some((t, &bad)) = triangles
        .iter()
        .enumerate()
        .find_map(|(t, tri)| tri.iter().find(|&&v| u64::from(v) >= count).map(|v| (t, v)))
    {
        return Err(Error::IndexOutOfRange {
            path: path.to_path_buf(),
            what: "face triangle".into(),
            index: t as u64,
            vertex: i64::from(bad),
            count,
        });
    }
    Ok(Body {
        plan,
        vertices,
        triangles,
    })
}

/// Refuses the first vertex (lowest index, then file order) whose position, normal, colour or
/// texture coordinate is NaN or infinite, naming the property: any of them would poison every
/// bound, render and gradient downstream. Integer properties cannot hold one, so only columns
/// with a float property are scanned; properties without a role are kept as read.
fn check_finite(
    path: &Path,
    element: &Element,
    plan: &VertexPlan,
    data: &VertexData,
) -> Result<(), Error> {
    let mut columns: Vec<(&[f32], Vec<usize>)> = vec![(
        bytemuck::cast_slice(&data.positions),
        plan.position.to_vec(),
    )];
    if let (Some(v), Some(ix)) = (&data.normals, plan.normal) {
        columns.push((bytemuck::cast_slice(v), ix.to_vec()));
    }
    if let (Some(v), Some(ix)) = (&data.colors, plan.main) {
        columns.push((bytemuck::cast_slice(v), ix.to_vec()));
    }
    if !plan.cameras.is_empty() {
        columns.push((
            bytemuck::cast_slice(&data.camera_colors),
            plan.cameras.concat(),
        ));
    }
    if let (Some(v), Some(ix)) = (&data.uvs, plan.uv) {
        columns.push((bytemuck::cast_slice(v), ix.to_vec()));
    }
    let first = columns
        .iter()
        .filter(|(_, ix)| ix.iter().any(|&i| plan.types[i].is_float()))
        .filter_map(|(values, ix)| {
            let row = values
                .par_chunks_exact(ix.len())
                .position_first(|r| r.iter().any(|x| !x.is_finite()))?;
            let r = &values[row * ix.len()..(row + 1) * ix.len()];
            let c = r.iter().position(|x| !x.is_finite()).unwrap_or(0);
            Some((row, ix[c], r[c]))
        })
        .min_by_key(|&(row, property, _)| (row, property));
    let Some((row, property, mut value)) = first else {
        return Ok(());
    };
    if plan.uv.is_some_and(|uv| uv[1] == property) {
        // Undo the v flip of `store_row` so the value is the file's.
        value = 1.0 - value;
    }
    let mut value = value.to_string();
    if plan.types[property] == ScalarType::F64 && !value.contains("NaN") {
        value.push_str(" (infinite, or a double beyond the 32-bit float range)");
    }
    Err(Error::NonFinite {
        path: path.to_path_buf(),
        what: element.name.clone(),
        index: row as u64,
        property: element.properties[property].name.clone(),
        value,
    })
}

/// The bytes of the `element.count` fixed-size records starting at `pos`, or `Error::Truncated`.
fn records<'a>(
    path: &Path,
    bytes: &'a [u8],
    pos: usize,
    element: &Element,
    stride: usize,
) -> Result<&'a [u8], Error> {
    let needed = element.count.saturating_mul(stride as u64);
    let available = bytes.len().saturating_sub(pos) as u64;
    if needed > available {
        return Err(Error::Truncated {
            path: path.to_path_buf(),
            element: element.name.clone(),
            count: element.count,
            needed,
            available,
        });
    }
    Ok(&bytes[pos..pos + needed as usize])
}

/// The zero-copy fast path: every record has the same size, so records decode independently in parallel.
fn decode_fixed(
    plan: &VertexPlan,
    element: &Element,
    records: &[u8],
    stride: usize,
    big: bool,
    data: &mut VertexData,
) {
    let layout = FixedLayout::new(plan, element, big);
    let outs = data.split(CHUNK_POINTS, plan.cameras.len());
    outs.into_par_iter()
        .zip(records.par_chunks(CHUNK_POINTS * stride))
        .for_each(|(mut out, chunk)| {
            for (j, bytes) in chunk.chunks_exact(stride).enumerate() {
                store_row(
                    plan,
                    &mut out,
                    j,
                    &Record {
                        bytes,
                        layout: &layout,
                    },
                );
            }
        });
}

/// The general path for vertices: row by row (ASCII, or binary with list properties).
fn decode_rows(
    plan: &VertexPlan,
    element: &Element,
    cursor: &mut Cursor<'_>,
    data: &mut VertexData,
) -> Result<(), Error> {
    let n = data.positions.len();
    let mut outs = data.split(n.max(1), plan.cameras.len());
    let Some(out) = outs.first_mut() else {
        return Ok(());
    };
    let mut scalars = vec![0.0; element.properties.len()];
    let mut list = Vec::new();
    for j in 0..n {
        cursor.row(element, j as u64, &mut scalars, None, &mut list)?;
        store_row(plan, out, j, &scalars[..]);
    }
    Ok(())
}

/// Reads the face element's `vertex_indices` (or `vertex_index`) lists and fan-triangulates them.
fn read_faces(
    path: &Path,
    element: &Element,
    vertex_count: Option<u64>,
    cursor: &mut Cursor<'_>,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<(), Error> {
    let list_index = element
        .property_index("vertex_indices")
        .or_else(|| element.property_index("vertex_index"))
        .filter(|&i| matches!(element.properties[i].kind, PropertyKind::List { item, .. } if !item.is_float()))
        .ok_or_else(|| Error::Content {
            path: path.to_path_buf(),
            message: "the face element has no integer list property 'vertex_indices' or 'vertex_index'".into(),
        })?;
    let mut scalars = vec![0.0; element.properties.len()];
    let mut list = Vec::new();
    for f in 0..element.count {
        cursor.row(element, f, &mut scalars, Some(list_index), &mut list)?;
        if list.len() < 3 {
            return Err(cursor.error(
                element,
                f,
                format!(
                    "the face has {} vertex index(es); a polygon needs at least 3",
                    list.len()
                ),
            ));
        }
        if let Some(bad) = list.iter().find(|&&v| v < 0.0 || v > f64::from(u32::MAX)) {
            return Err(cursor.error(element, f, format!("vertex index {bad} is out of range")));
        }
        // With the vertices read first (as files write them), a face past them is named at its
        // line or bytes; otherwise the check after the body names the triangle.
        if let Some(count) = vertex_count
            && let Some(bad) = list.iter().find(|&&v| v >= count as f64)
        {
            return Err(cursor.error(
                element,
                f,
                format!("vertex index {bad}, but there are only {count} vertices"),
            ));
        }
        let v = |i: usize| list[i] as u32;
        for i in 1..list.len() - 1 {
            triangles.push([v(0), v(i), v(i + 1)]);
        }
    }
    Ok(())
}
