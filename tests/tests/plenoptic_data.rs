//! plenoptic-io on every mesh, cloud and bad file in `testdata`, checked against values read
//! independently from the files themselves (text parsing, raw bytes of the .bin buffers).
#![allow(clippy::print_stdout)] // tests report what they measured

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::{DVec3, Vec2, Vec3};
use plenoptic_io::summary::Summary;
use plenoptic_io::{
    CaptureCamera, Error, Model, PlenopticCloud, load, read_cloud, read_mesh, write_cloud,
};

fn data(rel: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../testdata")).join(rel)
}

/// Lines of a text file starting with `prefix`, split into numbers.
fn numbers(path: &Path, prefix: &str) -> Vec<Vec<f32>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter_map(|l| l.strip_prefix(prefix))
        .map(|l| l.split_whitespace().map(|t| t.parse().unwrap()).collect())
        .collect()
}

fn key(p: Vec3) -> [u32; 3] {
    p.to_array().map(f32::to_bits)
}

#[test]
fn spider_obj_with_windows_texture_paths() {
    let path = data("meshes/spider/spider.obj");
    let mesh = read_mesh(&path).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let faces = text.lines().filter(|l| l.starts_with("f ")).count();
    assert!(
        text.lines()
            .filter(|l| l.starts_with("f "))
            .all(|l| l.split_whitespace().count() == 4)
    );
    assert_eq!(faces, 1368);
    // Every face of spider.obj is a triangle.
    assert_eq!(mesh.triangles.len(), faces);
    let v: HashSet<[u32; 3]> = numbers(&path, "v ")
        .iter()
        .map(|v| key(Vec3::new(v[0], v[1], v[2])))
        .collect();
    let ours: HashSet<[u32; 3]> = mesh.positions.iter().map(|&p| key(p)).collect();
    assert_eq!(ours, v);
    // UVs are the file's (u, 1 − v).
    let vt: HashSet<[u32; 2]> = numbers(&path, "vt ")
        .iter()
        .map(|t| [t[0].to_bits(), (1.0 - t[1]).to_bits()])
        .collect();
    assert!(
        mesh.uvs
            .as_ref()
            .unwrap()
            .iter()
            .all(|uv| vt.contains(&[uv.x.to_bits(), uv.y.to_bits()]))
    );
    let names: Vec<&str> = mesh.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(
        names,
        ["Skin", "Brusttex", "HLeibTex", "BeinTex", "Augentex"]
    );
    assert_eq!(
        mesh.materials[0].base_color,
        [0.827451, 0.792157, 0.772549, 1.0]
    );
    // map_Kd .\wal67ar_small.jpg … resolved despite the backslashes; sizes as `file` reports them.
    let sizes: Vec<(u32, u32)> = mesh
        .materials
        .iter()
        .map(|m| {
            let t = &mesh.textures[m.texture.unwrap()];
            (t.width, t.height)
        })
        .collect();
    assert_eq!(
        sizes,
        [(250, 250), (250, 250), (249, 250), (768, 768), (128, 128)]
    );
    assert_eq!(mesh.triangle_materials.len(), mesh.triangles.len());
    assert!(
        mesh.triangle_materials
            .iter()
            .all(|&m| (m as usize) < mesh.materials.len())
    );
    let tex = &mesh.textures[0];
    assert_eq!(tex.pixels.len(), 250 * 250);
    assert!(
        tex.pixels
            .iter()
            .all(|p| p.iter().all(|c| (0.0..=1.0).contains(c)) && p[3] == 1.0)
    );
}

#[test]
fn obj_vertex_colours() {
    let path = data("meshes/misc/cube_with_vertexcolors.obj");
    let mesh = read_mesh(&path).unwrap();
    let expected: HashMap<[u32; 3], [f32; 3]> = numbers(&path, "v ")
        .iter()
        .map(|v| (key(Vec3::new(v[0], v[1], v[2])), [v[3], v[4], v[5]]))
        .collect();
    assert_eq!(expected.len(), 8);
    assert_eq!(mesh.triangles.len(), 12);
    let colors = mesh.colors.as_ref().unwrap();
    for (p, c) in mesh.positions.iter().zip(colors) {
        assert_eq!(expected[&key(*p)], *c);
    }
    assert!(mesh.materials.is_empty() && mesh.triangle_materials.is_empty());
}

/// The raw little-endian f32 values of a glTF buffer.
fn floats(bytes: &[u8], offset: usize, count: usize) -> Vec<f32> {
    bytes[offset..offset + 4 * count]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

#[test]
fn gltf_and_glb_box_with_texture_and_node_transform() {
    let bin = std::fs::read(data("meshes/box-textured/BoxTextured0.bin")).unwrap();
    // POSITION: accessor 2 = bufferView 1 (offset 576 in the .bin, see the .gltf) + 288.
    let gltf: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(data("meshes/box-textured/BoxTextured.gltf")).unwrap(),
    )
    .unwrap();
    let view_offset = gltf["bufferViews"][1]["byteOffset"].as_u64().unwrap_or(0) as usize;
    let raw = floats(&bin, view_offset + 288, 24 * 3);
    for file in ["BoxTextured.gltf", "BoxTextured.glb"] {
        let mesh = read_mesh(&data(&format!("meshes/box-textured/{file}"))).unwrap();
        assert_eq!(
            (mesh.positions.len(), mesh.triangles.len()),
            (24, 12),
            "{file}"
        );
        // The root node's matrix maps (x, y, z) to (x, z, −y).
        for (i, p) in mesh.positions.iter().enumerate() {
            assert_eq!(
                *p,
                Vec3::new(raw[3 * i], raw[3 * i + 2], -raw[3 * i + 1]),
                "{file} vertex {i}"
            );
        }
        assert_eq!(mesh.materials.len(), 1);
        assert_eq!(mesh.materials[0].name, "Texture");
        assert_eq!(mesh.materials[0].base_color, [1.0; 4]);
        let t = &mesh.textures[mesh.materials[0].texture.unwrap()];
        assert_eq!((t.width, t.height), (211, 211));
        assert_eq!(mesh.uvs.as_ref().unwrap().len(), 24);
        assert!(
            mesh.normals
                .as_ref()
                .unwrap()
                .iter()
                .all(|n| (n.length() - 1.0).abs() < 1e-5)
        );
        assert_eq!(mesh.triangle_materials, vec![0; 12]);
    }
}

#[test]
fn ply_points_without_faces_is_a_cloud() {
    let path = data("meshes/misc/points.ply");
    let Model::Cloud(cloud) = load(&path).unwrap() else {
        panic!("points.ply has no faces")
    };
    assert_eq!(cloud.len(), 4);
    assert_eq!(cloud.num_cameras, 0);
    assert_eq!(cloud.positions[1], Vec3::new(0.0, 0.0, 1.0));
    assert_eq!(cloud.colors[1], [1.0, 0.0, 1.0]);
    assert_eq!(cloud.normals.as_ref().unwrap()[3], Vec3::new(1.0, 1.0, 0.0));
    assert!(
        read_mesh(&path)
            .unwrap_err()
            .to_string()
            .contains("no faces")
    );
}

#[test]
fn ply_float_colour_mesh() {
    let path = data("meshes/misc/float-color.ply");
    let Model::Mesh(mesh) = load(&path).unwrap() else {
        panic!("float-color.ply has a face")
    };
    assert_eq!(mesh.triangles, vec![[0, 1, 2]]);
    assert_eq!(mesh.positions[2], Vec3::new(200.0, 200.0, 0.0));
    assert_eq!(mesh.colors.as_ref().unwrap(), &vec![[0.0, 0.0, 1.0]; 3]);
    // As a cloud, the alpha column is kept as an extra property.
    let cloud = read_cloud(&path).unwrap();
    assert_eq!(cloud.extra[0].name, "alpha");
    assert_eq!(cloud.extra[0].values, vec![1.0; 3]);
}

#[test]
fn ply_binary_cube_matches_its_raw_bytes() {
    let path = data("meshes/misc/cube_binary.ply");
    let bytes = std::fs::read(&path).unwrap();
    let body = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let raw = floats(&bytes, body, 24);
    let mesh = read_mesh(&path).unwrap();
    assert_eq!(mesh.positions.len(), 8);
    assert_eq!(mesh.triangles.len(), 12);
    for (i, p) in mesh.positions.iter().enumerate() {
        assert_eq!(p.to_array(), [raw[3 * i], raw[3 * i + 1], raw[3 * i + 2]]);
    }
    // Faces: uchar 3, then three little-endian i32.
    let mut at = body + 96;
    for tri in &mesh.triangles {
        assert_eq!(bytes[at], 3);
        let idx: Vec<u32> = bytes[at + 1..at + 13]
            .chunks_exact(4)
            .map(|c| i32::from_le_bytes([c[0], c[1], c[2], c[3]]) as u32)
            .collect();
        assert_eq!(tri.as_slice(), idx.as_slice());
        at += 13;
    }
}

#[test]
fn ply_quads_with_st_coordinates() {
    let mesh = read_mesh(&data("meshes/misc/cube_uv.ply")).unwrap();
    assert_eq!(mesh.positions.len(), 24);
    // Six quads, fan-triangulated.
    assert_eq!(mesh.triangles.len(), 12);
    let uvs = mesh.uvs.as_ref().unwrap();
    // Vertex 2 has s = 1, t = 1: top-right of the image in OpenGL terms, so (1, 0) here.
    assert_eq!(uvs[2], Vec2::new(1.0, 0.0));
    assert_eq!(uvs[0], Vec2::new(0.0, 1.0));
    assert_eq!(mesh.normals.as_ref().unwrap()[4], Vec3::new(0.0, -0.0, 1.0));
}

#[test]
fn stanford_bunny() {
    let path = data("meshes/misc/bun_zipper_res4.ply");
    let mesh = read_mesh(&path).unwrap();
    assert_eq!((mesh.positions.len(), mesh.triangles.len()), (453, 948));
    assert_eq!(
        mesh.positions[0],
        Vec3::new(-0.0312216, 0.126304, 0.00514924)
    );
    let text = std::fs::read_to_string(&path).unwrap();
    let last = text.lines().last().unwrap();
    let idx: Vec<u32> = last
        .split_whitespace()
        .skip(1)
        .map(|t| t.parse().unwrap())
        .collect();
    assert_eq!(mesh.triangles[947].as_slice(), idx.as_slice());
    let cloud = read_cloud(&path).unwrap();
    let extras: Vec<&str> = cloud.extra.iter().map(|e| e.name.as_str()).collect();
    assert_eq!(extras, ["confidence", "intensity"]);
    assert_eq!(cloud.extra[0].values[0], f64::from(0.850855f32));
}

/// The message of the error for `rel`, checked to name the file.
fn failure(rel: &str) -> (Error, String) {
    let path = data(rel);
    let err = match load(&path) {
        Ok(_) => panic!("{rel} loaded without error"),
        Err(e) => e,
    };
    let message = err.to_string();
    println!("{message}");
    let name = path.file_name().unwrap().to_string_lossy().into_owned();
    assert!(message.contains(&name), "{message}");
    (err, message)
}

#[test]
fn every_bad_file_gives_a_typed_error_naming_file_and_problem() {
    let (e, m) = failure("bad/pond.0.ply");
    assert!(matches!(e, Error::Truncated { count: 70_051, .. }), "{m}");
    assert!(m.contains("70051 vertex"), "{m}");
    let (e, m) = failure("bad/issue623.ply");
    // The header (12 lines) declares a vertex_indices list in the vertex element; the rows lack it.
    assert!(matches!(&e, Error::Body { index: 0, .. }), "{m}");
    assert!(m.contains("line 13") && m.contains("vertex_indices"), "{m}");
    let (e, m) = failure("bad/empty.ply");
    assert!(
        matches!(e, Error::Header { line: 1, .. }) && m.contains("empty"),
        "{m}"
    );
    let (e, m) = failure("bad/empty.obj");
    assert!(
        matches!(e, Error::Obj { .. }) && m.contains("no faces"),
        "{m}"
    );
    let (e, m) = failure("bad/malformed.obj");
    assert!(
        matches!(e, Error::Obj { .. } | Error::IndexOutOfRange { .. }),
        "{m}"
    );
    let (e, m) = failure("bad/malformed2.obj");
    assert!(matches!(e, Error::Obj { .. }), "{m}");
    for f in ["IndexOutOfRange", "AllIndicesOutOfRange"] {
        let (e, m) = failure(&format!("bad/gltf/IndexOutOfRange/{f}.gltf"));
        assert!(matches!(e, Error::IndexOutOfRange { count: 24, .. }), "{m}");
    }
    let (e, m) = failure("bad/gltf/MissingBin/BoxTextured.gltf");
    assert!(
        matches!(e, Error::Gltf { .. })
            && m.contains("buffer 0 refers to 'BoxTextured0.bin', which does not exist"),
        "{m}"
    );
    // The infinite positions come without the min/max that glTF 2.0 requires of POSITION, which
    // the validating importer reports first.
    let (e, m) = failure("bad/gltf/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb");
    assert!(
        matches!(e, Error::Gltf { .. }) && m.contains("POSITION"),
        "{m}"
    );
}

#[test]
fn written_plenoptic_file_keeps_its_rig_comments() {
    let n = 1000;
    let positions: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(i as f32, (i * 7 % 4096) as f32, 2048.0))
        .collect();
    let cameras: Vec<CaptureCamera> = (0..13)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / 13.0;
            let mut m = [0.0; 16];
            m[0] = 1.0;
            m[5] = 1.0;
            m[10] = 1.0;
            m[15] = 1.0;
            m[12] = 300.0 * a.cos();
            m[13] = 90.0;
            m[14] = 300.0 * a.sin();
            CaptureCamera {
                position: (DVec3::new(m[12], m[13], m[14])
                    - DVec3::new(-45.2095, 7.18301, -54.3561))
                    / 0.179523,
                matrix: Some(m),
            }
        })
        .collect();
    let cloud = PlenopticCloud {
        positions,
        normals: Some(vec![Vec3::Y; n]),
        colors: (0..n)
            .map(|i| [(i % 256) as f32 / 255.0, 0.0, 1.0])
            .collect(),
        num_cameras: 13,
        camera_colors: (0..n * 13)
            .map(|j| {
                [
                    (j % 256) as f32 / 255.0,
                    ((j / 3) % 256) as f32 / 255.0,
                    0.5f32.min(1.0) * 0.0,
                ]
            })
            .collect(),
        cameras,
        frame_to_world_scale: Some(0.179523),
        frame_to_world_translation: Some(DVec3::new(-45.2095, 7.18301, -54.3561)),
        width: Some(4095),
        ..PlenopticCloud::default()
    };
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frame.ply");
    write_cloud(&path, &cloud).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap();
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    for line in [
        "comment frame_to_world_scale 0.179523",
        "comment frame_to_world_translation -45.2095 7.18301 -54.3561",
        "comment width 4095",
        "comment rig_count 13",
        "property uchar red12",
    ] {
        assert!(
            header.lines().any(|l| l == line),
            "{line} missing from\n{header}"
        );
    }
    let read = read_cloud(&path).unwrap();
    assert_eq!(read.cameras, cloud.cameras);
    assert_eq!(read.camera_colors, cloud.camera_colors);
    assert_eq!(
        (read.frame_to_world_scale, read.width),
        (Some(0.179523), Some(4095))
    );
    let s = Summary::of(&Model::Cloud(read));
    assert_eq!(s.kind, "plenoptic cloud");
    assert_eq!(s.cameras.len(), 13);
    assert_eq!(
        s.cameras[0].position,
        Some(cloud.cameras[0].position.to_array())
    );
}

#[test]
fn summaries_of_every_good_file() {
    let expected = [
        ("meshes/spider/spider.obj", "mesh", 1368),
        ("meshes/misc/cube_with_vertexcolors.obj", "mesh", 12),
        ("meshes/box-textured/BoxTextured.gltf", "mesh", 12),
        ("meshes/box-textured/BoxTextured.glb", "mesh", 12),
        ("meshes/misc/bun_zipper_res4.ply", "mesh", 948),
        ("meshes/misc/cube_binary.ply", "mesh", 12),
        ("meshes/misc/cube_uv.ply", "mesh", 12),
        ("meshes/misc/float-color.ply", "mesh", 1),
        ("meshes/misc/points.ply", "point cloud", 0),
    ];
    for (rel, kind, triangles) in expected {
        let s = Summary::of(&load(&data(rel)).unwrap());
        assert_eq!(
            (s.kind, s.triangles.unwrap_or(0)),
            (kind, triangles),
            "{rel}"
        );
        assert!(s.bounds.is_some(), "{rel}");
    }
}
