//! The reference views written as a COLMAP dataset read back through colmap-io and plenoptic-io.

use colmap_io::Format;
use plenoptic_io::Model;
use plenoptic_render::{
    DatasetOptions, RigConfig, ViewOptions, bounding_sphere, dataset_image_name, fibonacci_rig,
    write_dataset,
};
use plenoptic_scenes::{DemoConfig, demo_scene};

#[test]
fn dataset_round_trips_through_colmap_io() {
    let cloud = demo_scene(&DemoConfig {
        grid: 32,
        ..Default::default()
    })
    .unwrap();
    let model = Model::Cloud(cloud.clone());
    let (c, r) = bounding_sphere(&model).unwrap();
    let cams = fibonacci_rig(
        c,
        r,
        &RigConfig {
            cameras: 5,
            width: 64,
            height: 48,
            ..RigConfig::default()
        },
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let count = std::sync::atomic::AtomicUsize::new(0);
    let opts = DatasetOptions {
        depth: true,
        ..DatasetOptions::default()
    };
    // Views asked without depth still get it when the dataset writes depth maps.
    let images = write_dataset(
        dir.path(),
        &model,
        &cams,
        &ViewOptions {
            depth: false,
            ..ViewOptions::default()
        },
        &opts,
        &|| {
            count.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        },
        |_, image| image,
    )
    .unwrap();
    assert_eq!(count.into_inner(), 5);
    assert_eq!(images.len(), 5);
    for fmt in [Format::Text, Format::Binary] {
        let rec = colmap_io::read_model_as(&dir.path().join("sparse/0"), fmt).unwrap();
        assert_eq!(rec.images.len(), 5);
        assert_eq!(rec.points3d.len(), cloud.len());
        for (i, cam) in cams.iter().enumerate() {
            let got = rec.camera_of(i as u32 + 1).unwrap();
            assert!((got.center() - cam.center()).length() < 1e-6);
            assert_eq!(rec.images[&(i as u32 + 1)].name, dataset_image_name(i));
        }
    }
    // The PNG on disk is the returned image, quantised.
    let png = image::open(dir.path().join("images/view_002.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(png.dimensions(), (64, 48));
    for (a, b) in png.as_raw().iter().zip(&images[2].rgb) {
        assert_eq!(*a, (b * 255.0).round() as u8);
    }
    assert!(dir.path().join("masks/view_002.png").is_file());
    assert!(dir.path().join("depth/view_002.exr").is_file());
    assert_eq!(images[2].depth.len(), 64 * 48);
    assert!(images[2].depth.iter().any(|&z| z > 0.0));
    let ply = plenoptic_io::read_cloud(&dir.path().join("sparse/0/points3D.ply")).unwrap();
    assert_eq!(ply.positions, cloud.positions);
    assert!(ply.normals.is_some());

    // Written again into the same folder with 2 cameras, no masks and no depth: the earlier
    // run's views 2..4, its masks and its depth maps were left beside the new images (a reader
    // paired them with the new views). The user's own files stay.
    std::fs::write(dir.path().join("images/notes.txt"), b"mine").unwrap();
    // A run killed while writing its views left its atomic writes' temporaries (the writer's
    // pid is gone: above the kernel's pid_max); they went through every later run. Another
    // live process's temporary (pid 1) and a user's dotfile stay.
    let dead = ".view_003.png.4194305.76.tmp";
    std::fs::write(dir.path().join("images").join(dead), b"half").unwrap();
    std::fs::write(
        dir.path().join("sparse/0/.images.txt.4194305.2.tmp"),
        b"half",
    )
    .unwrap();
    std::fs::write(dir.path().join("images/.view_001.png.1.9.tmp"), b"live").unwrap();
    std::fs::write(dir.path().join("images/.notes.4194305.1.tmp"), b"mine").unwrap();
    write_dataset(
        dir.path(),
        &model,
        &cams[..2],
        &ViewOptions::default(),
        &DatasetOptions {
            masks: false,
            ..DatasetOptions::default()
        },
        &|| {},
        |_, _| (),
    )
    .unwrap();
    let listed = |folder: &str| -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir.path().join(folder))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    };
    if cfg!(target_os = "linux") {
        assert_eq!(
            listed("images"),
            [
                ".notes.4194305.1.tmp",
                ".view_001.png.1.9.tmp",
                "notes.txt",
                "view_000.png",
                "view_001.png"
            ]
        );
        assert!(
            !listed("sparse/0").iter().any(|n| n.ends_with(".tmp")),
            "{:?}",
            listed("sparse/0")
        );
    }
    assert!(listed("masks").is_empty(), "{:?}", listed("masks"));
    assert!(listed("depth").is_empty(), "{:?}", listed("depth"));
}
