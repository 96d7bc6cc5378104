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
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use camera_model::Camera;
use plenoptic_io::Model;
use splat_core::Splats;
use splat_train::eval::{EvalOptions, Metrics, RenderedView, evaluate_views};
use splat_train::init::SurfaceIndex;
use splat_train::schedule::Pace;
use splat_train::{BudgetConfig, BudgetSearch, TrainConfig, Trainer, View, from_unorm16};

use crate::config::{Config, InitMode};
use crate::progress::{Event, Observer};
use crate::report::{
    CurvePoint, HeldoutPoint, HeldoutScore, InputInfo, Report, RunReport, StageTiming, StepZero,
    ViewPictures, write_report,
};
use crate::resume::{
    self, InputStamp, ModeState, ResumeError, RunState, Schedule, Status, TrainedState,
};
use plenoptic_render::{self as views, Rig, ViewImage};
use splat_init::{self as init, InitSummary, SurfacePoints};

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
    /// The least-squares colour solve refused a training view.
    #[error("initialisation: {0}")]
    ColourSolve(#[from] splat_init::SolveError),
    /// The trainer refused its inputs.
    #[error("training: {0}")]
    Train(Box<splat_train::Error>),
    /// The trained model could not be evaluated (e.g. no held-out view covers a pixel).
    #[error("evaluation: {0}")]
    Eval(Box<splat_train::EvalError>),
    /// The previous frame's model cannot warm-start this one.
    #[error("warm start from {path}: {problem}")]
    WarmStart {
        /// The previous frame's model.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
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
    /// A round of the automatic splat budget failed.
    #[error(transparent)]
    Budget(#[from] splat_train::RoundError),
    /// The viewer beside the report could not be written.
    #[error("cannot write the viewer: {0}")]
    Viewer(Box<crate::viewer::ViewerError>),
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
boxed_from!(Load: plenoptic_io::Error, Views: views::Error, Init: init::InitError, Train: splat_train::Error, Eval: splat_train::EvalError, Viewer: crate::viewer::ViewerError);

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PipelineError + '_ {
    move |source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Reference view `index` as the trainer wants it: straight (un-premultiplied) colour and its
/// mask ([`View::from_premultiplied`]). It takes the rendered image, so that a frame's views are
/// converted one at a time instead of held twice.
///
/// # Errors
/// [`PipelineError::Train`] naming the view and the first value that is not finite (the
/// renderer makes none; the trainer would refuse one).
pub fn training_view(
    index: usize,
    name: String,
    camera: Camera,
    image: ViewImage,
) -> Result<View, PipelineError> {
    View::from_premultiplied(name.clone(), camera, &image.rgb, &image.alpha)
        .map_err(|problem| splat_train::Error::View {
            index,
            name,
            problem,
        })
        .map_err(PipelineError::from)
}

/// Fewest steps of each size timed (after one untimed step) to estimate a time-budgeted run's
/// length before its schedule is laid out.
const PROBE_STEPS: u32 = 4;

/// Most steps of each size the probe times: on small views a step takes milliseconds, and a
/// few of them measured the demo's steps 10-40 % off.
const PROBE_MAX_STEPS: u32 = 48;

/// The probe times more than [`PROBE_STEPS`] steps of a size until they have taken this share
/// of the time budget (or [`PROBE_MAX_STEPS`] are timed).
const PROBE_BUDGET_SHARE: f64 = 0.005;

/// A run whose steps, at the speed of the first [`PROBE_STEPS`] timed, would take no more than
/// this share of its time budget cannot be cut short by it, even with the splat budget's extra
/// branch steps: the probe stops there rather than time more (at a paper-scale frame those cost
/// about 5 s). The run still re-estimates its pace as it goes.
const PROBE_EASY_FIT: f64 = 0.5;

/// The number of steps a run will take: its iteration count, or, with a time budget, the steps
/// that fit in the budget at the speed of steps timed on a throw-away trainer after an untimed
/// one ([`PROBE_STEPS`] of them, more on fast steps ([`PROBE_BUDGET_SHARE`]) unless the run
/// fits in the budget with room to spare ([`PROBE_EASY_FIT`]); the probe's time
/// is taken from the budget; the arithmetic is [`splat_train::schedule::steps_in_budget`]).
/// With a coarse warm-up the probe times steps on the reduced views first, then on the full
/// ones, and the warm-up's share of the steps counts at its own speed. Returns the steps, the
/// remaining budget and the speeds timed (the run's [`Pace`] starts from them).
fn step_budget(
    splats: &Splats,
    views: &Arc<Vec<View>>,
    tc: &TrainConfig,
) -> Result<(u32, Option<Duration>, Option<Pace>), PipelineError> {
    let Some(budget) = tc.time_budget else {
        return Ok((tc.iterations, None, None));
    };
    // One untimed step (buffers, targets), then the timed ones; once per view size.
    let per_size = PROBE_MAX_STEPS + 1;
    let probe_cfg = TrainConfig {
        iterations: if tc.warmup.is_some() {
            2 * per_size
        } else {
            per_size
        },
        densify: None,
        time_budget: None,
        warmup: tc.warmup.map(|w| splat_train::Warmup {
            until: per_size,
            ..w
        }),
        ..tc.clone()
    };
    let enough = budget.mul_f64(PROBE_BUDGET_SHARE);
    let t0 = Instant::now();
    let mut probe = Trainer::new(splats.clone(), Arc::clone(views), probe_cfg)?;
    let setup = t0.elapsed();
    // One untimed step, then steps timed until there are enough; returns their time and count.
    // `run_step_s` turns the step time timed so far into the run's mean step time (a lower bound
    // of it while only the warm-up's size is timed).
    let time_steps = |probe: &mut Trainer, run_step_s: &dyn Fn(f64) -> f64| {
        probe.run_until(probe.iteration() + 1, |_| {});
        let t = Instant::now();
        let mut timed = 0;
        while keep_timing(timed, t.elapsed(), enough, |step_s| {
            run_step_s(step_s) * f64::from(tc.iterations) > PROBE_EASY_FIT * budget.as_secs_f64()
        }) {
            probe.run_until(probe.iteration() + 1, |_| {});
            timed += 1;
        }
        (t.elapsed(), timed)
    };
    // A full-size step takes at least as long as a warm-up step.
    let first = time_steps(&mut probe, &|step_s| step_s);
    let ((timed, timed_steps), coarse) = match tc.warmup {
        Some(w) => {
            probe.end_warmup();
            let share = (f64::from(w.until) / f64::from(tc.iterations.max(1))).min(1.0);
            let coarse_s = first.0.as_secs_f64() / f64::from(first.1);
            let full = time_steps(&mut probe, &|full_s| {
                splat_train::schedule::mean_step_s(full_s, Some((share, coarse_s)))
            });
            (full, Some((share, coarse_s)))
        }
        None => (first, None),
    };
    let (steps, left) = splat_train::schedule::steps_in_budget(
        tc.iterations,
        budget,
        t0.elapsed(),
        setup,
        timed,
        timed_steps,
        coarse,
    );
    let pace = Pace {
        step_s: Some(timed.as_secs_f64() / f64::from(timed_steps)),
        coarse_step_s: coarse.map(|(_, c)| c),
    };
    Ok((steps, Some(left), Some(pace)))
}

/// Whether the time-budget probe times one more step of a size, after `timed` steps took
/// `elapsed`: always up to [`PROBE_STEPS`], never beyond [`PROBE_MAX_STEPS`], and in between
/// while they have taken less than `enough` and the run, at their mean step time, `may_bind`
/// (could come near its budget).
fn keep_timing(
    timed: u32,
    elapsed: Duration,
    enough: Duration,
    may_bind: impl Fn(f64) -> bool,
) -> bool {
    timed < PROBE_MAX_STEPS
        && (timed < PROBE_STEPS
            || (elapsed < enough && may_bind(elapsed.as_secs_f64() / f64::from(timed))))
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
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RunOptions {
    /// Continue the run saved in the output folder, if there is one (else start afresh).
    pub resume: bool,
    /// A sequence's warm start: surface init adds the training corrections of the previous
    /// frame's model ([`splat_init::warm`]).
    pub warm_start: Option<WarmStart>,
}

/// The previous frame a warm start takes its training corrections from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WarmStart {
    /// Its input file (its initialisation is reproduced from it, with this run's settings).
    pub input: PathBuf,
    /// Its trained model (`splats.ply`).
    pub model: PathBuf,
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

/// Runs the whole pipeline on `input` from the start, writing into `out`, reporting progress
/// to `observer` ([`crate::progress::ignore`] for none).
pub fn run(
    input: &Path,
    out: &Path,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<Outcome, PipelineError> {
    execute(input, out, cfg, observer, None, None)
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
    observer: Observer<'_>,
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
            let layout = Layout::new(out);
            let (model, html) = (layout.main_model(), layout.html());
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
    execute(input, out, cfg, observer, saved, opts.warm_start.as_ref())
        .map(|o| Finish::Completed(Box::new(o)))
}

/// The stages of a run, in order (the numbers in [`Event::Stage`]).
const STAGES: u32 = 6;

/// The stages, from the beginning or continuing `saved`: load → reference views and dataset →
/// for each init mode (init → train → evaluate) → export the models → report.
fn execute(
    input: &Path,
    out: &Path,
    cfg: &Config,
    observer: Observer<'_>,
    saved: Option<RunState>,
    warm_start: Option<&WarmStart>,
) -> Result<Outcome, PipelineError> {
    cfg.validate()?;
    let started = Instant::now();
    let layout = Layout::new(out);
    layout.clear_results(saved.is_none())?;
    let mut clock = StageClock::default();

    let loaded = load(input, observer)?;
    clock.lap("load");
    layout.create(cfg.output.dataset)?;
    let mut state = open_state(input, cfg, &layout, saved, observer)?;
    let rig = views::build_rig(&loaded.model, &cfg.rig)?;
    clock.lap("rig");
    let refs = reference_views(
        input,
        &loaded.model,
        &rig,
        cfg,
        &layout,
        &mut state,
        observer,
        &mut clock,
    )?;
    // The input is not needed past here: its points move into `surfaces` (a paper-scale cloud
    // holds 0.6 GB, most of it per-camera colours, that a copy would hold twice).
    let Loaded { model, info } = loaded;
    let mut surfaces = Surfaces::of(model, cfg);

    let mut trained = Vec::new();
    let modes = init_modes(cfg);
    let count = modes.len();
    for (k, mode) in modes.into_iter().enumerate() {
        let run = RunOf {
            mode,
            index: k,
            last: k + 1 == count,
            model_path: layout.model_path(k, mode),
            warm_start: warm_start.filter(|_| mode == InitMode::Surface),
        };
        let model = init_train_eval(
            &run,
            &mut surfaces,
            &refs,
            cfg,
            &layout,
            &mut state,
            observer,
        )?;
        observer(Event::Note(format!(
            "{mode} init: held-out PSNR {:.2} dB on black, {:.2} dB on white, {} splats",
            model.report.metrics.psnr_black,
            model.report.metrics.psnr_white,
            model.report.metrics.splats
        )));
        trained.push(model);
    }

    // The models only now that every run is trained and evaluated, the report after them and the
    // "finished" state last: whatever a kill leaves behind, a model file is the final one.
    export(&mut trained, cfg, observer)?;
    let outcome = report(
        &info, &refs, trained, cfg, &layout, clock, started, observer,
    )?;
    state.status = Status::Finished;
    state.save(out)?;
    remove_dir_if_present(&layout.checkpoints)?;
    Ok(outcome)
}

/// The folders and files of a run in its output folder.
#[derive(Debug, Clone)]
struct Layout {
    out: PathBuf,
    model_dir: PathBuf,
    report_dir: PathBuf,
    dataset_dir: PathBuf,
    checkpoints: PathBuf,
}

impl Layout {
    fn new(out: &Path) -> Self {
        Self {
            out: out.to_path_buf(),
            model_dir: out.join("model"),
            report_dir: out.join("report"),
            dataset_dir: out.join("dataset"),
            checkpoints: out.join(resume::CHECKPOINT_DIR),
        }
    }

    /// `model/splats.ply`: the first init mode's model.
    fn main_model(&self) -> PathBuf {
        self.model_dir.join("splats.ply")
    }

    /// `report/report.html`.
    fn html(&self) -> PathBuf {
        self.report_dir.join("report.html")
    }

    /// The model of the `k`-th init mode: `splats.ply`, then `splats-MODE.ply`.
    fn model_path(&self, k: usize, mode: InitMode) -> PathBuf {
        if k == 0 {
            self.main_model()
        } else {
            self.model_dir.join(format!("splats-{mode}.ply"))
        }
    }

    /// Removes what marks a finished run, and for a fresh run the saved state and checkpoints.
    ///
    /// Markers of a finished run go first, so a failure later cannot leave an old,
    /// complete-looking model or report beside new, partial data; a fresh run must not pick up an
    /// earlier run's state or checkpoints.
    fn clear_results(&self, fresh: bool) -> Result<(), PipelineError> {
        let models = ["splats", "splats-sparse", "splats-surface"]
            .into_iter()
            .flat_map(|stem| {
                MODEL_EXTENSIONS.map(|ext| self.model_dir.join(format!("{stem}.{ext}")))
            });
        let reports = [self.report_dir.join("report.json"), self.html()];
        for marker in models.chain(reports) {
            remove_file_if_present(&marker)?;
        }
        if fresh {
            remove_file_if_present(&self.out.join(resume::STATE_FILE))?;
            remove_dir_if_present(&self.checkpoints)?;
        }
        Ok(())
    }

    /// Creates the run's folders (`dataset/` only when it is written).
    fn create(&self, dataset: bool) -> Result<(), PipelineError> {
        for d in [&self.model_dir, &self.report_dir, &self.checkpoints] {
            std::fs::create_dir_all(d).map_err(io_err(d))?;
        }
        if dataset {
            std::fs::create_dir_all(&self.dataset_dir).map_err(io_err(&self.dataset_dir))?;
        }
        Ok(())
    }
}

/// Wall time of each stage, for the report.
#[derive(Debug)]
struct StageClock {
    timings: Vec<StageTiming>,
    since: Instant,
}

impl Default for StageClock {
    fn default() -> Self {
        Self {
            timings: Vec::new(),
            since: Instant::now(),
        }
    }
}

impl StageClock {
    /// Records the time since the last lap as stage `name`.
    fn lap(&mut self, name: &str) {
        self.timings.push(StageTiming {
            stage: name.to_string(),
            seconds: self.since.elapsed().as_secs_f64(),
        });
        self.since = Instant::now();
    }
}

/// The loaded input and what the report says of it.
#[derive(Debug)]
pub struct Loaded {
    /// The cloud or mesh.
    pub model: Model,
    /// Its file, kind and counts.
    pub info: InputInfo,
}

/// Stage 1: reads the input and refuses one that is empty or cannot make a model.
pub fn load(input: &Path, observer: Observer<'_>) -> Result<Loaded, PipelineError> {
    observer(Event::Stage {
        index: 1,
        of: STAGES,
        what: format!("loading {}", input.display()),
    });
    let model = plenoptic_io::load(input)?;
    let info = input_info(input, &model);
    if info.points == 0 {
        return Err(PipelineError::EmptyInput(input.to_path_buf()));
    }
    plenoptic_render::degenerate::check_model(input, &model)?;
    Ok(Loaded { model, info })
}

/// The saved state to continue, or a new one; from here until the end the folder says "running".
fn open_state(
    input: &Path,
    cfg: &Config,
    layout: &Layout,
    saved: Option<RunState>,
    observer: Observer<'_>,
) -> Result<RunState, PipelineError> {
    let mut state = match saved {
        Some(s) => {
            observer(Event::Note(format!(
                "resuming the run in {} ({})",
                layout.out.display(),
                resume_summary(&s)
            )));
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
    state.status = Status::Running;
    state.save(&layout.out)?;
    Ok(state)
}

/// The reference views as the trainer and the evaluator take them.
#[derive(Debug)]
pub struct References {
    /// Training views (straight colour with their masks), named as in the dataset; shared with
    /// the trainer, which reads them in place.
    pub train: Arc<Vec<View>>,
    /// Held-out views, for evaluation only.
    pub heldout: Vec<View>,
}

/// Stage 2: renders the training views (writing them as the COLMAP dataset unless a resumed run
/// already has) and the held-out views, and refuses a rig that sees nothing.
#[allow(clippy::too_many_arguments)]
fn reference_views(
    input: &Path,
    model: &Model,
    rig: &Rig,
    cfg: &Config,
    layout: &Layout,
    state: &mut RunState,
    observer: Observer<'_>,
    clock: &mut StageClock,
) -> Result<References, PipelineError> {
    observer(Event::Stage {
        index: 2,
        of: STAGES,
        what: format!(
            "rendering {} training views{} and {} held-out views at {}×{}",
            rig.train.len(),
            if cfg.output.dataset {
                " (and the COLMAP dataset)"
            } else {
                ""
            },
            rig.heldout.len(),
            cfg.rig.width,
            cfg.rig.height
        ),
    });
    let mut opts = cfg.renderer.for_model(model);
    opts.background = [0.0; 3];
    // The trainer keeps colour and coverage; the dataset writer asks for depth if it writes it.
    opts.depth = false;
    if opts.point_size != cfg.renderer.point_size {
        observer(Event::Note(format!(
            "the cloud samples its surface more sparsely than one point per voxel: its points \
             are drawn {:.2} voxels wide (not {}) so the surface is closed \
             (renderer.close_surface)",
            opts.point_size, cfg.renderer.point_size
        )));
    }
    let dataset_opts = views::DatasetOptions {
        bit_depth: if cfg.output.png16 {
            views::BitDepth::Sixteen
        } else {
            views::BitDepth::Eight
        },
        masks: true,
        depth: false,
    };
    // Each view becomes the trainer's view as soon as it is rendered (its depth dropped), so a
    // frame's full images are never all held at once.
    let to_training = |i: usize, image: ViewImage| {
        training_view(i, views::dataset_image_name(i), rig.train[i], image)
    };
    let train = if state.dataset_written || !cfg.output.dataset {
        // The dataset's PNGs are quantised: training needs the renders themselves, which are
        // deterministic, so they are made again in memory.
        if state.dataset_written {
            observer(Event::Note(
                "the dataset is already written: rendering the training views in memory".into(),
            ));
        }
        let train = views::render_views_with(model, &rig.train, &opts, to_training)?
            .into_iter()
            .collect::<Result<Vec<_>, _>>()?;
        clock.lap("render training views");
        train
    } else {
        observer(Event::Begin {
            unit: "views",
            total: rig.train.len() as u64,
            done: 0,
        });
        let done = AtomicU64::new(0);
        let train = views::write_dataset(
            &layout.dataset_dir,
            model,
            &rig.train,
            &opts,
            &dataset_opts,
            &|| {
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                observer(Event::Advance {
                    done: n,
                    message: None,
                });
            },
            to_training,
        )?
        .into_iter()
        .collect::<Result<Vec<_>, _>>()?;
        observer(Event::End);
        state.dataset_written = true;
        state.save(&layout.out)?;
        clock.lap("render training views + write dataset");
        train
    };
    let heldout: Vec<View> = views::render_views_with(model, &rig.heldout, &opts, |i, image| {
        training_view(i, heldout_name(i), rig.heldout[i], image)
    })?
    .into_iter()
    .collect::<Result<_, _>>()?;
    let covered: Vec<bool> = heldout
        .iter()
        .map(|v| v.mask.as_ref().is_none_or(|m| m.iter().any(|&a| a > 0)))
        .collect();
    plenoptic_render::degenerate::check_coverage(input, "held-out", &covered, heldout_name)?;
    clock.lap("render held-out views");
    if cfg.output.dataset {
        observer(Event::Note(format!(
            "dataset written to {}",
            layout.dataset_dir.display()
        )));
    }
    Ok(References {
        train: Arc::new(train),
        heldout,
    })
}

/// The input's surface as initialisation and the distance metric use it.
#[derive(Debug)]
pub struct Surfaces {
    /// The points splats are initialised on.
    pub init: SurfacePoints,
    /// The surface the evaluator measures splat distances to: the cloud, or dense mesh samples,
    /// indexed once (`None` when it has no points).
    pub distance: Option<SurfaceIndex>,
}

impl Surfaces {
    /// Drops the initialisation's points once every model is initialised: a paper-scale
    /// cloud's per-camera colours (0.5 GB) would otherwise stay through training.
    fn release_init(&mut self) {
        self.init = SurfacePoints::default();
    }

    /// The surfaces of `model` under `cfg` (a cloud's columns move into them).
    #[must_use]
    pub fn of(model: Model, cfg: &Config) -> Self {
        let distance = match &model {
            Model::Cloud(_) => None,
            Model::Mesh(m) => Some(init::sample_mesh(m, 200_000, cfg.training.seed ^ 0x5eed)),
        };
        // Mesh samples: K of them when `--splats K` is given, so that K means splats for meshes too.
        let init = SurfacePoints::from_owned_model(
            model,
            cfg.init.mesh_points,
            cfg.init.splats.unwrap_or(cfg.init.mesh_samples),
            cfg.training.seed,
        );
        // A cloud's own points (and normals, where its file has them) are the surface.
        let surface = distance.as_ref().unwrap_or(&init);
        let distance = SurfaceIndex::new(&surface.positions, surface.normals.as_deref());
        Self { init, distance }
    }
}

/// The init modes a run trains: the configured one, and the other with `compare_init`.
fn init_modes(cfg: &Config) -> Vec<InitMode> {
    let mut modes = vec![cfg.init.mode];
    if cfg.output.compare_init {
        modes.push(match cfg.init.mode {
            InitMode::Surface => InitMode::Sparse,
            InitMode::Sparse => InitMode::Surface,
        });
    }
    modes
}

/// Which model of the run: its init mode, its index among the run's modes, its file, and the
/// previous frame's model a warm start takes its training corrections from.
#[derive(Debug, Clone)]
struct RunOf<'a> {
    mode: InitMode,
    index: usize,
    /// Whether no model of the run is initialised after this one.
    last: bool,
    model_path: PathBuf,
    warm_start: Option<&'a WarmStart>,
}

/// One trained and evaluated model, not yet written.
#[derive(Debug)]
pub struct TrainedModel {
    /// Its part of the report.
    pub report: RunReport,
    /// Its renders of the held-out views.
    pub renders: Vec<RenderedView>,
    /// The splats.
    pub splats: Splats,
}

/// The initial splats and schedule of a model, or where training continues from.
struct Initialised {
    summary: InitSummary,
    schedule: Schedule,
    step_zero: Option<StepZero>,
    /// Fresh splats; `None` when training continues from the checkpoint.
    fresh: Option<Splats>,
}

/// Stages 3–5 for one init mode: initialises (or finds the checkpoint to continue from),
/// trains and evaluates one model of the run, whose progress `state` records.
fn init_train_eval(
    run: &RunOf<'_>,
    surfaces: &mut Surfaces,
    refs: &References,
    cfg: &Config,
    layout: &Layout,
    state: &mut RunState,
    observer: Observer<'_>,
) -> Result<TrainedModel, PipelineError> {
    let mut clock = StageClock::default();
    let init = initialise(run, surfaces, refs, cfg, layout, state, observer)?;
    // (Already released on a fresh start; a run continued from its checkpoint comes back
    // before that.)
    if run.last {
        surfaces.release_init();
    }
    clock.lap("init");
    let (splats, train_report, heldout_curve, budget) = train(
        run,
        init.fresh,
        &init.schedule,
        init.summary.sh_degree,
        refs,
        cfg,
        layout,
        state,
        observer,
    )?;
    clock.lap("train");
    let (splats, sh_bands) = if budget.plan.is_some() {
        let (s, choice) = choose_bands(splats, &budget, refs, cfg, observer)?;
        (s, Some(choice))
    } else {
        (splats, None)
    };
    let (metrics, renders) = evaluate(run.mode, &splats, refs, surfaces, cfg, observer)?;
    clock.lap("evaluate");
    // The probe timed the initialised model; a resumed session's trainer starts from another.
    let at = train_report.timings.at_initial_size;
    let probed_size_steps =
        (init.schedule.pace.is_some() && at.splats == init.summary.splats as u64).then_some(at);
    let report = RunReport {
        init: init.summary,
        iterations: train_report.iterations,
        train_seconds: train_report.elapsed_s,
        stopped_by_budget: train_report.stopped_by_budget,
        step_estimate_s: init.schedule.step_estimate_s,
        probe_pace: init.schedule.pace,
        run_pace: train_report.timings.mean_pace(),
        probed_size_steps,
        step_zero: init.step_zero,
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
        heldout_curve,
        budget,
        budget_tolerance_db: cfg.budget.tolerance_db,
        sh_bands,
        metrics,
        model_path: run.model_path.clone(),
        // Filled in when the model is written, after every run is done.
        model_bytes: 0,
        compact_files: Vec::new(),
        timings: clock.timings,
    };
    Ok(TrainedModel {
        report,
        renders,
        splats,
    })
}

/// Stage 3: the initial splats and the training schedule, unless training continues from a
/// checkpoint. The schedule is fixed once, before the first step, and saved: a resumed run must
/// train on the same one even when it came from timed probe steps.
fn initialise(
    run: &RunOf<'_>,
    surfaces: &mut Surfaces,
    refs: &References,
    cfg: &Config,
    layout: &Layout,
    state: &mut RunState,
    observer: Observer<'_>,
) -> Result<Initialised, PipelineError> {
    let (mode, k, out) = (run.mode, run.index, &layout.out);
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
    if let Some(m) = saved.as_ref().filter(|_| resume_from_checkpoint) {
        observer(Event::Stage {
            index: 3,
            of: STAGES,
            what: format!("{mode} init: continuing from {}", ckpt.display()),
        });
        return Ok(Initialised {
            summary: m.init.clone(),
            schedule: m.schedule,
            step_zero: m.step_zero.clone(),
            fresh: None,
        });
    }
    observer(Event::Stage {
        index: 3,
        of: STAGES,
        what: format!("{mode} init"),
    });
    let mut init_cfg = cfg.init.clone();
    init_cfg.mode = mode;
    let budget = budget_applies(cfg, mode).then_some(&cfg.budget);
    // `--splats K` caps the search's start, never raises it (`BudgetConfig::start_splats`).
    if let Some(b) = budget {
        let points = surfaces.init.len();
        let asked = init_cfg.splats;
        let start = b.start_splats(points, mean_covered_pixels(&refs.train), asked);
        if start < asked.unwrap_or(points).min(points) {
            let asked = asked.map_or(String::new(), |k| format!(", under the {k} asked for"));
            observer(Event::Note(format!(
                "splat budget: {points} points merged to about {start} ({} per covered pixel \
                 of the mean training view{asked}) before training",
                b.splats_per_pixel
            )));
            init_cfg.splats = Some(start);
        }
    }
    let (mut splats, mut summary) = init::initialise(
        &surfaces.init,
        &init_cfg,
        cfg.renderer.exponent,
        cfg.training.seed,
    )?;
    if let Some(previous) = run.warm_start {
        warm_start(&mut splats, previous, &init_cfg, cfg, observer)?;
        summary.warm_start = Some(previous.model.clone());
    }
    observer(Event::Note(format!(
        "{} splats, SH degree {}{}",
        summary.splats,
        summary.sh_degree,
        summary
            .sh_fit_rms
            .map(|e| format!(
                " (SH fit RMS by degree: {:.4} {:.4} {:.4} {:.4})",
                e[0], e[1], e[2], e[3]
            ))
            .unwrap_or_default()
    )));
    let step_zero = colour_solve(mode, &mut splats, surfaces, refs, cfg, observer)?;
    // The points are not needed past here by the last model: release them before the time
    // budget's probe builds a trainer of its own (at a paper-scale frame they are 0.6 GB, and
    // with the probe's trainer on top they set the run's peak memory).
    if run.last {
        surfaces.release_init();
    }
    let schedule = match &saved {
        Some(m) => m.schedule,
        None => {
            let base = cfg.train_config(mode, summary.sh_degree);
            let schedule = plan(
                &splats,
                &refs.train,
                &base,
                cfg.training.scale_densify,
                budget,
            )?;
            state.modes.push(ModeState {
                mode,
                init: summary.clone(),
                schedule,
                step_zero: Some(step_zero.clone()),
                heldout_curve: Vec::new(),
                budget: BudgetSearch::default(),
                trained: None,
            });
            state.save(out)?;
            schedule
        }
    };
    Ok(Initialised {
        summary,
        schedule,
        step_zero: Some(step_zero),
        fresh: Some(splats),
    })
}

/// Warm start: reproduces the previous frame's initialisation from its input and adds what
/// training changed in it to `splats` ([`init::carry_training`]).
fn warm_start(
    splats: &mut Splats,
    previous: &WarmStart,
    init_cfg: &init::InitConfig,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(), PipelineError> {
    let warm_err = |problem: String| PipelineError::WarmStart {
        path: previous.model.clone(),
        problem,
    };
    let trained = splat_core::ply::read_splats(&previous.model)
        .map_err(|e| warm_err(format!("cannot read it: {e}")))?;
    let loaded = load(&previous.input, &crate::progress::ignore)?;
    let surfaces = Surfaces::of(loaded.model, cfg);
    let (initial, _) = init::initialise(
        &surfaces.init,
        init_cfg,
        cfg.renderer.exponent,
        cfg.training.seed,
    )?;
    let carried =
        init::carry_training(splats, &initial, &trained).map_err(|e| warm_err(e.to_string()))?;
    if let Some(c) = carried {
        observer(Event::Note(format!(
            "warm start: {} splats took the training corrections of {} (rigid motion {:.2}° and \
             {:.3} taken out; median distance {:.3})",
            c.splats,
            previous.model.display(),
            c.motion.angle_deg(),
            c.motion.translation.length(),
            c.median_distance
        )));
    }
    Ok(())
}

/// Whether the automatic splat budget runs for `mode`: surface init that does not densify (a
/// densifying run grows and prunes by its own rules).
fn budget_applies(cfg: &Config, mode: InitMode) -> bool {
    cfg.budget.auto && mode == InitMode::Surface && !cfg.init.densify_surface
}

/// The pixels the input covers in the mean training view (reference alpha above ½).
fn mean_covered_pixels(views: &[View]) -> f64 {
    let covered: usize = views
        .iter()
        .map(|v| match &v.mask {
            Some(m) => m.iter().filter(|&&a| from_unorm16(a) > 0.5).count(),
            None => v.image.len() / 3,
        })
        .sum();
    covered as f64 / views.len().max(1) as f64
}

/// Stage 3 (end): scores the initial splats on the held-out views and, for surface init with
/// `init.colour_solve_iterations` > 0, replaces their SH coefficients by the least-squares solve
/// against the training views (`splat_init::colour_solve`) and scores them again.
fn colour_solve(
    mode: InitMode,
    splats: &mut Splats,
    surfaces: &Surfaces,
    refs: &References,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<StepZero, PipelineError> {
    let score = |s: &Splats| -> Result<HeldoutScore, PipelineError> {
        let (m, _) = evaluate_views(
            s,
            &refs.heldout,
            surfaces.distance.as_ref(),
            &cfg.eval_options(),
        )?;
        Ok(HeldoutScore::from(&m))
    };
    let fit = score(splats)?;
    let iterations = cfg.init.colour_solve_iterations;
    if mode != InitMode::Surface || iterations == 0 {
        return Ok(StepZero {
            fit,
            solved: None,
            solve: None,
            solve_seconds: 0.0,
        });
    }
    let start = Instant::now();
    let report = splat_init::solve_colours(
        splats,
        &refs.train,
        &splat_init::SolveOptions {
            iterations,
            ..splat_init::SolveOptions::default()
        },
    )?;
    let solve_seconds = start.elapsed().as_secs_f64();
    let solved = score(splats)?;
    observer(Event::Note(format!(
        "colour solve ({} iterations, {solve_seconds:.1} s): held-out PSNR at step 0 {:.2} → {:.2} dB on black, {:.2} → {:.2} dB on white",
        report.iterations, fit.psnr_black, solved.psnr_black, fit.psnr_white, solved.psnr_white
    )));
    Ok(StepZero {
        fit,
        solved: Some(solved),
        solve: Some(report),
        solve_seconds,
    })
}

/// Stage 4: trains from `fresh` splats, or from the run's checkpoint, to the end of the schedule
/// (or finds it trained already), checkpointing as it goes. Returns the splats, the trainer's
/// report and the held-out curve (`eval.every`).
#[allow(clippy::too_many_arguments)]
fn train(
    run: &RunOf<'_>,
    fresh: Option<Splats>,
    schedule: &Schedule,
    sh_degree: u32,
    refs: &References,
    cfg: &Config,
    layout: &Layout,
    state: &mut RunState,
    observer: Observer<'_>,
) -> Result<Trained, PipelineError> {
    let (mode, k, out) = (run.mode, run.index, &layout.out);
    let ckpt = resume::checkpoint_path(out, mode);
    observer(Event::Stage {
        index: 4,
        of: STAGES,
        what: format!(
            "training {} iterations{}",
            cfg.training.iterations,
            cfg.training
                .time_budget_s
                .map(|b| format!(" (budget {b:.0} s)"))
                .unwrap_or_default()
        ),
    });
    let tc = scheduled_config(cfg.train_config(mode, sh_degree), schedule);
    if let (Some(steps), Some(d)) = (schedule.densify_steps, tc.densify) {
        observer(Event::Note(format!(
            "densification scaled to ~{steps} steps: from step {} every {} until {}, opacity reset every {}",
            d.start, d.interval, d.stop, d.opacity_reset_interval
        )));
    }
    let mut trainer = match fresh {
        Some(splats) => {
            let mut t = Trainer::new(splats, Arc::clone(&refs.train), tc)?;
            if let Some(pace) = schedule.pace {
                t.start_pace(pace);
            }
            t
        }
        None => Trainer::resume(&ckpt, Arc::clone(&refs.train), tc).map_err(|e| {
            ResumeError::Checkpoint {
                path: ckpt.clone(),
                problem: e.to_string(),
            }
        })?,
    };
    // The curve as far as the checkpoint: points taken after it are taken again.
    let mut probe = HeldoutProbe {
        views: &refs.heldout,
        every: cfg.eval.every,
        options: cfg.eval_options(),
        curve: state
            .modes
            .get(k)
            .map(|m| m.heldout_curve.clone())
            .unwrap_or_default(),
    };
    probe.curve.retain(|p| p.iteration <= trainer.iteration());
    let mut search = state
        .modes
        .get(k)
        .map(|m| m.budget.clone())
        .unwrap_or_default();
    search.plan = schedule.budget;
    let already = state.modes.get(k).and_then(|m| m.trained);
    if already.is_none() {
        search.rewind(trainer.iteration());
    }
    let report = match already {
        Some(t) => {
            observer(Event::Note(format!(
                "trained already ({} steps)",
                trainer.iteration()
            )));
            trainer.report(t.stopped_by_budget)
        }
        None => {
            if trainer.iteration() > 0 {
                observer(Event::Note(format!(
                    "continuing from step {}",
                    trainer.iteration()
                )));
            }
            let every = Duration::from_secs_f64(cfg.output.checkpoint_interval_s);
            let saving = Saving {
                checkpoint: &ckpt,
                every,
                state,
                mode_index: k,
                out,
            };
            let budget = Budgeting {
                search: &mut search,
                config: &cfg.budget,
            };
            let report = train_to_end(&mut trainer, saving, &mut probe, budget, observer)?;
            if let Some(m) = state.modes.get_mut(k) {
                m.trained = Some(TrainedState {
                    stopped_by_budget: report.stopped_by_budget,
                });
            }
            state.save(out)?;
            report
        }
    };
    Ok((trainer.splats().clone(), report, probe.curve, search))
}

/// What stage 4 returns: the splats, the trainer's report, the held-out curve and the splat
/// budget's rounds.
type Trained = (
    Splats,
    splat_train::TrainReport,
    Vec<HeldoutPoint>,
    BudgetSearch,
);

/// The automatic splat budget's search while a model trains, and its settings.
struct Budgeting<'a> {
    search: &'a mut BudgetSearch,
    config: &'a BudgetConfig,
}

/// Scores the model on the held-out views every `every` steps while it trains.
struct HeldoutProbe<'a> {
    views: &'a [View],
    every: u32,
    options: EvalOptions,
    curve: Vec<HeldoutPoint>,
}

impl HeldoutProbe<'_> {
    /// Adds the point of the trainer's current step when one is due: at step 0, every `every`
    /// steps and at the last step (`last`). A multiple of `every` that a splat budget round
    /// trained past (its two branches train between two calls) is taken at the first step
    /// after the round, so the curve has a point in every `every` steps.
    fn take(&mut self, trainer: &Trainer, elapsed_s: f64, last: bool) -> Result<(), PipelineError> {
        let it = trainer.iteration();
        let previous = self.curve.last().map(|p| p.iteration);
        if self.every == 0 || previous.is_some_and(|p| p >= it) {
            return Ok(());
        }
        let passed = previous.is_some_and(|p| it / self.every > p / self.every);
        if !(it.is_multiple_of(self.every) || last || passed) {
            return Ok(());
        }
        let (metrics, _) = evaluate_views(trainer.splats(), self.views, None, &self.options)?;
        self.curve.push(HeldoutPoint::new(it, elapsed_s, &metrics));
        Ok(())
    }
}

/// Stage 4 (end), with the splat budget: the SH degree and per-splat bands the held-out views
/// need ([`splat_train::sh_bands::choose_bands`]), within what the budget's rounds left of its
/// tolerance.
fn choose_bands(
    splats: Splats,
    search: &BudgetSearch,
    refs: &References,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(Splats, splat_train::sh_bands::BandChoice), PipelineError> {
    let b = &cfg.budget;
    let tolerance = b
        .bands_tolerance_db
        .min(search.left_db(b.tolerance_db).max(0.0));
    let options = cfg.eval_options();
    // One render a view, as the budget's rounds score: the full evaluation adds a second render,
    // the SSIMs and the error breakdown to each view, none of which the choice reads.
    let mut psnr = |s: &Splats| -> Result<f64, PipelineError> {
        let (black, white) = splat_train::psnr_black_and_white(s, &refs.heldout, &options)?;
        Ok(splat_train::psnr_both(black, white))
    };
    let (splats, choice) =
        splat_train::sh_bands::choose_bands(&splats, tolerance, b.static_sh_rms, &mut psnr)?;
    observer(Event::Note(format!(
        "SH bands: degree {} kept of {} (held-out PSNR by degree: {}); {} splats without view \
         dependence lost their higher bands",
        choice.degree,
        choice.trained_degree,
        choice
            .psnr_by_degree
            .iter()
            .map(|p| format!("{p:.2}"))
            .collect::<Vec<_>>()
            .join(", "),
        choice.flattened
    )));
    Ok((splats, choice))
}

/// Stage 5: scores a trained model on the held-out views.
fn evaluate(
    mode: InitMode,
    splats: &Splats,
    refs: &References,
    surfaces: &Surfaces,
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(Metrics, Vec<RenderedView>), PipelineError> {
    observer(Event::Stage {
        index: 5,
        of: STAGES,
        what: format!("evaluating the {mode} model"),
    });
    Ok(evaluate_views(
        splats,
        &refs.heldout,
        surfaces.distance.as_ref(),
        &cfg.eval_options(),
    )?)
}

/// Stage 5 (end): writes every model in the formats asked for, noting sizes in its report.
fn export(
    trained: &mut [TrainedModel],
    cfg: &Config,
    observer: Observer<'_>,
) -> Result<(), PipelineError> {
    if cfg.training.antialiased {
        observer(Event::Note(
            "the model was trained antialiased (training.antialiased): its PLY says so in a \
             header comment (SplatRenderMode: mip) and its SPZ in a flag, which our viewer, \
             Brush, PlayCanvas / SuperSplat and splat-transform read; a viewer that ignores them \
             draws it with more coverage than it was trained to have, and .splat and .glb files \
             cannot say it (docs/benchmarks/fidelity.md sections 14 and 15)"
                .into(),
        ));
    }
    for (k, model) in trained.iter_mut().enumerate() {
        let run = &mut model.report;
        observer(Event::Stage {
            index: 5,
            of: STAGES,
            what: format!("writing {}", run.model_path.display()),
        });
        let t = Instant::now();
        let formats = ModelFormats {
            antialiased: cfg.training.antialiased,
            splat: k == 0 && cfg.output.splat_file,
            spz: cfg.output.spz.then_some(cfg.output.spz_version),
            glb: cfg.output.glb,
        };
        let compact = write_model(&run.model_path, &model.splats, formats)?;
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
    Ok(())
}

/// Stage 6: writes the report (JSON and HTML).
#[allow(clippy::too_many_arguments)]
fn report(
    input: &InputInfo,
    refs: &References,
    trained: Vec<TrainedModel>,
    cfg: &Config,
    layout: &Layout,
    clock: StageClock,
    started: Instant,
    observer: Observer<'_>,
) -> Result<Outcome, PipelineError> {
    observer(Event::Stage {
        index: 6,
        of: STAGES,
        what: "writing the report".to_string(),
    });
    let renders: Vec<Vec<RenderedView>> = trained.iter().map(|t| t.renders.clone()).collect();
    let pictures = pick_pictures(&refs.heldout, &renders, cfg.eval.report_views);
    if let Some(main) = trained.first() {
        let title = format!("transcode: {}", input.path.display());
        crate::viewer::write_report_viewer(
            &layout.report_dir,
            &title,
            &main.splats,
            cfg.training.antialiased,
            &refs.heldout,
            &main.renders,
        )?;
    }
    let mut report = Report {
        version: env!("CARGO_PKG_VERSION").to_string(),
        input: input.clone(),
        config: cfg.clone(),
        train_views: refs.train.len(),
        heldout_views: refs.heldout.len(),
        timings: clock.timings,
        runs: trained.into_iter().map(|t| t.report).collect(),
        total_seconds: 0.0,
    };
    report.total_seconds = started.elapsed().as_secs_f64();
    let html =
        write_report(&layout.report_dir, &report, &pictures).map_err(io_err(&layout.report_dir))?;
    Ok(Outcome {
        report,
        html,
        model: layout.main_model(),
    })
}

/// Every extension a model file of a run may have: a run deletes them all before it starts.
const MODEL_EXTENSIONS: [&str; 4] = ["ply", "splat", "spz", "glb"];

/// The files written beside a model's PLY.
#[derive(Clone, Copy, Debug)]
struct ModelFormats {
    /// The model was trained antialiased (the PLY's header and the SPZ's flag say so).
    antialiased: bool,
    splat: bool,
    /// The SPZ version to write, if any.
    spz: Option<u32>,
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
    // Each file by its extension, the render mode marked where the format has a place for it.
    let spz = splat_core::spz::SpzOptions {
        version: formats.spz.unwrap_or(splat_core::spz::VERSION),
        ..splat_core::spz::SpzOptions::default()
    };
    let write = |p: &Path| {
        splat_core::model_file::write_model(p, splats, formats.antialiased, &spz)
            .map_err(model_err(p))
    };
    write(path)?;
    let mut written = Vec::new();
    for (ext, wanted) in [
        ("splat", formats.splat),
        ("spz", formats.spz.is_some()),
        ("glb", formats.glb),
    ] {
        if wanted {
            let p = path.with_extension(ext);
            write(&p)?;
            written.push(p);
        }
    }
    Ok(written)
}

/// The schedule of a run about to start: with `scale_schedule` and densification, the steps the
/// densification schedule is scaled to ([`step_budget`]: timed probe steps under a time budget)
/// and the budget left after the probe; otherwise the configuration's own.
fn plan(
    splats: &Splats,
    views: &Arc<Vec<View>>,
    tc: &TrainConfig,
    scale_schedule: bool,
    budget: Option<&BudgetConfig>,
) -> Result<Schedule, PipelineError> {
    let scaled = scale_schedule && tc.densify.is_some();
    // Rounds are placed at shares of the run's steps: under a time budget, the probe's estimate.
    let (steps, time_budget, pace) = if scaled || budget.is_some() {
        step_budget(splats, views, tc)?
    } else {
        (tc.iterations, tc.time_budget, None)
    };
    // The mean step of the planned run: its warm-up and full steps in their shares.
    let step_estimate_s = pace.and_then(|p| {
        let coarse = tc.warmup.zip(p.coarse_step_s);
        Some(splat_train::schedule::mean_step_s(
            p.step_s?,
            coarse.map(|(w, c)| (w.share(tc.iterations), c)),
        ))
    });
    Ok(Schedule {
        densify_steps: scaled.then_some(steps),
        time_budget: time_budget.or(tc.time_budget),
        budget: budget.and_then(|b| b.plan(steps)),
        step_estimate_s,
        pace,
    })
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

/// Where and how often [`train_to_end`] saves its progress.
struct Saving<'a> {
    checkpoint: &'a Path,
    /// Wall time between checkpoints.
    every: Duration,
    state: &'a mut RunState,
    mode_index: usize,
    out: &'a Path,
}

impl Saving<'_> {
    /// Saves the held-out curve so far in the run state, then the trainer's checkpoint. The
    /// state goes first: a point newer than the checkpoint is dropped and taken again on resume.
    fn save(
        &mut self,
        trainer: &Trainer,
        curve: &[HeldoutPoint],
        search: &BudgetSearch,
    ) -> Result<(), PipelineError> {
        if let Some(m) = self.state.modes.get_mut(self.mode_index) {
            m.heldout_curve = curve.to_vec();
            m.budget = search.clone();
        }
        self.state.save(self.out)?;
        trainer.save_checkpoint(self.checkpoint)?;
        Ok(())
    }
}

/// Runs `trainer` to the end of its schedule one step at a time, reporting progress, taking
/// the held-out curve's points, and checkpointing every `saving.every` of wall time and once
/// more at the end (the later stages resume from that).
///
/// The trainer pauses between two steps to save or score, which changes nothing it computes: a
/// run checkpointed or scored at any moments ends bit-identical to one that never stopped.
fn train_to_end(
    trainer: &mut Trainer,
    mut saving: Saving<'_>,
    probe: &mut HeldoutProbe<'_>,
    mut budget: Budgeting<'_>,
    observer: Observer<'_>,
) -> Result<splat_train::TrainReport, PipelineError> {
    let total = trainer.horizon();
    observer(Event::Begin {
        unit: "steps",
        total: u64::from(total),
        done: u64::from(trainer.iteration()),
    });
    // The held-out curve's scores (`--eval-every`, off by default) are a measurement of the
    // run and stay off its clock, so the curve's time axis is training time, as in `transcode
    // train`; the checkpoints are part of the run, and a time budget pays for them
    // (`Trainer::count_time_between_steps`).
    if trainer.iteration() == 0 {
        probe.take(trainer, 0.0, false)?;
    }
    let mut shown_total = total;
    let mut advance = |p: &splat_train::Progress| {
        if p.total != shown_total {
            shown_total = p.total;
            observer(Event::Total(u64::from(p.total)));
        }
        let message = p
            .step
            .iteration
            .is_multiple_of(25)
            .then(|| format!("PSNR {:.2} dB, {} splats", p.step.psnr, p.step.splats));
        observer(Event::Advance {
            done: u64::from(p.step.iteration),
            message,
        });
    };
    let mut saved_at = Instant::now();
    let report = loop {
        while budget.search.due(trainer.iteration()) {
            budget_round(trainer, &mut budget, probe, &mut advance, observer)?;
        }
        let r = trainer.run_until(trainer.iteration() + 1, &mut advance);
        // The horizon as it stands now: under a time budget it is re-estimated every step, and
        // it grows when the steps get faster (a budget round's merge), so the length estimated
        // before the first step would end the schedule early, with budget left.
        let last = r.iterations >= trainer.horizon() || r.stopped_by_budget;
        probe.take(trainer, r.elapsed_s, last)?;
        if last {
            // A time budget that laid the schedule over fewer steps than configured stopped it.
            break trainer.report(r.stopped_by_budget || trainer.budget_binds());
        }
        if saved_at.elapsed() >= saving.every {
            let t = Instant::now();
            saving.save(trainer, &probe.curve, budget.search)?;
            trainer.count_time_between_steps(t.elapsed().as_secs_f64());
            saved_at = Instant::now();
        }
    };
    saving.save(trainer, &probe.curve, budget.search)?;
    observer(Event::End);
    Ok(report)
}

/// Runs the splat budget's due round: both branches, scored on the held-out views on black and
/// on white ([`splat_train::BudgetRound::drop_db`] takes the worse).
fn budget_round(
    trainer: &mut Trainer,
    budget: &mut Budgeting<'_>,
    probe: &HeldoutProbe<'_>,
    advance: &mut dyn FnMut(&splat_train::Progress),
    observer: Observer<'_>,
) -> Result<(), PipelineError> {
    let mut heldout_psnr = |s: &Splats| -> Result<splat_train::HeldoutPsnr, PipelineError> {
        let (black, white) = splat_train::psnr_black_and_white(s, probe.views, &probe.options)?;
        Ok(splat_train::HeldoutPsnr { black, white })
    };
    let (due_at, n) = (trainer.iteration(), trainer.splats().len());
    let round = budget
        .search
        .run_round(trainer, budget.config, &mut heldout_psnr, advance)?;
    for skip in budget
        .search
        .skipped
        .iter()
        .filter(|s| s.iteration == due_at)
    {
        let why = if skip.floor_db > skip.left_db {
            format!("it could not cost less than {:.3} dB", skip.floor_db)
        } else {
            format!(
                "its first look could not cost less than {:.3} dB, too much to be looked at again",
                skip.first_look_floor_db
            )
        };
        observer(Event::Note(format!(
            "splat budget, step {due_at}: a merge keeping {:.1} % of {n} splats skipped: {why}, \
             and {:.3} dB of the tolerance is left",
            100.0 * skip.keep,
            skip.left_db
        )));
    }
    let Some(round) = round else {
        let why = if budget.search.no_time_left {
            "too little of the time budget is left for a round's two branches; the search ends"
        } else if budget
            .search
            .skipped
            .last()
            .is_some_and(|s| s.iteration == due_at)
        {
            "no merge left that could cost less than what is left of the tolerance; the search ends"
        } else {
            "nothing left to merge"
        };
        observer(Event::Note(format!(
            "splat budget, step {}: {why} at {} splats",
            trainer.iteration(),
            trainer.splats().len()
        )));
        return Ok(());
    };
    let cost = match (round.pruned_psnr, round.drop_db()) {
        (Some(p), Some(d)) => format!(
            "costs {d:+.3} dB held-out{}, the worse of black ({p:.2} against {:.2}) and white \
             ({:.2} against {:.2})",
            match (round.first_look_db, round.second_look_db) {
                (Some(f), Some(second)) => format!(
                    " with both branches trained to the end of the run (the first look \
                     {f:+.3}, the second {second:+.3})"
                ),
                (Some(f), None) =>
                    format!(" after a second trial of both branches (the first {f:+.3})"),
                _ => String::new(),
            },
            round.kept_psnr,
            round.pruned_psnr_white.unwrap_or(f64::NAN),
            round.kept_psnr_white.unwrap_or(f64::NAN),
        ),
        _ => "not measured".into(),
    };
    let left = budget.search.left_db(budget.config.tolerance_db);
    observer(Event::Note(format!(
        "splat budget, step {}: {} → {} splats {cost}; {} ({:.1} s)",
        round.iteration,
        round.splats,
        round.candidate,
        if round.out_of_time {
            "out of time, kept the whole model".into()
        } else if round.accepted && budget.search.tolerance_spent {
            "merged; too little of the tolerance is left for another round, the search ends".into()
        } else if round.accepted {
            format!("merged, {left:.3} dB of the tolerance left")
        } else if budget.search.finished() {
            "over the tolerance, kept the whole model; the search ends".into()
        } else {
            "over the tolerance, kept the whole model; the next round merges fewer".into()
        },
        round.seconds.total(),
    )));
    Ok(())
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Steps a probe times when each takes `step` and the run at that speed may bind or not.
    fn timed_steps(step: Duration, enough: Duration, binds: bool) -> u32 {
        let mut timed = 0;
        while keep_timing(timed, step * timed, enough, |s| {
            assert!((s - step.as_secs_f64()).abs() < 1e-9, "mean step {s}");
            binds
        }) {
            timed += 1;
        }
        timed
    }

    #[test]
    fn the_probe_times_more_steps_only_where_the_budget_may_bind() {
        let enough = Duration::from_secs(3);
        // Slow steps: the minimum either way, since four of them already take the share.
        let slow = Duration::from_secs(1);
        assert_eq!(timed_steps(slow, enough, true), PROBE_STEPS);
        assert_eq!(timed_steps(slow, enough, false), PROBE_STEPS);
        // 125 ms steps: timed until they have taken the share (24 of them), unless the run
        // fits easily.
        let paper = Duration::from_millis(125);
        assert_eq!(timed_steps(paper, enough, true), 24);
        assert_eq!(timed_steps(paper, enough, false), PROBE_STEPS);
        // Millisecond steps: capped.
        let fast = Duration::from_millis(1);
        assert_eq!(timed_steps(fast, enough, true), PROBE_MAX_STEPS);
        assert_eq!(timed_steps(fast, enough, false), PROBE_STEPS);
    }

    #[test]
    fn every_model_file_that_can_say_the_model_was_trained_antialiased_says_so() {
        let splats = Splats::from_points(
            &[glam::Vec3::ZERO, glam::Vec3::X],
            &[[1.0, 0.5, 0.0], [0.0, 0.5, 1.0]],
            &[glam::Vec3::splat(0.1); 2],
            None,
            0.9,
            1,
        )
        .unwrap();
        let dir = tempfile::tempdir().unwrap();
        for antialiased in [false, true] {
            let path = dir.path().join(format!("splats{antialiased}.ply"));
            let formats = ModelFormats {
                antialiased,
                splat: true,
                spz: Some(if antialiased { 4 } else { 3 }),
                glb: true,
            };
            let others = write_model(&path, &splats, formats).unwrap();
            assert_eq!(others.len(), 3);
            for p in std::iter::once(path).chain(others) {
                let file = splat_core::model_file::read_model(&p).unwrap();
                assert_eq!(file.splats.len(), 2);
                let recorded = antialiased && file.format.records_antialiased();
                assert_eq!(file.antialiased, recorded, "{}", p.display());
            }
        }
    }
}
