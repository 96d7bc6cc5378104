//! NaN and infinities in a real COLMAP model (testdata/colmap/maupertuis), each changed in one
//! value, in the text and in the binary files: refused with the file, the place and the field.

use std::path::{Path, PathBuf};

use colmap_io::{Error, Format, Location, Problem, read_model, read_model_as, write_model};

fn maupertuis() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/colmap/maupertuis/sparse/0"
    ))
}

/// The maupertuis text model copied into `dir` with word `k` (0-based) of 1-based line `line`
/// of `file` replaced by `value`.
fn text_with(dir: &Path, file: &str, line: usize, k: usize, value: &str) {
    for f in ["cameras.txt", "images.txt", "points3D.txt"] {
        let text = std::fs::read_to_string(maupertuis().join(f)).unwrap();
        let text = if f == file {
            let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
            let mut words: Vec<&str> = lines[line - 1].split(' ').collect();
            words[k] = value;
            lines[line - 1] = words.join(" ");
            lines.join("\n") + "\n"
        } else {
            text
        };
        std::fs::write(dir.join(f), text).unwrap();
    }
}

/// The error of reading `dir`, checked to be a located `NonFinite` of `file`.
fn refused(dir: &Path, format: Format, file: &str) -> (Location, Problem, String) {
    let err = read_model_as(dir, format).unwrap_err();
    let message = err.to_string();
    match err {
        Error::Format {
            path,
            location,
            problem: problem @ Problem::NonFinite { .. },
        } => {
            assert_eq!(path, dir.join(file), "{message}");
            (location, problem, message)
        }
        other => panic!("expected a non-finite format error, got {other}"),
    }
}

#[test]
fn text_model_refuses_nan_and_inf_with_file_line_and_field() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The good copy reads.
    text_with(dir, "cameras.txt", 4, 5, "539.5");
    assert_eq!(read_model(dir).unwrap().points3d.len(), 1039);

    // cameras.txt line 4: `1 SIMPLE_PINHOLE 1919 1079 1847.53 959.5 539.5`; cx becomes NaN.
    text_with(dir, "cameras.txt", 4, 5, "nan");
    let (loc, problem, m) = refused(dir, Format::Text, "cameras.txt");
    assert_eq!(loc, Location::Line(4));
    assert!(
        m.ends_with("cameras.txt: line 4: camera 1, PARAMS[1] (cx): NaN is not a finite number"),
        "{m}"
    );
    assert!(matches!(
        problem,
        Problem::NonFinite {
            record: "camera",
            id: 1,
            ..
        }
    ));

    // images.txt line 5: `4 QW QX QY QZ TX TY TZ 1 03.jpg`; QX becomes inf.
    text_with(dir, "images.txt", 5, 2, "inf");
    let (loc, _, m) = refused(dir, Format::Text, "images.txt");
    assert_eq!(loc, Location::Line(5));
    assert!(
        m.ends_with("image 4, QX: inf is not a finite number"),
        "{m}"
    );
    // … and TZ becomes -inf.
    text_with(dir, "images.txt", 5, 7, "-inf");
    let (_, _, m) = refused(dir, Format::Text, "images.txt");
    assert!(
        m.ends_with("image 4, TZ: -inf is not a finite number"),
        "{m}"
    );

    // points3D.txt line 5: `707 X Y Z …`; Y becomes NaN.
    text_with(dir, "points3D.txt", 5, 2, "NaN");
    let (loc, _, m) = refused(dir, Format::Text, "points3D.txt");
    assert_eq!(loc, Location::Line(5));
    assert!(
        m.ends_with("point3D 707, Y: NaN is not a finite number"),
        "{m}"
    );
}

#[test]
fn binary_model_refuses_nan_and_inf_at_the_field_offset() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = read_model(&maupertuis()).unwrap();
    let dir = tmp.path();
    write_model(dir, &rec, Format::Binary).unwrap();
    let patch = |file: &str, at: usize, value: f64| {
        let good = std::fs::read(dir.join(file)).unwrap();
        let mut bad = good.clone();
        bad[at..at + 8].copy_from_slice(&value.to_le_bytes());
        std::fs::write(dir.join(file), bad).unwrap();
        good
    };
    // cameras.bin: count (8), then camera 1: id 4, model 4, width 8, height 8, params (f cx cy).
    let good = patch("cameras.bin", 8 + 24 + 16, f64::NAN);
    let (loc, _, m) = refused(dir, Format::Binary, "cameras.bin");
    assert_eq!(loc, Location::Offset(48));
    assert!(
        m.ends_with("camera 1, PARAMS[2] (cy): NaN is not a finite number"),
        "{m}"
    );
    std::fs::write(dir.join("cameras.bin"), good).unwrap();

    // images.bin: count (8), then the image with the lowest id: id 4, QW QX QY QZ TX TY TZ.
    let first_image = *rec.images.keys().next().unwrap();
    let good = patch("images.bin", 8 + 4 + 8 * 5, f64::INFINITY);
    let (loc, _, m) = refused(dir, Format::Binary, "images.bin");
    assert_eq!(loc, Location::Offset(52));
    assert!(
        m.ends_with(&format!(
            "image {first_image}, TY: inf is not a finite number"
        )),
        "{m}"
    );
    std::fs::write(dir.join("images.bin"), good).unwrap();

    // points3D.bin: count (8), then the point with the lowest id: id 8, X Y Z.
    let first_point = *rec.points3d.keys().next().unwrap();
    patch("points3D.bin", 8 + 8 + 16, f64::NEG_INFINITY);
    let (loc, _, m) = refused(dir, Format::Binary, "points3D.bin");
    assert_eq!(loc, Location::Offset(32));
    assert!(
        m.ends_with(&format!(
            "point3D {first_point}, Z: -inf is not a finite number"
        )),
        "{m}"
    );
}

/// Found by an adversarial sweep: an image whose quaternion is `0 0 0 0` was read, and training
/// then normalised it into NaNs. Text and binary refuse it at the image's line or QW's offset.
#[test]
fn a_zero_quaternion_is_refused_in_both_formats() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // images.txt line 5: `4 QW QX QY QZ TX TY TZ 1 03.jpg`; the quaternion becomes zero.
    text_with(dir, "images.txt", 5, 1, "0");
    let text = std::fs::read_to_string(dir.join("images.txt")).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let mut words: Vec<String> = lines[4].split(' ').map(str::to_string).collect();
    for w in &mut words[1..=4] {
        *w = "0".into();
    }
    lines[4] = words.join(" ");
    std::fs::write(dir.join("images.txt"), lines.join("\n") + "\n").unwrap();
    let err = read_model_as(dir, Format::Text).unwrap_err();
    let m = err.to_string();
    assert!(
        m.contains(
            "images.txt: line 5: image 4, QW QX QY QZ: [0.0, 0.0, 0.0, 0.0] is not a rotation"
        ),
        "{m}"
    );

    let bin = tmp.path().join("bin");
    std::fs::create_dir(&bin).unwrap();
    let mut rec = read_model(&maupertuis()).unwrap();
    let first = *rec.images.keys().next().unwrap();
    rec.images.get_mut(&first).unwrap().qvec = [0.0; 4];
    write_model(&bin, &rec, Format::Binary).unwrap();
    let err = read_model_as(&bin, Format::Binary).unwrap_err();
    let m = err.to_string();
    // QW follows the count (8 bytes) and the image id (4 bytes).
    assert!(m.contains("images.bin: byte offset 12"), "{m}");
    assert!(m.contains("is not a rotation"), "{m}");
}

/// A camera with no pixels or a focal length that is not positive was read (`colmap info`
/// listed it; only training refused it): each is refused at its line or its bytes.
#[test]
fn cameras_without_pixels_or_focal_length_are_refused_where_they_are() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // cameras.txt line 4: `1 SIMPLE_PINHOLE 1919 1079 1847.53 959.5 539.5`.
    for (k, value, expected) in [
        (
            2,
            "0",
            "line 4: camera 1, WIDTH × HEIGHT: 0 × 1079 is not an image size",
        ),
        (
            3,
            "0",
            "line 4: camera 1, WIDTH × HEIGHT: 1919 × 0 is not an image size",
        ),
        (
            4,
            "0",
            "line 4: camera 1, PARAMS[0] (f): 0 is not a focal length; it must be positive",
        ),
        (
            4,
            "-1847.53",
            "line 4: camera 1, PARAMS[0] (f): -1847.53 is not a focal length; it must be positive",
        ),
    ] {
        text_with(dir, "cameras.txt", 4, k, value);
        let m = read_model_as(dir, Format::Text).unwrap_err().to_string();
        assert!(m.ends_with(expected), "{m}");
    }
    // A negative principal point is a camera (an off-centre crop): read.
    text_with(dir, "cameras.txt", 4, 5, "-20");
    assert!(read_model_as(dir, Format::Text).is_ok());

    let bin = tempfile::tempdir().unwrap();
    let rec = read_model(&maupertuis()).unwrap();
    write_model(bin.path(), &rec, Format::Binary).unwrap();
    let good = std::fs::read(bin.path().join("cameras.bin")).unwrap();
    // cameras.bin: count (8), then camera 1: id 4, model 4, width 8, height 8, params (f cx cy).
    for (at, bytes, offset, expected) in [
        (16, 0u64.to_le_bytes(), 16, "WIDTH × HEIGHT: 0 × 1079"),
        (24, 0u64.to_le_bytes(), 24, "WIDTH × HEIGHT: 1919 × 0"),
        (
            32,
            0f64.to_le_bytes(),
            32,
            "PARAMS[0] (f): 0 is not a focal length",
        ),
    ] {
        let mut bad = good.clone();
        bad[at..at + 8].copy_from_slice(&bytes);
        std::fs::write(bin.path().join("cameras.bin"), bad).unwrap();
        let err = read_model_as(bin.path(), Format::Binary).unwrap_err();
        let m = err.to_string();
        assert!(
            matches!(err, Error::Format { location: Location::Offset(o), .. } if o == offset)
                && m.contains(expected),
            "{m}"
        );
    }
}
