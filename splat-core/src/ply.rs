//! The Inria 3DGS PLY (`gaussian_model.py::save_ply/load_ply`): one `vertex` element with
//! `x y z [nx ny nz] f_dc_0..2 f_rest_* opacity scale_0..2 rot_0..3`.
//!
//! Reading accepts any property order (Brush and others write their own), `float` or `double`
//! (and integer types) for every property, binary little/big endian or ASCII, with or without
//! normals, and derives the SH degree from the number of `f_rest` (0/9/24/45), which are
//! channel-major: `f_rest_{c·K' + j}` is coefficient j + 1 of channel c, K' = (degree + 1)² − 1.
//! Writing produces exactly Inria's layout: binary little endian, all `float`, normals as zeros.
//!
//! How a model is drawn travels in a header comment: a model trained with the antialiased
//! (Mip-Splatting) opacity compensation is written with Brush's `comment SplatRenderMode: mip`,
//! which Brush, PlayCanvas (SuperSplat) and splat-transform read and keep; reading also accepts
//! Postshot's `antialiased 1` and `postshot.anti_aliasing=1`, case-insensitively, the last such
//! comment deciding ([`PlyModel::antialiased`]).

use std::io::Write;
use std::path::Path;

use glam::Vec3;

use ply_core::{Element, Header, PlyFormat, PropertyKind, ScalarType, parse_ascii, read_binary};

use crate::{Error, Splats, num_sh_coeffs};

/// Largest vertex count accepted (a header claiming more is refused before allocating).
pub const MAX_SPLATS: usize = 200_000_000;

fn header_err(path: &Path, line: usize, message: impl Into<String>) -> Error {
    Error::Header {
        path: path.to_path_buf(),
        line,
        message: message.into(),
    }
}

/// Parses the header with `ply-core`, naming `path` in the error.
fn parse_header(path: &Path, data: &[u8]) -> Result<Header, Error> {
    ply_core::parse_header(data).map_err(|e| header_err(path, e.line, e.problem.to_string()))
}

/// Column of each 3DGS attribute in the vertex element.
struct Columns {
    mean: [usize; 3],
    dc: [usize; 3],
    rest: Vec<usize>,
    opacity: usize,
    scale: [usize; 3],
    rot: [usize; 4],
}

impl Columns {
    /// Every column that becomes part of a splat, in file order.
    fn used(&self) -> Vec<usize> {
        let mut used: Vec<usize> = [
            &self.mean[..],
            &self.dc,
            &self.rest,
            &[self.opacity],
            &self.scale,
            &self.rot,
        ]
        .concat();
        used.sort_unstable();
        used
    }
}

/// The first attribute of a vertex whose value is not a finite f32 (NaN, ±inf, or a double
/// beyond the f32 range), as [`Error::NonFinite`]: one such value makes the splat, and every
/// pixel and gradient it touches, NaN.
fn check_finite(
    path: &Path,
    el: &Element,
    used: &[usize],
    index: usize,
    values: &[f64],
) -> Result<(), Error> {
    match used.iter().find(|&&c| !(values[c] as f32).is_finite()) {
        None => Ok(()),
        Some(&c) => Err(Error::NonFinite {
            path: path.to_path_buf(),
            index,
            property: el.properties[c].name.clone(),
            value: values[c],
        }),
    }
}

fn find_columns(path: &Path, el: &Element) -> Result<Columns, Error> {
    let mut names = Vec::with_capacity(el.properties.len());
    for p in &el.properties {
        match p.kind {
            PropertyKind::Scalar(_) => names.push(p.name.as_str()),
            PropertyKind::List { .. } => {
                return Err(header_err(
                    path,
                    0,
                    "the vertex element has a list property; 3DGS vertices hold scalars only",
                ));
            }
        }
    }
    // A cloud or a mesh given where a model is expected: say what it is rather than name the
    // first missing property.
    if ply_core::GAUSSIAN_SPLAT_PROPERTIES
        .iter()
        .all(|n| !names.contains(n))
    {
        return Err(header_err(
            path,
            0,
            format!(
                "not a 3D Gaussian Splatting model: its vertices have none of {} (a point cloud \
                 or a mesh, which is input for training, not a model)",
                ply_core::GAUSSIAN_SPLAT_PROPERTIES.join(", ")
            ),
        ));
    }
    let col = |n: &str| -> Result<usize, Error> {
        names
            .iter()
            .position(|&m| m == n)
            .ok_or_else(|| header_err(path, 0, format!("vertex property `{n}` is missing")))
    };
    let mut rest = Vec::new();
    while let Some(c) = names
        .iter()
        .position(|&m| m == format!("f_rest_{}", rest.len()))
    {
        rest.push(c);
    }
    let n_rest_props = names.iter().filter(|m| m.starts_with("f_rest_")).count();
    if n_rest_props != rest.len() {
        return Err(header_err(
            path,
            0,
            format!(
                "f_rest properties are not numbered 0..{} without gaps ({n_rest_props} present)",
                n_rest_props
            ),
        ));
    }
    Ok(Columns {
        mean: [col("x")?, col("y")?, col("z")?],
        dc: [col("f_dc_0")?, col("f_dc_1")?, col("f_dc_2")?],
        rest,
        opacity: col("opacity")?,
        scale: [col("scale_0")?, col("scale_1")?, col("scale_2")?],
        rot: [col("rot_0")?, col("rot_1")?, col("rot_2")?, col("rot_3")?],
    })
}

/// The header comment that marks a model trained antialiased: Brush's spelling, the one
/// splat-transform writes whichever form it read.
pub const ANTIALIASED_COMMENT: &str = "SplatRenderMode: mip";

/// A model read from a 3DGS PLY, with what its header says of how it is drawn.
#[derive(Clone, Debug, PartialEq)]
pub struct PlyModel {
    /// The splats.
    pub splats: Splats,
    /// The header says the model was trained with the antialiased opacity compensation
    /// (`SplatRenderMode: mip`, or Postshot's comments), so it is drawn with it.
    pub antialiased: bool,
}

/// How a model is written.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PlyOptions {
    /// Writes [`ANTIALIASED_COMMENT`] into the header.
    pub antialiased: bool,
}

/// Whether a header's comments say the model is drawn antialiased: the last comment that names
/// a render mode decides (as splat-transform reads them); none: not antialiased.
fn antialiased_from_comments<'a>(comments: impl Iterator<Item = &'a str>) -> bool {
    let mut antialiased = false;
    for c in comments {
        let c = c.trim().to_ascii_lowercase();
        let said = if let Some(mode) = c.strip_prefix("splatrendermode:") {
            Some(mode.trim() == "mip")
        } else if let Some(flag) = c.strip_prefix("antialiased ") {
            Some(flag.trim() == "1")
        } else {
            c.strip_prefix("postshot.anti_aliasing=")
                .map(|flag| flag.trim() == "1")
        };
        if let Some(said) = said {
            antialiased = said;
        }
    }
    antialiased
}

/// Reads a 3DGS PLY file's splats (see [`read_model`] for how they are drawn).
pub fn read_splats(path: &Path) -> Result<Splats, Error> {
    read_model(path).map(|m| m.splats)
}

/// Reads a 3DGS PLY file: its splats and how its header says they are drawn.
pub fn read_model(path: &Path) -> Result<PlyModel, Error> {
    let data = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_model(path, &data)
}

/// Parses the bytes of a 3DGS PLY file's splats; `path` is used in error messages.
pub fn parse_splats(path: &Path, data: &[u8]) -> Result<Splats, Error> {
    parse_model(path, data).map(|m| m.splats)
}

/// Parses the bytes of a 3DGS PLY file: its splats and how its header says they are drawn;
/// `path` is used in error messages.
pub fn parse_model(path: &Path, data: &[u8]) -> Result<PlyModel, Error> {
    let header = parse_header(path, data)?;
    let antialiased = antialiased_from_comments(header.comments.iter().map(|(_, c)| c.as_str()));
    let (vi, el) = header
        .element("vertex")
        .ok_or_else(|| header_err(path, 0, "no `vertex` element"))?;
    let columns = find_columns(path, el)?;
    let degree = sh_degree(path, columns.rest.len())?;
    let n = vertex_count(path, el)?;
    let vertices = Vertices {
        path,
        data,
        header: &header,
        index: vi,
        count: n,
    };
    let mut builder = SplatBuilder::new(path, el, columns, degree);
    match header.format {
        PlyFormat::Ascii => vertices.read_ascii(&mut builder)?,
        PlyFormat::BinaryLittleEndian | PlyFormat::BinaryBigEndian => {
            vertices.read_binary(&mut builder)?;
        }
    }
    Ok(PlyModel {
        splats: builder.splats,
        antialiased,
    })
}

/// The SH degree that `rest` `f_rest` properties make.
fn sh_degree(path: &Path, rest: usize) -> Result<u32, Error> {
    match rest {
        0 => Ok(0),
        9 => Ok(1),
        24 => Ok(2),
        45 => Ok(3),
        n => Err(header_err(
            path,
            0,
            format!("{n} f_rest properties; 3DGS degree 0–3 has 0, 9, 24 or 45"),
        )),
    }
}

/// The vertex count the header claims, refused above [`MAX_SPLATS`] before anything is
/// allocated for it.
fn vertex_count(path: &Path, el: &Element) -> Result<usize, Error> {
    match usize::try_from(el.count) {
        Ok(n) if n <= MAX_SPLATS => Ok(n),
        _ => Err(header_err(
            path,
            0,
            format!(
                "{} vertices claimed (at most {MAX_SPLATS} are accepted)",
                el.count
            ),
        )),
    }
}

/// Splats made from vertex rows (each row's values as f64, one per property, file order).
struct SplatBuilder<'a> {
    path: &'a Path,
    el: &'a Element,
    columns: Columns,
    /// The columns that become part of a splat, for the finiteness check.
    used: Vec<usize>,
    splats: Splats,
    /// One splat's SH coefficients, reused.
    sh: Vec<[f32; 3]>,
}

impl<'a> SplatBuilder<'a> {
    fn new(path: &'a Path, el: &'a Element, columns: Columns, degree: u32) -> Self {
        Self {
            path,
            el,
            used: columns.used(),
            columns,
            splats: Splats::new(degree),
            sh: vec![[0.0_f32; 3]; num_sh_coeffs(degree)],
        }
    }

    /// Room for `n` splats' means (once the body is known to hold them).
    fn reserve(&mut self, n: usize) {
        self.splats.means.reserve(n);
    }

    /// Vertex `index`'s row as a splat, refused if a value it uses is not a finite f32.
    fn add(&mut self, index: usize, v: &[f64]) -> Result<(), Error> {
        check_finite(self.path, self.el, &self.used, index, v)?;
        let cols = &self.columns;
        let f = |c: usize| v[c] as f32;
        let kp = self.sh.len() - 1;
        self.sh[0] = cols.dc.map(f);
        for j in 0..kp {
            for (ch, coef) in (0..3).map(|ch| (ch, f(cols.rest[ch * kp + j]))) {
                self.sh[j + 1][ch] = coef;
            }
        }
        self.splats.push(
            Vec3::new(f(cols.mean[0]), f(cols.mean[1]), f(cols.mean[2])),
            Vec3::new(f(cols.scale[0]), f(cols.scale[1]), f(cols.scale[2])),
            cols.rot.map(f),
            f(cols.opacity),
            &self.sh,
        );
        Ok(())
    }
}

/// The vertex element's rows in a file's body.
struct Vertices<'a> {
    path: &'a Path,
    /// The whole file.
    data: &'a [u8],
    header: &'a Header,
    /// Index of the vertex element among the header's elements.
    index: usize,
    /// Vertices claimed (at most [`MAX_SPLATS`]).
    count: usize,
}

impl Vertices<'_> {
    fn element(&self) -> &Element {
        &self.header.elements[self.index]
    }

    /// Each property's value type (`find_columns` refused list properties).
    fn types(&self) -> Vec<ScalarType> {
        self.element()
            .properties
            .iter()
            .map(|p| match p.kind {
                PropertyKind::Scalar(ty) | PropertyKind::List { item: ty, .. } => ty,
            })
            .collect()
    }

    fn body(&self) -> &[u8] {
        &self.data[self.header.body_offset..]
    }

    /// An error at byte `offset` of the file, item `index`.
    fn body_err(&self, offset: usize, index: usize, message: String) -> Error {
        Error::Body {
            path: self.path.to_path_buf(),
            offset: offset as u64,
            index,
            message,
        }
    }

    /// The rows of an ASCII body: one line an item, the elements before the vertices skipped.
    fn read_ascii(&self, builder: &mut SplatBuilder<'_>) -> Result<(), Error> {
        let (n, el, types) = (self.count, self.element(), self.types());
        let text = std::str::from_utf8(self.body()).map_err(|e| {
            self.body_err(
                self.header.body_offset + e.valid_up_to(),
                0,
                "ASCII body is not text".into(),
            )
        })?;
        let mut lines = text.lines().filter(|l| !l.trim().is_empty());
        // Skip elements before the vertex element (one line per item); stop at the end of
        // the text, or a huge claimed count would spin for ever.
        for (ei, e) in self.header.elements[..self.index].iter().enumerate() {
            for _ in 0..e.count {
                if lines.next().is_none() {
                    return Err(self.body_err(
                        self.data.len(),
                        ei,
                        format!("element `{}` runs past the end of the file", e.name),
                    ));
                }
            }
        }
        let mut values = vec![0.0_f64; types.len()];
        for i in 0..n {
            let line = lines.next().ok_or_else(|| {
                self.body_err(
                    self.data.len(),
                    i,
                    format!("file ends after {i} of {n} vertices"),
                )
            })?;
            let mut it = line.split_whitespace();
            for (c, (slot, &ty)) in values.iter_mut().zip(&types).enumerate() {
                *slot = it.next().and_then(|w| parse_ascii(w, ty)).ok_or_else(|| {
                    // The line's own offset in the file (it is a slice of the file's bytes).
                    let at = line.as_ptr() as usize - self.data.as_ptr() as usize;
                    self.body_err(
                        at,
                        i,
                        format!(
                            "property {c} (`{}`) is missing or not a valid {}",
                            el.properties[c].name,
                            ty.name()
                        ),
                    )
                })?;
            }
            builder.add(i, &values)?;
        }
        Ok(())
    }

    /// The rows of a binary body: fixed-size records after the elements before them, the
    /// body's length checked against the claimed count before any is read.
    fn read_binary(&self, builder: &mut SplatBuilder<'_>) -> Result<(), Error> {
        let (n, types, body) = (self.count, self.types(), self.body());
        let big = self.header.format == PlyFormat::BinaryBigEndian;
        let mut off = 0;
        for (ei, e) in self.header.elements[..self.index].iter().enumerate() {
            off = skip_element(body, off, e, big)
                .map_err(|m| self.body_err(self.header.body_offset + off, ei, m))?;
        }
        let mut layout = Vec::with_capacity(types.len());
        let mut stride = 0;
        for &ty in &types {
            layout.push((stride, ty));
            stride += ty.size();
        }
        let need = n.checked_mul(stride).and_then(|b| b.checked_add(off));
        if need.is_none_or(|need| need > body.len()) {
            // Named by the first vertex the file cuts, at the offset where it starts.
            let whole = (body.len().saturating_sub(off)) / stride.max(1);
            return Err(self.body_err(
                self.header.body_offset + off + whole * stride,
                whole,
                format!(
                    "{n} vertices of {stride} bytes need {} bytes but the body after this \
                     offset has {}",
                    n.saturating_mul(stride),
                    body.len().saturating_sub(off)
                ),
            ));
        }
        builder.reserve(n);
        let mut values = vec![0.0_f64; types.len()];
        for i in 0..n {
            let rec = &body[off + i * stride..off + (i + 1) * stride];
            for (slot, &(o, ty)) in values.iter_mut().zip(&layout) {
                *slot = read_binary(&rec[o..], ty, big);
            }
            builder.add(i, &values)?;
        }
        Ok(())
    }
}

/// Skips one element's items in a binary body, returning the offset after it.
fn skip_element(body: &[u8], mut off: usize, e: &Element, big: bool) -> Result<usize, String> {
    let past_end = || format!("element `{}` runs past the end of the file", e.name);
    if let Some(stride) = e.fixed_stride() {
        return usize::try_from(e.count)
            .ok()
            .and_then(|count| count.checked_mul(stride))
            .and_then(|b| b.checked_add(off))
            .filter(|&end| end <= body.len())
            .ok_or_else(past_end);
    }
    for _ in 0..e.count {
        for p in &e.properties {
            let (size, n) = match p.kind {
                PropertyKind::Scalar(ty) => (ty.size(), 1),
                PropertyKind::List { count, item } => {
                    if off + count.size() > body.len() {
                        return Err(past_end());
                    }
                    let n = read_binary(&body[off..], count, big);
                    off += count.size();
                    (item.size(), n.max(0.0) as usize)
                }
            };
            off = n
                .checked_mul(size)
                .and_then(|b| b.checked_add(off))
                .filter(|&end| end <= body.len())
                .ok_or_else(past_end)?;
        }
    }
    Ok(off)
}

/// Returns the Inria property names in file order for SH degree `degree`.
#[must_use]
pub fn inria_property_names(degree: u32) -> Vec<String> {
    let mut names: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| (*s).to_string())
    .collect();
    names.extend((0..3 * (num_sh_coeffs(degree) - 1)).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    names
}

/// Writes `splats` as an Inria 3DGS PLY, atomically (a temporary file in the same directory,
/// renamed over `path` once complete).
pub fn write_splats(path: &Path, splats: &Splats) -> Result<(), Error> {
    write_model(path, splats, &PlyOptions::default())
}

/// Writes `splats` as an Inria 3DGS PLY with the header `options` ask for, atomically.
pub fn write_model(path: &Path, splats: &Splats, options: &PlyOptions) -> Result<(), Error> {
    splats.validate()?;
    atomic_output::write_atomic_with(path, |w| {
        let names = inria_property_names(splats.sh_degree);
        let mut head = String::from("ply\nformat binary_little_endian 1.0\n");
        if options.antialiased {
            head.push_str("comment ");
            head.push_str(ANTIALIASED_COMMENT);
            head.push('\n');
        }
        head.push_str(&format!("element vertex {}\n", splats.len()));
        for n in &names {
            head.push_str("property float ");
            head.push_str(n);
            head.push('\n');
        }
        head.push_str("end_header\n");
        w.write_all(head.as_bytes())?;
        let k = splats.coeffs_per_splat();
        let mut rec: Vec<f32> = Vec::with_capacity(names.len());
        for i in 0..splats.len() {
            rec.clear();
            rec.extend(splats.means[i].to_array());
            rec.extend([0.0; 3]);
            let sh = splats.sh_of(i);
            rec.extend(sh[0]);
            for ch in 0..3 {
                rec.extend(sh[1..k].iter().map(|c| c[ch]));
            }
            rec.push(splats.opacity_logits[i]);
            rec.extend(splats.log_scales[i].to_array());
            rec.extend(splats.rotations[i]);
            for v in &rec {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        Ok(())
    })
    .map_err(|e| Error::io(path, e))
}
