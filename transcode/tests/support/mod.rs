//! Helpers shared by the binary's integration tests (`resume.rs`, `sequence.rs`,
//! `train_resume.rs`, `train_backgrounds.rs`): the binary as a child process, its success
//! checked, a session killed at a chosen moment and the generator of those moments, and the
//! demo's training and held-out datasets. Each test uses some of them.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// `transcode ARGS` with its output captured.
pub fn transcode(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_transcode"));
    c.args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        // A test must not pick up the shard of a Slurm job it happens to run in.
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env_remove("SLURM_ARRAY_TASK_COUNT")
        .env_remove("JOB_COMPLETION_INDEX");
    c
}

/// Asserts that `out` is a success (else fails naming `what`, with what it printed); returns what
/// it printed, standard output then standard error.
pub fn check(out: &Output, what: &str) -> String {
    let said = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(out.status.success(), "{what} failed: {said}");
    said
}

/// Runs `command` until it exits or `after` has passed, then kills it with SIGKILL. Returns
/// whether it exited on its own, and its output.
pub fn run_or_kill(command: &mut Command, after: Duration) -> (bool, Output) {
    let mut child = command.spawn().unwrap();
    let deadline = Instant::now() + after;
    let mut finished = false;
    while Instant::now() < deadline {
        if child.try_wait().unwrap().is_some() {
            finished = true;
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    if !finished {
        child.kill().unwrap();
    }
    (finished, child.wait_with_output().unwrap())
}

/// A small, deterministic generator for the kill moments (SplitMix64 with a fixed seed), so a
/// failing schedule of kills can be replayed.
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next number, uniform in [0, 1).
    pub fn next_unit(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// `p` as a command-line argument (the tests' temporary paths are UTF-8).
pub fn arg(p: &Path) -> String {
    p.to_str().unwrap().to_owned()
}

/// The demo scene on a `grid`³ voxel grid written to `root/demo.ply`, and `transcode views` of
/// it at `resolution`² into `root/train` (`train_cameras` cameras) and `root/heldout`
/// (`heldout_cameras`), each with its masks; returns the two dataset folders.
pub fn demo_datasets(
    root: &Path,
    grid: u32,
    [train_cameras, heldout_cameras]: [usize; 2],
    resolution: u32,
) -> (PathBuf, PathBuf) {
    let cloud = plenoptic_scenes::demo_scene(&plenoptic_scenes::DemoConfig {
        grid,
        ..plenoptic_scenes::DemoConfig::default()
    })
    .unwrap();
    let input = root.join("demo.ply");
    plenoptic_io::write_cloud(&input, &cloud).unwrap();
    let (train, heldout) = (root.join("train"), root.join("heldout"));
    for (dir, cameras) in [(&train, train_cameras), (&heldout, heldout_cameras)] {
        let out = transcode(&[
            "views",
            &arg(&input),
            "--out",
            &arg(dir),
            "--cameras",
            &cameras.to_string(),
            "--resolution",
            &resolution.to_string(),
        ])
        .output()
        .unwrap();
        check(&out, "views");
        assert!(dir.join("masks").is_dir());
    }
    (train, heldout)
}
