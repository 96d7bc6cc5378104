//! The whole pipeline, input model to 3DGS model with a report, stage by stage.
//!
//! `load → rig → render training and held-out views → COLMAP dataset → initialise → train →
//! evaluate → model PLY → report`. Every file is written atomically, and the files that mark a
//! run as finished (the model and the report) are removed before a run starts and written last,
//! so an interrupted or failed run never leaves output that looks complete.
//!
//! A run records its progress in `DIR/state.json` and checkpoints its training at a bounded
//! interval of wall time ([`crate::resume`]), so [`run_with`] can continue a killed run: the
//! dataset is reused, training continues from its checkpoint on the schedule chosen before it
//! began, and what is cheap and deterministic (views in memory, evaluation, report) is redone.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use camera_model::Camera;
use glam::Vec3;
use indicatif::{ProgressBar, ProgressStyle};
use plenoptic_io::Model;
use splat_core::Splats;
use splat_train::eval::{EvalOptions, Metrics, RenderedView, evaluate_views};
use splat_train::{Background, TrainConfig, Trainer, View};

use crate::config::{Config, InitMode};
use crate::report::{
    CurvePoint, InputInfo, Report, RunReport, StageTiming, ViewPictures, write_report,
};
use crate::resume::{
    self, InputStamp, ModeState, ResumeError, RunState, Schedule, Status, TrainedState,
};
use plenoptic_render::{self as views, ViewImage};
use splat_init::{self as init, SurfacePoints};

/// Errors of the pipeline, each naming the stage and the file.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The input could not be read.
    #[error("cannot load the input: {0}")]
    Load(Box<plenoptic_io::Error>),
    /// The input holds nothing to render.
    #[error("the input {0} holds no points or triangles")]
    EmptyInput(PathBuf),
    /// The input cannot make a model (no extent, too few points, no area, nothing visible).
    #[error("{0}")]
    Degenerate(#[from] plenoptic_render::degenerate::DegenerateError),
    /// The configuration is invalid.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The cameras could not be placed.
    #[error("cannot place the cameras: {0}")]
    Rig(#[from] camera_model::Error),
    /// The reference views could not be rendered or written.
    #[error("reference views: {0}")]
    Views(Box<views::Error>),
    /// The dataset could not be written.
    #[error("cannot write the COLMAP dataset in {path}: {message}")]
    Dataset {
        /// The dataset folder.
        path: PathBuf,
        /// The cause.
        message: String,
    },
    /// Initialisation failed.
    #[error("initialisation: {0}")]
    Init(Box<init::InitError>),
    /// The trainer refused its inputs.
    #[error("training: {0}")]
    Train(Box<splat_train::Error>),
    /// The trained model could not be evaluated (e.g. no held-out view covers a pixel).
    #[error("evaluation: {0}")]
    Eval(Box<splat_train::EvalError>),
    /// The model could not be written.
    #[error("cannot write the model {path}: {source}")]
    Model {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: Box<splat_core::Error>,
    },
    /// A file or folder could not be written or removed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The saved run cannot be resumed, or its state cannot be saved.
    #[error(transparent)]
    Resume(#[from] ResumeError),
}

/// Boxes the large error types of the stages into [`PipelineError`].
macro_rules! boxed_from {
    ($($variant:ident: $ty:ty),*) => {$(
        impl From<$ty> for PipelineError {
            fn from(e: $ty) -> Self {
                Self::$variant(Box::new(e))
            }
        }
    )*};
}
boxed_from!(Load: plenoptic_io::Error, Views: views::Error, Init: init::InitError, Train: splat_train::Error, Eval: splat_train::EvalError);

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PipelineError + '_ {
    move |source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A reference view as the trainer wants it: straight (un-premultiplied) colour and its mask
/// ([`View::from_premultiplied`]).
#[must_use]
pub fn training_view(name: String, camera: Camera, image: &ViewImage) -> View {
    View::from_premultiplied(name, camera, &image.rgb, image.alpha.clone())
}

/// The trainer's configuration for one init mode.
#[must_use]
pub fn train_config(cfg: &Config, mode: InitMode, sh_degree: u32) -> TrainConfig {
    let t = &cfg.training;
    let surface = mode == InitMode::Surface;
    let mut tc = TrainConfig {
        iterations: t.iterations,
        seed: t.seed,
        lr: t.lr,
        ssim_weight: t.ssim_weight,
        sh_degree: Some(sh_degree),
        sh_degree_interval: t.sh_degree_interval,
        densify: if !surface || cfg.init.densify_surface {
            Some(t.densify)
        } else {
            None
        },
        background: if t.random_background {
            Background::Random
        } else {
            Background::Fixed([0.0; 3])
        },
        time_budget: t.time_budget_s.map(Duration::from_secs_f64),
        alpha_loss_weight: t.alpha_loss,
        history_every: t.history_every,
        ..TrainConfig::default()
    };
    // Surface splats sit on the input's points: keep them there unless asked (or densifying).
    tc.frozen.positions = surface && !cfg.init.free_positions && tc.densify.is_none();
    tc
}

/// Steps timed (after one untimed warm-up step) to estimate a time-budgeted run's length before
/// its densification is scheduled.
const PROBE_STEPS: u32 = 4;

/// The number of steps a run will take: its iteration count, or, with a time budget, the steps
/// that fit in the budget at the speed of [`PROBE_STEPS`] steps timed on a throw-away trainer
/// after a warm-up step (the probe's time is taken from the budget; the arithmetic is
/// [`splat_train::schedule::steps_in_budget`]). Returns the steps and the remaining budget.
fn step_budget(
    splats: &Splats,
    views: &[View],
    tc: &TrainConfig,
) -> Result<(u32, Option<Duration>), PipelineError> {
    let Some(budget) = tc.time_budget else {
        return Ok((tc.iterations, None));
    };
    let probe_cfg = TrainConfig {
        iterations: PROBE_STEPS + 1,
        densify: None,
        time_budget: None,
        ..tc.clone()
    };
    let t0 = Instant::now();
    let mut probe = Trainer::new(splats.clone(), views.to_vec(), probe_cfg)?;
    let setup = t0.elapsed();
    // The first step allocates the loss buffers and targets: time the ones after it.
    probe.run_until(1, |_| {});
    let t1 = Instant::now();
    probe.run_until(PROBE_STEPS + 1, |_| {});
    let timed = t1.elapsed();
    let (steps, left) = splat_train::schedule::steps_in_budget(
        tc.iterations,
        budget,
        t0.elapsed(),
        setup,
        timed,
        PROBE_STEPS,
    );
    Ok((steps, Some(left)))
}

/// What a finished run produced.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The report (also written as JSON).
    pub report: Report,
    /// `DIR/report/report.html`.
    pub html: PathBuf,
    /// `DIR/model/splats.ply`.
    pub model: PathBuf,
}

/// How [`run_with`] starts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RunOptions {
    /// Print nothing (progress goes to stderr otherwise).
    pub quiet: bool,
    /// Continue the run saved in the output folder, if there is one (else start afresh).
    pub resume: bool,
}

/// How [`run_with`] ended.
#[derive(Debug, Clone)]
pub enum Finish {
    /// The run is complete; this call did the rest of its work.
    Completed(Box<Outcome>),
    /// Asked to resume a run that had already finished: nothing was redone.
    AlreadyFinished {
        /// `DIR/model/splats.ply`.
        model: PathBuf,
        /// `DIR/report/report.html`.
        html: PathBuf,
    },
}

/// Runs the whole pipeline on `input` from the start, writing into `out`. Progress goes to stderr
/// unless `quiet`.
pub fn run(input: &Path, out: &Path, cfg: &Config, quiet: bool) -> Result<Outcome, PipelineError> {
    execute(input, out, cfg, quiet, None)
}

/// Runs the pipeline, or with `opts.resume` continues the run saved in `out`: a run with the same
/// input and configuration (else [`ResumeError::Mismatch`]) that was interrupted continues from
/// its last checkpoint, a finished one is left as it is ([`Finish::AlreadyFinished`]), and without
/// a saved run it starts from the beginning.
pub fn run_with(
    input: &Path,
    out: &Path,
    cfg: &Config,
    opts: RunOptions,
) -> Result<Finish, PipelineError> {
    let saved = if opts.resume {
        cfg.validate()?;
        RunState::load(out)?
    } else {
        None
    };
    if let Some(state) = &saved {
        let stamp = InputStamp::of(input).map_err(|source| ResumeError::Io {
            path: input.to_path_buf(),
            source,
        })?;
        state.check_same_run(out, &stamp, cfg)?;
        if state.status == Status::Finished {
            let model = out.join("model").join("splats.ply");
            let html = out.join("report").join("report.html");
            if model.is_file() && html.is_file() {
                return Ok(Finish::AlreadyFinished { model, html });
            }
            return Err(ResumeError::Malformed {
                path: out.join(resume::STATE_FILE),
                problem: "the run finished but its model or report is gone".into(),
            }
            .into());
        }
    }
    execute(input, out, cfg, opts.quiet, saved).map(|o| Finish::Completed(Box::new(o)))
}

/// The stages, from the beginning or continuing `saved`.
fn execute(
    input: &Path,
    out: &Path,
    cfg: &Config,
    quiet: bool,
    saved: Option<RunState>,
) -> Result<Outcome, PipelineError> {
    cfg.validate()?;
    let started = Instant::now();
    let say = |msg: String| {
        if !quiet {
            eprintln!("{msg}");
        }
    };
    let model_dir = out.join("model");
    let report_dir = out.join("report");
    let dataset_dir = out.join("dataset");
    // Markers of a finished run go first, so a failure below cannot leave an old, complete-looking
    // model or report beside new, partial data.
    let models = ["splats", "splats-sparse", "splats-surface"]
        .into_iter()
        .flat_map(|stem| MODEL_EXTENSIONS.map(|ext| model_dir.join(format!("{stem}.{ext}"))));
    let reports = [
        report_dir.join("report.json"),
        report_dir.join("report.html"),
    ];
    for marker in models.chain(reports) {
        match std::fs::remove_file(&marker) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => return Err(io_err(&marker)(e)),
        }
    }
    let checkpoints = out.join(resume::CHECKPOINT_DIR);
    if saved.is_none() {
        // A fresh run must not pick up an earlier run's state or checkpoints.
        remove_file_if_present(&out.join(resume::STATE_FILE))?;
        remove_dir_if_present(&checkpoints)?;
    }
    let mut timings = Vec::new();
    let mut stage = Instant::now();
    let mut lap = |name: &str, timings: &mut Vec<StageTiming>| {
        timings.push(StageTiming {
            stage: name.to_string(),
            seconds: stage.elapsed().as_secs_f64(),
        });
        stage = Instant::now();
    };

    say(format!("[1/6] loading {}", input.display()));
    let model = plenoptic_io::load(input)?;
    let info = input_info(input, &model);
    if info.points == 0 {
        return Err(PipelineError::EmptyInput(input.to_path_buf()));
    }
    plenoptic_render::degenerate::check_model(input, &model)?;
    lap("load", &mut timings);
    for d in [&model_dir, &report_dir, &dataset_dir, &checkpoints] {
        std::fs::create_dir_all(d).map_err(io_err(d))?;
    }
    let mut state = match saved {
        Some(s) => {
            say(format!(
                "      resuming the run in {} ({})",
                out.display(),
                resume_summary(&s)
            ));
            s
        }
        None => {
            let stamp = InputStamp::of(input).map_err(|source| ResumeError::Io {
                path: input.to_path_buf(),
                source,
            })?;
            RunState::start(stamp, cfg)
        }
    };
    // From here until the end the folder says "running".
    state.status = Status::Running;
    state.save(out)?;

    let rig = views::build_rig(&model, &cfg.rig)?;
    lap("rig", &mut timings);

    say(format!(
        "[2/6] rendering {} training views (and the COLMAP dataset) and {} held-out views at {}×{}",
        rig.train.len(),
        rig.heldout.len(),
        cfg.rig.width,
        cfg.rig.height
    ));
    let mut opts = cfg.renderer.clone();
    opts.background = [0.0; 3];
    let dataset_opts = views::DatasetOptions {
        bit_depth: if cfg.output.png16 {
            views::BitDepth::Sixteen
        } else {
            views::BitDepth::Eight
        },
        masks: true,
        depth: false,
    };
    let train_images = if state.dataset_written {
        // The dataset's PNGs are quantised: training needs the renders themselves, which are
        // deterministic, so they are made again in memory.
        say("      the dataset is already written: rendering the training views in memory".into());
        let images = views::render_views(&model, &rig.train, &opts)?;
        lap("render training views", &mut timings);
        images
    } else {
        let bar = progress_bar(rig.train.len() as u64, quiet, "views");
        let images = views::write_dataset(
            &dataset_dir,
            &model,
            &rig.train,
            &opts,
            &dataset_opts,
            &|| {
                bar.inc(1);
            },
        )?;
        bar.finish_and_clear();
        state.dataset_written = true;
        state.save(out)?;
        lap("render training views + write dataset", &mut timings);
        images
    };
    let heldout_images = views::render_views(&model, &rig.heldout, &opts)?;
    plenoptic_render::degenerate::check_views(
        input,
        "held-out",
        heldout_images.iter().map(|v| v.alpha.as_slice()),
        heldout_name,
    )?;
    lap("render held-out views", &mut timings);
    say(format!(
        "      dataset written to {}",
        dataset_dir.display()
    ));
    // Mesh samples: K of them when `--splats K` is given, so that K means splats for meshes too.
    let surface = SurfacePoints::from_model(
        &model,
        cfg.init.mesh_points,
        cfg.init.splats.unwrap_or(cfg.init.mesh_samples),
        cfg.training.seed,
    );

    let train_views: Vec<View> = rig
        .train
        .iter()
        .zip(&train_images)
        .enumerate()
        .map(|(i, (c, img))| training_view(views::dataset_image_name(i), *c, img))
        .collect();
    drop(train_images);
    let heldout: Vec<View> = rig
        .heldout
        .iter()
        .zip(heldout_images)
        .enumerate()
        .map(|(i, (c, img))| View::from_premultiplied(heldout_name(i), *c, &img.rgb, img.alpha))
        .collect();

    // The surface for the distance metric: the cloud itself, or dense samples of the mesh.
    let distance_surface = match &model {
        Model::Cloud(_) => surface.positions.clone(),
        Model::Mesh(m) => init::sample_mesh(m, 200_000, cfg.training.seed ^ 0x5eed).positions,
    };
    let spacing = init::point_spacing(&distance_surface);

    let mut modes = vec![cfg.init.mode];
    if cfg.output.compare_init {
        modes.push(match cfg.init.mode {
            InitMode::Surface => InitMode::Sparse,
            InitMode::Sparse => InitMode::Surface,
        });
    }
    let mut runs = Vec::new();
    let mut renders_per_run: Vec<Vec<RenderedView>> = Vec::new();
    let mut trained_models = Vec::new();
    for (k, &mode) in modes.iter().enumerate() {
        let model_path = if k == 0 {
            model_dir.join("splats.ply")
        } else {
            model_dir.join(format!("splats-{mode}.ply"))
        };
        let (run, renders, trained) = init_train_eval(
            &surface,
            &train_views,
            &heldout,
            (&distance_surface, spacing),
            cfg,
            mode,
            &model_path,
            (out, &mut state, k),
            quiet,
        )?;
        say(format!(
            "      {mode} init: held-out PSNR {:.2} dB on black, {:.2} dB on white, {} splats",
            run.metrics.psnr_black, run.metrics.psnr_white, run.metrics.splats
        ));
        runs.push(run);
        renders_per_run.push(renders);
        trained_models.push(trained);
    }

    // The models only now that every run is trained and evaluated, the report after them and the
    // "finished" state last: whatever a kill leaves behind, a model file is the final one.
    for (k, (run, trained)) in runs.iter_mut().zip(&trained_models).enumerate() {
        say(format!("[5/6] writing {}", run.model_path.display()));
        let t = Instant::now();
        let formats = ModelFormats {
            splat: k == 0 && cfg.output.splat_file,
            spz: cfg.output.spz,
            glb: cfg.output.glb,
        };
        let compact = write_model(&run.model_path, trained, formats)?;
        run.model_bytes = std::fs::metadata(&run.model_path).map_or(0, |m| m.len());
        run.compact_files = compact
            .into_iter()
            .map(|p| {
                let bytes = std::fs::metadata(&p).map_or(0, |m| m.len());
                (p, bytes)
            })
            .collect();
        run.timings.push(StageTiming {
            stage: "write model".to_string(),
            seconds: t.elapsed().as_secs_f64(),
        });
    }
    let main_model = model_dir.join("splats.ply");

    say("[6/6] writing the report".to_string());
    let pictures = pick_pictures(&heldout, &renders_per_run, cfg.eval.report_views);
    let mut report = Report {
        version: env!("CARGO_PKG_VERSION").to_string(),
        input: info,
        config: cfg.clone(),
        train_views: train_views.len(),
        heldout_views: heldout.len(),
        timings,
        runs,
        total_seconds: 0.0,
    };
    report.total_seconds = started.elapsed().as_secs_f64();
    let html = write_report(&report_dir, &report, &pictures).map_err(io_err(&report_dir))?;
    state.status = Status::Finished;
    state.save(out)?;
    remove_dir_if_present(&checkpoints)?;
    Ok(Outcome {
        report,
        html,
        model: main_model,
    })
}

/// Initialises, trains and evaluates one model: the `k`-th init mode of the run in `out`, whose
/// progress `state` records (and, when resuming, already holds). Returns its report, its held-out
/// renders and the trained splats, which the caller writes once every mode is done.
#[allow(clippy::too_many_arguments)]
fn init_train_eval(
    surface: &SurfacePoints,
    train_views: &[View],
    heldout: &[View],
    distance_surface: (&[Vec3], f32),
    cfg: &Config,
    mode: InitMode,
    model_path: &Path,
    (out, state, k): (&Path, &mut RunState, usize),
    quiet: bool,
) -> Result<(RunReport, Vec<RenderedView>, Splats), PipelineError> {
    let mut timings = Vec::new();
    let mut stage = Instant::now();
    let mut lap = |name: &str, timings: &mut Vec<StageTiming>| {
        timings.push(StageTiming {
            stage: name.to_string(),
            seconds: stage.elapsed().as_secs_f64(),
        });
        stage = Instant::now();
    };
    let say = |msg: String| {
        if !quiet {
            eprintln!("{msg}");
        }
    };
    let ckpt = resume::checkpoint_path(out, mode);
    let saved = state.modes.get(k).cloned();
    if let Some(m) = &saved
        && m.mode != mode
    {
        return Err(ResumeError::Malformed {
            path: out.join(resume::STATE_FILE),
            problem: format!("run {k} is {} init, the configuration says {mode}", m.mode),
        }
        .into());
    }
    let resume_from_checkpoint = saved.is_some() && ckpt.is_file();
    if saved.is_none() {
        // No checkpoint can belong to a mode the state does not list yet.
        remove_file_if_present(&ckpt)?;
    }
    if saved.as_ref().is_some_and(|m| m.trained.is_some()) && !resume_from_checkpoint {
        return Err(ResumeError::Checkpoint {
            path: ckpt,
            problem: "the trained model's checkpoint is missing".into(),
        }
        .into());
    }

    // Initial splats, unless training continues from a checkpoint, and the training schedule.
    // The schedule is fixed once, before the first step, and saved: a resumed run must train on
    // the same one even when it came from timed probe steps.
    let mut fresh = None;
    let (summary, schedule) = match &saved {
        Some(m) if resume_from_checkpoint => {
            say(format!(
                "[3/6] {mode} init: continuing from {}",
                ckpt.display()
            ));
            lap("init", &mut timings);
            (m.init.clone(), m.schedule)
        }
        _ => {
            say(format!("[3/6] {mode} init"));
            let mut init_cfg = cfg.init.clone();
            init_cfg.mode = mode;
            let (splats, summary) =
                init::initialise(surface, &init_cfg, cfg.renderer.exponent, cfg.training.seed)?;
            say(format!(
                "      {} splats, SH degree {}{}",
                summary.splats,
                summary.sh_degree,
                summary
                    .sh_fit_rms
                    .map(|e| format!(
                        " (SH fit RMS by degree: {:.4} {:.4} {:.4} {:.4})",
                        e[0], e[1], e[2], e[3]
                    ))
                    .unwrap_or_default()
            ));
            lap("init", &mut timings);
            let schedule = match &saved {
                Some(m) => m.schedule,
                None => {
                    let base = train_config(cfg, mode, summary.sh_degree);
                    let schedule = plan(&splats, train_views, &base, cfg.training.scale_densify)?;
                    state.modes.push(ModeState {
                        mode,
                        init: summary.clone(),
                        schedule,
                        trained: None,
                    });
                    state.save(out)?;
                    schedule
                }
            };
            fresh = Some(splats);
            (summary, schedule)
        }
    };

    say(format!(
        "[4/6] training {} iterations{}",
        cfg.training.iterations,
        cfg.training
            .time_budget_s
            .map(|b| format!(" (budget {b:.0} s)"))
            .unwrap_or_default()
    ));
    let base = train_config(cfg, mode, summary.sh_degree);
    let tc = scheduled_config(base, &schedule);
    if let (Some(steps), Some(d)) = (schedule.densify_steps, tc.densify) {
        say(format!(
            "      densification scaled to ~{steps} steps: from step {} every {} until {}, opacity reset every {}",
            d.start, d.interval, d.stop, d.opacity_reset_interval
        ));
    }
    let mut trainer = match fresh {
        Some(splats) => Trainer::new(splats, train_views.to_vec(), tc)?,
        None => Trainer::resume(&ckpt, train_views.to_vec(), tc).map_err(|e| {
            ResumeError::Checkpoint {
                path: ckpt.clone(),
                problem: e.to_string(),
            }
        })?,
    };
    let train_report = match saved.and_then(|m| m.trained) {
        Some(t) => {
            say(format!(
                "      trained already ({} steps)",
                trainer.iteration()
            ));
            trainer.report(t.stopped_by_budget)
        }
        None => {
            if trainer.iteration() > 0 {
                say(format!(
                    "      continuing from step {}",
                    trainer.iteration()
                ));
            }
            let every = Duration::from_secs_f64(cfg.output.checkpoint_interval_s);
            let report = train(&mut trainer, &ckpt, every, quiet)?;
            if let Some(m) = state.modes.get_mut(k) {
                m.trained = Some(TrainedState {
                    stopped_by_budget: report.stopped_by_budget,
                });
            }
            state.save(out)?;
            report
        }
    };
    let trained = trainer.splats().clone();
    drop(trainer);
    lap("train", &mut timings);

    say(format!("[5/6] evaluating the {mode} model"));
    let (metrics, renders): (Metrics, Vec<RenderedView>) = evaluate_views(
        &trained,
        heldout,
        Some(distance_surface),
        &EvalOptions::from(&cfg.eval),
    )?;
    lap("evaluate", &mut timings);
    let run = RunReport {
        init: summary,
        iterations: train_report.iterations,
        train_seconds: train_report.elapsed_s,
        stopped_by_budget: train_report.stopped_by_budget,
        curve: train_report
            .history
            .iter()
            .map(|h| CurvePoint {
                iteration: h.iteration,
                elapsed_s: h.elapsed_s,
                psnr: h.psnr,
                splats: h.splats,
            })
            .collect(),
        metrics,
        model_path: model_path.to_path_buf(),
        // Filled in when the model is written, after every run is done.
        model_bytes: 0,
        compact_files: Vec::new(),
        timings,
    };
    Ok((run, renders, trained))
}

/// Every extension a model file of a run may have: a run deletes them all before it starts.
const MODEL_EXTENSIONS: [&str; 4] = ["ply", "splat", "spz", "glb"];

/// The files written beside a model's PLY.
#[derive(Clone, Copy, Debug)]
struct ModelFormats {
    splat: bool,
    spz: bool,
    glb: bool,
}

/// Writes the model PLY and the other formats asked for, each atomically, beside it; returns the
/// paths of the others.
fn write_model(
    path: &Path,
    splats: &Splats,
    formats: ModelFormats,
) -> Result<Vec<PathBuf>, PipelineError> {
    let model_err = |p: &Path| {
        let p = p.to_path_buf();
        move |source: splat_core::Error| PipelineError::Model {
            path: p,
            source: Box::new(source),
        }
    };
    splat_core::ply::write_splats(path, splats).map_err(model_err(path))?;
    let mut written = Vec::new();
    if formats.splat {
        let p = path.with_extension("splat");
        splat_core::export::write_splat(&p, splats).map_err(model_err(&p))?;
        written.push(p);
    }
    if formats.spz {
        let p = path.with_extension("spz");
        splat_core::spz::write_spz(&p, splats, &splat_core::spz::SpzOptions::default())
            .map_err(model_err(&p))?;
        written.push(p);
    }
    if formats.glb {
        let p = path.with_extension("glb");
        splat_core::glb::write_glb(&p, splats).map_err(model_err(&p))?;
        written.push(p);
    }
    Ok(written)
}

/// The schedule of a run about to start: with `scale_schedule` and densification, the steps the
/// densification schedule is scaled to ([`step_budget`]: timed probe steps under a time budget)
/// and the budget left after the probe; otherwise the configuration's own.
fn plan(
    splats: &Splats,
    views: &[View],
    tc: &TrainConfig,
    scale_schedule: bool,
) -> Result<Schedule, PipelineError> {
    if scale_schedule && tc.densify.is_some() {
        let (steps, left) = step_budget(splats, views, tc)?;
        Ok(Schedule {
            densify_steps: Some(steps),
            time_budget: left,
        })
    } else {
        Ok(Schedule {
            densify_steps: None,
            time_budget: tc.time_budget,
        })
    }
}

/// `tc` on `schedule`: the densification scaled to its steps, its time budget.
fn scheduled_config(mut tc: TrainConfig, schedule: &Schedule) -> TrainConfig {
    if let (Some(steps), Some(d)) = (schedule.densify_steps, tc.densify) {
        tc.densify = Some(splat_train::schedule::scale_densify(
            &d,
            steps,
            tc.lr.opacity,
        ));
    }
    if schedule.time_budget.is_some() {
        tc.time_budget = schedule.time_budget;
    }
    tc
}

/// Trains to the end with a progress bar, saving the trainer's state to `ckpt` whenever `every`
/// has passed since the last save, and once more at the end (the later stages resume from that).
///
/// The trainer pauses between two steps to save, which changes nothing it computes: a run
/// checkpointed at any moments ends bit-identical to one that never stopped.
fn train(
    trainer: &mut Trainer,
    ckpt: &Path,
    every: Duration,
    quiet: bool,
) -> Result<splat_train::TrainReport, PipelineError> {
    let total = trainer.config().iterations;
    let bar = progress_bar(u64::from(total), quiet, "steps");
    bar.set_position(u64::from(trainer.iteration()));
    let mut saved_at = Instant::now();
    let report = loop {
        let r = trainer.run_until(trainer.iteration() + 1, |p| {
            bar.set_position(u64::from(p.step.iteration));
            if p.step.iteration % 25 == 0 {
                bar.set_message(format!(
                    "PSNR {:.2} dB, {} splats",
                    p.step.psnr, p.step.splats
                ));
            }
        });
        if r.iterations >= total || r.stopped_by_budget {
            break r;
        }
        if saved_at.elapsed() >= every {
            trainer.save_checkpoint(ckpt)?;
            saved_at = Instant::now();
        }
    };
    trainer.save_checkpoint(ckpt)?;
    bar.finish_and_clear();
    Ok(report)
}

/// Removes `path` (a file) unless it is not there.
fn remove_file_if_present(path: &Path) -> Result<(), PipelineError> {
    match std::fs::remove_file(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(io_err(path)(e)),
    }
}

/// Removes the folder `path` and its contents unless it is not there.
fn remove_dir_if_present(path: &Path) -> Result<(), PipelineError> {
    match std::fs::remove_dir_all(path) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(()),
        Err(e) => Err(io_err(path)(e)),
    }
}

/// One line on what a saved run has done.
fn resume_summary(s: &RunState) -> String {
    let mut parts = vec![if s.dataset_written {
        "dataset written".to_string()
    } else {
        "dataset not written".to_string()
    }];
    for m in &s.modes {
        parts.push(format!(
            "{} {}",
            m.mode,
            if m.trained.is_some() {
                "trained"
            } else {
                "training"
            }
        ));
    }
    parts.join(", ")
}

/// A progress bar on stderr (hidden when `quiet`) counting `unit`.
fn progress_bar(total: u64, quiet: bool, unit: &str) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(&format!(
            "      {{bar:30}} {{pos}}/{{len}} {unit}, {{elapsed_precise}} elapsed, ETA {{eta}} {{msg}}"
        ))
        .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    bar
}

/// Pictures of up to `n` held-out views spread over the set.
fn pick_pictures(heldout: &[View], renders: &[Vec<RenderedView>], n: usize) -> Vec<ViewPictures> {
    let n = n.min(heldout.len());
    (0..n)
        .map(|k| k * heldout.len() / n.max(1))
        .map(|i| {
            let v = &heldout[i];
            ViewPictures {
                name: v.name.clone(),
                width: v.camera.intrinsics.width,
                height: v.camera.intrinsics.height,
                reference: v
                    .on_background([0.0; 3])
                    .iter()
                    .map(|x| x.clamp(0.0, 1.0))
                    .collect(),
                renders: renders.iter().map(|r| r[i].rgb.clone()).collect(),
            }
        })
        .collect()
}

/// The name of held-out view `i` in reports and messages.
fn heldout_name(i: usize) -> String {
    format!("heldout_{i:03}")
}

/// What the input file holds.
#[must_use]
pub fn input_info(path: &Path, model: &Model) -> InputInfo {
    let bytes = std::fs::metadata(path).map_or(0, |m| m.len());
    match model {
        Model::Cloud(c) => InputInfo {
            path: path.to_path_buf(),
            kind: if c.num_cameras > 0 {
                "plenoptic cloud".into()
            } else {
                "point cloud".into()
            },
            points: c.len(),
            triangles: 0,
            capture_cameras: c.num_cameras,
            bytes,
        },
        Model::Mesh(m) => InputInfo {
            path: path.to_path_buf(),
            kind: "mesh".into(),
            points: m.positions.len(),
            triangles: m.triangles.len(),
            capture_cameras: m.num_cameras,
            bytes,
        },
    }
}
