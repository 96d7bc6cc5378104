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
//!
//! One module a stage, in the order a run takes them: `input` (1: the file, its surface),
//! `references` (2: reference views and the COLMAP dataset), `initialise` (3: initial splats;
//! `schedule` fixes the run's steps before the first one), `train` (4: training, checkpoints, the
//! held-out curve; `budget` drives the automatic splat budget's rounds in it) and `output` (5
//! and 6: evaluation, model files, report); `layout` owns the output folder and its saved state,
//! `error` the error. This file holds the run itself ([`run`], [`run_with`]) and the stages'
//! order.

mod budget;
mod error;
mod initialise;
mod input;
mod layout;
mod output;
mod references;
mod schedule;
mod train;

pub use error::PipelineError;
pub use input::{Loaded, Surfaces, input_info, load, refuse_splat_model};
pub use references::{References, training_view};

use std::path::{Path, PathBuf};
use std::time::Instant;

use plenoptic_render as views;
use splat_core::Splats;
use splat_train::eval::RenderedView;

use crate::config::{Config, InitMode};
use crate::progress::{Event, Observer};
use crate::report::{CurvePoint, Report, RunReport, StageTiming};
use crate::resume::{InputStamp, ResumeError, RunState, Status};
use budget::choose_bands;
use initialise::{init_modes, initialise};
use layout::{Layout, open_state, remove_dir_if_present};
use output::{evaluate, export, report};
use references::reference_views;
use train::train;

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
            return match finished_outputs_problem(&layout) {
                None => Ok(Finish::AlreadyFinished { model, html }),
                Some(problem) => Err(ResumeError::OutputsGone {
                    dir: out.to_path_buf(),
                    problem,
                }
                .into()),
            };
        }
    }
    execute(input, out, cfg, observer, saved, opts.warm_start.as_ref())
        .map(|o| Finish::Completed(Box::new(o)))
}

/// What is wrong with a finished run's outputs, or `None` when its model reads whole and its
/// report is there and parses: a finished run is checked, not taken on its state's word (a model
/// cut short or removed since was reported as finished, and a sequence counted it).
fn finished_outputs_problem(layout: &Layout) -> Option<String> {
    let model = layout.main_model();
    if let Err(e) = splat_core::ply::read_model(&model) {
        return Some(format!("its model {} cannot be read: {e}", model.display()));
    }
    let html = layout.html();
    if !html.is_file() {
        return Some(format!("its report {} is gone", html.display()));
    }
    let json = layout.report_dir.join("report.json");
    let parsed = std::fs::read(&json)
        .map_err(|e| e.to_string())
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).map_err(|e| e.to_string()));
    parsed
        .err()
        .map(|e| format!("its report {} cannot be read: {e}", json.display()))
}

/// The stages of a run, in order (the numbers in [`Event::Stage`]).
const STAGES: u32 = 6;

/// Refuses an input whose model could not be drawn or stored, before anything is rendered:
/// - cameras within [`error::NEAR_PLANE_CLEARANCE`] near planes of the object (the near plane
///   is in absolute units, as in every 3DGS renderer, so an object under about 0.01 units
///   across was culled whole and trained to an empty model reported as a success);
/// - coordinates beyond SPZ's 24-bit positions (the run trained, then failed to write the
///   report's viewer, which carries the model as SPZ).
fn check_placeable(rig: &views::Rig) -> Result<(), PipelineError> {
    let near = splat_core::constants::NEAR_PLANE;
    let gap = rig
        .train
        .iter()
        .chain(&rig.heldout)
        .map(|c| c.pose.center().distance(rig.center) - rig.radius)
        .fold(f64::INFINITY, f64::min);
    if gap < error::NEAR_PLANE_CLEARANCE * f64::from(near) {
        return Err(PipelineError::TooSmall {
            radius: rig.radius,
            gap,
            near,
        });
    }
    // The model's splats stay near the input (a percent past its bounds, with room to move):
    // beyond SPZ's positions the run trained, then failed to write the viewer.
    let largest = (rig.center.abs().max_element() + rig.radius) * 1.01;
    let limit = splat_core::spz::MAX_COORDINATE;
    if largest > f64::from(limit) {
        let at = largest as f32;
        return Err(PipelineError::TooFar {
            largest,
            radius: rig.radius,
            limit,
            ulp: at.next_up() - at,
            centre: rig.center.to_array(),
        });
    }
    Ok(())
}

/// Coarsest spacing of 32-bit floats at the input's coordinates, as a share of its radius, that
/// passes without a note: the reference views and the splats' positions are f32 in the input's
/// frame, so an input far from the origin against its size is drawn and trained coarsely (the
/// 32-unit demo moved 10⁵ units out, where floats are 1/128 apart, a share of 2.8 × 10⁻⁴,
/// lost 0.5 dB; 10⁶ units, 1 dB; 8 · 10⁶, 2–7 dB; 10³ units nothing measurable).
const MAX_FLOAT_STEP_SHARE: f64 = 1e-4;

/// A note for an input that sits far from the origin against its size (see
/// [`MAX_FLOAT_STEP_SHARE`]), or `None`.
fn far_from_origin_note(rig: &views::Rig) -> Option<String> {
    let largest = (rig.center.abs().max_element() + rig.radius) as f32;
    let step = f64::from(largest.next_up() - largest);
    let share = step / rig.radius;
    (share > MAX_FLOAT_STEP_SHARE).then(|| {
        format!(
            "the input sits up to {largest:.0} units from the origin, where 32-bit floats are \
             {step} units apart ({share:.1e} of its radius {:.4e}): its reference views and \
             the splats' positions lose precision there (the demo moved 10^5 units out loses \
             about 0.5 dB, 10^6 units about 1 dB); for the best model subtract its centre \
             ({:?}) first",
            rig.radius,
            rig.center.to_array()
        )
    })
}

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
    if cfg.rig.heldout_cameras == 0 {
        // The model is scored, and the splat budget judged, on the held-out views.
        return Err(crate::config::ConfigError::Invalid {
            path: None,
            key: "rig.heldout_cameras".into(),
            problem: "must be at least 1: a run scores its model on the held-out views".into(),
        }
        .into());
    }
    // The views are trained on: a size the rasteriser refuses failed only after all of them
    // were rendered (the reference renderer and `transcode views` go to 16384²).
    splat_core::Rasterizer::check_view_size(cfg.rig.width, cfg.rig.height).map_err(|e| {
        crate::config::ConfigError::Invalid {
            path: None,
            key: "rig.width/rig.height".into(),
            problem: format!("the training views are too large: {e}"),
        }
    })?;
    let started = Instant::now();
    if out.exists() && !out.is_dir() {
        return Err(PipelineError::OutputNotFolder(out.to_path_buf()));
    }
    let saved_run = saved.is_some();
    let layout = Layout::new(out);
    // Held until the run returns: a second run into this folder would clear what this one
    // writes.
    let _writer = crate::lock::WriterLock::acquire(&layout.lock_file())?;
    layout.check_input_outside(input)?;
    if let Some(sparse) = &cfg.init.points3d {
        // Sparse init reads its COLMAP model after the dataset stage has rewritten the
        // dataset's own model, which a `--points3d` inside `dataset/` would be.
        layout.check_input_outside(sparse)?;
    }
    layout.clear_results(saved.is_none())?;
    let mut clock = StageClock::default();

    let loaded = load(input, observer)?;
    clock.lap("load");
    layout.create(cfg.output.dataset)?;
    let mut state = open_state(input, cfg, &layout, saved, observer)?;
    let rig = views::build_rig(&loaded.model, &cfg.rig)?;
    check_placeable(&rig)?;
    if let Some(note) = far_from_origin_note(&rig) {
        observer(Event::Note(note));
    }
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
    clock.lap("write models");
    let resumed = saved_run;
    let outcome = report(
        &info, &refs, trained, cfg, &layout, clock, started, resumed, observer,
    )?;
    state.status = Status::Finished;
    state.save(out)?;
    remove_dir_if_present(&layout.checkpoints)?;
    Ok(outcome)
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

#[cfg(test)]
mod tests {
    use glam::DVec3;

    use super::*;

    fn rig_at(center: DVec3, radius: f64) -> views::Rig {
        views::Rig {
            train: Vec::new(),
            heldout: Vec::new(),
            center,
            radius,
        }
    }

    /// The demo's 16-unit radius passes at the origin and 10³ units out (floats 6e-5 apart, a
    /// share of 4e-6), and is noted 10⁵ units out (1/128 apart, 4.9e-4), where it lost 0.5 dB.
    #[test]
    fn inputs_far_from_the_origin_against_their_size_are_noted() {
        assert_eq!(
            far_from_origin_note(&rig_at(DVec3::splat(24.0), 16.0)),
            None
        );
        assert_eq!(far_from_origin_note(&rig_at(DVec3::splat(1e3), 16.0)), None);
        let note = far_from_origin_note(&rig_at(DVec3::new(1e5, 0.0, 0.0), 16.0))
            .expect("noted 10^5 units out");
        assert!(note.contains("100016 units from the origin"), "{note}");
        assert!(note.contains("0.0078125 units apart"), "{note}");
        assert!(
            note.contains("subtract its centre ([100000.0, 0.0, 0.0])"),
            "{note}"
        );
        // A paper-scale frame on its 4095-voxel grid is not.
        assert_eq!(
            far_from_origin_note(&rig_at(DVec3::splat(2048.0), 1500.0)),
            None
        );
    }

    /// The refusal says how far the model may reach and, when the input is wider than SPZ's
    /// range itself, to scale it rather than move it.
    #[test]
    fn inputs_beyond_spz_are_told_to_move_or_to_shrink() {
        let far = check_placeable(&rig_at(DVec3::new(9e6, 0.0, 0.0), 10.0)).unwrap_err();
        let text = far.to_string();
        assert!(text.contains("reaches 9090010 units"), "{text}");
        assert!(
            text.contains("subtract its centre, [9000000.0, 0.0, 0.0]"),
            "{text}"
        );
        assert!(text.contains("1 units apart"), "{text}");
        let wide = check_placeable(&rig_at(DVec3::ZERO, 5e7)).unwrap_err();
        assert!(wide.to_string().contains("scale it down"), "{wide}");
    }
}
