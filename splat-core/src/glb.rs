//! Splats as binary glTF (`.glb`) with the `KHR_gaussian_splatting` extension (Khronos, review
//! draft): one point primitive whose attributes are the splats' position, log-scale, unit
//! rotation (x, y, z, w), opacity and SH coefficients, so any glTF tool can carry the model and a
//! viewer without splat support still shows it as coloured points (`COLOR_0`).
//!
//! Values are stored as `float`, without quantisation, in glTF's y-up frame (the half turn of
//! [`crate::frame`]); the attributes follow the extension's table: `POSITION`, `COLOR_0` (the
//! diffuse colour clamped to [0, 1] and the opacity, as normalised bytes, for the fallback),
//! `KHR_gaussian_splatting:SCALE`, `:ROTATION`, `:OPACITY`, `:SH_DEGREE_0_COEF_0` and
//! `:SH_DEGREE_ℓ_COEF_n` for every band up to the model's degree.
//!
//! Written by hand: the `gltf` crate reads glTF but does not build files, and the container is
//! small (a 12-byte header, a JSON chunk and a binary chunk, each 4-byte aligned).

use std::path::Path;

use serde_json::{Value, json};

use crate::frame::y_up_frame;
use crate::{Error, Splats, sh_dc_to_rgb};

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
        floats(s.log_scales.iter().flat_map(|v| v.to_array())),
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
    if splats.is_empty() {
        return Err(Error::Inconsistent(
            "a glTF accessor holds at least one element, so an empty model cannot be written"
                .into(),
        ));
    }
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
    let bytes = encode_glb(splats)?;
    atomic_output::write_atomic(path, &bytes).map_err(|e| Error::io(path, e))
}
