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

/// `read_mesh` on `text` in a thread, failing the test (instead of hanging it) after 30 s.
fn read_with_deadline(text: String) -> Result<plenoptic_io::Mesh, Error> {
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let (_dir, path) = write(&text);
        let _ = send.send(read_mesh(&path));
    });
    receive
        .recv_timeout(std::time::Duration::from_secs(30))
        .expect("read_mesh did not return within 30 s")
}

#[test]
fn node_cycles_and_shared_children_are_errors_not_endless_loops() {
    // Found by the mesh_gltf fuzz target: the traversal followed a cycle forever, adding the
    // mesh's triangles on every lap until memory ran out.
    let tree = r#""nodes": [{"translation": [1, 2, 3], "children": [1]}, {"scale": [2, 2, 2], "mesh": 0}]"#;
    for (nodes, scene_roots, node) in [
        // 0 → 1 → 0.
        (
            r#""nodes": [{"children": [1]}, {"mesh": 0, "children": [0]}]"#,
            "[0]",
            0,
        ),
        // 0 → 0, with no mesh on the way (a hang without any allocation).
        (r#""nodes": [{"children": [0]}, {"mesh": 0}]"#, "[0]", 0),
        // Two roots sharing the child 1.
        (
            r#""nodes": [{"children": [1]}, {"mesh": 0}, {"children": [1]}]"#,
            "[0, 2]",
            1,
        ),
    ] {
        let text = document(4, "2.0")
            .replace(tree, nodes)
            .replace(r#""nodes": [0]"#, &format!(r#""nodes": {scene_roots}"#));
        assert!(text.contains(nodes), "the test document changed");
        let e = read_with_deadline(text).unwrap_err();
        assert!(matches!(e, Error::Gltf { .. }), "{e:?}");
        let message = e.to_string();
        assert!(
            message.contains(&format!("node {node} is reached twice")),
            "{message}"
        );
    }
    // The tree itself still reads.
    assert!(read_with_deadline(document(4, "2.0")).is_ok());
}

#[test]
fn accessor_counts_the_file_cannot_back_are_errors() {
    let positions = r#"{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#;
    let views = r#"{"buffer": 0, "byteOffset": 36, "byteLength": 36}]"#;
    for (accessor, expected) in [
        // A count of 0 underflowed gltf's bounds arithmetic (a panic with overflow checks).
        (
            r#"{"bufferView": 0, "componentType": 5126, "count": 0, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "count is 0",
        ),
        // Four billion zeros from a sparse accessor without a buffer view: 48 GB asked for
        // by a 1 KB file.
        (
            r#"{"componentType": 5126, "count": 4000000000, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0], "sparse": {"count": 1, "indices": {"bufferView": 2, "componentType": 5125}, "values": {"bufferView": 0}}}"#,
            "4000000000 items with no buffer view",
        ),
        // Found by the mesh_gltf fuzz target (on NORMAL): gltf's reader asserts that the
        // layout matches the attribute; without debug assertions it read 12-byte items from
        // 2-byte ones.
        (
            r#"{"bufferView": 0, "componentType": 5123, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "U16 Vec3 is not a layout glTF allows here",
        ),
        // Found by the mesh_gltf fuzz target too: a byteStride of 8 under 12-byte items.
        (
            r#"{"bufferView": 3, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "byte stride 8 is smaller than one item (12 bytes)",
        ),
        (
            r#"{"componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0], "sparse": {"count": 0, "indices": {"bufferView": 2, "componentType": 5125}, "values": {"bufferView": 0}}}"#,
            "sparse count is 0",
        ),
        // Found by an adversarial sweep: each of these was reported as "no POSITION
        // attribute" (gltf's reader returns nothing when the items do not fit).
        (
            r#"{"bufferView": 0, "componentType": 5126, "count": 1000000000, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "1000000000 items of 12 bytes, 12 apart from byte 0, reach past the 36 bytes of buffer view 0",
        ),
        (
            r#"{"bufferView": 0, "byteOffset": 4000000000, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "3 items of 12 bytes, 12 apart from byte 4000000000, reach past the 36 bytes of buffer view 0",
        ),
        (
            r#"{"bufferView": 4, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "3 items of 12 bytes, 252 apart from byte 0, reach past the 36 bytes of buffer view 4",
        ),
        (
            r#"{"bufferView": 5, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "buffer view 5 (36 bytes from byte 60) reaches past the 72 bytes of buffer 0",
        ),
        (
            r#"{"bufferView": 6, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}"#,
            "buffer view 6 (18446744073709551615 bytes from byte 0) reaches past the 72 bytes of buffer 0",
        ),
        (
            r#"{"componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0], "sparse": {"count": 2, "indices": {"bufferView": 2, "componentType": 5125}, "values": {"bufferView": 0}}}"#,
            "its sparse indices: 2 items of 4 bytes, 4 apart from byte 0, reach past the 4 bytes of buffer view 2",
        ),
        (
            r#"{"componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0], "sparse": {"count": 1, "indices": {"bufferView": 2, "componentType": 5125}, "values": {"bufferView": 0, "byteOffset": 30}}}"#,
            "its sparse values: 1 items of 12 bytes, 12 apart from byte 30, reach past the 36 bytes of buffer view 0",
        ),
    ] {
        let text = document(4, "2.0").replace(positions, accessor).replace(
            views,
            r#"{"buffer": 0, "byteOffset": 36, "byteLength": 36}, {"buffer": 0, "byteOffset": 0, "byteLength": 4}, {"buffer": 0, "byteOffset": 0, "byteLength": 36, "byteStride": 8}, {"buffer": 0, "byteOffset": 0, "byteLength": 36, "byteStride": 252}, {"buffer": 0, "byteOffset": 60, "byteLength": 36}, {"buffer": 0, "byteOffset": 0, "byteLength": 18446744073709551615}]"#,
        );
        assert!(text.contains(accessor), "the test document changed");
        let e = read_with_deadline(text).unwrap_err();
        assert!(matches!(e, Error::Gltf { .. }), "{e:?}");
        let message = e.to_string();
        assert!(
            message.contains("mesh 0 primitive 0 Positions (accessor 0)")
                && message.contains(expected),
            "{message}"
        );
    }
}

/// Indices that reach past their buffer view were read from the bytes beyond it; a POSITION
/// accessor with no buffer view (nor sparse values) is named by the importer.
#[test]
fn indices_past_their_view_and_viewless_positions_are_named() {
    let with_indices = document(4, "2.0")
        .replace(
            r#""COLOR_0": 1}, "mode""#,
            r#""COLOR_0": 1}, "indices": 2, "mode""#,
        )
        .replace(
            r#"{"buffer": 0, "byteOffset": 36, "byteLength": 36}]"#,
            r#"{"buffer": 0, "byteOffset": 36, "byteLength": 36}, {"buffer": 0, "byteOffset": 0, "byteLength": 8}]"#,
        )
        .replace(
            r#"{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}"#,
            r#"{"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3"}, {"bufferView": 2, "componentType": 5125, "count": 3, "type": "SCALAR"}"#,
        );
    assert!(with_indices.contains(r#""indices": 2"#) && with_indices.contains("5125"));
    let message = read_with_deadline(with_indices).unwrap_err().to_string();
    assert!(
        message.contains("mesh 0 primitive 0 indices (accessor 2)")
            && message.contains(
                "3 items of 4 bytes, 4 apart from byte 0, reach past the 8 bytes of buffer view 2"
            ),
        "{message}"
    );
    let viewless = document(4, "2.0").replace(
        r#"{"bufferView": 0, "componentType""#,
        r#"{"componentType""#,
    );
    assert!(viewless.contains(r#"{"componentType": 5126, "count": 3, "type": "VEC3", "min""#));
    let message = read_with_deadline(viewless).unwrap_err().to_string();
    assert!(
        message.contains("accessors[0].bufferView: Missing data"),
        "{message}"
    );
}

/// A GLB cut short, a `.glb` that is not one, a GLB shorter than its header and a `.gltf` that
/// is not JSON: the importer said "failed to fill whole buffer" or "expected value at line 1
/// column 1".
#[test]
fn broken_containers_are_named_as_such() {
    let glb = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/meshes/box-textured/BoxTextured.glb"
    ))
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8], &str); 4] = [
        (
            "cut.glb",
            &glb[..1000],
            "the GLB header declares 4696 bytes but the file has 1000",
        ),
        (
            "noise.glb",
            b"not a glb file at all",
            "not a GLB file: it does not start with the magic",
        ),
        (
            "short.glb",
            &glb[..8],
            "a GLB header is 12 bytes; the file has 8",
        ),
        ("noise.gltf", b"\x00\x01binary", "not a glTF JSON file"),
    ];
    for (name, bytes, expected) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let e = read_mesh(&path).unwrap_err().to_string();
        assert!(e.contains(expected), "{name}: {e}");
    }
    // A byte-order mark before the JSON is not the problem the importer is left to judge.
    let path = dir.path().join("bom.gltf");
    std::fs::write(
        &path,
        [b"\xEF\xBB\xBF".as_slice(), document(4, "2.0").as_bytes()].concat(),
    )
    .unwrap();
    let e = read_mesh(&path)
        .map(|_| String::new())
        .unwrap_or_else(|e| e.to_string());
    assert!(!e.contains("not a glTF JSON file"), "{e}");
}
