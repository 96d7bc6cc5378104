//! PLY cloud reader/writer: bit-exact round trips in every format and layout, ply-rs-bw as an
//! independent oracle, rig comments, plenoptic PLY meshes, and the refusal of bad files.

use std::path::Path;

use glam::{DVec3, Vec3};
use plenoptic_io::{
    CaptureCamera, Error, ExtraProperty, Model, PlenopticCloud, PlyFormat, PlyLayout, ScalarType,
    load, read_cloud, read_mesh, write_cloud,
};
use proptest::prelude::*;

/// A tiny deterministic generator so that test data depend only on a seed.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        // SplitMix64.
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// The layout parameters a test varies.
#[derive(Debug, Clone, Copy)]
struct Spec {
    n: usize,
    cameras: usize,
    format: PlyFormat,
    position: ScalarType,
    color: ScalarType,
    normals: bool,
    main_color: bool,
    rig: bool,
    extra: bool,
    seed: u64,
}

/// A colour value that the given type stores exactly, as the reader normalises it.
fn color_value(rng: &mut Rng, ty: ScalarType) -> f32 {
    match ty {
        ScalarType::U8 => rng.below(256) as f32 / 255.0,
        ScalarType::U16 => rng.below(65536) as f32 / 65535.0,
        _ => rng.unit(),
    }
}

/// A cloud following `spec`, with its layout set (properties shuffled by the seed).
fn make_cloud(spec: Spec) -> PlenopticCloud {
    let mut rng = Rng(spec.seed);
    let coord = |rng: &mut Rng| match spec.position {
        ScalarType::F32 | ScalarType::F64 => (rng.unit() - 0.5) * 8000.0,
        _ => rng.below(4096) as f32,
    };
    let positions: Vec<Vec3> = (0..spec.n)
        .map(|_| Vec3::new(coord(&mut rng), coord(&mut rng), coord(&mut rng)))
        .collect();
    let normals = spec.normals.then(|| {
        (0..spec.n)
            .map(|_| Vec3::new(rng.unit(), -rng.unit(), rng.unit()))
            .collect()
    });
    let color3 = |rng: &mut Rng| {
        [
            color_value(rng, spec.color),
            color_value(rng, spec.color),
            color_value(rng, spec.color),
        ]
    };
    let colors: Vec<[f32; 3]> = (0..spec.n).map(|_| color3(&mut rng)).collect();
    let camera_colors: Vec<[f32; 3]> = (0..spec.n * spec.cameras)
        .map(|_| color3(&mut rng))
        .collect();
    let mut properties: Vec<(String, ScalarType)> = ["x", "y", "z"]
        .iter()
        .map(|s| (s.to_string(), spec.position))
        .collect();
    if spec.normals {
        properties.extend(
            ["nx", "ny", "nz"]
                .iter()
                .map(|s| (s.to_string(), ScalarType::F32)),
        );
    }
    if spec.main_color {
        properties.extend(
            ["red", "green", "blue"]
                .iter()
                .map(|s| (s.to_string(), spec.color)),
        );
    }
    for k in 0..spec.cameras {
        properties.extend(
            ["red", "green", "blue"]
                .iter()
                .map(|s| (format!("{s}{k}"), spec.color)),
        );
    }
    let extra = if spec.extra {
        properties.push(("psz".into(), ScalarType::I16));
        vec![ExtraProperty {
            name: "psz".into(),
            values: (0..spec.n)
                .map(|_| rng.below(2000) as f64 - 1000.0)
                .collect(),
        }]
    } else {
        Vec::new()
    };
    // Any property order must work: Fisher–Yates with the seed.
    for i in (1..properties.len()).rev() {
        properties.swap(i, rng.below(i as u64 + 1) as usize);
    }
    let scale = 0.179523;
    let translation = DVec3::new(-45.2095, 7.18301, -54.3561);
    let cameras = if spec.rig {
        (0..spec.cameras)
            .map(|_| {
                let m: [f64; 16] = std::array::from_fn(|_| (f64::from(rng.unit()) - 0.5) * 400.0);
                CaptureCamera {
                    position: (DVec3::new(m[12], m[13], m[14]) - translation) / scale,
                    matrix: Some(m),
                }
            })
            .collect()
    } else {
        Vec::new()
    };
    let colors = if spec.main_color {
        colors
    } else if spec.cameras > 0 {
        // The reader's documented fallback: the mean of the camera colours.
        camera_colors
            .chunks_exact(spec.cameras)
            .map(|c| {
                let mut s = [0.0f32; 3];
                for v in c {
                    for i in 0..3 {
                        s[i] += v[i];
                    }
                }
                s.map(|x| x / spec.cameras as f32)
            })
            .collect()
    } else {
        vec![[0.5; 3]; spec.n]
    };
    PlenopticCloud {
        positions,
        normals,
        colors,
        num_cameras: spec.cameras,
        camera_colors,
        cameras,
        frame_to_world_scale: spec.rig.then_some(scale),
        frame_to_world_translation: spec.rig.then_some(translation),
        width: spec.rig.then_some(4095),
        extra,
        layout: Some(PlyLayout {
            format: spec.format,
            properties,
            comments: vec!["Version 2, Copyright 2017, 8i Labs, Inc.".into()],
        }),
    }
}

fn round_trip(spec: Spec) {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.ply");
    let b = dir.path().join("b.ply");
    let cloud = make_cloud(spec);
    write_cloud(&a, &cloud).unwrap();
    let read = read_cloud(&a).unwrap();
    assert_eq!(read, cloud, "{spec:?}");
    write_cloud(&b, &read).unwrap();
    assert_eq!(
        std::fs::read(&a).unwrap(),
        std::fs::read(&b).unwrap(),
        "{spec:?}"
    );
}

const FORMATS: [PlyFormat; 3] = [
    PlyFormat::Ascii,
    PlyFormat::BinaryLittleEndian,
    PlyFormat::BinaryBigEndian,
];

#[test]
fn round_trip_is_bit_exact_in_every_format_and_colour_type() {
    for format in FORMATS {
        for color in [
            ScalarType::U8,
            ScalarType::U16,
            ScalarType::F32,
            ScalarType::F64,
        ] {
            for (cameras, position) in [
                (13, ScalarType::F32),
                (0, ScalarType::F64),
                (20, ScalarType::U16),
            ] {
                round_trip(Spec {
                    n: 300,
                    cameras,
                    format,
                    position,
                    color,
                    normals: true,
                    main_color: true,
                    rig: cameras > 0,
                    extra: true,
                    seed: cameras as u64 * 7 + 1,
                });
            }
        }
    }
}

#[test]
fn large_binary_cloud_round_trips_through_parallel_chunks() {
    // More points than one parallel chunk, 13 cameras as in 8iVSLF.
    round_trip(Spec {
        n: 70_000,
        cameras: 13,
        format: PlyFormat::BinaryLittleEndian,
        position: ScalarType::F32,
        color: ScalarType::U8,
        normals: true,
        main_color: true,
        rig: true,
        extra: false,
        seed: 5,
    });
}

#[test]
fn default_layout_is_the_8ivslf_layout() {
    let mut cloud = make_cloud(Spec {
        n: 10,
        cameras: 13,
        format: PlyFormat::BinaryLittleEndian,
        position: ScalarType::F32,
        color: ScalarType::U8,
        normals: true,
        main_color: true,
        rig: true,
        extra: false,
        seed: 9,
    });
    cloud.layout = None;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.ply");
    write_cloud(&path, &cloud).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let header_len = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    // 66 bytes a point: float x y z, float nx ny nz, uchar rgb, 13 × uchar rgb (formats.md §1.3).
    assert_eq!(bytes.len() - header_len, 10 * 66);
    let read = read_cloud(&path).unwrap();
    assert_eq!(read.positions, cloud.positions);
    assert_eq!(read.camera_colors, cloud.camera_colors);
    assert_eq!(read.cameras, cloud.cameras);
    assert_eq!(read.width, Some(4095));
}

#[test]
fn camera_without_matrix_is_written_with_its_centre() {
    let mut cloud = make_cloud(Spec {
        n: 4,
        cameras: 2,
        format: PlyFormat::Ascii,
        position: ScalarType::F32,
        color: ScalarType::U8,
        normals: false,
        main_color: true,
        rig: true,
        extra: false,
        seed: 3,
    });
    cloud.frame_to_world_scale = Some(0.5);
    cloud.frame_to_world_translation = Some(DVec3::new(1.0, 2.0, 3.0));
    cloud.cameras = vec![
        CaptureCamera {
            position: DVec3::new(100.0, 200.0, -300.0),
            matrix: None,
        },
        CaptureCamera {
            position: DVec3::new(-4.0, 0.0, 8.0),
            matrix: None,
        },
    ];
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.ply");
    write_cloud(&path, &cloud).unwrap();
    let text = String::from_utf8(std::fs::read(&path).unwrap()).unwrap();
    // world = voxel · 0.5 + (1, 2, 3) in values 12..14.
    assert!(
        text.contains("comment rig_matrix_0 1 0 0 0 0 1 0 0 0 0 1 0 51 102 -147 1\n"),
        "{text}"
    );
    let read = read_cloud(&path).unwrap();
    assert_eq!(read.cameras[1].position, DVec3::new(-4.0, 0.0, 8.0));
}

/// One vertex as ply-rs-bw reads it: property name → value.
type Row = std::collections::HashMap<String, f64>;

/// The values ply-rs-bw reads for every vertex property, as f64.
fn oracle(path: &Path) -> Vec<Row> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::{DefaultElement, Property};
    let mut f = std::fs::File::open(path).unwrap();
    let ply = Parser::<DefaultElement>::new().read_ply(&mut f).unwrap();
    ply.payload["vertex"]
        .iter()
        .map(|e| {
            e.iter()
                .map(|(k, v)| {
                    let x = match v {
                        Property::Char(x) => f64::from(*x),
                        Property::UChar(x) => f64::from(*x),
                        Property::Short(x) => f64::from(*x),
                        Property::UShort(x) => f64::from(*x),
                        Property::Int(x) => f64::from(*x),
                        Property::UInt(x) => f64::from(*x),
                        Property::Float(x) => f64::from(*x),
                        Property::Double(x) => *x,
                        other => panic!("unexpected list {other:?}"),
                    };
                    (k.clone(), x)
                })
                .collect()
        })
        .collect()
}

#[test]
fn agrees_with_ply_rs_bw_on_every_value() {
    for format in FORMATS {
        for color in [ScalarType::U8, ScalarType::U16, ScalarType::F32] {
            let cloud = make_cloud(Spec {
                n: 200,
                cameras: 12,
                format,
                position: ScalarType::F32,
                color,
                normals: true,
                main_color: true,
                rig: true,
                extra: true,
                seed: 11,
            });
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("o.ply");
            write_cloud(&path, &cloud).unwrap();
            let ours = read_cloud(&path).unwrap();
            let theirs = oracle(&path);
            assert_eq!(theirs.len(), ours.len());
            let scale = match color {
                ScalarType::U8 => 255.0,
                ScalarType::U16 => 65535.0,
                _ => 1.0,
            };
            for (i, row) in theirs.iter().enumerate() {
                for (c, axis) in ["x", "y", "z"].iter().enumerate() {
                    assert_eq!(row[*axis] as f32, ours.positions[i][c]);
                    assert_eq!(
                        row[&format!("n{axis}")] as f32,
                        ours.normals.as_ref().unwrap()[i][c]
                    );
                }
                for (c, ch) in ["red", "green", "blue"].iter().enumerate() {
                    assert_eq!(row[*ch] as f32 / scale as f32, ours.colors[i][c]);
                    for k in 0..12 {
                        assert_eq!(
                            row[&format!("{ch}{k}")] as f32 / scale as f32,
                            ours.camera_colors_of(i)[k][c]
                        );
                    }
                }
                assert_eq!(row["psz"], ours.extra[0].values[i]);
            }
        }
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn header_promising_more_than_the_file_holds_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cloud = make_cloud(Spec {
        n: 100,
        cameras: 13,
        format: PlyFormat::BinaryLittleEndian,
        position: ScalarType::F32,
        color: ScalarType::U8,
        normals: true,
        main_color: true,
        rig: false,
        extra: false,
        seed: 1,
    });
    let full = dir.path().join("full.ply");
    write_cloud(&full, &cloud).unwrap();
    let mut bytes = std::fs::read(&full).unwrap();
    bytes.pop();
    let p = write(dir.path(), "short.ply", &bytes);
    match read_cloud(&p).unwrap_err() {
        Error::Truncated {
            element,
            count,
            needed,
            available,
            ..
        } => {
            assert_eq!(
                (element.as_str(), count, needed, available),
                ("vertex", 100, 6600, 6599)
            );
        }
        e => panic!("{e}"),
    }
    // 10^15 promised vertices must fail at once, without trying to allocate petabytes.
    let p = write(dir.path(), "huge.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0");
    assert!(matches!(
        read_cloud(&p).unwrap_err(),
        Error::Truncated {
            count: 1_000_000_000_000_000,
            ..
        }
    ));
    let p = write(dir.path(), "huge.ply", b"ply\nformat ascii 1.0\nelement vertex 4000000000\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n");
    assert!(matches!(
        read_cloud(&p).unwrap_err(),
        Error::Truncated { .. }
    ));
    // Found by cargo-fuzz: a fixed-size vertex element after a face element whose lists use more
    // than the minimum the up-front check assumes; the records must be bounds-checked too.
    let mut text = b"ply\nformat binary_little_endian 1.0\nelement face 2\nproperty list uchar int vertex_indices\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    text.push(3);
    text.extend([0u8; 12]);
    text.push(3);
    text.extend([0u8; 12]);
    text.extend([0u8; 14]);
    let p = write(dir.path(), "lists.ply", &text);
    match read_cloud(&p).unwrap_err() {
        Error::Truncated {
            element,
            needed,
            available,
            ..
        } => assert_eq!((element.as_str(), needed, available), ("vertex", 36, 14)),
        e => panic!("{e}"),
    }
    // The smallest possible ASCII body (one-character values, no final newline) is accepted.
    let p = write(dir.path(), "tight.ply", b"ply\nformat ascii 1.0\nelement vertex 2\nproperty uchar x\nproperty uchar y\nproperty uchar z\nend_header\n1 2 3\n4 5 6");
    assert_eq!(
        read_cloud(&p).unwrap().positions[1],
        Vec3::new(4.0, 5.0, 6.0)
    );
    let p = write(dir.path(), "rows.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6 7 8 9 1 2 3\n");
    let e = read_cloud(&p).unwrap_err().to_string();
    assert!(
        e.contains("vertex 1 (line 9)") && e.contains("\"7\""),
        "{e}"
    );
}

#[test]
fn first_non_finite_coordinate_is_reported_with_its_index() {
    let dir = tempfile::tempdir().unwrap();
    for format in FORMATS {
        let mut cloud = make_cloud(Spec {
            n: 50_000,
            cameras: 2,
            format,
            position: ScalarType::F32,
            color: ScalarType::U8,
            normals: false,
            main_color: true,
            rig: false,
            extra: false,
            seed: 2,
        });
        cloud.positions[40_321].y = f32::NAN;
        cloud.positions[40_999].x = f32::INFINITY;
        let p = dir.path().join("nan.ply");
        write_cloud(&p, &cloud).unwrap();
        match read_cloud(&p).unwrap_err() {
            Error::NonFinite { index, what, .. } => {
                assert_eq!((index, what.as_str()), (40_321, "vertex"))
            }
            e => panic!("{e}"),
        }
    }
}

#[test]
fn rig_comments_that_disagree_with_the_colours_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let m = ["0"; 16].join(" ");
    let body = "1 2 3 10 20 30 40 50 60\n";
    let head = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red0\nproperty uchar green0\nproperty uchar blue0\nproperty uchar red1\nproperty uchar green1\nproperty uchar blue1\nend_header\n";
    let with = |comments: &str| {
        format!(
            "ply\nformat ascii 1.0\n{comments}{}{body}",
            &head["ply\nformat ascii 1.0\n".len()..]
        )
    };
    let p = write(
        dir.path(),
        "count.ply",
        with(&format!("comment rig_count 3\ncomment rig_matrix_0 {m}\n")).as_bytes(),
    );
    let e = read_cloud(&p).unwrap_err().to_string();
    assert!(
        e.contains("rig_count is 3 but the vertex element has colours for 2 camera(s)"),
        "{e}"
    );
    let p = write(
        dir.path(),
        "missing.ply",
        with(&format!("comment rig_count 2\ncomment rig_matrix_0 {m}\n")).as_bytes(),
    );
    let e = read_cloud(&p).unwrap_err().to_string();
    assert!(e.contains("camera 1 of 2 has no rig_matrix_1"), "{e}");
    let p = write(
        dir.path(),
        "ok.ply",
        with(&format!(
            "comment rig_count 2\ncomment rig_matrix_0 {m}\ncomment rig_matrix_1 {m}\n"
        ))
        .as_bytes(),
    );
    let cloud = read_cloud(&p).unwrap();
    assert_eq!(
        cloud.camera_colors,
        vec![
            [10.0 / 255.0, 20.0 / 255.0, 30.0 / 255.0],
            [40.0 / 255.0, 50.0 / 255.0, 60.0 / 255.0]
        ]
    );
    // No main colour in the file: the mean of the camera colours.
    assert_eq!(
        cloud.colors,
        vec![[25.0 / 255.0, 35.0 / 255.0, 45.0 / 255.0]]
    );
    let p = write(
        dir.path(),
        "hole.ply",
        head.replace("red1", "red2").as_bytes(),
    );
    assert!(read_cloud(&p).is_err());
}

#[test]
fn plenoptic_ply_mesh_has_per_vertex_camera_colours_and_load_chooses_by_faces() {
    let dir = tempfile::tempdir().unwrap();
    let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
        property float s\nproperty float t\nproperty uchar red0\nproperty uchar green0\nproperty uchar blue0\n\
        property uchar red1\nproperty uchar green1\nproperty uchar blue1\nelement face 1\nproperty list uchar int vertex_index\nend_header\n\
        0 0 0 0 0 255 0 0 0 0 255\n1 0 0 1 0 0 255 0 0 0 255\n1 1 0 1 1 0 0 255 0 0 255\n0 1 0 0 1 255 255 255 0 0 255\n4 0 1 2 3\n";
    let p = write(dir.path(), "quad.ply", text.as_bytes());
    let mesh = read_mesh(&p).unwrap();
    assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    assert_eq!(mesh.num_cameras, 2);
    assert_eq!(
        mesh.camera_colors_of(1),
        &[[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    // PLY t grows upwards; Mesh UVs have (0, 0) at the top-left.
    assert_eq!(mesh.uvs.as_ref().unwrap()[3], glam::Vec2::new(0.0, 0.0));
    assert!(matches!(load(&p).unwrap(), Model::Mesh(_)));
    let no_faces = text
        .replace("element face 1", "element face 0")
        .replace("4 0 1 2 3\n", "");
    let p = write(dir.path(), "nofaces.ply", no_faces.as_bytes());
    assert!(matches!(load(&p).unwrap(), Model::Cloud(c) if c.len() == 4 && c.num_cameras == 2));
    let bad = text.replace("4 0 1 2 3", "4 0 1 2 9");
    let p = write(dir.path(), "badface.ply", bad.as_bytes());
    // Named at its line (the 17 header lines, 4 vertex rows, then the face's).
    let e = read_mesh(&p).unwrap_err().to_string();
    assert!(
        e.contains("badface.ply")
            && e.contains("line 22")
            && e.contains("vertex index 9, but there are only 4 vertices"),
        "{e}"
    );
    // Faces written before their vertices are checked once both are read.
    let face_first = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_index\n\
         element vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n\
         3 0 1 7\n0 0 0\n1 0 0\n0 1 0\n";
    let p = write(dir.path(), "facefirst.ply", face_first.as_bytes());
    let e = read_mesh(&p).unwrap_err();
    assert!(
        matches!(
            e,
            Error::IndexOutOfRange {
                vertex: 7,
                count: 3,
                ..
            }
        ),
        "{e}"
    );
}

fn spec_strategy() -> impl Strategy<Value = Spec> {
    (
        0usize..40,
        0usize..16,
        prop::sample::select(FORMATS.to_vec()),
        prop::sample::select(vec![
            ScalarType::F32,
            ScalarType::F64,
            ScalarType::I32,
            ScalarType::U16,
        ]),
        prop::sample::select(vec![
            ScalarType::U8,
            ScalarType::U16,
            ScalarType::F32,
            ScalarType::F64,
        ]),
        any::<[bool; 4]>(),
        any::<u64>(),
    )
        .prop_map(|(n, cameras, format, position, color, flags, seed)| Spec {
            n,
            cameras,
            format,
            position,
            color,
            normals: flags[0],
            main_color: flags[1],
            rig: flags[2] && cameras > 0,
            extra: flags[3],
            seed,
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn any_layout_round_trips_bit_exactly(spec in spec_strategy()) {
        round_trip(spec);
    }

    /// Mutated headers and payloads never panic: every outcome is Ok or a typed error.
    #[test]
    fn mutated_files_never_panic(
        spec in spec_strategy(),
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>(), 0u8..4), 1..6),
        cut in any::<prop::sample::Index>(),
        truncate in any::<bool>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        write_cloud(&p, &make_cloud(spec)).unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        for (at, value, kind) in edits {
            let i = at.index(bytes.len());
            match kind {
                0 => bytes[i] = value,
                1 => bytes.insert(i, value),
                2 => { bytes.remove(i); }
                // Digits in the header change counts and indices: the interesting mutations.
                _ => bytes[i] = b'0' + value % 10,
            }
        }
        if truncate {
            bytes.truncate(cut.index(bytes.len() + 1));
        }
        std::fs::write(&p, &bytes).unwrap();
        let _ = read_cloud(&p);
        let _ = load(&p);
        let _ = read_mesh(&p);
    }
}
