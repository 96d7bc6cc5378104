//! `transcode train`: train splats on a COLMAP dataset folder (`images/` + `sparse/0/`, and
//! `masks/` when there are masks).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use serde::Serialize;
use splat_core::{RenderOptions, Splats};
use splat_train::schedule::next_stop;
use splat_train::{
    Background, Dataset, DensifyConfig, HistoryEntry, Photometric, TrainConfig, TrainReport,
    Trainer, View, Warmup, evaluate_with, read_dataset,
};

use atomic_output::write_atomic;

/// How the initial splats are made.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Init {
    /// The dataset's SfM points (`points3D`), with their colours (Inria's default).
    Points3d,
    /// Uniform random points in the bounding box of the SfM points (or of the cameras).
    Random,
}

/// Background behind the splats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum BackgroundArg {
    /// Black (Inria's default).
    Black,
    /// White.
    White,
    /// A random colour every step (useful with masks).
    Random,
}

/// The loss's photometric term beside D-SSIM (`splat_train::Photometric`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum PhotometricArg {
    /// Mean absolute error (Inria's).
    L1,
    /// Root mean squared error: large errors weigh more (docs/pipeline.md).
    L2,
}

/// Arguments of `transcode train`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// COLMAP dataset folder with `images/` and `sparse/0/` (PINHOLE or SIMPLE_PINHOLE), and
    /// optionally `masks/` (grey coverage, same names as the images, which then hold colour on
    /// black): masked views are trained over the chosen background.
    pub dataset: PathBuf,
    /// Output folder for `splats.ply`, `history.json` and `checkpoint.bin`.
    #[arg(long)]
    pub out: PathBuf,
    /// Optimisation steps (one view each).
    #[arg(long, default_value_t = 7000)]
    pub iterations: u32,
    /// Initial splats.
    #[arg(long, value_enum, default_value_t = Init::Points3d)]
    pub init: Init,
    /// Number of splats for `--init random`.
    #[arg(long, default_value_t = 10_000)]
    pub random_points: usize,
    /// Keep splat positions fixed (implies no densification).
    #[arg(long, conflicts_with = "densify")]
    pub freeze_positions: bool,
    /// Grow and prune splats with Inria's adaptive density control (the default).
    #[arg(long, overrides_with = "no_densify")]
    pub densify: bool,
    /// Keep the splat set fixed.
    #[arg(long, overrides_with = "densify")]
    pub no_densify: bool,
    /// Never grow beyond this many splats.
    #[arg(long, default_value_t = DensifyConfig::default().max_splats)]
    pub max_splats: usize,
    /// SH degree of the model (0–3).
    #[arg(long, default_value_t = 3, value_parser = clap::value_parser!(u32).range(0..=3))]
    pub sh_degree: u32,
    /// Evaluate every K iterations (0: only at the end).
    #[arg(long, default_value_t = 0)]
    pub eval_every: u32,
    /// A second COLMAP dataset of held-out views to evaluate on (default: the training views).
    #[arg(long)]
    pub heldout: Option<PathBuf>,
    /// Continue from `OUT/checkpoint.bin` up to `--iterations`, with the same other settings
    /// (a finished run is left as it is).
    #[arg(long)]
    pub resume: bool,
    /// Write `OUT/checkpoint.bin` every K iterations (0: only by wall time and at the end).
    #[arg(long, default_value_t = 0)]
    pub checkpoint_every: u32,
    /// Also write `OUT/checkpoint.bin` whenever this many seconds of wall time have passed since
    /// the last one (0: after every step).
    #[arg(
        long,
        value_name = "SECONDS",
        default_value_t = transcode::config::DEFAULT_CHECKPOINT_INTERVAL_S,
        value_parser = super::config::parse_interval_seconds
    )]
    pub checkpoint_interval: f64,
    /// Divide the image size by this factor (intrinsics are scaled to match).
    #[arg(long, default_value_t = 1.0)]
    pub downscale: f64,
    /// Background colour.
    #[arg(long, value_enum, default_value_t = BackgroundArg::Black)]
    pub background: BackgroundArg,
    /// The loss's photometric term beside D-SSIM.
    #[arg(long, value_enum, default_value_t = PhotometricArg::L1)]
    pub photometric: PhotometricArg,
    /// Train (and evaluate) with the antialiased (Mip-Splatting) opacity compensation; the
    /// PLY then says so in its header (`comment SplatRenderMode: mip`), which Brush,
    /// PlayCanvas / SuperSplat, splat-transform and our viewer follow (docs/pipeline.md).
    #[arg(long)]
    pub antialiased: bool,
    /// Seed of the run.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Stop after this many seconds of training.
    #[arg(long, value_name = "SECONDS", value_parser = super::config::parse_budget_seconds)]
    pub time_budget: Option<f64>,
    /// Warm up on views reduced by this integer factor (≥ 2; 1 = no warm-up).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub warmup_factor: u32,
    /// Number of warm-up steps at the reduced size.
    #[arg(long, default_value_t = 0)]
    pub warmup_steps: u32,
    /// Do not show a progress bar.
    #[arg(long)]
    pub quiet: bool,
}

/// One evaluation during the run.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
struct EvalPoint {
    iteration: u32,
    elapsed_s: f64,
    splats: usize,
    psnr: f64,
    ssim: f64,
}

/// Contents of `history.json`.
#[derive(Debug, Serialize)]
struct History<'a> {
    dataset: String,
    heldout: Option<String>,
    views: usize,
    eval_views: usize,
    iterations: u32,
    elapsed_s: f64,
    wall_s: f64,
    splats: usize,
    non_finite: splat_train::NonFinite,
    refine: splat_train::RefineReport,
    timings_s: Timings,
    steps: &'a [HistoryEntry],
    evaluations: &'a [EvalPoint],
}

/// Time per phase in seconds.
#[derive(Debug, Serialize)]
struct Timings {
    forward: f64,
    loss: f64,
    backward: f64,
    adam: f64,
    refine: f64,
}

/// Runs `transcode train`: reads the dataset, sets the trainer up (or continues the run saved in
/// `OUT`), trains to the end with its evaluations and checkpoints, and writes the model and the
/// history last.
pub fn run(args: Args) -> anyhow::Result<()> {
    let wall = Instant::now();
    check_args(&args)?;
    let files = RunFiles::new(&args.out);
    let settings = Settings::of(&args);
    let resume = resuming(&args, &files, &settings)?;
    let Dataset {
        views,
        reconstruction: rec,
    } = read_dataset(&args.dataset, args.downscale)?;
    refuse_background_without_masks(&args, &views, &args.dataset)?;
    let eval_views = match &args.heldout {
        Some(dir) => {
            let heldout = read_dataset(dir, args.downscale)?.views;
            // Scored on the training background: held-out views without coverage were scored
            // as if their black background were the object (1.89 dB on white).
            refuse_background_without_masks(&args, &heldout, dir)?;
            heldout
        }
        None => views.clone(),
    };
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let config = train_config(&args);
    let mut trainer = if resume {
        Trainer::resume(&files.checkpoint, views, config).with_context(|| {
            format!(
                "cannot resume from {} (run without --resume to start over)",
                files.checkpoint.display()
            )
        })?
    } else {
        let splats = initial_splats(&args, &rec, &views)?;
        Trainer::new(splats, views, config).context("cannot set up training")?
    };
    let spent = trainer.report(false).elapsed_s;
    let over =
        trainer.iteration() >= args.iterations || args.time_budget.is_some_and(|b| spent >= b);
    if resume && over && files.ply.is_file() && files.history.is_file() {
        println!(
            "the run in {} is already finished ({} iterations); nothing to resume",
            args.out.display(),
            trainer.iteration()
        );
        println!(
            "wrote {} and {}",
            files.ply.display(),
            files.history.display()
        );
        return Ok(());
    }
    // A checkpoint past the steps asked for cannot be taken back to them: say so rather than
    // write the model of more steps than asked.
    if resume && trainer.iteration() > args.iterations {
        bail!(
            "the checkpoint in {} is at step {}, past --iterations {}: resume with --iterations \
             {} or more to finish it there, or run without --resume to start over",
            args.out.display(),
            trainer.iteration(),
            args.iterations,
            trainer.iteration()
        );
    }
    files.clear(resume)?;
    let evaluations = if resume {
        files.saved_evaluations(trainer.iteration())?
    } else {
        let json = serde_json::to_vec_pretty(&settings).context("cannot encode the settings")?;
        write_atomic(&files.settings, &json)
            .with_context(|| format!("cannot write {}", files.settings.display()))?;
        Vec::new()
    };
    if !args.quiet {
        eprintln!(
            "training on {} views ({}×{}), {} splats, scene extent {:.3}",
            trainer.views().len(),
            trainer.views()[0].camera.intrinsics.width,
            trainer.views()[0].camera.intrinsics.height,
            trainer.splats().len(),
            trainer.extent()
        );
        if resume {
            eprintln!(
                "continuing from step {} of {} ({}, {} evaluation(s) kept)",
                trainer.iteration(),
                args.iterations,
                files.checkpoint.display(),
                evaluations.len()
            );
        }
    }
    let (report, evals) = train_to_end(&args, &files, &mut trainer, &eval_views, evaluations)?;

    let ply_options = splat_core::ply::PlyOptions {
        antialiased: args.antialiased,
    };
    splat_core::ply::write_model(&files.ply, trainer.splats(), &ply_options)
        .with_context(|| format!("cannot write {}", files.ply.display()))?;
    write_history(
        &files.history,
        &args,
        &report,
        &evals,
        eval_views.len(),
        trainer.views().len(),
        wall.elapsed(),
    )?;
    summary(
        &report,
        evals.last(),
        &files.ply,
        &files.history,
        wall.elapsed(),
    );
    Ok(())
}

/// Refuses numeric flags outside their range.
fn check_args(args: &Args) -> anyhow::Result<()> {
    if !(args.downscale.is_finite() && args.downscale >= 1.0) {
        bail!("--downscale {} must be at least 1", args.downscale);
    }
    if args.warmup_steps > 0 && args.warmup_factor < 2 {
        bail!(
            "--warmup-steps {} needs --warmup-factor 2 or more (1 is no warm-up)",
            args.warmup_steps
        );
    }
    if args.warmup_steps > 0 && args.warmup_steps >= args.iterations {
        bail!(
            "--warmup-steps {} must be fewer than --iterations {}: the run would end before it \
             trained on full-size views",
            args.warmup_steps,
            args.iterations
        );
    }
    let densifies = !args.no_densify && !args.freeze_positions;
    if args.init == Init::Random && densifies && args.random_points > args.max_splats {
        bail!(
            "--random-points {} is above --max-splats {}: densification would never add one",
            args.random_points,
            args.max_splats
        );
    }
    Ok(())
}

/// Whether this call continues the run saved in `OUT`: `--resume` and a checkpoint to continue
/// from, saved with the same settings (else an error naming the ones that differ). Killed before
/// its first checkpoint, a run has nothing to continue from and starts again.
fn resuming(args: &Args, files: &RunFiles, settings: &Settings) -> anyhow::Result<bool> {
    let resume = args.resume && files.checkpoint.is_file();
    if args.resume && !resume && !args.quiet {
        eprintln!(
            "no checkpoint in {}: starting from the beginning",
            args.out.display()
        );
    }
    if !resume {
        return Ok(false);
    }
    let saved: Settings = read_saved(&files.settings)?;
    if saved != *settings {
        bail!(
            "the run in {} was started with other settings ({}); resume it with the same \
             ones (only --iterations, --time-budget, --eval-every and the checkpoint flags may \
             change), or run without --resume to start over",
            args.out.display(),
            saved.differences(settings).join(", ")
        );
    }
    Ok(true)
}

/// A JSON file a run saved for `--resume`.
fn read_saved<T: serde::de::DeserializeOwned>(path: &Path) -> anyhow::Result<T> {
    let bytes = std::fs::read(path).with_context(|| {
        format!(
            "cannot read {} (run without --resume to start over)",
            path.display()
        )
    })?;
    serde_json::from_slice(&bytes).with_context(|| {
        format!(
            "{} is damaged; run without --resume to start over",
            path.display()
        )
    })
}

/// Refuses a random or white background on views that hold their own (no mask, no alpha).
fn refuse_background_without_masks(
    args: &Args,
    views: &[View],
    dataset: &Path,
) -> anyhow::Result<()> {
    if args.background != BackgroundArg::Black
        && let Some(v) = views.iter().find(|v| v.mask.is_none())
    {
        bail!(
            "--background {}: {} has no mask in {} and no alpha channel, so its pixels already \
             hold their own background and another cannot be put behind them; train with \
             --background black, or add masks/ (coverage images named like the images)",
            format!("{:?}", args.background).to_lowercase(),
            v.name,
            dataset.join("masks").display()
        );
    }
    Ok(())
}

/// The files of a training run in `OUT`.
struct RunFiles {
    /// The settings the run was started with ([`SETTINGS_FILE`]).
    settings: PathBuf,
    /// The trainer's checkpoint.
    checkpoint: PathBuf,
    /// The evaluations taken up to the checkpoint, saved beside it.
    evaluations: PathBuf,
    /// The model: with the history, what marks a finished run.
    ply: PathBuf,
    history: PathBuf,
}

impl RunFiles {
    fn new(out: &Path) -> Self {
        Self {
            settings: out.join(SETTINGS_FILE),
            checkpoint: out.join("checkpoint.bin"),
            evaluations: out.join("train-evaluations.json"),
            ply: out.join("splats.ply"),
            history: out.join("history.json"),
        }
    }

    /// Removes the files that mark a finished run, so an interrupted run never looks finished
    /// (they come back only at its end); a fresh run also drops an earlier run's checkpoint and
    /// evaluations, which its settings no longer describe.
    fn clear(&self, resume: bool) -> anyhow::Result<()> {
        let markers = [&self.ply, &self.history];
        let earlier = [&self.checkpoint, &self.evaluations];
        let stale = markers
            .iter()
            .chain(if resume { &[][..] } else { &earlier[..] });
        for path in stale {
            match std::fs::remove_file(path) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => {
                    return Err(e).with_context(|| format!("cannot remove {}", path.display()));
                }
            }
        }
        Ok(())
    }

    /// The evaluations a resumed run keeps: those saved up to its checkpoint's step (a point
    /// taken after it is taken again, from the same splats). A run saved before the file existed
    /// has none.
    fn saved_evaluations(&self, iteration: u32) -> anyhow::Result<Vec<EvalPoint>> {
        if !self.evaluations.is_file() {
            return Ok(Vec::new());
        }
        let mut points: Vec<EvalPoint> = read_saved(&self.evaluations)?;
        points.retain(|p| p.iteration <= iteration);
        Ok(points)
    }

    /// Saves the evaluations so far, then the trainer's checkpoint. The evaluations go first: a
    /// point newer than the checkpoint is dropped and taken again on resume.
    fn save(&self, trainer: &Trainer, evaluations: &[EvalPoint]) -> anyhow::Result<()> {
        let json =
            serde_json::to_vec_pretty(evaluations).context("cannot encode the evaluations")?;
        write_atomic(&self.evaluations, &json)
            .with_context(|| format!("cannot write {}", self.evaluations.display()))?;
        trainer
            .save_checkpoint(&self.checkpoint)
            .context("cannot write the checkpoint")
    }
}

/// Trains to `--iterations` (or the time budget), evaluating every `--eval-every` steps and at
/// the end, and checkpointing every `--checkpoint-every` steps, by wall time and at the end.
/// Returns the trainer's report and every evaluation of the run, `evals` (a resumed run's
/// earlier ones) first.
///
/// The trainer pauses at each evaluation or checkpoint so that both happen outside its timed
/// steps; it pauses after every step to look at the clock for the wall-time checkpoints
/// (pausing changes nothing it computes).
fn train_to_end(
    args: &Args,
    files: &RunFiles,
    trainer: &mut Trainer,
    eval_views: &[View],
    mut evals: Vec<EvalPoint>,
) -> anyhow::Result<(TrainReport, Vec<EvalPoint>)> {
    let background = match args.background {
        BackgroundArg::White => Vec3::ONE,
        BackgroundArg::Black | BackgroundArg::Random => Vec3::ZERO,
    };
    let bar = progress_bar(args.iterations, trainer.iteration(), args.quiet);
    let mut ema: Option<(f64, f64)> = None;
    let mut pending_eval = false;
    let mut pending_ckpt = false;
    let interval = Duration::from_secs_f64(args.checkpoint_interval);
    let mut saved_at = Instant::now();
    let report = loop {
        let stop_at = next_stop(
            trainer.iteration(),
            args.iterations,
            args.eval_every,
            args.checkpoint_every,
        )
        .min(trainer.iteration() + 1);
        let r = trainer.run_until(stop_at, |p| {
            let (l, q) = ema.map_or((p.step.loss, p.step.psnr), |(l, q)| {
                (0.95 * l + 0.05 * p.step.loss, 0.95 * q + 0.05 * p.step.psnr)
            });
            ema = Some((l, q));
            bar.set_position(u64::from(p.step.iteration));
            if p.step.iteration % 10 == 0 {
                bar.set_message(format!(
                    "loss {l:.4}  PSNR {q:.2} dB  {} splats",
                    p.step.splats
                ));
            }
        });
        let it = r.iterations;
        pending_eval |= args.eval_every > 0 && it.is_multiple_of(args.eval_every);
        pending_ckpt |= args.checkpoint_every > 0 && it.is_multiple_of(args.checkpoint_every);
        pending_ckpt |= saved_at.elapsed() >= interval;
        let done = it >= args.iterations || r.stopped_by_budget;
        if (pending_eval || done) && evals.last().is_none_or(|e| e.iteration < it) {
            let opts = RenderOptions {
                background,
                active_sh_degree: trainer.splats().sh_degree,
                antialiased: args.antialiased,
                linear_colour: false,
            };
            let e = evaluate_with(trainer.splats(), eval_views, &opts)?;
            let line = format!(
                "iteration {it}: {:.2} dB PSNR, SSIM {:.4} on {} views after {:.1} s, {} splats",
                e.psnr,
                e.ssim,
                eval_views.len(),
                r.elapsed_s,
                r.splats
            );
            if bar.is_hidden() {
                eprintln!("{line}");
            } else {
                bar.println(line);
            }
            evals.push(EvalPoint {
                iteration: it,
                elapsed_s: r.elapsed_s,
                splats: r.splats,
                psnr: e.psnr,
                ssim: e.ssim,
            });
        }
        pending_eval = false;
        if pending_ckpt || done {
            files.save(trainer, &evals)?;
            pending_ckpt = false;
            saved_at = Instant::now();
        }
        if done {
            break r;
        }
    };
    bar.finish_and_clear();
    Ok((report, evals))
}

/// Name of the file in `OUT` that records the settings a run was started with.
const SETTINGS_FILE: &str = "train-settings.json";

/// The settings that define a run of `transcode train`: `--resume` refuses others. Floats are
/// kept as their shortest decimal text, which reads back exactly.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, serde::Deserialize)]
struct Settings {
    dataset: String,
    heldout: Option<String>,
    init: String,
    random_points: usize,
    freeze_positions: bool,
    densify: bool,
    max_splats: usize,
    sh_degree: u32,
    downscale: String,
    background: String,
    /// Runs started before the setting existed trained with L1.
    #[serde(default = "l1_name")]
    photometric: String,
    /// Runs started before the setting existed trained plain.
    #[serde(default)]
    antialiased: bool,
    seed: u64,
    warmup_factor: u32,
    warmup_steps: u32,
}

/// The name [`Settings`] gives the L1 term.
fn l1_name() -> String {
    format!("{:?}", PhotometricArg::L1)
}

impl Settings {
    fn of(args: &Args) -> Self {
        let path = |p: &Path| {
            std::fs::canonicalize(p)
                .unwrap_or_else(|_| p.to_path_buf())
                .display()
                .to_string()
        };
        Self {
            dataset: path(&args.dataset),
            heldout: args.heldout.as_deref().map(path),
            init: format!("{:?}", args.init),
            random_points: args.random_points,
            freeze_positions: args.freeze_positions,
            densify: !args.no_densify && !args.freeze_positions,
            max_splats: args.max_splats,
            sh_degree: args.sh_degree,
            downscale: args.downscale.to_string(),
            background: format!("{:?}", args.background),
            photometric: format!("{:?}", args.photometric),
            antialiased: args.antialiased,
            seed: args.seed,
            warmup_factor: args.warmup_factor,
            warmup_steps: args.warmup_steps,
        }
    }

    /// `name: saved → now` for each setting that differs.
    fn differences(&self, now: &Self) -> Vec<String> {
        let (Ok(serde_json::Value::Object(a)), Ok(serde_json::Value::Object(b))) =
            (serde_json::to_value(self), serde_json::to_value(now))
        else {
            return Vec::new();
        };
        a.iter()
            .filter(|(k, v)| b.get(*k) != Some(*v))
            .map(|(k, v)| {
                format!(
                    "{k}: {v} → {}",
                    b.get(k).unwrap_or(&serde_json::Value::Null)
                )
            })
            .collect()
    }
}

/// The trainer configuration the arguments ask for.
fn train_config(args: &Args) -> TrainConfig {
    let densify = !args.no_densify && !args.freeze_positions;
    let mut c = TrainConfig {
        iterations: args.iterations,
        seed: args.seed,
        sh_degree: Some(args.sh_degree),
        densify: densify.then(|| DensifyConfig {
            max_splats: args.max_splats,
            // Inria densifies until 15k of 30k steps: keep the same half-way stop in shorter runs.
            stop: DensifyConfig::default().stop.min(args.iterations / 2),
            ..DensifyConfig::default()
        }),
        background: match args.background {
            BackgroundArg::Black => Background::Fixed([0.0; 3]),
            BackgroundArg::White => Background::Fixed([1.0; 3]),
            BackgroundArg::Random => Background::Random,
        },
        photometric: match args.photometric {
            PhotometricArg::L1 => Photometric::L1,
            PhotometricArg::L2 => Photometric::L2,
        },
        time_budget: args.time_budget.map(Duration::from_secs_f64),
        history_every: 10,
        antialiased: args.antialiased,
        ..TrainConfig::default()
    };
    c.frozen.positions = args.freeze_positions;
    if args.warmup_factor >= 2 && args.warmup_steps > 0 {
        c.warmup = Some(Warmup {
            factor: args.warmup_factor,
            until: args.warmup_steps,
        });
    }
    c
}

/// Inria's initial splats (splat-init's sparse init): isotropic kNN scales, identity rotation,
/// opacity 0.1, SH DC from the colour and higher bands zero; the points are the dataset's
/// points3D, or random ones (mid grey) in their bounds or, with fewer than 2 points, in the
/// bounds of the camera centres. Laid out in Morton order, as the pipeline's initial splats.
fn initial_splats(
    args: &Args,
    rec: &colmap_io::Reconstruction,
    views: &[View],
) -> anyhow::Result<Splats> {
    let (points, colors) = match args.init {
        Init::Points3d => {
            if rec.points3d.is_empty() {
                bail!("the dataset has no 3D points: use --init random");
            }
            splat_init::colmap_points(rec)
        }
        Init::Random => {
            let points: Vec<Vec3> = rec.points3d.values().map(|p| p.xyz.as_vec3()).collect();
            let centres: Vec<Vec3> = views.iter().map(|v| v.camera.center().as_vec3()).collect();
            let (lo, hi) = random_init_bounds(&points, &centres).ok_or_else(|| {
                anyhow::anyhow!(
                    "--init random: the dataset's 3D points and its camera centres each sit at \
                     one place, so they bound no volume to scatter points in; give the dataset \
                     points3D that span the scene (or use --init points3d)"
                )
            })?;
            splat_init::random_points(lo, hi, args.random_points, args.seed)
        }
    };
    let splats = splat_init::sparse_splats(
        &points,
        &colors,
        splat_init::InitConfig::default().sparse_opacity,
        args.sh_degree,
    )?;
    Ok(splat_init::in_morton_order(&splats))
}

/// The box `--init random` scatters its points in: the points3D's bounds, unless they hold
/// fewer than two points or all sit at about one place (a box under a millionth of the camera
/// centres' across, where every random point would start in the same spot), then the camera
/// centres' bounds. `None` when neither bounds a volume.
fn random_init_bounds(points: &[Vec3], centres: &[Vec3]) -> Option<(Vec3, Vec3)> {
    let diagonal = |(lo, hi): (Vec3, Vec3)| (hi - lo).length();
    let cameras = splat_init::bounds(centres);
    let cameras_across = if centres.is_empty() {
        0.0
    } else {
        diagonal(cameras)
    };
    if points.len() >= 2 {
        let box_ = splat_init::bounds(points);
        let across = diagonal(box_);
        if across.is_finite() && across > 0.0 && across >= 1e-6 * cameras_across {
            return Some(box_);
        }
    }
    (cameras_across.is_finite() && cameras_across > 0.0).then_some(cameras)
}

fn progress_bar(total: u32, done: u32, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(u64::from(total));
    if let Ok(style) = ProgressStyle::with_template(
        "{elapsed_precise} [{bar:30}] {pos}/{len} ({per_sec}, eta {eta}) {msg}",
    ) {
        bar.set_style(style.progress_chars("=> "));
    }
    bar.set_position(u64::from(done));
    bar
}

#[allow(clippy::too_many_arguments)]
fn write_history(
    path: &Path,
    args: &Args,
    report: &TrainReport,
    evals: &[EvalPoint],
    eval_views: usize,
    views: usize,
    wall: Duration,
) -> anyhow::Result<()> {
    let t = &report.timings;
    let h = History {
        dataset: args.dataset.display().to_string(),
        heldout: args.heldout.as_ref().map(|p| p.display().to_string()),
        views,
        eval_views,
        iterations: report.iterations,
        elapsed_s: report.elapsed_s,
        wall_s: wall.as_secs_f64(),
        splats: report.splats,
        non_finite: report.non_finite,
        refine: report.refine,
        timings_s: Timings {
            forward: t.forward.as_secs_f64(),
            loss: t.loss.as_secs_f64(),
            backward: t.backward.as_secs_f64(),
            adam: t.adam.as_secs_f64(),
            refine: t.refine.as_secs_f64(),
        },
        steps: &report.history,
        evaluations: evals,
    };
    let json = serde_json::to_vec_pretty(&h).context("cannot encode the history")?;
    write_atomic(path, &json).with_context(|| format!("cannot write {}", path.display()))
}

fn summary(
    report: &TrainReport,
    last: Option<&EvalPoint>,
    ply: &Path,
    history: &Path,
    wall: Duration,
) {
    let per_s = if report.elapsed_s > 0.0 {
        f64::from(report.iterations) / report.elapsed_s
    } else {
        0.0
    };
    println!(
        "trained {} iterations in {:.1} s ({per_s:.1} it/s; {:.1} s wall this session), {} splats{}",
        report.iterations,
        report.elapsed_s,
        wall.as_secs_f64(),
        report.splats,
        if report.stopped_by_budget {
            ", stopped by the time budget"
        } else {
            ""
        }
    );
    if let Some(e) = last {
        println!("evaluation: PSNR {:.2} dB, SSIM {:.4}", e.psnr, e.ssim);
    }
    let r = &report.refine;
    println!(
        "densification: {} cloned, {} split, {} pruned",
        r.cloned, r.split, r.pruned
    );
    let nf = &report.non_finite;
    if nf.skipped_steps + nf.zeroed_gradients + nf.reset_splats + nf.removed_splats > 0 {
        println!(
            "non-finite values handled: {} steps skipped, {} gradients zeroed, {} splats reset, {} removed",
            nf.skipped_steps, nf.zeroed_gradients, nf.reset_splats, nf.removed_splats
        );
    }
    println!("wrote {} and {}", ply.display(), history.display());
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    fn args(extra: &[&str]) -> Args {
        let argv = ["train", "data", "--out", "out"]
            .into_iter()
            .chain(extra.iter().copied());
        match Cli::try_parse_from(argv) {
            Ok(cli) => cli.args,
            Err(e) => panic!("{e}"),
        }
    }

    /// Points3D all at one place bound no volume: the random points fill the cameras' box
    /// instead, and a scene whose points and cameras both collapse is refused.
    #[test]
    fn random_init_ignores_points_that_sit_at_one_place() {
        let cams = [Vec3::new(-4.0, 0.0, 0.0), Vec3::new(4.0, 2.0, 1.0)];
        let spread = [Vec3::new(-1.0, -1.0, -1.0), Vec3::new(1.0, 0.5, 1.0)];
        assert_eq!(
            random_init_bounds(&spread, &cams),
            Some((spread[0], spread[1]))
        );
        let heap = [Vec3::splat(0.25); 100];
        assert_eq!(random_init_bounds(&heap, &cams), Some((cams[0], cams[1])));
        let one = [Vec3::ONE];
        assert_eq!(random_init_bounds(&one, &cams), Some((cams[0], cams[1])));
        assert_eq!(random_init_bounds(&heap, &[Vec3::ZERO, Vec3::ZERO]), None);
        assert_eq!(random_init_bounds(&[], &[]), None);
        // A flat scene (a wall) is a real box with no depth: kept.
        let wall = [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0)];
        assert_eq!(random_init_bounds(&wall, &cams), Some((wall[0], wall[1])));
    }

    /// A run started before `--photometric` existed saved no such setting: it resumes as the
    /// L1 run it was, and an L2 run is told apart from it by that setting alone.
    #[test]
    fn settings_saved_without_the_photometric_term_resume_as_l1() {
        let now = Settings::of(&args(&[]));
        let mut saved = serde_json::to_value(&now).expect("settings serialise");
        let Some(fields) = saved.as_object_mut() else {
            panic!("settings serialise as an object")
        };
        assert!(fields.remove("photometric").is_some());
        let saved: Settings = serde_json::from_value(saved).expect("old settings read");
        assert_eq!(saved, now);
        let l2 = Settings::of(&args(&["--photometric", "l2"]));
        assert_eq!(
            saved.differences(&l2),
            vec!["photometric: \"L1\" → \"L2\"".to_string()]
        );
        assert_eq!(train_config(&args(&[])).photometric, Photometric::L1);
        // The same for the antialiased setting: absent, a plain run.
        let mut saved = serde_json::to_value(&now).expect("settings serialise");
        if let Some(fields) = saved.as_object_mut() {
            assert_eq!(
                fields.remove("antialiased"),
                Some(serde_json::Value::Bool(false))
            );
        }
        let saved: Settings = serde_json::from_value(saved).expect("old settings read");
        assert_eq!(saved, now);
        let aa = Settings::of(&args(&["--antialiased"]));
        assert_eq!(
            saved.differences(&aa),
            vec!["antialiased: false → true".to_string()]
        );
        assert!(train_config(&args(&["--antialiased"])).antialiased);
        assert!(!train_config(&args(&[])).antialiased);
        assert_eq!(
            train_config(&args(&["--photometric", "l2"])).photometric,
            Photometric::L2
        );
    }
}
