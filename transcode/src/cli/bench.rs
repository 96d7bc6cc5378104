//! `transcode bench`: generates a frame of a given size and measures the pipeline's speed
//! figures on it ([`transcode::bench`]), so anyone can re-measure them on their machine.

use std::path::PathBuf;

use anyhow::Context as _;
use plenoptic_scenes::{AUTO_GRID, DemoConfig, SynthConfig, demo_scene, synth_from_mesh};
use transcode::bench::{BenchOptions, BenchReport, run_bench};

use super::synth::Grid;

/// Arguments of `transcode bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Measure this existing frame (any input `run` reads) instead of generating one.
    #[arg(long, conflicts_with_all = ["mesh", "frame"])]
    input: Option<PathBuf>,
    /// Synthesise the frame from this mesh (as `transcode synth`); without it, the built-in demo
    /// scene voxelised finely enough for about `--points` points.
    #[arg(long)]
    mesh: Option<PathBuf>,
    /// Points of the generated frame (surface samples with `--mesh`; samples sharing a voxel
    /// merge, so the frame holds somewhat fewer).
    #[arg(long, default_value_t = 3_000_000)]
    points: usize,
    /// Voxel grid of the synthesised frame (with `--mesh`), or `auto`.
    #[arg(long, default_value = "auto")]
    grid: Grid,
    /// Capture cameras of the generated frame.
    #[arg(long, default_value_t = 13)]
    cameras: usize,
    /// Views are N × N pixels.
    #[arg(long, default_value_t = BenchOptions::default().resolution, value_name = "N")]
    resolution: u32,
    /// Splats the initialisation is capped at.
    #[arg(long, default_value_t = BenchOptions::default().splats)]
    splats: usize,
    /// Repeats of each rasteriser figure, and rounds of the training step by thread count
    /// (medians quoted).
    #[arg(long, default_value_t = BenchOptions::default().repeats, value_parser = at_least_one)]
    repeats: usize,
    /// Training steps timed (and a quarter of them, at least 3, per round and thread count).
    #[arg(
        long,
        default_value_t = BenchOptions::default().steps,
        value_parser = clap::value_parser!(u32).range(1..)
    )]
    steps: u32,
    /// Thread counts to time the rasteriser and the training step at, comma-separated (default:
    /// 1 and all of the machine's, which gives the serial fraction); the step is timed at each
    /// count in rounds, the counts in turn. Each in 1..=1024.
    #[arg(long, value_delimiter = ',', value_parser = clap::value_parser!(u16).range(1..=1024))]
    threads: Vec<u16>,
    /// Keep the generated frame at this path (default: a temporary file, removed after).
    #[arg(long)]
    frame: Option<PathBuf>,
    /// Also write the figures as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Runs `transcode bench`.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(input) = &args.input {
        super::config::require_file(input, "input")?;
        let report = run_bench(input, &options(&args), &mut |what| eprintln!("  {what}"))?;
        return finish(&report, &args);
    }
    let cloud = match &args.mesh {
        Some(path) => {
            eprintln!(
                "synthesising about {} points from {}",
                args.points,
                path.display()
            );
            let mesh = plenoptic_io::read_mesh(path)
                .with_context(|| format!("cannot read the mesh {}", path.display()))?;
            let config = SynthConfig {
                points: args.points,
                cameras: args.cameras,
                grid: args.grid.0.unwrap_or(AUTO_GRID),
                ..SynthConfig::default()
            };
            synth_from_mesh(&mesh, &config)
                .with_context(|| format!("cannot synthesise from {}", path.display()))?
        }
        None => {
            // The scene's point count grows with the square of its grid (128: about 35,000).
            let base = DemoConfig::default();
            let scale = (args.points as f64 / 35_000.0).sqrt();
            let grid = ((f64::from(base.grid) * scale).round() as u32).clamp(16, 1 << 14);
            eprintln!("generating the demo scene on a {grid}-voxel grid");
            demo_scene(&DemoConfig {
                grid,
                cameras: args.cameras,
                ..base
            })
            .context("generating the demo scene")?
        }
    };
    let (frame, temporary) = match &args.frame {
        Some(p) => (p.clone(), false),
        None => (
            std::env::temp_dir().join(format!("transcode-bench-{}.ply", std::process::id())),
            true,
        ),
    };
    plenoptic_io::write_cloud(&frame, &cloud)
        .with_context(|| format!("cannot write the frame {}", frame.display()))?;
    drop(cloud);
    let result = run_bench(&frame, &options(&args), &mut |what| eprintln!("  {what}"));
    if temporary {
        // Best effort: a leftover temporary file is not worth failing the measurement for.
        let _ = std::fs::remove_file(&frame);
    }
    finish(&result?, &args)
}

/// The measurement's options from the arguments (threads: 1 and the machine's by default).
fn options(args: &Args) -> BenchOptions {
    let machine = rayon::current_num_threads();
    BenchOptions {
        resolution: args.resolution,
        splats: args.splats,
        repeats: args.repeats,
        steps: args.steps,
        threads: if args.threads.is_empty() {
            vec![1, machine]
        } else {
            args.threads.iter().map(|&t| usize::from(t)).collect()
        },
    }
}

/// Prints the figures and writes the JSON when asked.
fn finish(report: &BenchReport, args: &Args) -> anyhow::Result<()> {
    print_report(report, &options(args));
    if let Some(path) = &args.json {
        let text = serde_json::to_string_pretty(report)?;
        atomic_output::write_atomic(path, text.as_bytes())
            .with_context(|| format!("cannot write {}", path.display()))?;
        println!("figures written to {}", path.display());
    }
    Ok(())
}

fn print_report(r: &BenchReport, opts: &BenchOptions) {
    println!(
        "frame: {} points, {} capture cameras, {:.1} MB",
        r.points,
        r.capture_cameras,
        r.file_bytes as f64 / 1e6
    );
    println!("read (median):                {:8.2} s", r.read_s);
    println!(
        "{} reference views at {}²:  {:8.2} s  (points drawn {:.2} voxels wide)",
        r.views, opts.resolution, r.views_s, r.point_size
    );
    println!("surface init to {} splats: {:8.2} s", r.splats, r.init_s);
    println!(
        "rasteriser, {} splats at {}², {} (tile, splat) pairs, {} evaluated (pixel, splat) pairs, {} loops:",
        r.splats,
        opts.resolution,
        r.tile_pairs,
        r.pixel_evaluations,
        if r.avx2 { "AVX2" } else { "portable" }
    );
    for f in &r.raster {
        println!(
            "  {:3} thread(s): forward {:8.1} ms, forward + backward {:8.1} ms (≈ {:.1} GFLOP/s)",
            f.threads, f.forward_ms, f.forward_backward_ms, f.gflops
        );
        let p = &f.phases_ms;
        println!(
            "      forward: project {:.1}, bin {:.1}, composite {:.1} ms; backward: tiles {:.1}, sums {:.1}, chain {:.1} ms; contribution pass {:.1} ms",
            p.project,
            p.bin,
            p.composite,
            p.backward_tiles,
            p.backward_sum,
            p.backward_chain,
            p.contributions
        );
    }
    if let Some(f) = r.serial_fraction {
        println!(
            "  serial fraction (Amdahl, fewest to most threads): {:.3}",
            f
        );
    }
    let s = &r.step;
    println!(
        "training step on full-resolution views ({} steps, {} threads): {:.1} ms = forward {:.1} + loss {:.1} + backward {:.1} + update {:.1} (the backward's chain to the parameters, Adam, clamps) + refine {:.1} + other {:.1}",
        s.steps,
        r.machine_threads,
        s.step_ms,
        s.forward_ms,
        s.loss_ms,
        s.backward_ms,
        s.adam_ms,
        s.refine_ms,
        s.step_ms - (s.forward_ms + s.loss_ms + s.backward_ms + s.adam_ms + s.refine_ms)
    );
    if let (Some(few), Some(most)) = (r.step_threads.first(), r.step_threads.last()) {
        let counts: Vec<String> = r
            .step_threads
            .iter()
            .map(|t| format!("{} threads {:.1} ms", t.threads, t.step_ms))
            .collect();
        println!(
            "training step by thread count ({} rounds in turn, medians): {}; {} → {} threads {:.2}×",
            few.rounds_ms.len(),
            counts.join(", "),
            few.threads,
            most.threads,
            few.step_ms / most.step_ms
        );
    }
    if let Some(w) = &r.warmup_step {
        println!(
            "warm-up step on views reduced {}-fold ({} steps, {} threads): {:.1} ms; a default run's mean step ({:.0} % warm-up): {:.1} ms",
            w.factor,
            w.steps,
            r.machine_threads,
            w.step_ms,
            100.0 * w.run_share,
            w.run_mean_ms
        );
    }
    if let Some(b) = r.peak_rss_bytes {
        println!("peak resident memory: {:.2} GB", b as f64 / 1e9);
    }
}

/// A count of at least 1 (`--repeats`: none timed nothing and printed 0.0 ms figures).
fn at_least_one(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(format!("expected a whole number of at least 1, got {s:?}")),
    }
}
