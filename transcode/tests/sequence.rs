//! `transcode sequence`: a sequence killed with SIGKILL at random moments and re-run until it
//! finishes writes the same models, byte for byte, as one never interrupted; what a kill leaves
//! never looks finished; shards split the frames into contiguous blocks and the last one merges
//! the manifests; bad frames are named, recorded as failed, and the others go on.
#![allow(clippy::print_stderr)] // tests report what they measured

use std::path::{Path, PathBuf};
use std::time::Instant;

mod support;
use support::{SplitMix, check, run_or_kill, transcode};

/// Small runs that keep every stage: 10 training and 2 held-out views at 48×48, 80 steps
/// (20 for a warm start), a checkpoint every 20 ms.
const CONFIG: &str = r#"
[rig]
cameras = 10
width = 48
height = 48
heldout_cameras = 2

[training]
iterations = 80

[eval]
report_views = 1
every = 40

[output]
checkpoint_interval_s = 0.02

[sequence]
warm_share = 0.25
"#;

fn spider() -> String {
    format!(
        "{}/../testdata/meshes/spider/spider.obj",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// `n` frames of the spider turning and moving (`synth --frames`), `cameras` capture cameras.
fn synth(dir: &Path, n: usize, cameras: usize, seed: u64) -> Vec<PathBuf> {
    let out = transcode(&[
        "synth",
        "--mesh",
        &spider(),
        "--points",
        "6000",
        "--grid",
        "60",
        "--frames",
        &n.to_string(),
        "--cameras",
        &cameras.to_string(),
        "--seed",
        &seed.to_string(),
        "--out",
        dir.to_str().unwrap(),
    ])
    .output()
    .unwrap();
    check(&out, "synth");
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert_eq!(files.len(), n);
    files
}

/// The frames' names: their file stems.
fn stems(files: &[PathBuf]) -> Vec<String> {
    files
        .iter()
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect()
}

fn json(path: &Path) -> serde_json::Value {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_slice(&bytes)
        .unwrap_or_else(|e| panic!("{} is not whole: {e}", path.display()))
}

fn states(manifest: &serde_json::Value) -> Vec<(String, String)> {
    manifest["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| {
            (
                f["name"].as_str().unwrap().to_string(),
                f["state"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

#[test]
fn a_sequence_killed_at_random_moments_resumes_to_the_same_models() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    let names = stems(&synth(&frames, 3, 13, 0));
    let config = tmp.path().join("small.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let (frames_s, config_s) = (frames.to_str().unwrap(), config.to_str().unwrap());
    let args = |out: &Path| -> Vec<String> {
        ["sequence", frames_s, "--out", out.to_str().unwrap()]
            .into_iter()
            .chain(["--config", config_s, "--quiet"])
            .map(String::from)
            .collect()
    };
    let run = |out: &Path| {
        let a = args(out);
        transcode(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let model = |out: &Path, name: &str| out.join("frames").join(name).join("model/splats.ply");

    // The reference: one uninterrupted run. Frame 1 starts cold, frames 2 and 3 warm.
    let whole = tmp.path().join("whole");
    let t0 = Instant::now();
    check(&run(&whole).output().unwrap(), "the uninterrupted sequence");
    let full = t0.elapsed();
    let reference: Vec<Vec<u8>> = names
        .iter()
        .map(|n| std::fs::read(model(&whole, n)).unwrap())
        .collect();
    let manifest = json(&whole.join("sequence.json"));
    assert_eq!(
        states(&manifest),
        names
            .iter()
            .map(|n| (n.clone(), "finished".to_string()))
            .collect::<Vec<_>>()
    );
    let warm: Vec<serde_json::Value> = manifest["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["warm_start"].clone())
        .collect();
    assert_eq!(
        warm,
        [
            serde_json::Value::Null,
            names[0].clone().into(),
            names[1].clone().into()
        ]
    );
    for (k, f) in manifest["frames"].as_array().unwrap().iter().enumerate() {
        let r = &f["result"];
        assert_eq!(r["iterations"], if k == 0 { 80 } else { 20 }, "frame {k}");
        assert!(r["psnr_black"].as_f64().unwrap() > 15.0, "frame {k}: {r}");
        assert_eq!(
            r["model_bytes"].as_u64().unwrap(),
            reference[k].len() as u64
        );
    }
    assert!(whole.join("sequence.html").is_file());
    assert_eq!(manifest["temporal"].as_array().unwrap().len(), 2);

    // Kill moments after each (re)start, from a fixed seed, growing by 0.5 % a session from 2 % of the
    // uninterrupted run's time: the short ones hit loading and views (every re-run loads the
    // frames again), the longer ones move the sequence on, frame by frame, through training,
    // export and the manifests, until a re-run finishes.
    let killed = tmp.path().join("killed");
    let mut rng = SplitMix(0x5e9_2026);
    let mut interrupted = [0; 3];
    for session in 0..200 {
        let m = (0.02 + 0.005 * f64::from(session)) * (1.0 + 0.1 * rng.next_unit());
        let (finished, out) = run_or_kill(&mut run(&killed), full.mul_f64(m));
        let status = out.status;
        // The shard manifest, when there, is always whole; a frame it calls finished has its
        // final model; no model file is ever a partial or different one.
        let shard = killed.join("shards/shard-0-of-1.json");
        let said = shard.exists().then(|| json(&shard));
        for (k, name) in names.iter().enumerate() {
            if let Ok(bytes) = std::fs::read(model(&killed, name)) {
                assert!(
                    bytes == reference[k],
                    "{name}: a model that is not the final one"
                );
            }
            if let Some(s) = &said
                && s["frames"][k]["state"] == "finished"
            {
                assert!(
                    model(&killed, name).is_file(),
                    "{name} finished without a model"
                );
            }
        }
        eprintln!(
            "at {:.0}% of {:.1} s: {} ({:?})",
            100.0 * m,
            full.as_secs_f64(),
            if finished { "finished" } else { "killed" },
            said.as_ref().map(states)
        );
        if finished {
            assert!(status.success(), "a re-run failed");
            break;
        }
        if let Some(k) = said
            .as_ref()
            .and_then(|s| states(s).iter().position(|(_, state)| state == "running"))
        {
            interrupted[k] += 1;
        }
    }
    eprintln!("kills with frame 1, 2, 3 in flight: {interrupted:?}");
    // The cold first frame and a warm frame must both be hit in flight. The last frame, short
    // (a warm start's few steps) and reached when the kill moments are longest, usually is too
    // (1 to 3 kills in our runs), but how often depends on the machine's load, so it is not
    // required.
    assert!(
        interrupted[0] >= 1 && interrupted[1] >= 1 && interrupted.iter().sum::<usize>() >= 8,
        "kills did not hit the cold and the warm frame in flight: {interrupted:?}"
    );

    // Re-run until it finishes, then compare byte for byte.
    check(&run(&killed).output().unwrap(), "the last re-run");
    for (k, name) in names.iter().enumerate() {
        assert!(
            std::fs::read(model(&killed, name)).unwrap() == reference[k],
            "{name} differs from the uninterrupted run's"
        );
    }
    let again = json(&killed.join("sequence.json"));
    assert_eq!(states(&again), states(&manifest));

    // Re-running a finished sequence trains nothing.
    let before = std::fs::metadata(model(&killed, &names[2]))
        .unwrap()
        .modified()
        .unwrap();
    let said = check(
        &transcode(&[
            "sequence",
            frames_s,
            "--out",
            killed.to_str().unwrap(),
            "--config",
            config_s,
        ])
        .output()
        .unwrap(),
        "re-running a finished sequence",
    );
    assert!(said.contains("was finished already"), "{said}");
    assert_eq!(
        std::fs::metadata(model(&killed, &names[2]))
            .unwrap()
            .modified()
            .unwrap(),
        before
    );
}

#[test]
fn shards_take_contiguous_blocks_and_the_last_merges() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    let names = stems(&synth(&frames, 5, 13, 1));
    let config = tmp.path().join("small.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let out = tmp.path().join("out");
    let shard = |index: &str, env: bool| {
        let mut c = transcode(&[
            "sequence",
            frames.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--config",
            config.to_str().unwrap(),
        ]);
        if env {
            // As a Slurm job array task would see it.
            c.env("SLURM_ARRAY_TASK_ID", index)
                .env("SLURM_ARRAY_TASK_COUNT", "2");
        } else {
            c.args(["--shard", &format!("{index}/2")]);
        }
        c.output().unwrap()
    };
    // Shard 1 of 2 first (frames 3 to 5), from Slurm's variables: the others are not done.
    let said = check(&shard("1", true), "shard 1/2");
    assert!(said.contains("frames 3..5 (3 frames)"), "{said}");
    assert!(!out.join("sequence.json").exists());
    let s1 = json(&out.join("shards/shard-1-of-2.json"));
    assert_eq!(
        states(&s1),
        names[2..]
            .iter()
            .map(|n| (n.clone(), "finished".to_string()))
            .collect::<Vec<_>>()
    );
    // A block's first frame starts cold, the next ones warm from the frame before.
    assert!(s1["frames"][0]["warm_start"].is_null());
    assert_eq!(s1["frames"][1]["warm_start"], names[2].as_str());
    assert_eq!(s1["frames"][2]["warm_start"], names[3].as_str());
    // Shard 0 (frames 1 and 2) finishes last and merges.
    let said = check(&shard("0", false), "shard 0/2");
    assert!(said.contains("frames 1..2 (2 frames)"), "{said}");
    let merged = json(&out.join("sequence.json"));
    assert_eq!(
        states(&merged),
        names
            .iter()
            .map(|n| (n.clone(), "finished".to_string()))
            .collect::<Vec<_>>()
    );
    assert!(out.join("sequence.html").is_file());
    // --collect alone writes the same manifest again.
    std::fs::remove_file(out.join("sequence.json")).unwrap();
    let collected = transcode(&[
        "sequence",
        frames.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--collect",
    ])
    .output()
    .unwrap();
    check(&collected, "--collect");
    assert_eq!(json(&out.join("sequence.json")), merged);

    // A shard another process is running is refused (a requeued task beside its first
    // attempt rewrote the same manifest and frames), and its manifest is left as it was; a
    // stray file in shards/ is not read as a manifest.
    let before = std::fs::read(out.join("shards/shard-0-of-2.json")).unwrap();
    let held =
        transcode::lock::WriterLock::acquire(&out.join("shards/.shard-0-of-2.lock")).unwrap();
    let busy = shard("0", false);
    assert!(!busy.status.success());
    let err = String::from_utf8_lossy(&busy.stderr);
    assert!(
        err.contains("shard 0/2: another transcode process"),
        "{err}"
    );
    assert_eq!(
        std::fs::read(out.join("shards/shard-0-of-2.json")).unwrap(),
        before
    );
    drop(held);
    std::fs::write(out.join("shards/shard-notes.json"), "{}").unwrap();
    check(&shard("0", false), "shard 0/2 beside a stray file");

    // A shard that does not exist is refused.
    let bad = shard("2", false);
    assert!(!bad.status.success());
    let err = String::from_utf8_lossy(&bad.stderr);
    assert!(err.contains("2/2"), "{err}");
}

#[test]
fn bad_frames_are_named_recorded_and_the_others_go_on() {
    let tmp = tempfile::tempdir().unwrap();
    let config = tmp.path().join("small.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let config = config.to_str().unwrap();
    let sequence = |input: &str, out: &Path| {
        transcode(&[
            "sequence",
            input,
            "--out",
            out.to_str().unwrap(),
            "--config",
            config,
        ])
        .output()
        .unwrap()
    };
    let refused = |input: &str, expect: &[&str]| {
        let out = sequence(input, &tmp.path().join("refused"));
        assert!(!out.status.success(), "{input} was accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        for e in expect {
            assert!(err.contains(e), "{input}: {err:?} does not say {e:?}");
        }
    };

    // An empty folder, a glob matching nothing, a missing folder.
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let empty_s = empty.to_str().unwrap();
    refused(empty_s, &[empty_s, "holds no frames"]);
    let glob = format!("{}/*.ply", tmp.path().join("nowhere").display());
    refused(&glob, &[&glob, "matches no"]);
    let missing = tmp.path().join("missing").to_str().unwrap().to_string();
    refused(&missing, &[&missing]);

    // Six frames: the second and the last unreadable, the fifth from a rig with another camera
    // count. (The last is one of the frames the framing sphere is taken from: the frame before
    // it stands in for it, and the bad frame fails alone.)
    let frames = tmp.path().join("frames");
    let good = synth(&frames, 3, 13, 2);
    let other = synth(&tmp.path().join("other"), 2, 12, 2);
    let renamed = |k: usize| frames.join(format!("f_{k}.ply"));
    std::fs::rename(&good[0], renamed(8)).unwrap();
    std::fs::write(
        renamed(9),
        b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n1 2\n",
    )
    .unwrap();
    std::fs::rename(&good[1], renamed(10)).unwrap(); // natural order: f_10 after f_9
    std::fs::rename(&good[2], renamed(11)).unwrap();
    std::fs::rename(&other[0], renamed(12)).unwrap();
    std::fs::write(renamed(13), b"not a ply at all").unwrap();
    let out = tmp.path().join("out");
    let run = sequence(frames.to_str().unwrap(), &out);
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        !run.status.success(),
        "a sequence with failed frames exited 0"
    );
    let manifest = json(&out.join("sequence.json"));
    let expected = [
        ("f_8".to_string(), "finished".to_string()),
        ("f_9".into(), "failed".into()),
        ("f_10".into(), "finished".into()),
        ("f_11".into(), "finished".into()),
        ("f_12".into(), "failed".into()),
        ("f_13".into(), "failed".into()),
    ];
    assert_eq!(states(&manifest), expected);
    assert!(error(&manifest, 1).contains("f_9.ply"));
    let e = error(&manifest, 4);
    assert!(
        e.contains("f_12.ply") && e.contains("12 capture cameras"),
        "{e}"
    );
    assert!(error(&manifest, 5).contains("f_13.ply"));
    // The frame after a failed one starts cold; the one after it warm again.
    assert!(manifest["frames"][2]["warm_start"].is_null());
    assert_eq!(manifest["frames"][3]["warm_start"], "f_10");
    assert!(
        ["f_9", "f_12", "f_13"].iter().all(|f| err.contains(f)),
        "{err}"
    );

    // In three shards (f_8 f_9 | f_10 f_11 | f_12 f_13) into the same folder (finished frames
    // are skipped, failed ones tried again): a shard's exit status speaks for its own frames,
    // so the all-good middle shard, finishing last and merging, exits 0; `--collect` then fails
    // naming every failed frame.
    let sharded = |shard: &str| {
        transcode(&[
            "sequence",
            frames.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--config",
            config,
            "--shard",
            shard,
        ])
        .output()
        .unwrap()
    };
    for bad in ["0/3", "2/3"] {
        let run = sharded(bad);
        assert!(
            !run.status.success(),
            "shard {bad} with a failed frame exited 0"
        );
    }
    std::fs::remove_file(out.join("sequence.json")).unwrap();
    check(&sharded("1/3"), "the all-good shard that merges");
    assert_eq!(states(&json(&out.join("sequence.json"))), expected);
    let collect = |quiet: bool| {
        let mut args = vec!["sequence", frames.to_str().unwrap(), "--out"];
        args.extend([out.to_str().unwrap(), "--collect"]);
        if quiet {
            args.push("--quiet");
        }
        transcode(&args).output().unwrap()
    };
    let collected = collect(false);
    let said = String::from_utf8_lossy(&collected.stderr);
    assert!(!collected.status.success());
    assert!(
        said.contains("3 frame(s) failed: f_9, f_12, f_13"),
        "{said}"
    );
    // --quiet prints nothing but the error.
    let quiet = collect(true);
    assert!(
        quiet.stdout.is_empty(),
        "{}",
        String::from_utf8_lossy(&quiet.stdout)
    );

    // A lost shard (its manifest gone, as if its task never ran): --collect says the sequence
    // is not finished and fails.
    for m in std::fs::read_dir(out.join("shards")).unwrap() {
        let m = m.unwrap().path();
        if !m.ends_with("shard-0-of-3.json") {
            std::fs::remove_file(m).unwrap();
        }
    }
    let collected = collect(false);
    let said = String::from_utf8_lossy(&collected.stderr);
    assert!(!collected.status.success());
    assert!(
        said.contains("4 are pending, running or killed (f_10, f_11, f_12, f_13)"),
        "{said}"
    );

    // A hole in the numbering (s_3 of s_1, s_2, s_4): a failed frame named as missing, the
    // others go on, exit non-zero.
    let holed = tmp.path().join("holed");
    let files = synth(&holed, 3, 13, 3);
    for (file, n) in files.iter().zip([1, 2, 4]) {
        std::fs::rename(file, holed.join(format!("s_{n}.ply"))).unwrap();
    }
    let out = tmp.path().join("holed-out");
    let run = sequence(holed.to_str().unwrap(), &out);
    assert!(!run.status.success());
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(
        err.contains("1 frame(s) missing from the numbering") && err.contains("s_3"),
        "{err}"
    );
    let manifest = json(&out.join("sequence.json"));
    assert_eq!(
        states(&manifest),
        [
            ("s_1".to_string(), "finished".to_string()),
            ("s_2".into(), "finished".into()),
            ("s_3".into(), "failed".into()),
            ("s_4".into(), "finished".into()),
        ]
    );
    let e = error(&manifest, 2);
    assert!(e.contains("s_3.ply") && e.contains("is missing"), "{e}");
    assert!(manifest["frames"][3]["warm_start"].is_null());
}

fn error(manifest: &serde_json::Value, k: usize) -> String {
    manifest["frames"][k]["error"].as_str().unwrap().to_string()
}

#[test]
fn without_the_dataset_a_frame_trains_the_same_model() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    let files = synth(&frames, 2, 13, 4);
    let config = tmp.path().join("small.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "run",
            files[0].to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(["--config", config.to_str().unwrap(), "--quiet"]);
        args.extend(extra);
        check(&transcode(&args).output().unwrap(), "run");
    };
    let (with, without) = (tmp.path().join("with"), tmp.path().join("without"));
    run(&with, &[]);
    run(&without, &["--no-dataset"]);
    assert!(with.join("dataset/sparse/0/cameras.bin").is_file());
    assert!(!without.join("dataset").exists());
    assert!(
        std::fs::read(with.join("model/splats.ply")).unwrap()
            == std::fs::read(without.join("model/splats.ply")).unwrap(),
        "the model depends on whether the dataset is written"
    );
    // Resumed, a run without the dataset renders the views again and is finished as before.
    run(&without, &["--no-dataset", "--resume"]);
    assert!(!without.join("dataset").exists());
}

/// A sequence re-run after a frame's file or the settings changed trains again what they
/// changed: the changed frame and the frame warm-started from it, to the models a first run on
/// the changed frames makes; the others are left as they are. (The saved run refused the
/// change, with advice to use a `--resume` that `sequence` does not have, and every re-run
/// failed the same way.)
#[test]
fn a_rerun_trains_again_what_changed_and_only_that() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    let files = synth(&frames, 3, 13, 7);
    let names = stems(&files);
    let config = tmp.path().join("small.toml");
    std::fs::write(&config, CONFIG).unwrap();
    let run = |out: &Path, extra: &[&str]| {
        let mut args = vec!["sequence", frames.to_str().unwrap(), "--out"];
        args.extend([out.to_str().unwrap(), "--config", config.to_str().unwrap()]);
        args.extend(extra);
        check(&transcode(&args).output().unwrap(), "sequence")
    };
    let models = |out: &Path| -> Vec<Vec<u8>> {
        names
            .iter()
            .map(|n| std::fs::read(out.join("frames").join(n).join("model/splats.ply")).unwrap())
            .collect()
    };
    let seq = tmp.path().join("seq");
    run(&seq, &["--quiet"]);
    let before = models(&seq);

    // Frame 2 (of 3) changes colour (its points, and so the sequence's framing sphere, stay):
    // frames 2 and 3 are trained again, frame 1 is left.
    let mut cloud = plenoptic_io::read_cloud(&files[1]).unwrap();
    for c in cloud.colors.iter_mut().chain(&mut cloud.camera_colors) {
        *c = c.map(|v| 1.0 - v);
    }
    plenoptic_io::write_cloud(&files[1], &cloud).unwrap();
    let said = run(&seq, &[]);
    assert!(
        said.contains(&format!(
            "{}: its earlier run began with a different version",
            names[1]
        )) && said.contains(&format!("{} was finished already", names[0]))
            && !said.contains(&format!("{} was finished already", names[2])),
        "{said}"
    );
    let after = models(&seq);
    assert_eq!(after[0], before[0]);
    assert_ne!(after[1], before[1]);
    let fresh = tmp.path().join("fresh");
    run(&fresh, &["--quiet"]);
    assert_eq!(after, models(&fresh), "the re-run differs from a first run");
    let manifest = json(&seq.join("sequence.json"));
    let warm: Vec<&str> = manifest["frames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["warm_start"].as_str().unwrap_or("-"))
        .collect();
    assert_eq!(warm, ["-", names[0].as_str(), names[1].as_str()]);
    assert!(states(&manifest).iter().all(|(_, s)| s == "finished"));

    // Another setting: every frame is trained again, and the run succeeds.
    let said = run(&seq, &["--iterations", "60"]);
    assert!(said.contains("it is trained again"), "{said}");
    assert_ne!(models(&seq)[0], before[0]);
    let manifest = json(&seq.join("sequence.json"));
    assert!(states(&manifest).iter().all(|(_, s)| s == "finished"));

    // A finished frame's model cut short since (it was counted as finished), then another's
    // report removed (the frame failed on every re-run, advising a `--resume` this command
    // does not have): each is trained again, to the same models.
    let current = models(&seq);
    let frame = |k: usize| seq.join("frames").join(&names[k]);
    std::fs::write(frame(1).join("model/splats.ply"), &current[1][..1000]).unwrap();
    let said = run(&seq, &["--iterations", "60"]);
    std::fs::remove_file(frame(0).join("report/report.html")).unwrap();
    let said_then = run(&seq, &["--iterations", "60"]);
    for (said, k, what) in [(said, 1, "its model"), (said_then, 0, "its report")] {
        let note = format!("{}: its earlier run finished, but {what}", names[k]);
        assert!(said.contains(&note), "{note}: {said}");
    }
    assert_eq!(models(&seq), current);
    let manifest = json(&seq.join("sequence.json"));
    assert!(states(&manifest).iter().all(|(_, s)| s == "finished"));
}
