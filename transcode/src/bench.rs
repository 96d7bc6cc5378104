//! `transcode bench`: the speed figures of a paper-scale frame, measured in one process so
//! anyone can re-measure them on their own machine (issue 14's list).
//!
//! Given a plenoptic frame written to a file, it times, in order: reading the file; rendering
//! the reference views of the rig (in memory, each made a training view as it is rendered, as
//! the pipeline does); surface initialisation capped at a splat count;
//! the rasteriser's forward and forward + backward passes on one training view (medians of
//! repeats, at each thread count asked for, so the scaling and the serial fraction come out of
//! the same run); training steps on the full-resolution views with the trainer's own split of
//! time per phase; with two or more thread counts, that step at each count, timed in rounds in
//! turn; and the coarse-to-fine warm-up's step on reduced views, with the mean step of a default
//! run that mixes the two kinds in their planned shares. Medians
//! are quoted for repeated figures; everything else is one measurement. The peak resident
//! memory is read from the operating system where it says (Linux).

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};
use splat_core::{RasterPhases, Rasterizer, RenderCamera, RenderStats, SplatGrads, Splats};
use splat_init::{InitConfig, InitMode, SurfacePoints};
use splat_train::{Trainer, View};

use crate::config::Config;
use crate::pipeline::training_view;

/// Floating-point operations the rasteriser spends on one evaluated (pixel, splat) pair in the
/// forward pass, and in forward + backward together: counted by hand from the tile loops
/// (docs/benchmarks/splat-core.md), so GFLOP/s figures are estimates. Since session 60 every
/// pixel of a half-row a splat reaches counts as evaluated (it is: the lanes outside the exact
/// span are computed and fail the alpha test), about twice the pixels inside the spans counted
/// before, so the figures are of work done rather than of useful work.
pub const FLOPS_PER_PAIR_FORWARD: f64 = 40.0;
/// See [`FLOPS_PER_PAIR_FORWARD`]: forward (40) plus backward (70).
pub const FLOPS_PER_PAIR_FORWARD_BACKWARD: f64 = 110.0;

/// What to measure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchOptions {
    /// Reference and training views are `resolution` × `resolution`.
    pub resolution: u32,
    /// Splats the surface initialisation is capped at.
    pub splats: usize,
    /// Repeats of each rasteriser figure and of the read, and rounds of the training step by
    /// thread count (medians quoted).
    pub repeats: usize,
    /// Training steps timed (after one warm-up step).
    pub steps: u32,
    /// Thread counts the rasteriser (and, with two or more, the training step) is timed at
    /// (the machine's own count when empty).
    pub threads: Vec<usize>,
}

impl Default for BenchOptions {
    fn default() -> Self {
        Self {
            resolution: 1024,
            splats: 250_000,
            repeats: 7,
            steps: 30,
            threads: Vec::new(),
        }
    }
}

/// The rasteriser at one thread count.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RasterFigure {
    /// Threads of the pool it ran in.
    pub threads: usize,
    /// Median forward time, ms.
    pub forward_ms: f64,
    /// Median forward + backward time, ms.
    pub forward_backward_ms: f64,
    /// Estimated useful GFLOP/s of forward + backward ([`FLOPS_PER_PAIR_FORWARD_BACKWARD`]).
    pub gflops: f64,
    /// Median of each phase over the repeats, ms: projection, binning, compositing into the
    /// output images (forward), then tile walks, per-splat sums, chain to the parameters (backward).
    pub phases_ms: PhaseTimes,
}

/// Median wall time of each rasteriser phase, ms (see `splat_core::RasterPhases`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PhaseTimes {
    /// Projection.
    pub project: f64,
    /// Depth sort and binning.
    pub bin: f64,
    /// Tile compositing, each tile written into the output images.
    pub composite: f64,
    /// Backward tile walks.
    pub backward_tiles: f64,
    /// Per-splat sums of the pair records.
    pub backward_sum: f64,
    /// Chain to the splat parameters.
    pub backward_chain: f64,
    /// A contribution pass (forward plus each splat's summed blending weight), as the splat
    /// budget runs once per training view when it scores a model.
    pub contributions: f64,
}

/// Mean milliseconds a training step spends in each phase.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepPhases {
    /// Steps averaged.
    pub steps: u64,
    /// Projection, binning and compositing.
    pub forward_ms: f64,
    /// L1 + D-SSIM and their image gradient.
    pub loss_ms: f64,
    /// Backward rasterisation (without densification: up to the per-splat sums).
    pub backward_ms: f64,
    /// Adam, clamps and the non-finite scan (without densification: with the backward's chain
    /// to the parameters, which the update runs chunk by chunk).
    pub adam_ms: f64,
    /// Densification bookkeeping.
    pub refine_ms: f64,
    /// Whole step, as the run timed it (the phases plus what lies between them).
    pub step_ms: f64,
    /// How many of the steps averaged trained on reduced (warm-up) views: 0 for the
    /// full-resolution figure.
    #[serde(default)]
    pub reduced_steps: u64,
}

/// The coarse-to-fine warm-up's step (training views reduced `factor`-fold in each side), and
/// what a default run's steps cost on average with it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WarmupStep {
    /// Reduction factor of the warm-up views' sides.
    pub factor: u32,
    /// Steps averaged.
    pub steps: u64,
    /// How many of them trained on reduced views, as the trainer counted them.
    pub reduced_steps: u64,
    /// Mean warm-up step, ms, at the machine's thread count.
    pub step_ms: f64,
    /// The share of a default run's steps that are warm-up steps.
    pub run_share: f64,
    /// A default run's mean step: `run_share` warm-up steps, the rest full-resolution
    /// ([`StepPhases::step_ms`]), ms.
    pub run_mean_ms: f64,
}

/// A training step at one thread count, timed in rounds interleaved with the other counts'.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StepAtThreads {
    /// Threads of the pool the steps ran in.
    pub threads: usize,
    /// Median over the rounds of each round's mean step, ms.
    pub step_ms: f64,
    /// Each round's mean step, ms, in order.
    pub rounds_ms: Vec<f64>,
}

/// Everything `transcode bench` measured.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BenchReport {
    /// Points in the frame.
    pub points: usize,
    /// Capture cameras of the frame.
    pub capture_cameras: usize,
    /// Bytes of the frame's file.
    pub file_bytes: u64,
    /// Median time to read the frame, s.
    pub read_s: f64,
    /// Reference views rendered (the rig's training views).
    pub views: usize,
    /// The cube side the reference renderer drew the points at (voxels).
    pub point_size: f32,
    /// Time to render them all and make them training views, s.
    pub views_s: f64,
    /// Surface initialisation, s.
    pub init_s: f64,
    /// Splats after initialisation.
    pub splats: usize,
    /// Evaluated (pixel, splat) pairs of the timed view's forward pass.
    pub pixel_evaluations: u64,
    /// (tile, splat) pairs of the timed view's forward pass.
    pub tile_pairs: u64,
    /// The rasteriser at each thread count.
    pub raster: Vec<RasterFigure>,
    /// Amdahl serial fraction of forward + backward from the fewest and most threads timed
    /// (`None` with one thread count).
    pub serial_fraction: Option<f64>,
    /// A training step's phases at the machine's thread count, on full-resolution views.
    pub step: StepPhases,
    /// The warm-up's step on reduced views, where the default configuration has a warm-up.
    #[serde(default)]
    pub warmup_step: Option<WarmupStep>,
    /// The training step at each thread count asked for (with two or more), timed round by
    /// round in turn, so that a machine whose speed drifts moves every count's figure alike.
    #[serde(default)]
    pub step_threads: Vec<StepAtThreads>,
    /// Peak resident memory of the process, bytes, where the OS reports it.
    pub peak_rss_bytes: Option<u64>,
    /// Threads of the machine's default pool.
    pub machine_threads: usize,
    /// Whether the rasteriser's AVX2 loops ran.
    pub avx2: bool,
}

/// Errors of a bench run.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// The frame could not be read.
    #[error("cannot read the frame {path}: {source}")]
    Read {
        /// The frame's file.
        path: std::path::PathBuf,
        /// The cause (boxed: reader errors are large).
        source: Box<plenoptic_io::Error>,
    },
    /// A stage of the pipeline failed on the frame.
    #[error("{0}")]
    Stage(String),
}

/// Runs the measurements on the frame at `frame` (a plenoptic or coloured cloud, or a mesh),
/// calling `progress` with a line before each stage.
///
/// # Errors
/// [`BenchError`] when the frame cannot be read or a stage fails on it.
pub fn run_bench(
    frame: &Path,
    opts: &BenchOptions,
    progress: &mut dyn FnMut(&str),
) -> Result<BenchReport, BenchError> {
    let repeats = opts.repeats.max(1);
    progress("reading the frame");
    let file_bytes = std::fs::metadata(frame).map_or(0, |m| m.len());
    let (model, read_s) = time_read(frame, repeats.min(3))?;
    let (points, capture_cameras) = match &model {
        plenoptic_io::Model::Cloud(c) => (c.len(), c.num_cameras),
        plenoptic_io::Model::Mesh(m) => (m.positions.len(), 0),
    };

    let mut cfg = Config::default();
    cfg.rig.width = opts.resolution;
    cfg.rig.height = opts.resolution;
    let rig = plenoptic_render::build_rig(&model, &cfg.rig).map_err(stage)?;
    progress(&format!(
        "rendering {} reference views at {}²",
        rig.train.len(),
        opts.resolution
    ));
    let t = Instant::now();
    let view_opts = plenoptic_render::ViewOptions {
        depth: false,
        ..cfg.renderer.for_model(&model)
    };
    // As the pipeline does: each view becomes the trainer's as soon as it is rendered (without
    // depth, which it drops), so a frame's full images are never all held at once (and their
    // pages are reused).
    let views: Arc<Vec<View>> =
        plenoptic_render::render_views_with(&model, &rig.train, &view_opts, |i, image| {
            training_view(i, format!("view_{i:03}"), rig.train[i], image)
        })
        .map_err(stage)?
        .into_iter()
        .collect::<Result<Vec<View>, _>>()
        .map_err(stage)?
        .into();
    let views_s = t.elapsed().as_secs_f64();

    progress(&format!("initialising at most {} splats", opts.splats));
    let t = Instant::now();
    let init_cfg = InitConfig {
        mode: InitMode::Surface,
        splats: Some(opts.splats),
        ..cfg.init.clone()
    };
    let surface = SurfacePoints::from_model(&model, init_cfg.mesh_points, init_cfg.mesh_samples, 0);
    drop(model);
    let (splats, summary) =
        splat_init::initialise(&surface, &init_cfg, cfg.renderer.exponent, 0).map_err(stage)?;
    drop(surface);
    let init_s = t.elapsed().as_secs_f64();

    let machine_threads = rayon::current_num_threads();
    let mut thread_counts = if opts.threads.is_empty() {
        vec![machine_threads]
    } else {
        opts.threads.clone()
    };
    thread_counts.sort_unstable();
    thread_counts.dedup();
    let camera = RenderCamera::try_from(&rig.train[0]).map_err(stage)?;
    let rasteriser = time_raster_by_threads(&splats, &camera, &thread_counts, repeats, progress)?;

    progress(&format!("timing {} training steps", opts.steps));
    let tc = cfg.train_config(InitMode::Surface, summary.sh_degree);
    let warmup_splats = tc.warmup.map(|_| splats.clone());
    let steps = time_training_steps(splats, &views, &tc, opts, &thread_counts, progress)?;
    let warmup_step = match (tc.warmup, warmup_splats) {
        (Some(w), Some(splats)) => {
            progress(&format!(
                "timing {} warm-up training steps (views reduced {}-fold)",
                opts.steps, w.factor
            ));
            Some(time_warmup_steps(
                splats,
                views,
                tc,
                w.factor,
                opts.steps,
                cfg.warmup_share(),
                steps.step.step_ms,
            )?)
        }
        _ => None,
    };

    Ok(BenchReport {
        points,
        capture_cameras,
        file_bytes,
        read_s,
        views: rig.train.len(),
        point_size: view_opts.point_size,
        views_s,
        init_s,
        splats: steps.trained_splats,
        pixel_evaluations: rasteriser.pixel_evaluations,
        tile_pairs: rasteriser.tile_pairs,
        serial_fraction: rasteriser.serial_fraction(),
        raster: rasteriser.figures,
        step: steps.step,
        warmup_step,
        step_threads: steps.by_threads,
        peak_rss_bytes: peak_rss_bytes(),
        machine_threads,
        avx2: rasteriser.avx2,
    })
}

/// A stage's failure on the frame, as [`BenchError::Stage`].
fn stage(e: impl std::fmt::Display) -> BenchError {
    BenchError::Stage(e.to_string())
}

/// Reads the frame `times` times; returns the model and the median read time, s.
fn time_read(frame: &Path, times: usize) -> Result<(plenoptic_io::Model, f64), BenchError> {
    let mut read_times = Vec::new();
    let mut model = None;
    for _ in 0..times.max(1) {
        let t = Instant::now();
        let m = plenoptic_io::load(frame).map_err(|source| BenchError::Read {
            path: frame.to_path_buf(),
            source: Box::new(source),
        })?;
        read_times.push(t.elapsed());
        model = Some(m);
    }
    let Some(model) = model else {
        unreachable!("the read loop runs at least once")
    };
    Ok((model, median(&mut read_times).as_secs_f64()))
}

/// The rasteriser's figures at each thread count, and the forward's counts.
struct RasterFigures {
    figures: Vec<RasterFigure>,
    pixel_evaluations: u64,
    tile_pairs: u64,
    avx2: bool,
}

impl RasterFigures {
    /// Amdahl's serial fraction of forward + backward from the fewest and the most threads
    /// timed (`None` with one count).
    fn serial_fraction(&self) -> Option<f64> {
        match (self.figures.first(), self.figures.last()) {
            (Some(a), Some(b)) if b.threads > a.threads => Some(amdahl_serial_fraction(
                a.threads as f64,
                b.threads as f64,
                b.forward_backward_ms / a.forward_backward_ms,
            )),
            _ => None,
        }
    }
}

/// Times the rasteriser's forward and forward + backward on one view at each of
/// `thread_counts` (in a pool of that many threads), `repeats` times each.
fn time_raster_by_threads(
    splats: &Splats,
    camera: &RenderCamera,
    thread_counts: &[usize],
    repeats: usize,
    progress: &mut dyn FnMut(&str),
) -> Result<RasterFigures, BenchError> {
    let mut out = RasterFigures {
        figures: Vec::new(),
        pixel_evaluations: 0,
        tile_pairs: 0,
        avx2: false,
    };
    for &threads in thread_counts {
        progress(&format!(
            "timing the rasteriser on {threads} thread(s), {repeats} repeats"
        ));
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads.max(1))
            .build()
            .map_err(stage)?;
        let (fwd, fwd_bwd, stats, phases_ms) =
            pool.install(|| time_raster(splats, camera, repeats));
        let evals = stats.pixel_evaluations;
        out.tile_pairs = stats.pairs as u64;
        out.pixel_evaluations = evals;
        out.avx2 = Rasterizer::new().uses_avx2();
        out.figures.push(RasterFigure {
            threads,
            forward_ms: ms(fwd),
            forward_backward_ms: ms(fwd_bwd),
            gflops: evals as f64 * FLOPS_PER_PAIR_FORWARD_BACKWARD / fwd_bwd.as_secs_f64() / 1e9,
            phases_ms,
        });
    }
    Ok(out)
}

/// The full-resolution training step: its phases at the machine's thread count, and (with two
/// or more counts asked for) at each count in turn.
struct TrainingSteps {
    step: StepPhases,
    by_threads: Vec<StepAtThreads>,
    /// The model's splats after the steps.
    trained_splats: usize,
}

/// Times `opts.steps` full-resolution training steps (after one untimed step) from `splats`,
/// then, with two or more `thread_counts`, rounds of steps at each count in turn.
fn time_training_steps(
    splats: Splats,
    views: &Arc<Vec<View>>,
    tc: &splat_train::TrainConfig,
    opts: &BenchOptions,
    thread_counts: &[usize],
    progress: &mut dyn FnMut(&str),
) -> Result<TrainingSteps, BenchError> {
    let repeats = opts.repeats.max(1);
    // Room for the steps timed at each thread count after the plain figure (`per_round` plus
    // one untimed, per count and round).
    let per_round = (opts.steps / 4).max(3);
    let by_threads = if thread_counts.len() > 1 {
        repeats as u32 * thread_counts.len() as u32 * (per_round + 1)
    } else {
        0
    };
    // The step is the full-resolution one: a default run trains its first share of steps on
    // reduced views (the warm-up, timed apart), and timing those as if they were full steps
    // made the figure depend on how many steps were asked for.
    let full_tc = splat_train::TrainConfig {
        iterations: opts.steps + 1 + by_threads,
        time_budget: None,
        densify: None,
        warmup: None,
        ..tc.clone()
    };
    let mut trainer = Trainer::new(splats, Arc::clone(views), full_tc).map_err(stage)?;
    trainer.run_until(1, |_| {});
    let before = trainer.report(false).timings;
    let started_s = trainer.report(false).elapsed_s;
    let report = trainer.run_until(opts.steps + 1, |_| {});
    let after = report.timings;
    let steps = (after.steps - before.steps).max(1);
    let per = |a: Duration, b: Duration| ms(a.saturating_sub(b)) / steps as f64;
    let step = StepPhases {
        steps,
        forward_ms: per(after.forward, before.forward),
        loss_ms: per(after.loss, before.loss),
        backward_ms: per(after.backward, before.backward),
        adam_ms: per(after.adam, before.adam),
        refine_ms: per(after.refine, before.refine),
        step_ms: 1e3 * (report.elapsed_s - started_s) / steps as f64,
        reduced_steps: after.coarse_steps - before.coarse_steps,
    };
    let by_threads = if thread_counts.len() > 1 {
        progress(&format!(
            "timing training steps at {thread_counts:?} threads in turn, {repeats} rounds"
        ));
        time_steps_by_threads(&mut trainer, thread_counts, repeats, per_round).map_err(stage)?
    } else {
        Vec::new()
    };
    Ok(TrainingSteps {
        step,
        by_threads,
        trained_splats: trainer.splats().len(),
    })
}

/// Times `steps` warm-up steps (views reduced `factor`-fold) from `splats`, and a default run's
/// mean step with `run_share` of its steps such and the rest at `full_step_ms`.
fn time_warmup_steps(
    splats: Splats,
    views: Arc<Vec<View>>,
    tc: splat_train::TrainConfig,
    factor: u32,
    steps: u32,
    run_share: f64,
    full_step_ms: f64,
) -> Result<WarmupStep, BenchError> {
    let warm_tc = splat_train::TrainConfig {
        iterations: steps + 1,
        time_budget: None,
        densify: None,
        warmup: Some(splat_train::Warmup {
            factor,
            until: steps + 1,
        }),
        ..tc
    };
    let mut trainer = Trainer::new(splats, views, warm_tc).map_err(stage)?;
    trainer.run_until(1, |_| {});
    let before = trainer.report(false);
    let report = trainer.run_until(steps + 1, |_| {});
    let timed = (report.timings.steps - before.timings.steps).max(1);
    let step_ms = 1e3 * (report.elapsed_s - before.elapsed_s) / timed as f64;
    Ok(WarmupStep {
        factor,
        steps: timed,
        reduced_steps: report.timings.coarse_steps - before.timings.coarse_steps,
        step_ms,
        run_share,
        // Linear in the step times, so milliseconds in, milliseconds out.
        run_mean_ms: splat_train::schedule::mean_step_s(full_step_ms, Some((run_share, step_ms))),
    })
}

/// The serial fraction f of Amdahl's law, T(n) = T(1)·(f + (1 − f)/n), from the ratio
/// `r` = T(b)/T(a) of times measured at `a` and `b` threads (clamped to [0, 1]: noise can put
/// a measured ratio outside the law's range).
#[must_use]
pub fn amdahl_serial_fraction(a: f64, b: f64, r: f64) -> f64 {
    // r·(f + (1 − f)/a) = f + (1 − f)/b, solved for f.
    let f = (1.0 / b - r / a) / (r - r / a - 1.0 + 1.0 / b);
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// Median forward, median forward + backward, the forward's counts, and each phase's median,
/// over `repeats` each (after one untimed pass that sizes the buffers).
fn time_raster(
    splats: &Splats,
    camera: &RenderCamera,
    repeats: usize,
) -> (Duration, Duration, RenderStats, PhaseTimes) {
    let opts = splat_core::RenderOptions::default();
    let mut r = Rasterizer::new();
    let mut grads = SplatGrads::zeros_like(splats);
    let d_rgb = vec![1e-3_f32; 3 * (camera.width as usize) * (camera.height as usize)];
    r.forward(splats, camera, &opts);
    r.backward(splats, camera, &opts, &d_rgb, None, None, &mut grads);
    let stats = r.stats();
    let mut fwd = Vec::with_capacity(repeats);
    let mut both = Vec::with_capacity(repeats);
    let mut phases = Vec::with_capacity(repeats);
    let mut contributions = Vec::with_capacity(repeats);
    let mut sums = vec![0.0; splats.len()];
    for _ in 0..repeats {
        let t = Instant::now();
        r.forward(splats, camera, &opts);
        fwd.push(t.elapsed());
        let t = Instant::now();
        r.forward(splats, camera, &opts);
        r.backward(splats, camera, &opts, &d_rgb, None, None, &mut grads);
        both.push(t.elapsed());
        phases.push(r.phases());
        let t = Instant::now();
        if r.accumulate_contributions(splats, camera, &opts, &mut sums)
            .is_ok()
        {
            contributions.push(t.elapsed());
        }
    }
    let phase = |get: fn(&RasterPhases) -> Duration| {
        ms(median(&mut phases.iter().map(get).collect::<Vec<_>>()))
    };
    let phase_times = PhaseTimes {
        project: phase(|p| p.project),
        bin: phase(|p| p.bin),
        composite: phase(|p| p.composite),
        backward_tiles: phase(|p| p.backward_tiles),
        backward_sum: phase(|p| p.backward_sum),
        backward_chain: phase(|p| p.backward_chain),
        contributions: ms(median(&mut contributions)),
    };
    (median(&mut fwd), median(&mut both), stats, phase_times)
}

/// Times `trainer`'s steps at each of `thread_counts` in turn: `rounds` rounds, each running
/// `per_round` steps at every count in its own pool, after one untimed step there (the trainer
/// must have that many steps left). The model trains on through the rounds, so each count sees
/// the same mix of early and later steps.
fn time_steps_by_threads(
    trainer: &mut Trainer,
    thread_counts: &[usize],
    rounds: usize,
    per_round: u32,
) -> Result<Vec<StepAtThreads>, rayon::ThreadPoolBuildError> {
    let pools = thread_counts
        .iter()
        .map(|&t| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(t.max(1))
                .build()
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut round_steps = vec![Vec::with_capacity(rounds); thread_counts.len()];
    for _ in 0..rounds {
        for (pool, times) in pools.iter().zip(&mut round_steps) {
            pool.install(|| {
                trainer.run_until(trainer.iteration() + 1, |_| {});
                let before = trainer.report(false).elapsed_s;
                let report = trainer.run_until(trainer.iteration() + per_round, |_| {});
                let mean_s = (report.elapsed_s - before) / f64::from(per_round);
                times.push(Duration::from_secs_f64(mean_s.max(0.0)));
            });
        }
    }
    Ok(thread_counts
        .iter()
        .zip(round_steps)
        .map(|(&threads, mut steps)| StepAtThreads {
            threads,
            rounds_ms: steps.iter().copied().map(ms).collect(),
            step_ms: ms(median(&mut steps)),
        })
        .collect())
}

fn median(d: &mut [Duration]) -> Duration {
    d.sort_unstable();
    d.get(d.len() / 2).copied().unwrap_or_default()
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// The process's peak resident set (`VmHWM` in /proc/self/status), where there is one.
#[must_use]
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn amdahl_serial_fraction_inverts_its_own_law() {
        for f in [0.0, 0.05, 0.3, 1.0] {
            for (a, b) in [(1.0, 2.0), (2.0, 16.0), (1.0, 8.0)] {
                let t = |n: f64| f + (1.0 - f) / n;
                let got = amdahl_serial_fraction(a, b, t(b) / t(a));
                assert!((got - f).abs() < 1e-12, "f {f} from {a}, {b}: {got}");
            }
        }
        // Better than linear scaling (noise) reads as no serial part.
        assert_eq!(amdahl_serial_fraction(1.0, 2.0, 0.4), 0.0);
    }
}
