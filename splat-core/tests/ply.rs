//! 3DGS PLY reading and writing: exact round trips, other tools' layouts, clear errors.
#![allow(clippy::needless_range_loop)] // index loops mirror the maths in these checks

mod common;

use std::path::Path;

use common::{Rng, gt_path, random_splats};
use glam::Vec3;
use splat_core::{Error, Splats, ply};

#[test]
fn writing_gt_ply_reproduces_its_bytes() {
    // gt.ply is in Inria's exact layout (all float), so our writer must produce the same bytes
    // except the normals, which 3DGS does not use (Inria writes zeros; gt.ply carries real ones).
    let mut original = std::fs::read(gt_path()).unwrap();
    let body = original
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    for rec in original[body..].chunks_mut(62 * 4) {
        rec[12..24].fill(0);
    }
    let s = ply::read_splats(&gt_path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("gt_copy.ply");
    ply::write_splats(&out, &s).unwrap();
    let written = std::fs::read(&out).unwrap();
    assert_eq!(written.len(), original.len());
    assert!(written == original, "bytes differ");
    // No temporary file is left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn round_trip_is_exact_for_every_degree() {
    for degree in 0..=3 {
        let mut rng = Rng::new(u64::from(degree) + 40);
        let s = random_splats(
            &mut rng,
            57,
            Vec3::ZERO,
            3.0,
            (-5.0, 1.0),
            (0.01, 0.99),
            degree,
        );
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        ply::write_splats(&p, &s).unwrap();
        let back = ply::read_splats(&p).unwrap();
        assert_eq!(back, s, "degree {degree}");
        let header = std::fs::read(&p).unwrap();
        let text = String::from_utf8_lossy(&header[..200]);
        assert!(text.starts_with(
            "ply\nformat binary_little_endian 1.0\nelement vertex 57\nproperty float x\n"
        ));
        assert_eq!(
            std::fs::metadata(&p).unwrap().len() as usize,
            header.iter().position(|_| false).unwrap_or(header.len())
        );
    }
}

#[test]
fn f_rest_is_channel_major() {
    let mut s = Splats::new(1);
    s.push(
        Vec3::ZERO,
        Vec3::ZERO,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        &[[0.0; 3], [1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]],
    );
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("c.ply");
    ply::write_splats(&p, &s).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let body = &bytes[bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11..];
    let f: Vec<f32> = body
        .chunks(4)
        .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
        .collect();
    // x y z nx ny nz dc0 dc1 dc2, then f_rest: R of coefficients 1..3, then G, then B.
    assert_eq!(&f[9..18], &[1.0, 4.0, 7.0, 2.0, 5.0, 8.0, 3.0, 6.0, 9.0]);
}

/// Writes a PLY with the given property order, types and format, from named per-vertex values.
fn write_custom(path: &Path, props: &[(&str, &str)], rows: &[Vec<f64>], format: &str) {
    let mut out = format!("ply\nformat {format} 1.0\ncomment written by a test\nelement camera 1\nproperty float fx\nproperty list uchar int ids\nelement vertex {}\n", rows.len()).into_bytes();
    for (ty, name) in props {
        out.extend(format!("property {ty} {name}\n").bytes());
    }
    out.extend(b"element face 0\nproperty list uchar int vertex_indices\nend_header\n");
    let le = format == "binary_little_endian";
    if format == "ascii" {
        out.extend(b"500 2 7 8\n");
    } else {
        let fx = 500.0_f32;
        out.extend(if le {
            fx.to_le_bytes()
        } else {
            fx.to_be_bytes()
        });
        out.push(2);
        for id in [7_i32, 8] {
            out.extend(if le {
                id.to_le_bytes()
            } else {
                id.to_be_bytes()
            });
        }
    }
    for row in rows {
        if format == "ascii" {
            let line: Vec<String> = row.iter().map(|v| format!("{v}")).collect();
            out.extend(line.join(" ").bytes());
            out.push(b'\n');
            continue;
        }
        for ((ty, _), v) in props.iter().zip(row) {
            match *ty {
                "double" => out.extend(if le { v.to_le_bytes() } else { v.to_be_bytes() }),
                _ => out.extend(if le {
                    (*v as f32).to_le_bytes()
                } else {
                    (*v as f32).to_be_bytes()
                }),
            }
        }
    }
    std::fs::write(path, out).unwrap();
}

#[test]
fn reads_other_property_orders_doubles_no_normals_and_other_encodings() {
    // Brush-like order (rotation and scale before the colour, no normals), some doubles.
    let mut names: Vec<String> = [
        "x", "y", "z", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        "opacity", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .iter()
    .map(|s| (*s).to_string())
    .collect();
    names.extend((0..9).map(|i| format!("f_rest_{i}")));
    let props: Vec<(&str, &str)> = names
        .iter()
        .enumerate()
        .map(|(i, n)| (if i % 3 == 0 { "double" } else { "float" }, n.as_str()))
        .collect();
    let rows: Vec<Vec<f64>> = (0..5)
        .map(|v| {
            (0..names.len())
                .map(|c| (v * 100 + c) as f64 * 0.25)
                .collect()
        })
        .collect();
    for format in ["binary_little_endian", "binary_big_endian", "ascii"] {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("brush.ply");
        write_custom(&p, &props, &rows, format);
        let s = ply::read_splats(&p).unwrap();
        assert_eq!(s.len(), 5);
        assert_eq!(s.sh_degree, 1);
        for (v, row) in rows.iter().enumerate() {
            let val = |n: &str| row[names.iter().position(|m| m == n).unwrap()] as f32;
            assert_eq!(
                s.means[v],
                Vec3::new(val("x"), val("y"), val("z")),
                "{format}"
            );
            assert_eq!(
                s.log_scales[v],
                Vec3::new(val("scale_0"), val("scale_1"), val("scale_2"))
            );
            assert_eq!(
                s.rotations[v],
                [val("rot_0"), val("rot_1"), val("rot_2"), val("rot_3")]
            );
            assert_eq!(s.opacity_logits[v], val("opacity"));
            let sh = s.sh_of(v);
            assert_eq!(sh[0], [val("f_dc_0"), val("f_dc_1"), val("f_dc_2")]);
            // Channel-major: f_rest_{c·3 + j} is coefficient j + 1 of channel c.
            for j in 0..3 {
                for c in 0..3 {
                    assert_eq!(sh[j + 1][c], val(&format!("f_rest_{}", c * 3 + j)));
                }
            }
        }
    }
}

fn expect_err(bytes: &[u8], needle: &str) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.ply");
    std::fs::write(&p, bytes).unwrap();
    let e = ply::read_splats(&p).unwrap_err();
    let msg = e.to_string();
    assert!(msg.contains("bad.ply") && msg.contains(needle), "{msg}");
}

#[test]
fn bad_files_give_clear_errors() {
    let good = std::fs::read(gt_path()).unwrap();
    expect_err(&good[..good.len() - 10], "vertices of 248 bytes need");
    // Cut inside vertex 2055: named at the offset where that vertex starts (it said the body's
    // start).
    let body = good.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let cut = &good[..body + 2055 * 248 + 100];
    expect_err(
        cut,
        &format!("byte offset {} (vertex 2055)", body + 2055 * 248),
    );
    // An ASCII row with a word that is no number, at its line's offset (it said 0).
    let names = [
        "x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
        "rot_0", "rot_1", "rot_2", "rot_3",
    ];
    let properties: String = names
        .iter()
        .map(|n| format!("property float {n}\n"))
        .collect();
    let ascii = format!(
        "ply\nformat ascii 1.0\nelement vertex 2\n{properties}end_header\n{}\n0 zero {}\n",
        ["0"; 14].join(" "),
        ["0"; 12].join(" ")
    );
    let second_row = ascii.find("0 zero").unwrap();
    expect_err(
        ascii.as_bytes(),
        &format!("byte offset {second_row} (vertex 1)"),
    );
    expect_err(b"hello\n", "not a PLY");
    // A point cloud's header (no splat property at all) is named as one, without a line.
    expect_err(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000\nproperty float x\nend_header\n",
        "bad.ply: PLY header: not a 3D Gaussian Splatting model: its vertices have none of f_dc_0, opacity, scale_0, rot_0",
    );
    let header = String::from_utf8_lossy(
        &good[..good.windows(11).position(|w| w == b"end_header\n").unwrap()],
    )
    .to_string();
    let huge =
        header.replace("element vertex 4000", "element vertex 1000000000000") + "end_header\n";
    expect_err(huge.as_bytes(), "at most");
    let no_opacity = header.replace("property float opacity\n", "") + "end_header\n";
    expect_err(no_opacity.as_bytes(), "`opacity` is missing");
    let odd_rest = header.replace("property float f_rest_44\n", "") + "end_header\n";
    expect_err(odd_rest.as_bytes(), "44 f_rest");
    expect_err(
        b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n",
        "end_header",
    );
    assert!(matches!(
        ply::read_splats(Path::new("/nonexistent/x.ply")),
        Err(Error::Io { .. })
    ));
}

#[test]
fn an_ascii_element_before_the_vertices_that_claims_too_many_rows_is_an_error_not_a_hang() {
    // The ASCII path skipped the rows of earlier elements one by one, counting on past the end
    // of the text: `element face 10^18` kept it busy for ever.
    let good = std::fs::read(gt_path()).unwrap();
    let header = String::from_utf8_lossy(
        &good[..good.windows(11).position(|w| w == b"end_header\n").unwrap()],
    )
    .replace("binary_little_endian", "ascii")
    .replace(
        "element vertex 4000",
        "element face 1000000000000000000\nproperty float a\nelement vertex 1",
    );
    let bytes = format!("{header}end_header\n1\n2\n");
    let (send, receive) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = send.send(ply::parse_splats(Path::new("bad.ply"), bytes.as_bytes()).map(|_| ()));
    });
    let e = receive
        .recv_timeout(std::time::Duration::from_secs(30))
        .expect("parse_splats did not return within 30 s")
        .unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("bad.ply") && msg.contains("element `face` runs past the end of the file"),
        "{msg}"
    );
}

#[test]
fn splat_export_writes_32_bytes_per_splat_sorted_by_size_times_opacity() {
    let mut rng = Rng::new(77);
    let s = random_splats(&mut rng, 33, Vec3::ZERO, 1.0, (-3.0, 0.0), (0.1, 0.9), 2);
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.splat");
    splat_core::export::write_splat(&p, &s).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    assert_eq!(bytes.len(), 33 * 32);
    let key = |r: &[u8]| {
        let f = |o: usize| f32::from_le_bytes(r[o..o + 4].try_into().unwrap());
        f(12) * f(16) * f(20) * f32::from(r[27])
    };
    let keys: Vec<f32> = bytes.chunks(32).map(key).collect();
    assert!(
        keys.windows(2).all(|w| w[0] >= w[1] * 0.99),
        "not sorted: {keys:?}"
    );
    let first = bytes.chunks(32).next().unwrap();
    let best = (0..33).max_by(|&a, &b| {
        let k = |i: usize| {
            (s.log_scales[i].x + s.log_scales[i].y + s.log_scales[i].z).exp() * s.opacity(i)
        };
        k(a).total_cmp(&k(b))
    });
    assert_eq!(first, &splat_core::export::encode_record(&s, best.unwrap()));
}

/// `bytes` (a PLY) with `comments` inserted as header lines after its format line.
fn with_comments(bytes: &[u8], comments: &[&str]) -> Vec<u8> {
    let format_end = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
    let format_end = format_end
        + bytes[format_end..]
            .iter()
            .position(|&b| b == b'\n')
            .unwrap()
        + 1;
    let mut out = bytes[..format_end].to_vec();
    for c in comments {
        out.extend_from_slice(format!("comment {c}\n").as_bytes());
    }
    out.extend_from_slice(&bytes[format_end..]);
    out
}

#[test]
fn an_antialiased_model_says_so_in_brush_s_header_comment() {
    let s = ply::read_splats(&gt_path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (aa, plain) = (dir.path().join("aa.ply"), dir.path().join("plain.ply"));
    ply::write_model(&aa, &s, &ply::PlyOptions { antialiased: true }).unwrap();
    ply::write_model(&plain, &s, &ply::PlyOptions::default()).unwrap();
    let (aa_bytes, plain_bytes) = (std::fs::read(&aa).unwrap(), std::fs::read(&plain).unwrap());
    // The tagged file is the plain one with exactly one header line more.
    assert_eq!(
        aa_bytes,
        with_comments(&plain_bytes, &["SplatRenderMode: mip"])
    );
    let back = ply::read_model(&aa).unwrap();
    assert!(back.antialiased);
    assert_eq!(back.splats, s);
    assert!(!ply::read_model(&plain).unwrap().antialiased);
}

#[test]
fn render_mode_comments_are_read_as_brush_postshot_and_splat_transform_write_them() {
    let s = ply::read_splats(&gt_path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.ply");
    ply::write_splats(&p, &s).unwrap();
    let plain = std::fs::read(&p).unwrap();
    let cases: [(&[&str], bool); 12] = [
        (&[], false),
        (
            &[
                "Exported from Brush",
                "SH degree: 3",
                "SplatRenderMode: mip",
            ],
            true,
        ),
        (&["SplatRenderMode: default"], false),
        (&["SplatRenderMode: 2dgs"], false),
        (&["  SPLATRENDERMODE:  MIP  "], true),
        (&["antialiased 1"], true),
        (&["antialiased 0"], false),
        (&["postshot.anti_aliasing=1"], true),
        (&["SplatRenderMode: banana"], false),
        // The last comment that names a mode decides; others do not reset it.
        (&["antialiased 1", "SplatRenderMode: default"], false),
        (
            &["SplatRenderMode: default", "antialiased 1", "made by hand"],
            true,
        ),
        (&["antialiasedness 1", "SplatRenderMode mip"], false),
    ];
    for (comments, want) in cases {
        let m = ply::parse_model(Path::new("c.ply"), &with_comments(&plain, comments)).unwrap();
        assert_eq!(m.antialiased, want, "{comments:?}");
        assert_eq!(m.splats, s);
    }
}
