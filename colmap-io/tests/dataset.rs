//! The dataset writer: images/ + sparse/0/ as trainers expect it.

use camera_model::{Camera, Intrinsics, Pose, rig};
use colmap_io::dataset::{DatasetWriter, points_without_tracks, reconstruction_from_cameras};
use colmap_io::{CameraModel, Error, Format, read_model};
use glam::DVec3;

fn cameras() -> Vec<(String, Camera)> {
    let k = Intrinsics::from_fov_y(64, 48, 30.0);
    rig::look_at_rig(
        &rig::fibonacci_sphere(5),
        DVec3::ZERO,
        10.0,
        k,
        rig::WORLD_UP,
    )
    .into_iter()
    .enumerate()
    .map(|(i, c)| (format!("cam_{i:03}.png"), c))
    .collect()
}

#[test]
fn writes_a_loadable_dataset() {
    let tmp = tempfile::tempdir().unwrap();
    let views = cameras();
    let mut rec = reconstruction_from_cameras(views.iter().map(|(n, c)| (n.as_str(), c))).unwrap();
    assert_eq!(
        rec.cameras.len(),
        1,
        "identical intrinsics share one camera"
    );
    assert_eq!(rec.cameras[&1].model, CameraModel::Pinhole);
    rec.points3d = points_without_tracks([(DVec3::ZERO, [255, 0, 0]), (DVec3::ONE, [0, 255, 0])]);
    let writer = DatasetWriter::create(tmp.path()).unwrap();
    // Images come already encoded: the writer stores the bytes as given.
    for (name, _) in &views {
        writer
            .write_image(name, b"\x89PNG placeholder bytes")
            .unwrap();
    }
    for format in [Format::Text, Format::Binary] {
        writer.finish(&rec, format).unwrap();
    }
    let back = read_model(&tmp.path().join("sparse/0")).unwrap();
    assert_eq!(back, rec);
    for (i, (name, cam)) in views.iter().enumerate() {
        let id = i as u32 + 1;
        assert_eq!(&back.images[&id].name, name);
        assert!(tmp.path().join("images").join(name).is_file());
        let read = back.camera_of(id).unwrap();
        assert_eq!(read.intrinsics, cam.intrinsics);
        assert!((read.center() - cam.center()).length() < 1e-12);
        // The principal point stays exactly at the image centre (Inria ignores cx, cy).
        assert_eq!((read.intrinsics.cx, read.intrinsics.cy), (32.0, 24.0));
    }
    let text = std::fs::read_to_string(tmp.path().join("sparse/0/images.txt")).unwrap();
    assert_eq!(
        text.lines().filter(|l| !l.starts_with('#')).count(),
        10,
        "blank POINTS2D lines"
    );
}

#[test]
fn refuses_datasets_trainers_cannot_load() {
    let tmp = tempfile::tempdir().unwrap();
    let views = cameras();
    let mut rec = reconstruction_from_cameras(views.iter().map(|(n, c)| (n.as_str(), c))).unwrap();
    let writer = DatasetWriter::create(tmp.path()).unwrap();
    for (name, _) in &views[1..] {
        writer.write_image(name, b"x").unwrap();
    }
    let err = writer.finish(&rec, Format::Binary).unwrap_err();
    assert!(err.to_string().contains("points3D is empty"), "{err}");
    rec.points3d = points_without_tracks([(DVec3::ZERO, [1, 2, 3])]);
    let err = writer.finish(&rec, Format::Binary).unwrap_err();
    assert!(
        matches!(&err, Error::Dataset { .. }) && err.to_string().contains("cam_000.png"),
        "{err}"
    );
    for bad in ["a b.png", "sub/a.png", "a.b.png", "noext", ".png"] {
        assert!(writer.write_image(bad, b"x").is_err(), "{bad}");
    }
    // Two names with the same stem would collide in Inria's loader.
    let pose = Pose::IDENTITY;
    let cam = Camera::new(Intrinsics::from_fov_y(8, 8, 40.0), pose);
    let mut dup = reconstruction_from_cameras([("x.png", &cam), ("x.jpg", &cam)]).unwrap();
    dup.points3d = points_without_tracks([(DVec3::ZERO, [1, 2, 3])]);
    writer.write_image("x.png", b"x").unwrap();
    writer.write_image("x.jpg", b"x").unwrap();
    assert!(
        writer
            .finish(&dup, Format::Text)
            .unwrap_err()
            .to_string()
            .contains("stem")
    );
}
