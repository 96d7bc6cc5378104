//! Property tests over every reader of untrusted files in this crate (the stable-toolchain
//! companion of the cargo-fuzz targets in `fuzz/`, see `docs/fuzzing.md`): arbitrary bytes and
//! randomly mutated real files go into the PLY reader (cloud and mesh), the OBJ loader and the
//! glTF/GLB loader. Each must return `Ok` or an `Error` whose message names the file; a panic,
//! a hang or an allocation the file cannot justify fails the test.

use std::path::Path;

use plenoptic_io::ply::{cloud_from_bytes, model_from_bytes};
use plenoptic_io::{Error, read_mesh};
use proptest::prelude::*;

/// Real files the mutations start from.
const PLY_SEEDS: &[&[u8]] = &[
    include_bytes!("../../testdata/meshes/misc/cube_binary.ply"),
    include_bytes!("../../testdata/meshes/misc/cube_uv.ply"),
    include_bytes!("../../testdata/meshes/misc/float-color.ply"),
    include_bytes!("../../testdata/meshes/misc/points.ply"),
    include_bytes!("../../testdata/bad/issue623.ply"),
];
const OBJ_SEEDS: &[&[u8]] = &[
    include_bytes!("../../testdata/meshes/misc/cube_with_vertexcolors.obj"),
    include_bytes!("../../testdata/bad/malformed.obj"),
    include_bytes!("../../testdata/bad/malformed2.obj"),
];
const GLTF_SEEDS: &[&[u8]] = &[
    include_bytes!("../../testdata/meshes/box-textured/BoxTextured.glb"),
    include_bytes!("../../testdata/meshes/box-textured/BoxTextured.gltf"),
    include_bytes!("../../testdata/bad/gltf/BoxWithInfinites-glTF-Binary/BoxWithInfinites.glb"),
];

/// A small plenoptic cloud in the 8iVSLF layout (rig comments, two cameras' uchar colours).
fn plenoptic_seed(format: &str) -> Vec<u8> {
    let mut text = format!(
        "ply\nformat {format} 1.0\ncomment frame_to_world_scale 0.0018\n\
         comment frame_to_world_translation 1 2 3\ncomment width 1023\ncomment rig_count 2\n\
         comment rig_matrix_0 1 0 0 0 0 1 0 0 0 0 1 0 0 2 -3 1\n\
         comment rig_matrix_1 1 0 0 0 0 1 0 0 0 0 1 0 1 2 -3 1\nelement vertex 3\n"
    );
    for name in ["x", "y", "z", "nx", "ny", "nz"] {
        text += &format!("property float {name}\n");
    }
    for k in 0..2 {
        for c in ["red", "green", "blue"] {
            text += &format!("property uchar {c}{k}\n");
        }
    }
    text += "end_header\n";
    let mut bytes = text.into_bytes();
    for i in 0..3u8 {
        let position = [f32::from(i), 2.0 * f32::from(i), 3.0, 0.0, 0.0, 1.0];
        let colours = [10 * i, 20, 30, 40, 50 * i, 60];
        if format == "ascii" {
            let row: Vec<String> = position
                .iter()
                .map(f32::to_string)
                .chain(colours.iter().map(u8::to_string))
                .collect();
            bytes.extend(row.join(" ").bytes());
            bytes.push(b'\n');
        } else {
            for v in position {
                bytes.extend(v.to_le_bytes());
            }
            bytes.extend(colours);
        }
    }
    bytes
}

/// Numbers that make readers misbehave when they trust a file.
#[path = "../../fuzz/props/mutation.rs"]
mod mutation;

use mutation::{apply, edit};

/// An error must name the file it is about.
fn check_error<T>(result: Result<T, Error>, name: &str) -> Result<(), TestCaseError> {
    if let Err(e) = result {
        let message = e.to_string();
        prop_assert!(
            message.contains(name),
            "error does not name {name}: {message}"
        );
    }
    Ok(())
}

/// Both PLY entry points on the same bytes.
fn read_ply(bytes: &[u8]) -> Result<(), TestCaseError> {
    let name = Path::new("props-input.ply");
    check_error(cloud_from_bytes(name, bytes), "props-input.ply")?;
    check_error(model_from_bytes(name, bytes), "props-input.ply")
}

/// `read_mesh` on the bytes written to a file called `name` in a fresh temporary directory.
fn read_mesh_file(name: &str, bytes: &[u8]) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    check_error(read_mesh(&path), name)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn ply_reader_survives_arbitrary_bytes(
        header in prop::sample::select(vec![
            "",
            "ply\n",
            "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n",
            "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n",
            "ply\nformat binary_big_endian 1.0\nelement vertex 1\nproperty double x\nproperty double y\nproperty double z\nproperty list uint uchar extra\nend_header\n",
        ]),
        body in prop::collection::vec(any::<u8>(), 0..512),
    ) {
        let mut bytes = header.as_bytes().to_vec();
        bytes.extend(body);
        read_ply(&bytes)?;
    }

    #[test]
    fn ply_reader_survives_mutated_files(
        seed in 0..PLY_SEEDS.len() + 3,
        edits in prop::collection::vec(edit(), 1..8),
    ) {
        let original = match seed.checked_sub(PLY_SEEDS.len()) {
            None => PLY_SEEDS[seed].to_vec(),
            Some(0) => plenoptic_seed("ascii"),
            Some(1) => plenoptic_seed("binary_little_endian"),
            Some(_) => plenoptic_seed("binary_big_endian"),
        };
        read_ply(&apply(original, &edits))?;
    }
}

proptest! {
    // The mesh loaders go through a file and (glTF) decode a texture: fewer cases.
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn obj_loader_survives_arbitrary_and_mutated_files(
        seed in 0..=OBJ_SEEDS.len(),
        random in prop::collection::vec(any::<u8>(), 0..256),
        edits in prop::collection::vec(edit(), 1..8),
    ) {
        let original = OBJ_SEEDS.get(seed).map_or(random, |s| s.to_vec());
        read_mesh_file("props-input.obj", &apply(original, &edits))?;
    }

    #[test]
    fn gltf_loader_survives_arbitrary_and_mutated_files(
        seed in 0..=GLTF_SEEDS.len(),
        random in prop::collection::vec(any::<u8>(), 0..256),
        edits in prop::collection::vec(edit(), 1..8),
        glb in any::<bool>(),
    ) {
        let original = GLTF_SEEDS.get(seed).map_or(random, |s| s.to_vec());
        let name = if glb { "props-input.glb" } else { "props-input.gltf" };
        read_mesh_file(name, &apply(original, &edits))?;
    }
}

const WRAPPED_TEXCOORD_OBJ: &str = r"g cube

v  0.0  0.0  0.0  0.48627  0.43137  0.47060
v  0.0  0.0  1.0  0.09412  0.00000  0.47451
v  0.0  1.0  0.0  0.01569  0.00000  0.17255
v  0.0  1.0  1.0  0.87843  0.00000  0.03922
v  1.0  0.0  0.0  0.09412  0.78431  0.09804
v  1.0  0.0  1.0  0.48627  0.03922  0.21961
v  1.0  1.0  0.0  0.30588  0.22390  0.19608
v  1.0  1.0   .0 01.09020  0.00000  0.78431

vn 0.0 0.0 1.0
vn 0.0 0.0 -1.0
vn 0.0 1.0 0.0
vn 0.0 -130 0.0
vn 1.0 0.0 0.0
vn -1.0 0.0 0.0

f 1//2 7//2 5/-2
f 1//2 3//2 7//2
f 1//6 4//6 3//6
f 1//6 2/ 7//2
f 1//6 4//6 3//6
f 1//6 2//6 3//6
f 3//3 8//
v 1 1 0
vt 0 0
vt 1 0
vt 0 1
vn 0 0 1
usemtl a
f 1/1/13 7//3
f 3//3 4//3 8//3
f /6 3//6
f 3//3 8//3 7//3
f 3//3 4//3 8//3
f 5//5 7//5 8//5
f 5//5 8//5 6//5
f 1//4 5//4 6//4
f 1//4 6//4 2//4
f 2//1 6//1 8//1
f 2//1 8//1 4//1";

#[test]
fn obj_face_with_a_relative_texcoord_index_before_the_first_is_an_error_not_a_panic() {
    // Found by the mesh_obj fuzz target (`f 1//2 7//2 5/-2` in a mutated cube): tobj resolves
    // `-2` against one texture coordinate to a wrapped index and multiplies it, which panics
    // with overflow checks on.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("wrapped.obj");
    // The fuzzer's input as it found it.
    std::fs::write(&path, WRAPPED_TEXCOORD_OBJ).unwrap();
    let e = read_mesh(&path).unwrap_err();
    assert!(matches!(e, Error::Obj { .. }), "{e:?}");
    assert!(e.to_string().contains("wrapped.obj"), "{e}");
}
