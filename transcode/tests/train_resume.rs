//! `transcode train --resume`: a training run killed with SIGKILL at any moment and resumed
//! until it finishes writes the same model, byte for byte, and the same evaluation points as a
//! run that was never interrupted (also when killed between its last checkpoint and its model);
//! what a killed run leaves never looks finished; a finished run is not redone; other settings
//! are refused.
#![allow(clippy::print_stderr)] // tests report what they measured

use std::path::Path;
use std::time::Instant;

mod support;
use support::{SplitMix, arg as s, check, demo_datasets, run_or_kill, transcode};

/// The files that mark a finished training run.
const FINISHED: [&str; 2] = ["splats.ply", "history.json"];

/// A short run with every kind of pause: evaluations every 40 steps on a held-out dataset, a
/// checkpoint every 20 ms of wall time, random backgrounds behind the masks.
fn train_args<'a>(train: &'a str, heldout: &'a str, out: &'a str) -> Vec<&'a str> {
    vec![
        "train",
        train,
        "--out",
        out,
        "--heldout",
        heldout,
        "--init",
        "random",
        "--random-points",
        "1500",
        "--iterations",
        "240",
        "--eval-every",
        "40",
        "--background",
        "random",
        "--checkpoint-interval",
        "0.02",
        "--quiet",
        "--resume",
    ]
}

/// The evaluation points of a finished run's `history.json`: step, splats, PSNR and SSIM.
fn evaluations(out: &Path) -> Vec<(u64, u64, f64, f64)> {
    let bytes = std::fs::read(out.join("history.json")).unwrap();
    let h: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
    h["evaluations"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| {
            (
                e["iteration"].as_u64().unwrap(),
                e["splats"].as_u64().unwrap(),
                e["psnr"].as_f64().unwrap(),
                e["ssim"].as_f64().unwrap(),
            )
        })
        .collect()
}

#[test]
fn a_training_run_killed_at_random_moments_resumes_to_the_same_model() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let (train, heldout) = demo_datasets(root, 32, [12, 3], 64);
    let (train, heldout) = (s(&train), s(&heldout));
    let (whole, killed) = (root.join("whole"), root.join("killed"));
    let killed_s = s(&killed);

    // The reference: one uninterrupted run.
    let t0 = Instant::now();
    let out = transcode(&train_args(&train, &heldout, &s(&whole)))
        .output()
        .unwrap();
    check(&out, "the uninterrupted run");
    let full = t0.elapsed();
    let reference = std::fs::read(whole.join("splats.ply")).unwrap();
    let reference_evaluations = evaluations(&whole);
    let steps: Vec<u64> = reference_evaluations.iter().map(|e| e.0).collect();
    assert_eq!(steps, [40, 80, 120, 160, 200, 240]);

    // Kill moments from a fixed seed, in turn one in each eighth of the first third of the
    // uninterrupted run's time: the short ones hit reading and set-up, the longer ones move the
    // run on from checkpoint to checkpoint. Sessions go on until one finishes (at most 40).
    let mut rng = SplitMix(0x7ea1_2026);
    let mut interrupted = 0;
    let mut finished = false;
    for session in 0..40 {
        let m = (f64::from(session % 8) + rng.next_unit()) / 24.0;
        let (ended, out) = run_or_kill(
            &mut transcode(&train_args(&train, &heldout, &killed_s)),
            full.mul_f64(m),
        );
        finished = ended;
        if !finished {
            interrupted += 1;
        }
        eprintln!(
            "at {:.0}% of {:.2} s: {}",
            100.0 * m,
            full.as_secs_f64(),
            if finished { "finished" } else { "killed" }
        );
        if finished {
            check(&out, "a resumed run");
            break;
        }
        // Whatever a kill leaves, a model file, if any, is the final one, and a history only
        // comes with it.
        if let Ok(bytes) = std::fs::read(killed.join("splats.ply")) {
            assert!(
                bytes == reference,
                "splats.ply exists but is not the final model"
            );
        }
        if killed.join("history.json").exists() {
            assert!(killed.join("splats.ply").is_file());
        }
    }
    assert!(
        interrupted >= 4,
        "only {interrupted} kills hit a running run"
    );
    if !finished {
        let out = transcode(&train_args(&train, &heldout, &killed_s))
            .output()
            .unwrap();
        check(&out, "the last resume");
    }
    assert!(
        std::fs::read(killed.join("splats.ply")).unwrap() == reference,
        "the resumed model differs from the uninterrupted run's"
    );
    // The evaluations taken before a kill are kept, those after the last checkpoint taken again
    // from the same splats: the same points, bit for bit.
    assert_eq!(evaluations(&killed), reference_evaluations);

    // A finished run is left as it is.
    let out = transcode(&train_args(&train, &heldout, &killed_s))
        .output()
        .unwrap();
    let said = check(&out, "resuming a finished run");
    assert!(said.contains("already finished"), "{said}");
    assert!(std::fs::read(killed.join("splats.ply")).unwrap() == reference);

    // Killed after its last checkpoint but before the model and history were written, a run
    // resumes to them without training or evaluating a step twice.
    for f in FINISHED {
        std::fs::remove_file(killed.join(f)).unwrap();
    }
    let out = transcode(&train_args(&train, &heldout, &killed_s))
        .output()
        .unwrap();
    check(&out, "resuming after the last checkpoint");
    assert!(std::fs::read(killed.join("splats.ply")).unwrap() == reference);
    assert_eq!(evaluations(&killed), reference_evaluations);

    // Other settings are refused, naming what changed.
    let mut other = train_args(&train, &heldout, &killed_s);
    other.extend(["--seed", "7"]);
    std::fs::remove_file(killed.join("splats.ply")).unwrap();
    let out = transcode(&other).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("seed: 0 → 7"), "{err}");

    // Fewer steps than the checkpoint holds are refused (the model of 240 steps was written as
    // "trained 240 iterations" for --iterations 100).
    let fewer: Vec<&str> = train_args(&train, &heldout, &killed_s)
        .into_iter()
        .map(|a| if a == "240" { "100" } else { a })
        .collect();
    let out = transcode(&fewer).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("is at step 240, past --iterations 100"),
        "{err}"
    );
    assert!(!killed.join("splats.ply").exists());
}
