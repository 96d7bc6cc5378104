//! `transcode synth --frames N`: a sequence of plenoptic frames on one grid and rig.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_transcode");

fn spider() -> String {
    format!(
        "{}/../testdata/meshes/spider/spider.obj",
        env!("CARGO_MANIFEST_DIR")
    )
}

#[test]
fn a_sequence_is_written_frame_by_frame_with_one_rig() {
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("seq");
    let run = Command::new(BIN)
        .args([
            "synth",
            "--mesh",
            &spider(),
            "--points",
            "20000",
            "--frames",
            "3",
        ])
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let mut names: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names.len(), 3, "{names:?}");
    assert!(names[0].starts_with("spider_vox") && names[0].ends_with("_0001.ply"));
    assert!(names[2].ends_with("_0003.ply"));
    let frames: Vec<_> = names
        .iter()
        .map(|n| plenoptic_io::read_cloud(&out.join(n)).unwrap())
        .collect();
    for f in &frames {
        assert_eq!(f.num_cameras, 13);
        assert_eq!(f.cameras, frames[0].cameras, "one rig");
        assert_eq!(f.width, frames[0].width, "one grid");
        assert_eq!(
            f.frame_to_world_translation,
            frames[0].frame_to_world_translation
        );
    }
    // It moves: the first and last frames' voxel centroids are apart.
    let centroid = |f: &plenoptic_io::PlenopticCloud| {
        f.positions.iter().copied().sum::<glam::Vec3>() / f.len() as f32
    };
    assert!((centroid(&frames[0]) - centroid(&frames[2])).length() > 2.0);

    let bad = Command::new(BIN)
        .args([
            "synth",
            "--mesh",
            &spider(),
            "--frames",
            "2",
            "--bend",
            "NaN",
        ])
        .arg("--out")
        .arg(tmp.path().join("bad"))
        .output()
        .unwrap();
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("finite") && err.contains("spider.obj"),
        "{err}"
    );
}

#[test]
fn a_single_frame_makes_its_folder_and_a_file_in_its_way_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let synth = |out: &std::path::Path| {
        Command::new(BIN)
            .args([
                "synth",
                "--mesh",
                &spider(),
                "--points",
                "3000",
                "--grid",
                "40",
            ])
            .arg("--out")
            .arg(out)
            .output()
            .unwrap()
    };
    // A folder that does not exist yet is made, as `run --out` makes its own.
    let nested = tmp.path().join("a").join("b").join("frame.ply");
    let run = synth(&nested);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let cloud = plenoptic_io::read_cloud(&nested).unwrap();
    assert_eq!(cloud.num_cameras, 13);
    assert!(!cloud.is_empty());
    // A plain file where the folder should be is refused, naming it, and nothing is written.
    let blocker = tmp.path().join("blocker");
    std::fs::write(&blocker, b"not a folder").unwrap();
    let bad = synth(&blocker.join("frame.ply"));
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(
        err.contains("cannot create the folder") && err.contains("blocker"),
        "{err}"
    );
    assert_eq!(std::fs::read(&blocker).unwrap(), b"not a folder");
    // Its own mesh as the output: refused, the mesh kept (the frame replaced it, exit 0).
    let mesh = tmp.path().join("cube.ply");
    let cube = std::fs::read(format!(
        "{}/../testdata/meshes/misc/cube_binary.ply",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    std::fs::write(&mesh, &cube).unwrap();
    let own = Command::new(BIN)
        .args(["synth", "--points", "3000", "--grid", "40", "--mesh"])
        .arg(&mesh)
        .arg("--out")
        .arg(&mesh)
        .output()
        .unwrap();
    assert!(!own.status.success());
    let err = String::from_utf8_lossy(&own.stderr);
    assert!(err.contains("which this command reads"), "{err}");
    assert_eq!(std::fs::read(&mesh).unwrap(), cube);
}
