//! glTF features checked on small documents written here: data: URI buffers, node hierarchies,
//! COLOR_0 and baseColorFactor, and the errors for other primitive modes and glTF 1.0.

use glam::Vec3;
use plenoptic_io::{Error, read_mesh};

/// Standard base64 (RFC 4648) of `bytes`, for data: URIs.
fn base64(bytes: &[u8]) -> String {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [
            chunk[0],
            *chunk.get(1).unwrap_or(&0),
            *chunk.get(2).unwrap_or(&0),
        ];
        let n = (u32::from(b[0]) << 16) | (u32::from(b[1]) << 8) | u32::from(b[2]);
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(ALPHABET[((n >> (18 - 6 * i)) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// A one-triangle document: positions, COLOR_0 (RGB float), a red-ish material, and two nodes:
/// the parent translates by (1, 2, 3), the child (holding the mesh) scales by 2.
fn document(mode: u32, version: &str) -> String {
    let positions = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let colors = [1.0f32, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
    let bytes: Vec<u8> = positions
        .iter()
        .chain(&colors)
        .flat_map(|v| v.to_le_bytes())
        .collect();
    format!(
        r#"{{
  "asset": {{"version": "{version}"}},
  "scene": 0,
  "scenes": [{{"nodes": [0]}}],
  "nodes": [{{"translation": [1, 2, 3], "children": [1]}}, {{"scale": [2, 2, 2], "mesh": 0}}],
  "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0, "COLOR_0": 1}}, "mode": {mode}, "material": 0}}]}}],
  "materials": [{{"name": "paint", "pbrMetallicRoughness": {{"baseColorFactor": [0.8, 0.1, 0.2, 1.0]}}}}],
  "buffers": [{{"byteLength": {len}, "uri": "data:application/octet-stream;base64,{data}"}}],
  "bufferViews": [{{"buffer": 0, "byteOffset": 0, "byteLength": 36}}, {{"buffer": 0, "byteOffset": 36, "byteLength": 36}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}}
  ]
}}"#,
        len = bytes.len(),
        data = base64(&bytes)
    )
}

fn write(text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.gltf");
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

#[test]
fn data_uri_hierarchy_colours_and_factor() {
    let (_dir, path) = write(&document(4, "2.0"));
    let mesh = read_mesh(&path).unwrap();
    // Child scale first, then parent translation: p ↦ 2p + (1, 2, 3).
    assert_eq!(
        mesh.positions,
        vec![
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(3.0, 2.0, 3.0),
            Vec3::new(1.0, 4.0, 3.0)
        ]
    );
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    assert_eq!(
        mesh.colors.unwrap(),
        vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    assert_eq!(mesh.materials[0].name, "paint");
    assert_eq!(mesh.materials[0].base_color, [0.8, 0.1, 0.2, 1.0]);
    assert_eq!(mesh.materials[0].texture, None);
    assert!(mesh.uvs.is_none());
}

#[test]
fn other_primitive_modes_are_refused() {
    let (_dir, path) = write(&document(0, "2.0"));
    let e = read_mesh(&path).unwrap_err();
    let m = e.to_string();
    assert!(
        matches!(e, Error::Gltf { .. })
            && m.contains("mesh 0 primitive 0")
            && m.contains("TRIANGLES"),
        "{m}"
    );
}

#[test]
fn gltf_1_is_refused() {
    let (_dir, path) = write(&document(4, "1.0"));
    let e = read_mesh(&path).unwrap_err();
    let m = e.to_string();
    assert!(
        matches!(e, Error::Gltf { .. }) && m.contains("glTF version 1.0 is not supported"),
        "{m}"
    );
}
