//! `transcode bench`: generates a frame, measures it and writes figures that hang together.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_transcode");

#[test]
fn bench_measures_a_generated_frame_and_an_existing_one() {
    let tmp = tempfile::tempdir().unwrap();
    let json = tmp.path().join("bench.json");
    let frame = tmp.path().join("frame.ply");
    let small = [
        "--points",
        "20000",
        "--resolution",
        "64",
        "--splats",
        "3000",
        "--repeats",
        "2",
        "--steps",
        "3",
        "--threads",
        "1,2",
    ];
    let run = Command::new(BIN)
        .arg("bench")
        .args(small)
        .arg("--frame")
        .arg(&frame)
        .arg("--json")
        .arg(&json)
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = String::from_utf8_lossy(&run.stdout).into_owned();
    assert!(text.contains("training step"), "{text}");
    let r: transcode::bench::BenchReport =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    // The demo scene at about 20,000 points, as written to the kept frame.
    let cloud = plenoptic_io::read_cloud(&frame).unwrap();
    assert_eq!(r.points, cloud.len());
    assert!((10_000..40_000).contains(&r.points), "{} points", r.points);
    assert_eq!(r.capture_cameras, 13);
    assert_eq!(r.file_bytes, std::fs::metadata(&frame).unwrap().len());
    assert_eq!(r.views, 44);
    assert!(r.splats > 0 && r.splats <= 3_000, "{} splats", r.splats);
    assert!(r.pixel_evaluations > 0);
    let threads: Vec<usize> = r.raster.iter().map(|f| f.threads).collect();
    assert_eq!(threads, [1, 2]);
    for f in &r.raster {
        assert!(f.forward_ms > 0.0 && f.forward_backward_ms > f.forward_ms * 0.5);
        assert!(f.gflops > 0.0 && f.gflops.is_finite());
    }
    let s = r.serial_fraction.unwrap();
    assert!((0.0..=1.0).contains(&s));
    assert_eq!(r.step.steps, 3);
    let phases = r.step.forward_ms + r.step.loss_ms + r.step.backward_ms + r.step.adam_ms;
    assert!(
        phases > 0.0 && phases <= r.step.step_ms * 1.001,
        "{:?}",
        r.step
    );
    assert!(r.read_s > 0.0 && r.views_s > 0.0 && r.init_s > 0.0);
    // The step is the full-resolution one; the default run's warm-up (a quarter of its steps,
    // with the splat budget on, on views halved in each side) is timed apart.
    assert_eq!(r.step.reduced_steps, 0, "{:?}", r.step);
    let w = r
        .warmup_step
        .as_ref()
        .expect("the default configuration has a warm-up");
    assert_eq!((w.factor, w.steps, w.reduced_steps), (2, 3, 3), "{w:?}");
    assert!((w.run_share - 0.25).abs() < 1e-12, "{w:?}");
    let expect = 0.25 * w.step_ms + 0.75 * r.step.step_ms;
    assert!(
        w.step_ms > 0.0 && (w.run_mean_ms - expect).abs() <= 1e-9 * expect,
        "{w:?}"
    );
    assert!(
        text.contains("warm-up step on views reduced 2-fold"),
        "{text}"
    );
    // The step at each thread count, rounds in turn: one figure a round, the median quoted.
    let counts: Vec<usize> = r.step_threads.iter().map(|t| t.threads).collect();
    assert_eq!(counts, [1, 2]);
    for t in &r.step_threads {
        assert_eq!(t.rounds_ms.len(), 2);
        assert!(t.rounds_ms.iter().all(|&ms| ms > 0.0 && ms.is_finite()));
        assert!(t.rounds_ms.contains(&t.step_ms), "{t:?}");
    }
    assert!(text.contains("training step by thread count"), "{text}");

    // The same frame again through --input: the same frame measured.
    let again = Command::new(BIN)
        .arg("bench")
        .arg("--input")
        .arg(&frame)
        .args(&small[2..])
        .output()
        .unwrap();
    assert!(
        again.status.success(),
        "{}",
        String::from_utf8_lossy(&again.stderr)
    );
    assert!(
        String::from_utf8_lossy(&again.stdout).contains(&format!("frame: {} points", r.points))
    );

    // A missing input is refused by name.
    let missing = Command::new(BIN)
        .args(["bench", "--input"])
        .arg(tmp.path().join("nope.ply"))
        .output()
        .unwrap();
    assert!(!missing.status.success());
    assert!(String::from_utf8_lossy(&missing.stderr).contains("nope.ply"));
}

/// `--steps 0` and `--repeats 0` timed nothing and printed training steps of 0.0 ms.
#[test]
fn nothing_timed_is_refused() {
    for (flag, value) in [("--steps", "0"), ("--repeats", "0")] {
        let run = Command::new(BIN)
            .args(["bench", "--points", "3000", flag, value])
            .output()
            .unwrap();
        assert!(!run.status.success(), "{flag} {value} was accepted");
        let err = String::from_utf8_lossy(&run.stderr);
        assert!(err.contains(flag), "{err}");
    }
}
