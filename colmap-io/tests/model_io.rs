//! Round trips, layout and error reports of COLMAP model files.

use std::collections::BTreeMap;
use std::path::Path;

use colmap_io::{
    CameraModel, CameraRecord, Error, Format, ImageRecord, Location, Point2D, Point3D, Problem,
    Reconstruction, TrackElement, read_model, read_model_as, write_model,
};
use glam::{DVec2, DVec3};

/// A model with one camera of every COLMAP model, awkward floats, images with and without
/// observations, unobserved keypoints, and points with and without tracks.
fn sample() -> Reconstruction {
    let mut rec = Reconstruction::default();
    let awkward = [
        1.0 / 3.0,
        -2.5e-7,
        1e300,
        959.5,
        0.1,
        -0.0,
        123_456_789.123_456_78,
        7e-310,
    ];
    for (i, model) in CameraModel::ALL.iter().enumerate() {
        let id = 10 + i as u32;
        // The awkward values as they are, except in a focal length, which must be positive
        // (a reader refuses the camera otherwise): there shifted past 1.
        let names = model.param_names();
        let params = (0..model.num_params())
            .map(|k| {
                let v: f64 = awkward[(i + k) % awkward.len()];
                if matches!(names[k], "f" | "fx" | "fy") {
                    v.abs() + 1.0 + k as f64
                } else {
                    v
                }
            })
            .collect();
        rec.cameras.insert(
            id,
            CameraRecord {
                id,
                model: *model,
                width: 640 + i as u64,
                height: 480,
                params,
            },
        );
    }
    for (k, id) in [3u32, 7, 1_000_000].into_iter().enumerate() {
        let points2d = if k == 2 {
            Vec::new() // an image with an empty POINTS2D line
        } else {
            (0..5)
                .map(|j| Point2D {
                    xy: DVec2::new(0.5 + j as f64 / 7.0, 1079.25 - j as f64),
                    point3d_id: (j % 2 == 0).then_some(100 + j as u64 / 2),
                })
                .collect()
        };
        rec.images.insert(
            id,
            ImageRecord {
                id,
                qvec: [0.860298, 0.0113506 + k as f64, 0.344769, -0.375358],
                tvec: [-7.96417, 1.0 / 3.0, 4.3645e-9],
                camera_id: 10 + k as u32,
                name: format!("view_{k:03}.png"),
                points2d,
            },
        );
    }
    for j in 0..3u64 {
        let track = [3u32, 7]
            .iter()
            .map(|&image_id| TrackElement {
                image_id,
                point2d_idx: 2 * j as u32,
            })
            .collect();
        rec.points3d.insert(
            100 + j,
            Point3D {
                xyz: DVec3::new(-2.39675, 4.62278 * j as f64, 1.0 / 7.0),
                rgb: [57, 255, j as u8],
                error: 0.326014,
                track,
            },
        );
    }
    // A point nobody observes (empty track), with an id far beyond u32.
    rec.points3d.insert(
        u64::from(u32::MAX) + 5,
        Point3D {
            xyz: DVec3::new(1e-20, -1e20, 0.0),
            rgb: [0, 0, 0],
            error: -1.0,
            track: Vec::new(),
        },
    );
    rec
}

fn files(dir: &Path, ext: &str) -> Vec<Vec<u8>> {
    ["cameras", "images", "points3D"]
        .iter()
        .map(|n| std::fs::read(dir.join(format!("{n}.{ext}"))).unwrap())
        .collect()
}

#[test]
fn text_and_binary_round_trips_are_exact() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = sample();
    let (txt, bin, txt2, bin2) = (
        tmp.path().join("txt"),
        tmp.path().join("bin"),
        tmp.path().join("txt2"),
        tmp.path().join("bin2"),
    );
    write_model(&txt, &rec, Format::Text).unwrap();
    write_model(&bin, &rec, Format::Binary).unwrap();
    let from_txt = read_model(&txt).unwrap();
    let from_bin = read_model(&bin).unwrap();
    // PartialEq on f64 would call −0.0 == 0.0; compare bit patterns through the binary encoding too.
    assert_eq!(from_txt, rec);
    assert_eq!(from_bin, rec);
    write_model(&bin2, &from_txt, Format::Binary).unwrap();
    write_model(&txt2, &from_bin, Format::Text).unwrap();
    assert_eq!(
        files(&bin, "bin"),
        files(&bin2, "bin"),
        "text → binary differs from direct binary"
    );
    assert_eq!(
        files(&txt, "txt"),
        files(&txt2, "txt"),
        "binary → text differs from direct text"
    );
}

/// The point files are encoded in parallel pieces of 32,768 points, eight pieces a batch: a
/// model of several batches (tracks of varying length, ids with gaps) must come back whole, its
/// records in id order in both files, each text line and binary record where a serial writer
/// would put it.
#[test]
fn many_points_written_in_pieces_keep_their_order() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rec = sample();
    rec.points3d = (0..300_000u64)
        .map(|i| {
            let id = 1 + 3 * i + i % 2; // gaps of 3 and 4
            let f = i as f64;
            let point = Point3D {
                xyz: DVec3::new(f / 7.0, -f * 1e-9, 1e6 + f / 3.0),
                rgb: [(i % 256) as u8, (i / 256 % 256) as u8, 7],
                error: if i % 5 == 0 { -1.0 } else { f / 11.0 },
                track: Vec::new(),
            };
            (id, point)
        })
        .collect();
    // The sample's points, whose tracks the sample's images observe, among them.
    let observed: Vec<(u64, Point3D)> = sample().points3d.into_iter().collect();
    for (id, p) in observed {
        rec.points3d.insert(id, p);
    }
    assert!(rec.points3d.len() > 9 * 32_768);
    let (txt, bin) = (tmp.path().join("txt"), tmp.path().join("bin"));
    write_model(&txt, &rec, Format::Text).unwrap();
    write_model(&bin, &rec, Format::Binary).unwrap();
    assert_eq!(read_model(&txt).unwrap(), rec);
    assert_eq!(read_model(&bin).unwrap(), rec);

    // Text: after the three header lines, line k is the k-th point in id order.
    let text = std::fs::read_to_string(txt.join("points3D.txt")).unwrap();
    let ids: Vec<u64> = text
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| l.split(' ').next().unwrap().parse().unwrap())
        .collect();
    assert_eq!(ids, rec.points3d.keys().copied().collect::<Vec<_>>());
    assert_eq!(text.lines().filter(|l| l.starts_with('#')).count(), 3);

    // Binary: the count, then each record's id where the records before it end.
    let bytes = std::fs::read(bin.join("points3D.bin")).unwrap();
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().unwrap());
    assert_eq!(u64_at(0), rec.points3d.len() as u64);
    let mut at = 8;
    for (&id, p) in &rec.points3d {
        assert_eq!(u64_at(at), id, "record at byte {at}");
        at += 8 + 24 + 3 + 8 + 8 + 8 * p.track.len();
    }
    assert_eq!(at, bytes.len());
}

#[test]
fn every_image_line_is_followed_by_its_points2d_line() {
    let tmp = tempfile::tempdir().unwrap();
    write_model(tmp.path(), &sample(), Format::Text).unwrap();
    let text = std::fs::read_to_string(tmp.path().join("images.txt")).unwrap();
    let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with('#')).collect();
    assert_eq!(lines.len(), 6);
    assert!(lines[1].contains(" -1 ") && lines[1].split(' ').count() == 15);
    assert_eq!(
        lines[5], "",
        "the image without keypoints keeps an empty POINTS2D line"
    );
    assert!(text.ends_with("view_002.png\n\n"));
}

#[test]
fn binary_layout_matches_colmap() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rec = Reconstruction::default();
    rec.cameras.insert(
        1,
        CameraRecord {
            id: 1,
            model: CameraModel::Pinhole,
            width: 4,
            height: 3,
            params: vec![1.0, 2.0, 3.0, 4.0],
        },
    );
    rec.images.insert(
        2,
        ImageRecord {
            id: 2,
            qvec: [1.0, 0.0, 0.0, 0.0],
            tvec: [0.0; 3],
            camera_id: 1,
            name: "a.png".into(),
            points2d: vec![Point2D {
                xy: DVec2::new(0.5, 0.5),
                point3d_id: None,
            }],
        },
    );
    rec.points3d.insert(
        9,
        Point3D {
            xyz: DVec3::ZERO,
            rgb: [1, 2, 3],
            error: 0.0,
            track: Vec::new(),
        },
    );
    write_model(tmp.path(), &rec, Format::Binary).unwrap();
    let [cameras, images, points] = <[Vec<u8>; 3]>::try_from(files(tmp.path(), "bin")).unwrap();
    // u64 count; u32 id, i32 model, u64 width, u64 height, 4 × f64.
    assert_eq!(cameras.len(), 8 + 24 + 32);
    assert_eq!(&cameras[12..16], &1i32.to_le_bytes());
    // u64 count; u32 id, 7 f64, u32 camera, "a.png\0", u64 n, (f64, f64, u64) with −1 as u64.
    assert_eq!(images.len(), 8 + 4 + 56 + 4 + 6 + 8 + 24);
    assert_eq!(&images[images.len() - 8..], &u64::MAX.to_le_bytes());
    // u64 count; u64 id, 3 f64, 3 u8, f64 error, u64 track length.
    assert_eq!(points.len(), 8 + 8 + 24 + 3 + 8 + 8);
}

#[test]
fn binary_is_preferred_and_newer_colmap_files_are_tolerated() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = sample();
    write_model(tmp.path(), &rec, Format::Binary).unwrap();
    let mut other = rec.clone();
    other.points3d.pop_last();
    write_model(tmp.path(), &other, Format::Text).unwrap();
    // rigs.bin / frames.bin written by COLMAP ≥ 3.12: not needed for the three classic files.
    std::fs::write(tmp.path().join("rigs.bin"), [1u8, 0, 0]).unwrap();
    std::fs::write(tmp.path().join("frames.bin"), b"\x07").unwrap();
    assert_eq!(read_model(tmp.path()).unwrap(), rec);
    assert_eq!(read_model_as(tmp.path(), Format::Text).unwrap(), other);
    std::fs::remove_file(tmp.path().join("points3D.bin")).unwrap();
    assert_eq!(
        read_model(tmp.path()).unwrap(),
        other,
        "an incomplete binary model falls back to text"
    );
    std::fs::remove_file(tmp.path().join("points3D.txt")).unwrap();
    assert!(matches!(read_model(tmp.path()), Err(Error::NoModel { .. })));
}

fn located(err: Error) -> (String, Location, Problem) {
    match err {
        Error::Format {
            path,
            location,
            problem,
        } => (
            path.file_name().unwrap().to_string_lossy().into_owned(),
            location,
            problem,
        ),
        other => panic!("expected a located format error, got {other}"),
    }
}

fn write_text_model(dir: &Path, cameras: &str, images: &str, points: &str) {
    std::fs::write(dir.join("cameras.txt"), cameras).unwrap();
    std::fs::write(dir.join("images.txt"), images).unwrap();
    std::fs::write(dir.join("points3D.txt"), points).unwrap();
}

#[test]
fn text_errors_name_file_and_line() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let images = "# c\n1 1 0 0 0 0 0 0 1 a.png\n10 20 5 11 12 -1\n";
    let points = "5 0 0 0 1 2 3 0.5 1 0\n";
    write_text_model(
        dir,
        "# header\n\n1 PINHOLE 10 10 1 2 3 4\n2 FISHEYE_X 10 10 1\n",
        images,
        points,
    );
    let (file, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!((file.as_str(), loc), ("cameras.txt", Location::Line(4)));
    assert_eq!(problem, Problem::UnknownModel("FISHEYE_X".into()));

    write_text_model(
        dir,
        "1 PINHOLE 10 10 1 2 3 4\n2 OPENCV 10 10 1 2 3 4\n",
        images,
        points,
    );
    let err = read_model(dir).unwrap_err();
    assert!(
        err.to_string()
            .contains("cameras.txt: line 2: camera model OPENCV takes 8 parameters, found 4"),
        "{err}"
    );

    // Observation 0 of image 1 refers to point 5 (exists), observation 1 to point 11 (missing).
    write_text_model(
        dir,
        "1 PINHOLE 10 10 1 2 3 4\n",
        "# c\n1 1 0 0 0 0 0 0 1 a.png\n10 20 5 11 12 11\n",
        points,
    );
    let (file, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!((file.as_str(), loc), ("images.txt", Location::Line(3)));
    assert_eq!(
        problem,
        Problem::MissingPoint3D {
            image_id: 1,
            point2d_idx: 1,
            point3d_id: 11
        }
    );

    write_text_model(
        dir,
        "1 PINHOLE 10 10 1 2 3 4\n",
        images,
        "5 0 0 0 1 2 3 0.5 1 0\n6 0 0 0 1 2 3 0.5 1 4\n",
    );
    let (file, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!((file.as_str(), loc), ("points3D.txt", Location::Line(2)));
    assert_eq!(
        problem,
        Problem::MissingObservation {
            point3d_id: 6,
            image_id: 1,
            point2d_idx: 4
        }
    );

    write_text_model(
        dir,
        "1 PINHOLE 10 10 1 2 3 4\n",
        "1 1 0 0 0 0 0 0 2 a.png\n\n",
        "",
    );
    let (file, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!((file.as_str(), loc), ("images.txt", Location::Line(1)));
    assert_eq!(
        problem,
        Problem::MissingCamera {
            image_id: 1,
            camera_id: 2
        }
    );

    write_text_model(
        dir,
        "1 PINHOLE 10 10 1 2 3 4\n",
        "1 1 0 0 0 0 0 0 1 a b.png\n\n",
        "",
    );
    let (_, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!(loc, Location::Line(1));
    assert!(matches!(problem, Problem::Malformed(_)));
}

#[test]
fn binary_errors_name_file_and_byte_offset() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let rec = sample();
    write_model(dir, &rec, Format::Binary).unwrap();
    let cameras = std::fs::read(dir.join("cameras.bin")).unwrap();

    // Truncated: cut the last parameter of the last camera in half.
    std::fs::write(dir.join("cameras.bin"), &cameras[..cameras.len() - 4]).unwrap();
    let (file, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!(file, "cameras.bin");
    assert_eq!(loc, Location::Offset(cameras.len() as u64 - 8));
    assert_eq!(
        problem,
        Problem::Truncated {
            needed: 8,
            available: 4
        }
    );

    // Unknown model id in the first camera (model id at byte 8 + 4).
    let mut bad = cameras.clone();
    bad[12..16].copy_from_slice(&99i32.to_le_bytes());
    std::fs::write(dir.join("cameras.bin"), &bad).unwrap();
    let (_, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!(
        (loc, problem),
        (Location::Offset(12), Problem::UnknownModel("id 99".into()))
    );

    // A count that the file cannot hold is refused before allocating.
    let mut huge = cameras.clone();
    huge[..8].copy_from_slice(&(1u64 << 60).to_le_bytes());
    std::fs::write(dir.join("cameras.bin"), &huge).unwrap();
    let (_, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!(loc, Location::Offset(0));
    assert!(matches!(
        problem,
        Problem::CountTooLarge { what: "camera", .. }
    ));
    std::fs::write(dir.join("cameras.bin"), &cameras).unwrap();

    // A point id that no point has: rewrite the first observation of the first image (id 3).
    let mut images = std::fs::read(dir.join("images.bin")).unwrap();
    let first_point_id = 8 + 4 + 56 + 4 + "view_000.png".len() + 1 + 8 + 16;
    images[first_point_id..first_point_id + 8].copy_from_slice(&4242u64.to_le_bytes());
    std::fs::write(dir.join("images.bin"), &images).unwrap();
    let (file, loc, problem) = located(read_model(dir).unwrap_err());
    assert_eq!(file, "images.bin");
    assert_eq!(loc, Location::Offset(first_point_id as u64 - 16));
    assert_eq!(
        problem,
        Problem::MissingPoint3D {
            image_id: 3,
            point2d_idx: 0,
            point3d_id: 4242
        }
    );

    // Trailing garbage is reported where it starts.
    images.truncate(0);
    write_model(dir, &rec, Format::Binary).unwrap();
    let mut points = std::fs::read(dir.join("points3D.bin")).unwrap();
    let len = points.len() as u64;
    points.push(0);
    std::fs::write(dir.join("points3D.bin"), &points).unwrap();
    let (file, loc, _) = located(read_model(dir).unwrap_err());
    assert_eq!(
        (file.as_str(), loc),
        ("points3D.bin", Location::Offset(len))
    );
}

#[test]
fn writing_refuses_inconsistent_or_unwritable_models() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rec = sample();
    rec.images.get_mut(&3).unwrap().points2d[0].point3d_id = Some(77);
    assert!(matches!(
        write_model(tmp.path(), &rec, Format::Binary),
        Err(Error::Invalid(Problem::MissingPoint3D { .. }))
    ));
    let mut rec = sample();
    rec.images.get_mut(&3).unwrap().name = "with space.png".into();
    assert!(matches!(
        write_model(tmp.path(), &rec, Format::Text),
        Err(Error::Invalid(Problem::BadName(_)))
    ));
    write_model(tmp.path(), &rec, Format::Binary).unwrap();
    assert_eq!(
        read_model(tmp.path()).unwrap(),
        rec,
        "binary names may hold spaces"
    );
    // Nothing half-written is left behind.
    let leftovers: Vec<_> = std::fs::read_dir(tmp.path())
        .unwrap()
        .filter_map(|e| {
            let name = e.unwrap().file_name().to_string_lossy().into_owned();
            name.starts_with('.').then_some(name)
        })
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn pinhole_conversions_and_refusals() {
    let rec = sample();
    // Image 3 uses camera 10 (SIMPLE_PINHOLE), image 7 camera 11 (PINHOLE), image 1e6 camera 12 (SIMPLE_RADIAL).
    let c = rec.camera_of(3).unwrap();
    let p = &rec.cameras[&10].params;
    assert_eq!(
        (
            c.intrinsics.fx,
            c.intrinsics.fy,
            c.intrinsics.cx,
            c.intrinsics.cy
        ),
        (p[0], p[0], p[1], p[2])
    );
    let c = rec.camera_of(7).unwrap();
    let p = &rec.cameras[&11].params;
    assert_eq!(
        (
            c.intrinsics.fx,
            c.intrinsics.fy,
            c.intrinsics.cx,
            c.intrinsics.cy
        ),
        (p[0], p[1], p[2], p[3])
    );
    let err = rec.camera_of(1_000_000).unwrap_err();
    assert!(matches!(
        err,
        Error::NotPinhole {
            camera_id: 12,
            model: "SIMPLE_RADIAL"
        }
    ));
    assert!(err.to_string().contains("SIMPLE_RADIAL"));
    // camera → record → camera is exact.
    let k = camera_model::Intrinsics::from_fov_y(1920, 1080, 20.0);
    let record = CameraRecord::from_intrinsics(4, &k).unwrap();
    assert_eq!(record.model, CameraModel::Pinhole);
    assert_eq!(record.intrinsics().unwrap(), k);
    let pose = camera_model::Pose::look_at(DVec3::new(3.0, 2.0, 1.0), DVec3::ZERO, DVec3::Y);
    let image = ImageRecord::new(1, 4, "a.png", &pose);
    assert_eq!(image.qvec, pose.wxyz());
    assert!((image.pose().rotation - pose.rotation).length() < 1e-15);
    let skewed = camera_model::Intrinsics { skew: 0.5, ..k };
    assert!(CameraRecord::from_intrinsics(4, &skewed).is_err());
    let _: BTreeMap<u32, CameraRecord> = rec.cameras;
}

/// Two images with one file name were read, and training took one picture from two poses:
/// refused at the second, in text and in binary.
#[test]
fn two_images_of_one_file_are_refused_at_the_second() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let images =
        "1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 1 1 b.png\n\n3 1 0 0 0 0 0 2 1 a.png\n\n";
    write_text_model(dir, "1 PINHOLE 10 10 1 2 3 4\n", images, "");
    let err = read_model(dir).unwrap_err();
    let message = err.to_string();
    let (file, loc, problem) = located(err);
    assert_eq!((file.as_str(), loc), ("images.txt", Location::Line(5)));
    assert_eq!(
        problem,
        Problem::DuplicateName {
            id: 3,
            first: 1,
            name: "a.png".into()
        }
    );
    assert!(
        message.ends_with(
            "line 5: image 3 has the name `a.png` of image 1; each image is its own file"
        ),
        "{message}"
    );

    // The same model in binary: the second image's record starts after the count (8 bytes)
    // and two records of 4 + 56 + 4 + 6 ("x.png\0") + 8 bytes each.
    let images = "1 1 0 0 0 0 0 0 1 a.png\n\n2 1 0 0 0 0 0 1 1 b.png\n\n";
    write_text_model(dir, "1 PINHOLE 10 10 1 2 3 4\n", images, "");
    let mut rec = read_model(dir).unwrap();
    let mut third = rec.images[&2].clone();
    third.id = 3;
    third.name = "a.png".into();
    rec.images.insert(3, third);
    let bin = tempfile::tempdir().unwrap();
    write_model(bin.path(), &rec, Format::Binary).unwrap();
    let (file, loc, problem) = located(read_model_as(bin.path(), Format::Binary).unwrap_err());
    assert_eq!(
        (file.as_str(), loc),
        ("images.bin", Location::Offset(8 + 2 * 78))
    );
    assert!(matches!(
        problem,
        Problem::DuplicateName {
            id: 3,
            first: 1,
            ..
        }
    ));
}
