//! NaN and infinities in real files of testdata/, each changed in one value: every reader refuses
//! them with an error naming the file, the element index and the property.

use std::path::{Path, PathBuf};

use plenoptic_io::{Error, load, read_cloud, write_cloud};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../testdata")).join(rel)
}

/// `rel` from testdata/ with `change` applied to its bytes, written as `name` in `dir`.
fn changed(dir: &Path, rel: &str, name: &str, change: impl FnOnce(&mut Vec<u8>)) -> PathBuf {
    let mut bytes = std::fs::read(data(rel)).unwrap();
    change(&mut bytes);
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Replaces the `n`-th (0-based) line of the text `bytes` whose first word is `row` (the
/// `k`-th word of it, 0-based) with `value`.
fn set_word(bytes: &mut Vec<u8>, row: impl Fn(usize, &str) -> bool, k: usize, value: &str) {
    let text = String::from_utf8(bytes.clone()).unwrap();
    let mut done = false;
    let lines: Vec<String> = text
        .split('\n')
        .enumerate()
        .map(|(i, line)| {
            if !done && row(i, line) {
                done = true;
                let mut words: Vec<&str> = line.split_whitespace().collect();
                words[k] = value;
                words.join(" ")
            } else {
                line.to_string()
            }
        })
        .collect();
    assert!(done, "no line matched");
    *bytes = lines.join("\n").into_bytes();
}

/// The error of loading `path`, checked to be `NonFinite` and to name the file.
fn refused(path: &Path) -> (Error, String) {
    let e = load(path).map(|_| ()).unwrap_err();
    let m = e.to_string();
    let name = path.file_name().unwrap().to_string_lossy().into_owned();
    assert!(matches!(e, Error::NonFinite { .. }), "{m}");
    assert!(m.starts_with(&format!("{}: ", path.display())), "{m}");
    assert!(m.contains(&name), "{m}");
    (e, m)
}

/// 0-based index of the first body line of an ASCII PLY.
fn body_start(bytes: &[u8]) -> usize {
    String::from_utf8_lossy(bytes)
        .lines()
        .position(|l| l == "end_header")
        .unwrap()
        + 1
}

#[test]
fn ascii_ply_normal_colour_and_double_position() {
    let dir = tempfile::tempdir().unwrap();
    // points.ply: x y z red green blue nx ny nz, 4 vertices; vertex 2's nx becomes NaN.
    let p = changed(dir.path(), "meshes/misc/points.ply", "points.ply", |b| {
        let start = body_start(b);
        set_word(b, |i, _| i == start + 2, 6, "nan");
    });
    let (_, m) = refused(&p);
    assert!(m.ends_with("points.ply: vertex 2, property nx: NaN"), "{m}");

    // float-color.ply is a mesh with float colours; vertex 1's green becomes +inf.
    let p = changed(dir.path(), "meshes/misc/float-color.ply", "fc.ply", |b| {
        let start = body_start(b);
        set_word(b, |i, _| i == start + 1, 4, "inf");
    });
    let (_, m) = refused(&p);
    assert!(m.ends_with("fc.ply: vertex 1, property green: inf"), "{m}");

    // points.ply with double positions: 1e300 is finite as a double but not as the f32 it is read into.
    let p = changed(dir.path(), "meshes/misc/points.ply", "double.ply", |b| {
        let text = String::from_utf8(b.clone())
            .unwrap()
            .replace("property float z", "property double z");
        *b = text.into_bytes();
        let start = body_start(b);
        set_word(b, |i, _| i == start + 3, 2, "-1e300");
    });
    let (e, m) = refused(&p);
    assert!(
        matches!(&e, Error::NonFinite { index: 3, property, .. } if property == "z"),
        "{m}"
    );
    assert!(
        m.contains("vertex 3, property z: -inf") && m.contains("double"),
        "{m}"
    );
    // The double column itself reads exactly when it is in range.
    let p = changed(dir.path(), "meshes/misc/points.ply", "double-ok.ply", |b| {
        let text = String::from_utf8(b.clone())
            .unwrap()
            .replace("property float z", "property double z");
        *b = text.into_bytes();
    });
    assert_eq!(read_cloud(&p).unwrap().positions[3].z, 1.0);
}

#[test]
fn binary_ply_position_is_refused_with_its_vertex() {
    let dir = tempfile::tempdir().unwrap();
    // cube_binary.ply: binary little endian, float x y z, 8 vertices then 12 faces.
    let p = changed(dir.path(), "meshes/misc/cube_binary.ply", "cube.ply", |b| {
        let body = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let at = body + 5 * 12 + 8; // vertex 5, z
        b[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    });
    let (_, m) = refused(&p);
    assert!(m.ends_with("cube.ply: vertex 5, property z: NaN"), "{m}");
}

#[test]
fn float_camera_colours_of_a_plenoptic_ply_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    // The real points.ply, given four capture cameras of float colours, in binary and ASCII.
    let mut cloud = read_cloud(&data("meshes/misc/points.ply")).unwrap();
    cloud.num_cameras = 4;
    cloud.camera_colors = (0..cloud.len() * 4)
        .map(|i| [0.1, 0.2, (i % 7) as f32 / 7.0])
        .collect();
    let mut layout = cloud.layout.clone().unwrap();
    for k in 0..4 {
        for c in ["red", "green", "blue"] {
            layout
                .properties
                .push((format!("{c}{k}"), plenoptic_io::ScalarType::F32));
        }
    }
    for format in [
        plenoptic_io::PlyFormat::BinaryLittleEndian,
        plenoptic_io::PlyFormat::Ascii,
    ] {
        layout.format = format;
        cloud.layout = Some(layout.clone());
        let good = dir.path().join("frame-good.ply");
        write_cloud(&good, &cloud).unwrap();
        assert_eq!(
            read_cloud(&good).unwrap().camera_colors,
            cloud.camera_colors
        );
        // One value changed: vertex 3, red3 (camera 3's first colour) becomes NaN.
        let mut bad = cloud.clone();
        bad.camera_colors[3 * 4 + 3][0] = f32::NAN;
        let p = dir.path().join("frame.ply");
        write_cloud(&p, &bad).unwrap();
        let (_, m) = refused(&p);
        assert!(
            m.ends_with("frame.ply: vertex 3, property red3: NaN"),
            "{format:?}: {m}"
        );
    }
}

#[test]
fn non_finite_rig_matrix_is_a_header_error_naming_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let m = ["1"; 16].join(" ");
    let p = changed(dir.path(), "meshes/misc/points.ply", "rig.ply", |b| {
        let text = String::from_utf8(b.clone()).unwrap().replacen(
            "element vertex",
            &format!(
                "comment rig_matrix_0 {}\nelement vertex",
                m.replacen("1", "nan", 1)
            ),
            1,
        );
        *b = text.into_bytes();
    });
    let e = load(&p).map(|_| ()).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, Error::Header { line: 3, .. }), "{msg}");
    assert!(
        msg.contains("rig.ply")
            && msg.contains("rig_matrix_0")
            && msg.contains("\"nan\" is not a finite number"),
        "{msg}"
    );
}

#[test]
fn obj_lines_with_nan_or_inf_are_refused_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    // cube_with_vertexcolors.obj: `v x y z r g b` on lines 3..10, `vn` on 12..17.
    let p = changed(
        dir.path(),
        "meshes/misc/cube_with_vertexcolors.obj",
        "c1.obj",
        |b| {
            set_word(b, |i, _| i == 6, 2, "nan"); // line 7: the 5th `v`, its y
        },
    );
    let (e, m) = refused(&p);
    assert!(m.ends_with("c1.obj: line 7: v 4, property y: NaN"), "{m}");
    assert!(matches!(e, Error::NonFinite { index: 4, .. }));
    let p = changed(
        dir.path(),
        "meshes/misc/cube_with_vertexcolors.obj",
        "c2.obj",
        |b| {
            set_word(b, |i, _| i == 3, 4, "1e39"); // line 4: the 2nd `v`, its red
        },
    );
    let (_, m) = refused(&p);
    assert!(
        m.contains("c2.obj: line 4: v 1, property red: 1e39 (beyond the 32-bit float range)"),
        "{m}"
    );
    let p = changed(
        dir.path(),
        "meshes/misc/cube_with_vertexcolors.obj",
        "c3.obj",
        |b| {
            set_word(b, |_, l| l.starts_with("vn 0.0 1.0"), 3, "-inf");
        },
    );
    let (_, m) = refused(&p);
    assert!(
        m.ends_with("c3.obj: line 14: vn 2, property z: -inf"),
        "{m}"
    );
}

#[test]
fn gltf_buffer_with_a_nan_position_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let src = data("meshes/box-textured");
    for f in ["BoxTextured.gltf", "CesiumLogoFlat.png"] {
        std::fs::copy(src.join(f), dir.path().join(f)).unwrap();
    }
    // POSITION is accessor 2: buffer view 1 (offset 0, stride 12) at byte offset 288.
    changed(
        dir.path(),
        "meshes/box-textured/BoxTextured0.bin",
        "BoxTextured0.bin",
        |b| {
            b[288 + 3 * 12..288 + 3 * 12 + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        },
    );
    let (_, m) = refused(&dir.path().join("BoxTextured.gltf"));
    assert!(
        m.ends_with("BoxTextured.gltf: glTF mesh 0 primitive 0 vertex 3, property POSITION.x: NaN"),
        "{m}"
    );
}
