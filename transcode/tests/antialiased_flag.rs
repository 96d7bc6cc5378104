//! `--antialiased` on the commands that train is `[training] antialiased = true`: the same model
//! bit for bit, whose PLY says how it is drawn, and a plain run's PLY says nothing.

use std::path::Path;
use std::process::Command;

use plenoptic_scenes::{DemoConfig, demo_scene};

const BIN: &str = env!("CARGO_BIN_EXE_transcode");

/// Small views and a short run, by flags: only the setting's way through the command is under
/// test.
const SMALL: [&str; 8] = [
    "--cameras",
    "8",
    "--resolution",
    "48",
    "--heldout",
    "1",
    "--iterations",
    "20",
];

/// Runs `transcode` with `args` and fails the test with what it printed if it fails.
fn transcode(args: &[&str]) {
    let output = Command::new(BIN).args(args).output().unwrap();
    assert!(
        output.status.success(),
        "transcode {args:?} failed:\n{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The model a run wrote, and whether its PLY says it was trained antialiased (read by the
/// project's PLY reader; the header's exact bytes are `splat-core/tests/ply.rs`'s to check).
fn model(out: &Path) -> (Vec<u8>, bool) {
    let path = out.join("model/splats.ply");
    let tagged = splat_core::ply::read_model(&path).unwrap().antialiased;
    (std::fs::read(&path).unwrap(), tagged)
}

#[test]
fn the_flag_trains_what_the_setting_trains_and_the_file_says_so() {
    let tmp = tempfile::tempdir().unwrap();
    let cloud = demo_scene(&DemoConfig {
        grid: 32,
        ..DemoConfig::default()
    })
    .unwrap();
    let input = tmp.path().join("demo.ply");
    plenoptic_io::write_cloud(&input, &cloud).unwrap();
    let aa_cfg = tmp.path().join("aa.toml");
    std::fs::write(&aa_cfg, "[training]\nantialiased = true\n").unwrap();
    let run = |name: &str, extra: &[&str]| {
        let out = tmp.path().join(name);
        let mut args = vec![
            "run",
            input.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--no-dataset",
            "--quiet",
        ];
        args.extend_from_slice(&SMALL);
        args.extend_from_slice(extra);
        transcode(&args);
        model(&out)
    };

    let (flagged, flagged_tagged) = run("flag", &["--antialiased"]);
    let (keyed, keyed_tagged) = run("key", &["--config", aa_cfg.to_str().unwrap()]);
    let (plain, plain_tagged) = run("plain", &[]);
    assert!(
        flagged_tagged && keyed_tagged,
        "an antialiased run's PLY is not tagged"
    );
    assert!(!plain_tagged, "a plain run's PLY is tagged antialiased");
    assert!(
        flagged == keyed,
        "--antialiased and [training] antialiased = true trained different models"
    );
    assert!(
        flagged != plain,
        "--antialiased changed nothing in the model"
    );

    // The demo takes the same flag.
    let demo = tmp.path().join("demo");
    let mut args = vec![
        "demo",
        "--out",
        demo.to_str().unwrap(),
        "--grid",
        "32",
        "--time-budget",
        "100000",
        "--no-dataset",
        "--quiet",
        "--antialiased",
    ];
    args.extend_from_slice(&SMALL);
    transcode(&args);
    assert!(model(&demo).1, "demo --antialiased wrote an untagged PLY");
}
