//! `transcode run --resume`: a run killed with SIGKILL at any moment and resumed until it
//! finishes writes the same model, byte for byte, as a run that was never interrupted; what a
//! killed run leaves never looks finished; a finished run is not redone; other settings are
//! refused.
#![allow(clippy::print_stderr)] // tests report what they measured

use std::path::{Path, PathBuf};
use std::time::Instant;

use plenoptic_scenes::{DemoConfig, demo_scene};

mod support;
use support::{SplitMix, check, run_or_kill, transcode};

/// A small run that still has every stage: 12 training and 2 held-out views at 64×64, surface
/// init with the automatic splat budget's rounds (a generous tolerance, so they merge) and
/// (with `compare_init`) sparse init with densification, a checkpoint every 20 ms; under a
/// time budget that does not bind, as the README demo's does not (its probe runs, and its
/// rounds train the same steps rather than the same times, so a resumed run redoes them
/// identically: at equal times they came out differently after a kill).
const CONFIG: &str = r#"
[rig]
cameras = 12
width = 64
height = 64
heldout_cameras = 2

[init]
random_points = 1500

[training]
iterations = 160
time_budget_s = 100000.0

[budget]
min_run_steps = 100
min_trial_steps = 10
tolerance_db = 10.0

[eval]
report_views = 1
every = 40

[output]
compare_init = true
checkpoint_interval_s = 0.02
"#;

const MODELS: [&str; 2] = ["model/splats.ply", "model/splats-sparse.ply"];

fn run_args<'a>(input: &'a str, out: &'a str, config: &'a str) -> Vec<&'a str> {
    vec![
        "run", input, "--out", out, "--config", config, "--quiet", "--resume",
    ]
}

/// What `state.json` says, if it is there; it must always parse (it is written atomically).
fn state_of(out: &Path) -> Option<serde_json::Value> {
    let bytes = std::fs::read(out.join("state.json")).ok()?;
    Some(serde_json::from_slice(&bytes).expect("state.json is whole"))
}

fn describe(state: &Option<serde_json::Value>) -> String {
    let Some(s) = state else {
        return "no state yet".into();
    };
    let modes: Vec<String> = s["modes"]
        .as_array()
        .map(|m| {
            m.iter()
                .map(|m| {
                    format!(
                        "{} {}",
                        m["mode"].as_str().unwrap_or("?"),
                        if m["trained"].is_null() {
                            "training"
                        } else {
                            "trained"
                        }
                    )
                })
                .collect()
        })
        .unwrap_or_default();
    format!(
        "{}, dataset written {}, {}",
        s["status"],
        s["dataset_written"],
        modes.join(", ")
    )
}

#[test]
fn a_run_killed_at_random_moments_resumes_to_the_same_model() {
    let tmp = tempfile::tempdir().unwrap();
    let cloud = demo_scene(&DemoConfig {
        grid: 32,
        ..DemoConfig::default()
    })
    .unwrap();
    let input: PathBuf = tmp.path().join("demo.ply");
    plenoptic_io::write_cloud(&input, &cloud).unwrap();
    let config = tmp.path().join("small.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let (input, config) = (input.to_str().unwrap(), config.to_str().unwrap());
    let whole = tmp.path().join("whole");
    let killed = tmp.path().join("killed");
    let (whole_s, killed_s) = (whole.to_str().unwrap(), killed.to_str().unwrap());

    // The reference: one uninterrupted run.
    let t0 = Instant::now();
    check(
        &transcode(&run_args(input, whole_s, config))
            .output()
            .unwrap(),
        "the uninterrupted run",
    );
    let full = t0.elapsed();
    let reference: Vec<Vec<u8>> = MODELS
        .iter()
        .map(|m| std::fs::read(whole.join(m)).unwrap())
        .collect();
    assert_eq!(state_of(&whole).unwrap()["status"], "finished");
    assert!(!whole.join("checkpoints").exists());

    // Kill moments after each (re)start, from a fixed seed: in turn one in each eighth of the
    // first quarter of the uninterrupted run's time. Every session redoes loading and views, so
    // the short ones hit those stages; the longer ones move the run on from checkpoint to
    // checkpoint until they hit training, evaluation, export or the report. Sessions go on until
    // one finishes (at most 40; the run is then resumed without a kill).
    let mut rng = SplitMix(0x5eed_2024);
    let mut interrupted = 0;
    let mut late = 0;
    for session in 0..40 {
        let m = (f64::from(session % 8) + rng.next_unit()) / 32.0;
        let (finished, out) = run_or_kill(
            &mut transcode(&run_args(input, killed_s, config)),
            full.mul_f64(m),
        );
        if !finished {
            interrupted += 1;
        }
        let status = out.status;
        let state = state_of(&killed);
        eprintln!(
            "at {:.0}% of {:.1} s: {} ({})",
            100.0 * m,
            full.as_secs_f64(),
            if finished { "finished" } else { "killed" },
            describe(&state)
        );
        if finished {
            assert!(status.success(), "a resumed run failed");
            break;
        }
        if state
            .as_ref()
            .is_some_and(|s| s["modes"].as_array().is_some_and(|m| m.len() == 2))
        {
            late += 1;
        }
        // Whatever a kill leaves: a model file, if any, is the final one, and a report only
        // comes with the models.
        for (m, r) in MODELS.iter().zip(&reference) {
            if let Ok(bytes) = std::fs::read(killed.join(m)) {
                assert!(&bytes == r, "{m} exists but is not the final model");
            }
        }
        if killed.join("report/report.json").exists() {
            assert!(MODELS.iter().all(|m| killed.join(m).is_file()));
        }
        if state.as_ref().is_none_or(|s| s["status"] != "finished") {
            let all_trained = state.as_ref().is_some_and(|s| {
                s["modes"]
                    .as_array()
                    .is_some_and(|m| m.len() == 2 && m.iter().all(|m| !m["trained"].is_null()))
            });
            assert!(
                all_trained || MODELS.iter().all(|m| !killed.join(m).exists()),
                "a model file appeared before training ended"
            );
        }
    }
    assert!(
        interrupted >= 5,
        "only {interrupted} kills hit a running run"
    );
    assert!(late >= 1, "no kill hit the second training or later");

    // Resume until it finishes, then compare byte for byte.
    check(
        &transcode(&run_args(input, killed_s, config))
            .output()
            .unwrap(),
        "the last resume",
    );
    for (m, r) in MODELS.iter().zip(&reference) {
        let bytes = std::fs::read(killed.join(m)).unwrap();
        assert!(&bytes == r, "{m} differs from the uninterrupted run's");
    }
    assert_eq!(state_of(&killed).unwrap()["status"], "finished");
    assert!(!killed.join("checkpoints").exists());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(killed.join("report/report.json")).unwrap()).unwrap();
    assert_eq!(report["runs"][0]["iterations"], 160);
    // The budget's rounds ran, at least two merged, and all were redone identically after
    // kills mid-round.
    let rounds = |r: &serde_json::Value| -> Vec<(u64, u64, bool)> {
        r["runs"][0]["budget"]["rounds"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| {
                (
                    x["iteration"].as_u64().unwrap(),
                    x["candidate"].as_u64().unwrap(),
                    x["accepted"].as_bool().unwrap(),
                )
            })
            .collect()
    };
    let merged = rounds(&report);
    assert!(merged.iter().filter(|r| r.2).count() >= 2, "{merged:?}");
    assert_eq!(
        report["runs"][0]["metrics"]["splats"].as_u64(),
        merged.iter().rev().find(|r| r.2).map(|r| r.1)
    );
    let html = std::fs::read_to_string(killed.join("report/report.html")).unwrap();
    assert!(html.contains("Splat budget: held-out PSNR against splats and size"));
    // Each round says where its time went, and the report sums it up.
    for r in report["runs"][0]["budget"]["rounds"].as_array().unwrap() {
        let t = &r["seconds"];
        for part in ["planning", "control", "merged", "scoring"] {
            let s = t[part].as_f64().unwrap();
            assert!(s.is_finite() && s > 0.0, "{part} of {r}");
        }
    }
    assert!(
        html.contains("The rounds took"),
        "no time sentence in the budget section"
    );
    // The held-out curves too: the same steps and scores (points after a checkpoint were taken
    // again from the same splats), only the training times differ.
    let whole_report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(whole.join("report/report.json")).unwrap()).unwrap();
    assert_eq!(rounds(&whole_report), merged);
    let scores = |r: &serde_json::Value, k: usize| -> Vec<(u64, f64, f64)> {
        r["runs"][k]["heldout_curve"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                (
                    p["iteration"].as_u64().unwrap(),
                    p["psnr_black"].as_f64().unwrap(),
                    p["ssim_white"].as_f64().unwrap(),
                )
            })
            .collect()
    };
    for k in 0..2 {
        // Every 40 steps; a multiple a budget round trained past (it trains both branches) is
        // taken at the first step after the round, inside its 13-step trial.
        let steps: Vec<u64> = scores(&whole_report, k).iter().map(|p| p.0).collect();
        assert_eq!(steps.len(), 5, "run {k}: {steps:?}");
        for (i, s) in (0..).zip(&steps) {
            assert!(*s >= 40 * i && *s <= 40 * i + 13, "run {k}: {steps:?}");
        }
        assert_eq!(steps.last(), Some(&160), "run {k}");
        assert_eq!(scores(&report, k), scores(&whole_report, k), "run {k}");
    }

    // Resuming a finished run redoes nothing.
    let model = killed.join(MODELS[0]);
    let before = std::fs::metadata(&model).unwrap().modified().unwrap();
    let said = check(
        &transcode(&run_args(input, killed_s, config))
            .output()
            .unwrap(),
        "resuming a finished run",
    );
    assert!(said.contains("already finished"), "{said}");
    assert_eq!(
        std::fs::metadata(&model).unwrap().modified().unwrap(),
        before
    );

    // Resuming with other settings is refused, and touches nothing.
    let mut args = run_args(input, killed_s, config);
    args.extend(["--iterations", "170"]);
    let out = transcode(&args).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("`training.iterations`: saved 160, now 170")
            && err.contains("without --resume"),
        "{err}"
    );
    assert!(std::fs::read(&model).unwrap() == reference[0]);
}
