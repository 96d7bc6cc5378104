//! NaN and infinities in the real 3DGS file testdata/splat-scene/gt.ply, each changed in one
//! value: every splat attribute is refused with the file, the vertex and the property.

use std::path::{Path, PathBuf};

use splat_core::Error;
use splat_core::ply::{parse_splats, read_splats};

fn gt() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene/gt.ply"
    ))
}

/// Header (up to and including `end_header\n`) and body of gt.ply, and its property names.
fn split(bytes: &[u8]) -> (usize, Vec<String>) {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let names = String::from_utf8_lossy(&bytes[..end])
        .lines()
        .filter_map(|l| l.strip_prefix("property float "))
        .map(str::to_string)
        .collect();
    (end, names)
}

fn message(path: &Path, bytes: &[u8]) -> (Error, String) {
    let e = parse_splats(path, bytes).unwrap_err();
    let m = e.to_string();
    (e, m)
}

#[test]
fn every_attribute_of_a_binary_file_is_checked() {
    let bytes = std::fs::read(gt()).unwrap();
    let (body, names) = split(&bytes);
    assert_eq!(names.len(), 62);
    let stride = 4 * names.len();
    let path = Path::new("gt.ply");
    let cases = [
        ("x", 0usize, f32::NAN),
        ("z", 17, f32::INFINITY),
        ("f_dc_1", 3999, f32::NAN),
        ("f_rest_0", 5, f32::NEG_INFINITY),
        ("f_rest_44", 1234, f32::NAN),
        ("opacity", 2000, f32::INFINITY),
        ("scale_2", 42, f32::NAN),
        ("rot_3", 3000, f32::NAN),
    ];
    for (name, vertex, value) in cases {
        let column = names.iter().position(|n| n == name).unwrap();
        let mut bad = bytes.clone();
        let at = body + vertex * stride + 4 * column;
        bad[at..at + 4].copy_from_slice(&value.to_le_bytes());
        let (e, m) = message(path, &bad);
        assert!(
            matches!(&e, Error::NonFinite { index, property, .. } if *index == vertex && property == name),
            "{m}"
        );
        assert_eq!(
            m,
            format!("gt.ply: vertex {vertex}, property {name}: {value}")
        );
    }
    // Normals are not part of a splat (Inria writes zeros): a NaN there is not an error.
    let nx = names.iter().position(|n| n == "nx").unwrap();
    let mut bad = bytes.clone();
    bad[body + 4 * nx..body + 4 * nx + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_eq!(parse_splats(path, &bad).unwrap().len(), 4000);
}

#[test]
fn ascii_and_double_files_are_checked_and_the_file_is_named() {
    let bytes = std::fs::read(gt()).unwrap();
    let (body, names) = split(&bytes);
    let stride = 4 * names.len();
    // The first three splats of gt.ply as ASCII with double opacity; vertex 2's rot_0 is NaN.
    let header = String::from_utf8_lossy(&bytes[..body])
        .replace("binary_little_endian", "ascii")
        .replace("element vertex 4000", "element vertex 3")
        .replace("property float opacity", "property double opacity");
    let rows: Vec<String> = (0..3)
        .map(|v| {
            (0..names.len())
                .map(|c| {
                    let at = body + v * stride + 4 * c;
                    let x = f32::from_le_bytes(bytes[at..at + 4].try_into().unwrap());
                    if v == 2 && names[c] == "rot_0" {
                        "nan".to_string()
                    } else {
                        x.to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect();
    let text = format!("{header}{}\n", rows.join("\n"));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("three.ply");
    std::fs::write(&path, &text).unwrap();
    let m = read_splats(&path).unwrap_err().to_string();
    assert_eq!(
        m,
        format!("{}: vertex 2, property rot_0: NaN", path.display())
    );
    // A double beyond the f32 range is refused too, with the value as written.
    let text = text.replace("nan", "0").replacen(
        &rows[1],
        &{
            let mut words: Vec<&str> = rows[1].split(' ').collect();
            let c = names.iter().position(|n| n == "opacity").unwrap();
            words[c] = "1e300";
            words.join(" ")
        },
        1,
    );
    std::fs::write(&path, &text).unwrap();
    let m = read_splats(&path).unwrap_err().to_string();
    assert!(
        m.ends_with("three.ply: vertex 1, property opacity: 1e300"),
        "{m}"
    );
    // With the value back in range, the three splats read and match gt.ply's.
    let good = text.replace("1e300", "0.5");
    std::fs::write(&path, &good).unwrap();
    let s = read_splats(&path).unwrap();
    let all = read_splats(&gt()).unwrap();
    assert_eq!(s.means[..], all.means[..3]);
}
