//! `transcode train` on a dataset with masks: a random (or white) background goes behind the
//! masked views, so training over random backgrounds scores at least as well on black as
//! training on black does; on a dataset without masks or alpha those backgrounds are refused.
//! Trained `--antialiased`, the model's PLY says so and its scores are of it drawn that way.
#![allow(clippy::print_stderr)] // tests report what they measured

use std::path::Path;

use glam::Vec3;

mod support;
use support::{arg as s, check, demo_datasets, transcode};

fn ok(args: &[&str]) {
    check(
        &transcode(args).output().unwrap(),
        &format!("transcode {args:?}"),
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
    let (train, heldout) = demo_datasets(root, 40, [16, 5], 96);
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

    // Trained antialiased: the same run as on black but for the image formation. Its PLY says
    // so, its held-out scores are of the model drawn that way, and training took another path.
    let aa = root.join("antialiased");
    ok(&[
        "train",
        &s(&train),
        "--out",
        &s(&aa),
        "--iterations",
        "300",
        "--heldout",
        &s(&heldout),
        "--antialiased",
        "--quiet",
    ]);
    let model = splat_core::ply::read_model(&aa.join("splats.ply")).unwrap();
    assert!(model.antialiased);
    let plain_model = splat_core::ply::read_model(&root.join("black/splats.ply")).unwrap();
    assert!(!plain_model.antialiased);
    assert_ne!(model.splats, plain_model.splats);
    let views = splat_train::read_dataset(&heldout, 1.0).unwrap().views;
    let drawn = |antialiased: bool| {
        let opts = splat_core::RenderOptions {
            background: Vec3::ZERO,
            active_sh_degree: model.splats.sh_degree,
            antialiased,
            linear_colour: false,
        };
        splat_train::evaluate_with(&model.splats, &views, &opts)
            .unwrap()
            .psnr
    };
    let history: serde_json::Value =
        serde_json::from_slice(&std::fs::read(aa.join("history.json")).unwrap()).unwrap();
    let reported = history["evaluations"]
        .as_array()
        .and_then(|e| e.last())
        .and_then(|e| e["psnr"].as_f64())
        .unwrap();
    let (compensated, plain) = (drawn(true), drawn(false));
    eprintln!(
        "trained antialiased: held-out {reported:.3} dB reported, {compensated:.3} drawn \
         compensated, {plain:.3} drawn plain"
    );
    assert!(
        (reported - compensated).abs() < 1e-9,
        "{reported} vs {compensated}"
    );
    assert!(
        (compensated - plain).abs() > 1e-3,
        "{compensated} vs {plain}"
    );

    // A masked training set with held-out views without masks: white was scored against their
    // black background (1.89 dB), so it is refused too, naming the held-out folder.
    std::fs::remove_dir_all(heldout.join("masks")).unwrap();
    let out = transcode(&[
        "train",
        &s(&train),
        "--heldout",
        &s(&heldout),
        "--out",
        &s(&root.join("refused-heldout")),
        "--iterations",
        "10",
        "--background",
        "white",
        "--quiet",
    ])
    .output()
    .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "an unmasked held-out set was accepted"
    );
    assert!(
        err.contains("has no mask in") && err.contains(&s(&heldout.join("masks"))),
        "{err}"
    );

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
        ])
        .output()
        .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{background} was accepted");
        assert!(
            err.contains(&format!("--background {background}")) && err.contains("has no mask"),
            "{err}"
        );
    }
}
