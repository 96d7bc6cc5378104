//! `transcode train` on a dataset with masks: a random (or white) background goes behind the
//! masked views, so training over random backgrounds scores at least as well on black as
//! training on black does; on a dataset without masks or alpha those backgrounds are refused.
#![allow(clippy::print_stderr)] // tests report what they measured

use std::path::Path;
use std::process::Command;

use glam::Vec3;
use plenoptic_scenes::{DemoConfig, demo_scene};

const BIN: &str = env!("CARGO_BIN_EXE_transcode");

fn transcode(args: &[&str]) -> std::process::Output {
    Command::new(BIN).args(args).output().unwrap()
}

fn ok(args: &[&str]) {
    let out = transcode(args);
    assert!(
        out.status.success(),
        "transcode {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Held-out PSNR on black of the model `dir/splats.ply` against the dataset `heldout`.
fn psnr_on_black(dir: &Path, heldout: &Path) -> f64 {
    let splats = splat_core::ply::read_splats(&dir.join("splats.ply")).unwrap();
    let views = splat_train::read_dataset(heldout, 1.0).unwrap().views;
    splat_train::evaluate(&splats, &views, Vec3::ZERO)
        .unwrap()
        .psnr
}

#[test]
fn random_backgrounds_go_behind_masks_and_need_them() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let cloud = demo_scene(&DemoConfig {
        grid: 40,
        ..DemoConfig::default()
    })
    .unwrap();
    let input = root.join("demo.ply");
    plenoptic_io::write_cloud(&input, &cloud).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_owned();
    let (train, heldout) = (root.join("train"), root.join("heldout"));
    for (dir, cameras) in [(&train, "16"), (&heldout, "5")] {
        ok(&[
            "views",
            &s(&input),
            "--out",
            &s(dir),
            "--cameras",
            cameras,
            "--resolution",
            "96",
        ]);
        assert!(dir.join("masks").is_dir());
    }
    let mut scores = Vec::new();
    for background in ["black", "random"] {
        let out = root.join(background);
        ok(&[
            "train",
            &s(&train),
            "--out",
            &s(&out),
            "--iterations",
            "300",
            "--background",
            background,
            "--quiet",
        ]);
        scores.push(psnr_on_black(&out, &heldout));
    }
    eprintln!(
        "300 steps, held-out PSNR on black: trained on black {:.2} dB, on random backgrounds {:.2} dB",
        scores[0], scores[1]
    );
    // Before masks were read, random backgrounds trained 9 dB worse than black.
    assert!(scores[1] >= scores[0], "{scores:?}");

    // Without masks, only black is accepted.
    std::fs::remove_dir_all(train.join("masks")).unwrap();
    for background in ["random", "white"] {
        let out = transcode(&[
            "train",
            &s(&train),
            "--out",
            &s(&root.join("refused")),
            "--iterations",
            "10",
            "--background",
            background,
            "--quiet",
        ]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{background} was accepted");
        assert!(
            err.contains(&format!("--background {background}")) && err.contains("has no mask"),
            "{err}"
        );
    }
}
