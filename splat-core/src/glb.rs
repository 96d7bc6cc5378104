//! Splats as binary glTF (`.glb`) with the `KHR_gaussian_splatting` extension (Khronos, review
//! draft): one point primitive whose attributes are the splats' position, linear scale, unit
//! rotation (x, y, z, w), opacity and SH coefficients, so any glTF tool can carry the model and a
//! viewer without splat support still shows it as coloured points (`COLOR_0`).
//!
//! Values are stored as `float`, without quantisation, in glTF's y-up frame (the half turn of
//! [`crate::frame`]); the attributes follow the extension's table: `POSITION`, `COLOR_0` (the
//! diffuse colour clamped to [0, 1] and the opacity, as normalised bytes, for the fallback),
//! `KHR_gaussian_splatting:SCALE` (linear, the exponential of Inria's log-scale), `:ROTATION`,
//! `:OPACITY` (activated, in [0, 1]), `:SH_DEGREE_0_COEF_0` and `:SH_DEGREE_ℓ_COEF_n` for every
//! band up to the model's degree.
//!
//! Written and read by hand: the `gltf` crate (1.4) does not build files; its document reader
//! refuses attribute names outside core glTF (such as `KHR_gaussian_splatting:SCALE`), and its
//! container reader `Glb::from_slice` subtracts 12 from the header's length unchecked, which
//! overflows on a lying header. The container is small (a 12-byte header, a JSON chunk and a
//! binary chunk, each 4-byte aligned), and reading it here checks every length before use.

use std::path::Path;

use serde_json::{Value, json};

use crate::frame::y_up_frame;
use crate::ply::MAX_SPLATS;
use crate::{Error, Splats, logit, sh_dc_to_rgb};

/// The extension's name, also the prefix of its attribute semantics.
pub const EXTENSION: &str = "KHR_gaussian_splatting";

/// glTF component type `FLOAT`.
const FLOAT: u32 = 5126;
/// glTF component type `UNSIGNED_BYTE`.
const UNSIGNED_BYTE: u32 = 5121;
/// glTF buffer-view target `ARRAY_BUFFER` (vertex attributes).
const ARRAY_BUFFER: u32 = 34962;
/// glTF primitive mode `POINTS`.
const POINTS: u32 = 0;
/// `glTF` read as a little-endian u32.
const GLB_MAGIC: u32 = 0x4654_6c67;
/// Chunk types `JSON` and `BIN\0`.
const CHUNK_JSON: u32 = 0x4e4f_534a;
const CHUNK_BIN: u32 = 0x004e_4942;

/// One attribute: its semantic, accessor type, component type and bytes.
struct Attribute {
    semantic: String,
    kind: &'static str,
    component: u32,
    normalized: bool,
    bytes: Vec<u8>,
    /// Per-component minimum and maximum (required for `POSITION`).
    bounds: Option<([f32; 3], [f32; 3])>,
}

fn floats(values: impl IntoIterator<Item = f32>) -> Vec<u8> {
    values.into_iter().flat_map(f32::to_le_bytes).collect()
}

/// Returns the attributes of `splats` (already in glTF's frame).
fn attributes(s: &Splats) -> Vec<Attribute> {
    let n = s.len();
    let float = |semantic: &str, kind: &'static str, bytes: Vec<u8>| Attribute {
        semantic: semantic.to_string(),
        kind,
        component: FLOAT,
        normalized: false,
        bytes,
        bounds: None,
    };
    let ext = |name: &str| format!("{EXTENSION}:{name}");
    let mut lo = [f32::INFINITY; 3];
    let mut hi = [f32::NEG_INFINITY; 3];
    for m in &s.means {
        for a in 0..3 {
            lo[a] = lo[a].min(m[a]);
            hi[a] = hi[a].max(m[a]);
        }
    }
    let mut out = vec![Attribute {
        bounds: Some((lo, hi)),
        ..float(
            "POSITION",
            "VEC3",
            floats(s.means.iter().flat_map(|m| m.to_array())),
        )
    }];
    let k = s.coeffs_per_splat();
    out.push(Attribute {
        semantic: "COLOR_0".into(),
        kind: "VEC4",
        component: UNSIGNED_BYTE,
        normalized: true,
        bytes: (0..n)
            .flat_map(|i| {
                let rgb = sh_dc_to_rgb(s.sh[i * k]);
                let a = s.opacity(i);
                [rgb[0], rgb[1], rgb[2], a].map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            })
            .collect(),
        bounds: None,
    });
    out.push(float(
        &ext("SCALE"),
        "VEC3",
        floats((0..n).flat_map(|i| s.scale(i).to_array())),
    ));
    out.push(float(
        &ext("ROTATION"),
        "VEC4",
        floats((0..n).flat_map(|i| s.rotation(i).to_array())),
    ));
    out.push(float(
        &ext("OPACITY"),
        "SCALAR",
        floats((0..n).map(|i| s.opacity(i))),
    ));
    for degree in 0..=s.sh_degree as usize {
        for coef in 0..2 * degree + 1 {
            let j = degree * degree + coef;
            out.push(float(
                &ext(&format!("SH_DEGREE_{degree}_COEF_{coef}")),
                "VEC3",
                floats((0..n).flat_map(|i| s.sh[i * k + j])),
            ));
        }
    }
    out
}

/// Returns the `.glb` bytes of `splats`.
pub fn encode_glb(splats: &Splats) -> Result<Vec<u8>, Error> {
    splats.validate()?;
    if let Some(i) = (0..splats.len()).find(|&i| {
        !(splats.means[i].is_finite()
            && splats.log_scales[i].is_finite()
            && splats.opacity_logits[i].is_finite()
            && splats.rotations[i].iter().all(|v| v.is_finite())
            && splats.sh_of(i).iter().flatten().all(|v| v.is_finite()))
    }) {
        return Err(Error::Inconsistent(format!(
            "splat {i} has a non-finite value, which glTF does not allow"
        )));
    }
    // (After the finiteness check, so a NaN is named as one; an empty model is refused here.)
    if let Some(problem) = crate::export::linear_scale_problem(splats, ".glb") {
        return Err(Error::Inconsistent(problem));
    }
    let s = y_up_frame(splats);
    let n = s.len();
    let mut bin = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut attribute_map = serde_json::Map::new();
    for (index, a) in attributes(&s).into_iter().enumerate() {
        // Every view starts 4-byte aligned, as glTF requires of float data.
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        views.push(json!({
            "buffer": 0,
            "byteOffset": bin.len(),
            "byteLength": a.bytes.len(),
            "target": ARRAY_BUFFER,
        }));
        bin.extend_from_slice(&a.bytes);
        let mut acc = json!({
            "bufferView": index,
            "componentType": a.component,
            "count": n,
            "type": a.kind,
        });
        if a.normalized {
            acc["normalized"] = Value::Bool(true);
        }
        if let Some((lo, hi)) = a.bounds {
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        accessors.push(acc);
        attribute_map.insert(a.semantic, json!(index));
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let doc = json!({
        "asset": { "version": "2.0", "generator": concat!("splat-core ", env!("CARGO_PKG_VERSION")) },
        "extensionsUsed": [EXTENSION],
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{
            "attributes": attribute_map,
            "mode": POINTS,
            "extensions": { EXTENSION: {
                "kernel": "ellipse",
                "colorSpace": "srgb_rec709_display",
                "sortingMethod": "cameraDistance",
                "projection": "perspective",
            } },
        }] }],
        "buffers": [{ "byteLength": bin.len() }],
        "bufferViews": views,
        "accessors": accessors,
    });
    let mut text = serde_json::to_vec(&doc).map_err(|e| Error::Inconsistent(e.to_string()))?;
    // The JSON chunk is padded with spaces to a multiple of 4 bytes.
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let total = u32::try_from(total).map_err(|_| {
        Error::Inconsistent(format!(
            "{total} bytes exceed the 4 GiB a .glb file can hold"
        ))
    })?;
    let mut out = Vec::with_capacity(total as usize);
    for word in [GLB_MAGIC, 2, total, text.len() as u32, CHUNK_JSON] {
        out.extend(word.to_le_bytes());
    }
    out.extend(text);
    for word in [bin.len() as u32, CHUNK_BIN] {
        out.extend(word.to_le_bytes());
    }
    out.extend(bin);
    Ok(out)
}

/// Writes `splats` as a `.glb` file with `KHR_gaussian_splatting`, atomically.
pub fn write_glb(path: &Path, splats: &Splats) -> Result<(), Error> {
    // The encoder's refusals name no file: this one names it.
    let bytes = encode_glb(splats).map_err(|e| match e {
        Error::Inconsistent(message) => Error::Unwritable {
            path: path.to_path_buf(),
            message,
        },
        other => other,
    })?;
    atomic_output::write_atomic(path, &bytes).map_err(|e| Error::io(path, e))
}

/// Reads a `.glb` file with a `KHR_gaussian_splatting` point primitive (see [`decode_glb`]).
pub fn read_glb(path: &Path) -> Result<Splats, Error> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode_glb(path, &data)
}

/// Decodes the bytes of a `.glb` file into splats in this crate's frame; `path` is used in error
/// messages.
///
/// Reads what [`encode_glb`] writes: the one primitive carrying `KHR_gaussian_splatting`, mode
/// `POINTS`, its attributes as `float` accessors in the GLB's binary chunk (any byte stride), the
/// SH degree given by the `SH_DEGREE_ℓ_COEF_n` attributes present. Quantised or sparse accessors,
/// external buffers and node transforms are refused with an error rather than misread. Every
/// length and index is checked against the file before anything is allocated.
pub fn decode_glb(path: &Path, data: &[u8]) -> Result<Splats, Error> {
    let err = |place: &str, message: String| Error::Glb {
        path: path.to_path_buf(),
        place: place.to_string(),
        message,
    };
    let Container { json, bin } = split_container(data).map_err(|(place, m)| err(place, m))?;
    let doc: Value = serde_json::from_slice(json)
        .map_err(|e| err("JSON chunk", format!("not a JSON document: {e}")))?;
    let doc = Document {
        path,
        doc: &doc,
        bin,
    };
    let prim = doc.splat_primitive()?;
    let attrs = prim["attributes"]
        .as_object()
        .ok_or_else(|| err("primitive", "no `attributes` object".into()))?;
    let n = doc.count_of(attrs, "POSITION")?;
    let read = |name: &str, kind: &str, width: usize| doc.floats(attrs, name, kind, width, n);
    let ext = |name: &str| format!("{EXTENSION}:{name}");
    let pos = read("POSITION", "VEC3", 3)?;
    let scale = read(&ext("SCALE"), "VEC3", 3)?;
    let rot = read(&ext("ROTATION"), "VEC4", 4)?;
    let opacity = read(&ext("OPACITY"), "SCALAR", 1)?;
    let degree = sh_degree(attrs).map_err(|m| err("primitive attributes", m))?;
    let mut bands = Vec::new();
    for d in 0..=degree as usize {
        for coef in 0..2 * d + 1 {
            bands.push(read(
                &ext(&format!("SH_DEGREE_{d}_COEF_{coef}")),
                "VEC3",
                3,
            )?);
        }
    }
    if let Some(i) = (0..3 * n).find(|&i| scale[i] <= 0.0) {
        return Err(err(
            &ext("SCALE"),
            format!(
                "splat {}: scale {}; scales must be positive",
                i / 3,
                scale[i]
            ),
        ));
    }
    if let Some(i) = (0..n).find(|&i| !(0.0..=1.0).contains(&opacity[i])) {
        return Err(err(
            &ext("OPACITY"),
            format!("splat {i}: opacity {}; opacities lie in [0, 1]", opacity[i]),
        ));
    }
    let v3 = |a: &[f32], i: usize| glam::Vec3::new(a[3 * i], a[3 * i + 1], a[3 * i + 2]);
    let mut s = Splats::new(degree);
    let mut sh = vec![[0.0_f32; 3]; bands.len()];
    for i in 0..n {
        for (c, band) in sh.iter_mut().zip(&bands) {
            *c = [band[3 * i], band[3 * i + 1], band[3 * i + 2]];
        }
        let [x, y, z, w] = [rot[4 * i], rot[4 * i + 1], rot[4 * i + 2], rot[4 * i + 3]];
        s.push(
            v3(&pos, i),
            v3(&scale, i).map(f32::ln),
            [w, x, y, z],
            logit(opacity[i]),
            &sh,
        );
    }
    // The half turn about x is its own inverse.
    Ok(y_up_frame(&s))
}

/// The chunks of a GLB container.
struct Container<'a> {
    json: &'a [u8],
    bin: Option<&'a [u8]>,
}

/// A problem with a GLB container: where (the header or a chunk) and what.
type ContainerError = (&'static str, String);

/// Splits a GLB container into its JSON chunk and its binary chunk (if any), checking the
/// header and every chunk length against the bytes present. Errors name the place and problem.
fn split_container(data: &[u8]) -> Result<Container<'_>, ContainerError> {
    let word = |o: usize| u32::from_le_bytes([data[o], data[o + 1], data[o + 2], data[o + 3]]);
    if data.len() < 12 {
        return Err((
            "header",
            format!("{} bytes, shorter than the 12-byte GLB header", data.len()),
        ));
    }
    if word(0) != GLB_MAGIC {
        return Err((
            "header",
            format!(
                "magic {:?}, expected \"glTF\" (not a binary glTF file)",
                String::from_utf8_lossy(&data[..4])
            ),
        ));
    }
    if word(4) != 2 {
        return Err((
            "header",
            format!("container version {}; only version 2 is read", word(4)),
        ));
    }
    let total = word(8) as usize;
    if total > data.len() || total < 12 {
        return Err((
            "header",
            format!(
                "declares {total} bytes, the file has {} (cut short or not a GLB)",
                data.len()
            ),
        ));
    }
    let data = &data[..total];
    // Returns the chunk at `pos`: its type, its bytes and where the next one starts.
    let chunk = |pos: usize, name: &'static str| {
        if pos + 8 > total {
            return Err((
                name,
                format!("its 8-byte header at byte {pos} is past the end ({total} bytes)"),
            ));
        }
        let (len, ty) = (word(pos) as usize, word(pos + 4));
        let end = (pos + 8).saturating_add(len);
        if end > total {
            return Err((
                name,
                format!(
                    "declares {len} bytes at byte {}, only {} remain: cut short",
                    pos + 8,
                    total - pos - 8
                ),
            ));
        }
        Ok((ty, &data[pos + 8..end], end))
    };
    let (ty, json, mut pos) = chunk(12, "JSON chunk")?;
    if ty != CHUNK_JSON {
        return Err((
            "JSON chunk",
            format!("the first chunk has type {ty:#010x}, expected JSON"),
        ));
    }
    // The binary chunk, when present, comes second; chunks of other types are skipped (glTF 2.0
    // §4.4.3.1).
    let mut bin = None;
    while pos < total {
        let (ty, bytes, next) = chunk(pos, "chunk after JSON")?;
        if ty == CHUNK_BIN && bin.is_none() {
            bin = Some(bytes);
        }
        pos = next;
    }
    Ok(Container { json, bin })
}

/// Returns the SH degree whose attributes are all present (0 to 3), or why they are not whole.
fn sh_degree(attrs: &serde_json::Map<String, Value>) -> Result<u32, String> {
    let has =
        |d: usize, c: usize| attrs.contains_key(&format!("{EXTENSION}:SH_DEGREE_{d}_COEF_{c}"));
    let mut degree = 0;
    for d in 1..=4 {
        if !has(d, 0) {
            break;
        }
        if d == 4 {
            return Err("SH degree 4 attributes; at most degree 3 is read".into());
        }
        degree = d as u32;
    }
    for d in 0..=4 {
        for c in 0..2 * d + 1 {
            let want = d <= degree as usize;
            if has(d, c) != want {
                return Err(if want {
                    format!("SH degree {degree} lacks {EXTENSION}:SH_DEGREE_{d}_COEF_{c}")
                } else {
                    format!(
                        "{EXTENSION}:SH_DEGREE_{d}_COEF_{c} without all the bands below it \
                         (the model's degree is {degree})"
                    )
                });
            }
        }
    }
    Ok(degree)
}

/// A parsed glTF document and its binary chunk, with the file for errors.
struct Document<'a> {
    path: &'a Path,
    doc: &'a Value,
    bin: Option<&'a [u8]>,
}

impl Document<'_> {
    fn err(&self, place: impl Into<String>, message: String) -> Error {
        Error::Glb {
            path: self.path.to_path_buf(),
            place: place.into(),
            message,
        }
    }

    /// Returns a non-negative integer field of `obj` (`None` when absent).
    fn uint(&self, obj: &Value, key: &str, place: &str) -> Result<Option<u64>, Error> {
        match obj.get(key) {
            None => Ok(None),
            Some(v) => v.as_u64().map(Some).ok_or_else(|| {
                self.err(
                    place,
                    format!("`{key}` is {v}, expected a non-negative integer"),
                )
            }),
        }
    }

    /// Returns the one mesh primitive with `KHR_gaussian_splatting`, after checking that it is
    /// a point primitive and that no node moves it.
    fn splat_primitive(&self) -> Result<&Value, Error> {
        let mut found = Vec::new();
        for (m, mesh) in self.doc["meshes"]
            .as_array()
            .into_iter()
            .flatten()
            .enumerate()
        {
            for (p, prim) in mesh["primitives"]
                .as_array()
                .into_iter()
                .flatten()
                .enumerate()
            {
                if prim["extensions"].get(EXTENSION).is_some() {
                    found.push((m, p, prim));
                }
            }
        }
        let (m, p, prim) = match found.as_slice() {
            [one] => *one,
            [] => {
                return Err(self.err(
                    "meshes",
                    format!("no primitive with the {EXTENSION} extension"),
                ));
            }
            many => {
                return Err(self.err(
                    "meshes",
                    format!(
                        "{} primitives with {EXTENSION}; this reader reads files with one",
                        many.len()
                    ),
                ));
            }
        };
        let place = format!("mesh {m} primitive {p}");
        let mode = self.uint(prim, "mode", &place)?.unwrap_or(4);
        if mode != u64::from(POINTS) {
            return Err(self.err(place, format!("mode {mode}; splats are POINTS (0)")));
        }
        for (k, node) in self.doc["nodes"]
            .as_array()
            .into_iter()
            .flatten()
            .enumerate()
        {
            if let Some(t) = ["matrix", "translation", "rotation", "scale"]
                .into_iter()
                .find(|t| node.get(t).is_some())
            {
                return Err(self.err(
                    format!("node {k}"),
                    format!("has a `{t}`; this reader does not apply node transforms"),
                ));
            }
        }
        Ok(prim)
    }

    /// Returns the accessor of `semantic` with its index and place name.
    fn accessor(
        &self,
        attrs: &serde_json::Map<String, Value>,
        semantic: &str,
    ) -> Result<(&Value, String), Error> {
        let index = attrs
            .get(semantic)
            .ok_or_else(|| self.err("primitive attributes", format!("no {semantic}")))?;
        let index = index.as_u64().ok_or_else(|| {
            self.err(
                "primitive attributes",
                format!("{semantic} is {index}, not an accessor index"),
            )
        })?;
        let place = format!("accessor {index} ({semantic})");
        let acc = usize::try_from(index)
            .ok()
            .and_then(|i| self.doc["accessors"].get(i))
            .filter(|a| a.is_object())
            .ok_or_else(|| self.err(&place, "does not exist".into()))?;
        Ok((acc, place))
    }

    /// Returns the element count of `semantic`'s accessor, within [`MAX_SPLATS`].
    fn count_of(
        &self,
        attrs: &serde_json::Map<String, Value>,
        semantic: &str,
    ) -> Result<usize, Error> {
        let (acc, place) = self.accessor(attrs, semantic)?;
        let count = self
            .uint(acc, "count", &place)?
            .ok_or_else(|| self.err(&place, "no `count`".into()))?;
        match usize::try_from(count) {
            Ok(n) if (1..=MAX_SPLATS).contains(&n) => Ok(n),
            _ => Err(self.err(
                &place,
                format!("count {count}; between 1 and {MAX_SPLATS} splats are read"),
            )),
        }
    }

    /// Returns the `n` × `width` floats of `semantic`'s accessor, which must be a `float`
    /// accessor of type `kind` with `n` elements lying inside the binary chunk.
    fn floats(
        &self,
        attrs: &serde_json::Map<String, Value>,
        semantic: &str,
        kind: &str,
        width: usize,
        n: usize,
    ) -> Result<Vec<f32>, Error> {
        let (acc, place) = self.accessor(attrs, semantic)?;
        let fail = |m: String| self.err(&place, m);
        let component = self.uint(acc, "componentType", &place)?;
        if component != Some(u64::from(FLOAT)) {
            return Err(fail(format!(
                "component type {component:?}; only FLOAT ({FLOAT}) accessors are read"
            )));
        }
        if acc["type"] != kind {
            return Err(fail(format!("type {}, expected {kind}", acc["type"])));
        }
        let count = self.uint(acc, "count", &place)?;
        if count != Some(n as u64) {
            return Err(fail(format!(
                "count {count:?} does not match POSITION's {n}"
            )));
        }
        if acc.get("sparse").is_some() {
            return Err(fail("sparse accessors are not read".into()));
        }
        let view_index = self.uint(acc, "bufferView", &place)?.ok_or_else(|| {
            fail("no bufferView (an all-zero accessor is not a splat attribute)".into())
        })?;
        let view = usize::try_from(view_index)
            .ok()
            .and_then(|i| self.doc["bufferViews"].get(i))
            .filter(|v| v.is_object())
            .ok_or_else(|| fail(format!("bufferView {view_index} does not exist")))?;
        let view_place = format!("bufferView {view_index}");
        let buffer = self.uint(view, "buffer", &view_place)?.unwrap_or(u64::MAX);
        let external = self.doc["buffers"]
            .get(0)
            .and_then(|b| b.get("uri"))
            .is_some();
        if buffer != 0 || external {
            return Err(fail(format!(
                "{view_place} is not in the GLB's binary chunk (buffer 0 without a uri)"
            )));
        }
        let bin = self
            .bin
            .ok_or_else(|| fail("the file has no binary chunk".into()))?;
        let view_offset = self.uint(view, "byteOffset", &view_place)?.unwrap_or(0);
        let view_length = self
            .uint(view, "byteLength", &view_place)?
            .ok_or_else(|| self.err(&view_place, "no byteLength".into()))?;
        if view_offset.saturating_add(view_length) > bin.len() as u64 {
            return Err(self.err(
                &view_place,
                format!(
                    "bytes {view_offset}..{} lie outside the {}-byte binary chunk",
                    view_offset.saturating_add(view_length),
                    bin.len()
                ),
            ));
        }
        let elem = 4 * width as u64;
        let stride = self.uint(view, "byteStride", &view_place)?.unwrap_or(elem);
        if stride < elem {
            return Err(self.err(
                &view_place,
                format!("byte stride {stride} is smaller than a {kind} of floats ({elem} bytes)"),
            ));
        }
        let offset = self.uint(acc, "byteOffset", &place)?.unwrap_or(0);
        // Offsets and strides come from the file, so the arithmetic is checked (n ≥ 1).
        let needed = (n as u64 - 1)
            .checked_mul(stride)
            .and_then(|b| b.checked_add(offset))
            .and_then(|b| b.checked_add(elem))
            .unwrap_or(u64::MAX);
        if needed > view_length {
            return Err(fail(format!(
                "{n} elements need {needed} bytes of {view_place}, which has {view_length}"
            )));
        }
        // The view lies inside `bin` (checked above), so these casts and slices are in range.
        let base = (view_offset + offset) as usize;
        let stride = stride as usize;
        let mut out = Vec::with_capacity(n * width);
        for i in 0..n {
            let at = base + i * stride;
            for c in 0..width {
                let o = at + 4 * c;
                let v = f32::from_le_bytes([bin[o], bin[o + 1], bin[o + 2], bin[o + 3]]);
                if !v.is_finite() {
                    return Err(Error::NonFinite {
                        path: self.path.to_path_buf(),
                        index: i,
                        property: format!("{semantic}[{c}]"),
                        value: f64::from(v),
                    });
                }
                out.push(v);
            }
        }
        Ok(out)
    }
}
