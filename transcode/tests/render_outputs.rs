//! `transcode render` writes only its own PNGs, under `--out`. Found by an adversarial sweep:
//! image names with `..` or absolute paths were written outside `--out`, `a.jpg` and `a.png`
//! overwrote each other, `--out DATASET/images` replaced the reference images (and `eval` then
//! scored the model against its own renders), a camera over the rasteriser's limit panicked,
//! and `--background R,G,B` (the form its help gave) was refused.

mod support;

use std::path::{Path, PathBuf};

use support::{arg, transcode};

fn scene() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene"
    ))
}

/// A COLMAP model in `dir` with the splat scene's first camera and pose, one image a name.
fn model_with_images(dir: &Path, names: &[&str], size: (u32, u32)) -> PathBuf {
    let model = dir.join("sparse/0");
    std::fs::create_dir_all(&model).unwrap();
    let src = scene().join("train/sparse/0");
    let camera = std::fs::read_to_string(src.join("cameras.txt")).unwrap();
    let camera = camera.lines().find(|l| !l.starts_with('#')).unwrap();
    let params: Vec<&str> = camera.split_whitespace().skip(4).collect();
    let (w, h) = size;
    std::fs::write(
        model.join("cameras.txt"),
        format!("1 PINHOLE {w} {h} {}\n", params.join(" ")),
    )
    .unwrap();
    let images = std::fs::read_to_string(src.join("images.txt")).unwrap();
    let pose: Vec<&str> = images
        .lines()
        .find(|l| !l.starts_with('#'))
        .unwrap()
        .split_whitespace()
        .skip(1)
        .take(8)
        .collect();
    let lines: String = names
        .iter()
        .enumerate()
        .map(|(i, n)| format!("{} {} {n}\n\n", i + 1, pose.join(" ")))
        .collect();
    std::fs::write(model.join("images.txt"), lines).unwrap();
    std::fs::write(model.join("points3D.txt"), "").unwrap();
    model
}

fn render(args: &[&str]) -> (bool, String) {
    let out = transcode(&[&["render", &arg(&scene().join("gt.ply"))], args].concat())
        .output()
        .unwrap();
    assert_ne!(out.status.code(), Some(101), "panicked");
    let said = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.success(), said)
}

#[test]
fn render_writes_under_out_and_never_over_its_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");

    let escaping = model_with_images(
        &dir.path().join("a"),
        &["ok.png", "../escaped.png"],
        (32, 24),
    );
    let (ok, said) = render(&["--colmap", &arg(&escaping), "--out", &arg(&out)]);
    assert!(!ok && said.contains("outside --out"), "{said}");
    assert!(!dir.path().join("escaped.png").exists() && !out.exists());
    let absolute = dir.path().join("absolute.png");
    let escaping = model_with_images(&dir.path().join("b"), &[&arg(&absolute)], (32, 24));
    let (ok, said) = render(&["--colmap", &arg(&escaping), "--out", &arg(&out)]);
    assert!(!ok && said.contains("outside --out"), "{said}");
    assert!(!absolute.exists());

    let twins = model_with_images(
        &dir.path().join("c"),
        &["same.jpg", "sub/x.png", "same.png"],
        (32, 24),
    );
    let (ok, said) = render(&["--colmap", &arg(&twins), "--out", &arg(&out)]);
    assert!(!ok && said.contains("would both be written to"), "{said}");
    assert!(!out.exists(), "rendered before refusing");
    // Names in subfolders are kept under --out.
    let (ok, said) = render(&[
        "--colmap",
        &arg(&twins),
        "--out",
        &arg(&out),
        "--images",
        "sub/x.png",
    ]);
    assert!(ok, "{said}");
    assert!(out.join("sub/x.png").is_file());

    // The dataset's own images are not render's to replace.
    let dataset = dir.path().join("dataset");
    let images = dataset.join("images");
    std::fs::create_dir_all(&images).unwrap();
    model_with_images(&dataset, &["view.png"], (32, 24));
    std::fs::write(images.join("view.png"), b"the reference").unwrap();
    let (ok, said) = render(&["--colmap", &arg(&dataset), "--out", &arg(&images)]);
    assert!(!ok && said.contains("which this command reads"), "{said}");
    assert_eq!(
        std::fs::read(images.join("view.png")).unwrap(),
        b"the reference"
    );
}

#[test]
fn render_takes_its_background_as_documented_and_refuses_oversized_cameras() {
    let dir = tempfile::tempdir().unwrap();
    let model = model_with_images(dir.path(), &["v.png"], (32, 24));
    let mut pngs = Vec::new();
    for (name, background) in [
        ("commas", &["0.2,0.4,0.6"][..]),
        ("spaces", &["0.2", "0.4", "0.6"]),
        ("default", &[]),
    ] {
        let out = dir.path().join(name);
        let mut args = vec![
            "--colmap".to_owned(),
            arg(&model),
            "--out".to_owned(),
            arg(&out),
        ];
        if !background.is_empty() {
            args.push("--background".to_owned());
            args.extend(background.iter().map(|s| (*s).to_owned()));
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (ok, said) = render(&args);
        assert!(ok, "{name}: {said}");
        pngs.push(std::fs::read(out.join("v.png")).unwrap());
    }
    assert_eq!(pngs[0], pngs[1], "R,G,B and R G B differ");
    assert_ne!(pngs[0], pngs[2], "the background was not used");
    for bad in ["0.5,0.5", "-0.1,0,0"] {
        let (ok, said) = render(&[
            "--colmap",
            &arg(&model),
            "--out",
            &arg(&dir.path().join("x")),
            "--background",
            bad,
        ]);
        assert!(!ok && said.contains("--background"), "{bad}: {said}");
    }

    let huge = model_with_images(&dir.path().join("huge"), &["v.png"], (8200, 8200));
    let (ok, said) = render(&[
        "--colmap",
        &arg(&huge),
        "--out",
        &arg(&dir.path().join("h")),
    ]);
    assert!(
        !ok && said.contains("over the rasteriser's limit"),
        "{said}"
    );
}
