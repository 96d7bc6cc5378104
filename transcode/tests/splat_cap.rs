//! `--splats K` is a cap on the automatic splat budget's start (two splats per covered pixel of
//! the mean training view), never a floor: a K above that start begins where `--splats auto`
//! does, a K below it begins at about K, and `--no-prune` keeps about K whatever the views.
#![allow(clippy::print_stderr)] // the test reports what it measured

use std::path::Path;
use std::process::Command;

use plenoptic_scenes::{DemoConfig, demo_scene};

const BIN: &str = env!("CARGO_BIN_EXE_transcode");

/// Small views and a run too short for budget rounds: only the start is under test.
const CONFIG: &str = r#"
[rig]
cameras = 8
width = 48
height = 48
heldout_cameras = 1

[training]
iterations = 5

[eval]
report_views = 1
"#;

/// Runs `transcode run` with `extra` arguments and returns the initial splat count its report
/// gives, and what it printed.
fn initial_splats(input: &Path, config: &Path, out: &Path, extra: &[&str]) -> (u64, String) {
    let output = Command::new(BIN)
        .arg("run")
        .arg(input)
        .arg("--out")
        .arg(out)
        .arg("--config")
        .arg(config)
        .arg("--no-dataset")
        .args(extra)
        .output()
        .unwrap();
    let printed = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(output.status.success(), "run {extra:?} failed:\n{printed}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report/report.json")).unwrap()).unwrap();
    let splats = report["runs"][0]["init"]["splats"]
        .as_u64()
        .expect("the report gives the initial splat count");
    (splats, printed)
}

#[test]
fn splats_k_caps_the_automatic_start_and_never_raises_it() {
    let tmp = tempfile::tempdir().unwrap();
    let cloud = demo_scene(&DemoConfig {
        grid: 48,
        ..DemoConfig::default()
    })
    .unwrap();
    let points = cloud.len() as u64;
    let input = tmp.path().join("demo.ply");
    plenoptic_io::write_cloud(&input, &cloud).unwrap();
    let config = tmp.path().join("small.toml");
    std::fs::write(&config, CONFIG).unwrap();

    // Each run in its own folder, named by what it tries.
    let run =
        |name: &str, extra: &[&str]| initial_splats(&input, &config, &tmp.path().join(name), extra);

    let (auto, printed) = run("auto", &[]);
    // 48² views: the demo's thousands of points outnumber twice the covered pixels.
    assert!(
        auto < points / 2,
        "the automatic start ({auto}) should be well under the {points} points"
    );
    assert!(
        printed.contains("per covered pixel"),
        "the start is not explained:\n{printed}"
    );

    // A cap above the automatic start: the same start, and the note names the cap.
    let above = (points as f64 * 0.9) as u64;
    let (capped, printed) = run("above", &["--splats", &above.to_string()]);
    assert_eq!(
        capped, auto,
        "--splats {above} should start where auto does"
    );
    assert!(
        printed.contains(&format!("under the {above} asked for")),
        "the note does not name the cap:\n{printed}"
    );

    // A cap below it: about K (the voxel sampling's count is within a few percent of K).
    let below = auto / 2;
    let (small, _) = run("below", &["--splats", &below.to_string()]);
    assert!(
        small <= auto * 2 / 3 && small.abs_diff(below) * 10 <= below,
        "--splats {below} started at {small} (auto {auto})"
    );

    // Without the budget, K is what is asked for, above the automatic start too.
    let (kept, _) = run("kept", &["--splats", &above.to_string(), "--no-prune"]);
    assert!(
        kept > auto && kept.abs_diff(above) * 10 <= above,
        "--splats {above} --no-prune started at {kept} (auto {auto})"
    );
    eprintln!(
        "{points} points: auto {auto}; --splats {above}: {capped}; --splats {below}: {small}; \
         --splats {above} --no-prune: {kept}"
    );
}
