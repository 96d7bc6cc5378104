//! The training loop: one view per step, render, loss, backward, Adam, refinement.

mod finite;
mod levels;
mod timings;

pub use timings::{SizedSteps, Timings};

pub(crate) use finite::zero_non_finite_grads;
use finite::{all_finite, first_non_finite, splat_is_finite};
use levels::{Level, downsample_view};

use std::sync::Arc;
use std::time::{Duration, Instant};

use glam::Vec3;
use rand::{RngExt, SeedableRng};
use rand_pcg::Pcg64;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats, logit};

use crate::adam::{AdamStep, Rates};
use crate::config::{Background, TrainConfig};
use crate::error::Error;
use crate::loss::{Loss, alpha_l1};
use crate::metrics::psnr_from_mse;
use crate::schedule::{
    Pace, WarmupShare, camera_extent, exponential_lr, scale_steps, sh_degree_at,
};
use crate::state::ParamState;
use crate::strategy::{DensifyStrategy, InriaDensify, RefineContext, RefineReport};
use crate::update::{UpdatePlan, update, update_chained};
use crate::view::View;

/// Log-scale range a splat is clamped to, relative to the scene extent: from a millionth of the
/// extent (far below a pixel at any sensible distance) to ten extents (larger than the scene).
const MIN_SCALE_OF_EXTENT: f32 = 1e-6;
const MAX_SCALE_OF_EXTENT: f32 = 10.0;
/// Opacity logits are clamped to ±this: sigmoid(±20) is 1 − 2e-9 and 2e-9, saturated in f32.
const MAX_OPACITY_LOGIT: f32 = 20.0;
/// Opacity given to a splat whose parameters became non-finite and are reset (Inria's initial 0.1).
const RESET_OPACITY: f32 = 0.1;

/// Figures of one step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepStats {
    /// 1-based index of the step.
    pub iteration: u32,
    /// Index of the view trained on.
    pub view: usize,
    /// Total loss of the step (NaN if the render was not finite).
    pub loss: f64,
    /// PSNR of the step's render against its view, in dB.
    pub psnr: f64,
    /// Splats after the step.
    pub splats: usize,
    /// What the refinement strategy did at this step.
    pub refine: RefineReport,
    /// Whether the step trained on the coarse warm-up's reduced views.
    pub coarse: bool,
}

/// What one step trains on, decided before it renders.
struct StepPlan {
    /// Index of the view (within its level).
    view: usize,
    /// Whether the view is the warm-up's reduced one.
    coarse: bool,
    /// The view's camera at its level's size.
    cam: RenderCamera,
    /// The background and SH degree the step renders with.
    opts: RenderOptions,
}

/// The step's loss, before the backward pass.
struct StepScore {
    /// The weighted total, with the alpha term where it applies.
    total: f64,
    /// The render's mean squared error against the target (for the step's PSNR).
    mse: f64,
    /// Whether the alpha term applied (the view has a mask and its weight is positive).
    use_alpha: bool,
}

/// One line of the training history.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HistoryEntry {
    /// 1-based iteration.
    pub iteration: u32,
    /// Training time in seconds: the sum of step times and of the work counted between them
    /// ([`Trainer::count_time_between_steps`]), excluding progress callbacks and pauses.
    pub elapsed_s: f64,
    /// Loss of this step's view.
    pub loss: f64,
    /// PSNR of this step's view, in dB.
    pub psnr: f64,
    /// Splat count.
    pub splats: usize,
}

/// Counts of non-finite events handled.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NonFinite {
    /// Steps whose render or loss was not finite (skipped, no update).
    pub skipped_steps: u64,
    /// Splat gradients that were not finite (zeroed for that step).
    pub zeroed_gradients: u64,
    /// Splats whose parameters became non-finite and were reset (positions frozen).
    pub reset_splats: u64,
    /// Splats whose parameters became non-finite and were removed.
    pub removed_splats: u64,
}

/// Progress reported to a callback after each step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Progress {
    /// The step just done.
    pub step: StepStats,
    /// Steps the run's schedule spans: its iteration count, or under a time budget the steps
    /// that fit ([`Trainer::horizon`], re-estimated at every step).
    pub total: u32,
    /// Training time so far.
    pub elapsed: Duration,
}

/// Summary of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrainReport {
    /// Iterations completed.
    pub iterations: u32,
    /// Training time in seconds: the steps' and the work counted between them
    /// ([`Trainer::count_time_between_steps`]); what a time budget measures.
    pub elapsed_s: f64,
    /// Whether the time budget stopped the run early.
    pub stopped_by_budget: bool,
    /// Final splat count.
    pub splats: usize,
    /// (iteration, elapsed, loss, PSNR, splats) every `history_every` steps.
    pub history: Vec<HistoryEntry>,
    /// Non-finite events handled.
    pub non_finite: NonFinite,
    /// Refinement totals.
    pub refine: RefineReport,
    /// Time per phase in this session.
    pub timings: Timings,
}

/// The in-memory state a [`Trainer`] can return to ([`Trainer::snapshot`]).
#[derive(Debug, Clone)]
pub struct Snapshot {
    state: ParamState,
    run: RunState,
    strategy: Vec<f32>,
}

impl Snapshot {
    /// The splats as they were.
    #[must_use]
    pub fn splats(&self) -> &Splats {
        &self.state.splats
    }
}

/// Everything about a run that a checkpoint restores besides the parameters.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct RunState {
    pub iteration: u32,
    pub rng: Pcg64,
    pub order: Vec<u32>,
    pub cursor: usize,
    pub elapsed_s: f64,
    pub history: Vec<HistoryEntry>,
    pub non_finite: NonFinite,
    pub refine: RefineReport,
    /// Log-scale given to a reset splat: the median of the initial model's largest log-scales.
    pub reset_log_scale: f32,
    /// Speed of a time-budgeted run, from which its schedule's length is re-estimated.
    #[serde(default)]
    pub pace: Pace,
    /// Highest SH degree the schedule has reached: a re-estimated (longer) schedule never takes
    /// a band away again.
    #[serde(default)]
    pub sh_reached: u32,
    /// Whether a full-resolution step has run after the warm-up: a re-estimated (longer)
    /// schedule never takes the run back to the reduced views.
    #[serde(default)]
    pub warmup_over: bool,
}

/// A CPU trainer of splats on posed images.
#[derive(Debug)]
pub struct Trainer {
    pub(crate) config: TrainConfig,
    /// Full-resolution views, then the reduced copies of the warm-up, if any.
    levels: Vec<Level>,
    pub(crate) state: ParamState,
    pub(crate) strategy: Option<Box<dyn DensifyStrategy>>,
    pub(crate) run: RunState,
    /// The gradients where a strategy observes them (empty otherwise: see `chained_update`).
    grads: SplatGrads,
    /// Whether `grads` is all zero (the update leaves it so for the next backward pass).
    grads_zeroed: bool,
    /// Without a strategy, take each chunk's gradients from the rasteriser's chain straight into
    /// the update (`update_chained`) rather than through `grads`; false only in the tests that
    /// hold the two ways to the same model.
    chained_update: bool,
    rasterizer: Rasterizer,
    loss: Option<Loss>,
    /// This step's target: its view over its background, in f32 ([`View::target_into`]).
    target: Vec<f32>,
    d_alpha: Vec<f32>,
    extent: f32,
    max_sh_degree: u32,
    timings: Timings,
    /// Whether a step has run in this process at each view size (full, then the warm-up's
    /// reduced views): the first allocates the loss buffers and is left out of the [`Pace`].
    warm: [bool; 2],
}

impl Trainer {
    /// Prepares a run of `config` on `views` from `splats` with Inria's density control when
    /// `config.densify` is set.
    ///
    /// # Errors
    /// [`Error::Config`] for a bad configuration, [`Error::View`] for a view whose image or mask
    /// does not fit its camera, [`Error::Splats`] for inconsistent or non-finite splats.
    ///
    /// `views` may be shared (`Arc<Vec<View>>`): a paper-scale frame's 44 views at 1024² hold
    /// 0.37 GB, which the trainer reads in place and never copies (each step expands its view
    /// over the step's background into a buffer of its own).
    pub fn new(
        splats: Splats,
        views: impl Into<Arc<Vec<View>>>,
        config: TrainConfig,
    ) -> Result<Self, Error> {
        let strategy = config
            .densify
            .map(|d| Box::new(InriaDensify::new(d)) as Box<dyn DensifyStrategy>);
        Self::build(splats, views.into(), config, strategy)
    }

    /// Like [`Trainer::new`] with a caller-chosen refinement strategy in place of the one
    /// `config.densify` describes (that field is then ignored).
    ///
    /// # Errors
    /// As [`Trainer::new`].
    pub fn with_strategy(
        splats: Splats,
        views: impl Into<Arc<Vec<View>>>,
        config: TrainConfig,
        strategy: Box<dyn DensifyStrategy>,
    ) -> Result<Self, Error> {
        Self::build(splats, views.into(), config, Some(strategy))
    }

    fn build(
        splats: Splats,
        views: Arc<Vec<View>>,
        config: TrainConfig,
        mut strategy: Option<Box<dyn DensifyStrategy>>,
    ) -> Result<Self, Error> {
        config.validate()?;
        splats
            .validate()
            .map_err(|e| Error::Splats(e.to_string()))?;
        if splats.is_empty() {
            return Err(Error::Splats("no splats to train".into()));
        }
        if let Some(i) = first_non_finite(&splats) {
            return Err(Error::Splats(format!(
                "splat {i} has a non-finite parameter"
            )));
        }
        if views.is_empty() {
            return Err(Error::Config("no training views".into()));
        }
        for (index, v) in views.iter().enumerate() {
            v.check().map_err(|problem| Error::View {
                index,
                name: v.name.clone(),
                problem,
            })?;
            // Without coverage the image's pixels already hold its own background: a random
            // one cannot go behind them, and the model would learn to paint it opaque.
            if config.background == Background::Random && v.mask.is_none() {
                return Err(Error::View {
                    index,
                    name: v.name.clone(),
                    problem: "has no mask or alpha channel, so a random background cannot be \
                              composited under it; train on a fixed background or give it a mask"
                        .into(),
                });
            }
        }
        let centres: Vec<glam::DVec3> = views.iter().map(|v| v.camera.center()).collect();
        let extent = camera_extent(&centres) as f32;
        let max_sh_degree = config
            .sh_degree
            .unwrap_or(splats.sh_degree)
            .min(splats.sh_degree);
        let mut sorted: Vec<f32> = splats.log_scales.iter().map(|s| s.max_element()).collect();
        sorted.sort_by(f32::total_cmp);
        let reset_log_scale = sorted[sorted.len() / 2];
        if let Some(s) = strategy.as_mut() {
            s.import_state(&[], splats.len()).map_err(Error::Config)?;
        }
        let run = RunState {
            iteration: 0,
            rng: Pcg64::seed_from_u64(config.seed),
            order: Vec::new(),
            cursor: 0,
            elapsed_s: 0.0,
            history: Vec::new(),
            non_finite: NonFinite::default(),
            refine: RefineReport::default(),
            reset_log_scale,
            pace: Pace::default(),
            sh_reached: 0,
            warmup_over: false,
        };
        let initial_splats = splats.len() as u64;
        let mut t = Self {
            // Allocated by the first step that needs it (none does without a strategy).
            grads: SplatGrads::default(),
            grads_zeroed: false,
            chained_update: true,
            state: ParamState::new(splats),
            levels: vec![Level::new(views)?],
            config,
            strategy,
            run,
            rasterizer: Rasterizer::new(),
            loss: None,
            target: Vec::new(),
            d_alpha: Vec::new(),
            extent,
            max_sh_degree,
            timings: Timings {
                at_initial_size: SizedSteps {
                    splats: initial_splats,
                    ..SizedSteps::default()
                },
                ..Timings::default()
            },
            warm: [false; 2],
        };
        if let Some(w) = t.config.warmup {
            let coarse = t.levels[0]
                .views
                .iter()
                .map(|v| downsample_view(v, w.factor))
                .collect();
            t.levels.push(Level::new(Arc::new(coarse))?);
        }
        Ok(t)
    }

    /// The splats being trained.
    #[must_use]
    pub fn splats(&self) -> &Splats {
        &self.state.splats
    }

    /// The training views, as given.
    #[must_use]
    pub fn views(&self) -> &[View] {
        &self.levels[0].views
    }

    /// Steps done so far.
    #[must_use]
    pub fn iteration(&self) -> u32 {
        self.run.iteration
    }

    /// Scene extent used to scale position rates and thresholds.
    #[must_use]
    pub fn extent(&self) -> f32 {
        self.extent
    }

    /// The configuration of the run.
    #[must_use]
    pub fn config(&self) -> &TrainConfig {
        &self.config
    }

    /// Time per phase in this session.
    #[must_use]
    pub fn timings(&self) -> Timings {
        self.timings
    }

    /// History recorded so far.
    #[must_use]
    pub fn history(&self) -> &[HistoryEntry] {
        &self.run.history
    }

    /// Non-finite events handled so far.
    #[must_use]
    pub fn non_finite(&self) -> NonFinite {
        self.run.non_finite
    }

    /// Background of this step: the fixed colour, or a random one from the run's generator.
    fn background(&mut self) -> Vec3 {
        match self.config.background {
            Background::Fixed(c) => Vec3::from(c),
            Background::Random => {
                let r = &mut self.run.rng;
                Vec3::new(r.random(), r.random(), r.random())
            }
        }
    }

    /// Next view of a random permutation of all views, reshuffled when used up (as Inria's
    /// `viewpoint_stack`).
    fn next_view(&mut self) -> usize {
        if self.run.cursor >= self.run.order.len() {
            let n = self.levels[0].views.len();
            self.run.order = (0..n as u32).collect();
            for i in (1..n).rev() {
                let j = self.run.rng.random_range(0..=i);
                self.run.order.swap(i, j);
            }
            self.run.cursor = 0;
        }
        let v = self.run.order[self.run.cursor] as usize;
        self.run.cursor += 1;
        v
    }

    /// The steps the run's schedules span: the configured iteration count, or under a time
    /// budget the steps its [`Pace`] says will fit (at most the iteration count).
    #[must_use]
    pub fn horizon(&self) -> u32 {
        let c = &self.config;
        match c.time_budget {
            Some(b) => self.run.pace.horizon(
                c.iterations,
                self.run.iteration,
                self.run.elapsed_s,
                b.as_secs_f64(),
                self.warmup_share(),
            ),
            None => c.iterations,
        }
    }

    /// Whether what is left of the time budget holds `steps` more steps at the run's pace,
    /// beyond the configured iteration count if need be (always, without a budget): room for
    /// training a branch that will be thrown away on top of the run's own steps.
    #[must_use]
    pub fn time_left_for(&self, steps: u32) -> bool {
        let c = &self.config;
        c.time_budget.is_none_or(|b| {
            let fit = self.run.pace.horizon(
                u32::MAX,
                self.run.iteration,
                self.run.elapsed_s,
                b.as_secs_f64(),
                self.warmup_share(),
            );
            u64::from(fit) >= u64::from(self.run.iteration) + u64::from(steps)
        })
    }

    /// Whether the time budget, not the iteration count, ends the run's schedule: under a
    /// budget, its [`Pace`] expects fewer steps to fit than are configured. Where it does not,
    /// the run trains every configured step whatever its speed.
    #[must_use]
    pub fn budget_binds(&self) -> bool {
        self.horizon() < self.config.iterations
    }

    /// Starts the run's speed estimate from `pace` (step times timed on a probe before the run)
    /// instead of from its own first steps; the run's steps then take over as they come.
    pub fn start_pace(&mut self, pace: Pace) {
        self.run.pace = pace;
    }

    /// Counts `seconds` of wall time spent for the run between its steps (scoring held-out
    /// views, planning a budget round's merges, saving a checkpoint) on the run's clock, which
    /// is what a time budget measures: that work shortens the schedule's horizon as steps do, so
    /// the run ends inside its budget and not the budget plus everything done between steps.
    /// Negative or non-finite times are ignored.
    pub fn count_time_between_steps(&mut self, seconds: f64) {
        if seconds.is_finite() && seconds > 0.0 {
            self.run.elapsed_s += seconds;
        }
    }

    /// Ends the coarse warm-up now: the next steps train on the full views (a probe that has
    /// timed enough warm-up steps goes on to time full ones).
    pub fn end_warmup(&mut self) {
        self.run.warmup_over = true;
    }

    /// The warm-up's share of the schedule, while it is not over.
    fn warmup_share(&self) -> Option<WarmupShare> {
        let w = self.config.warmup.filter(|_| !self.run.warmup_over)?;
        Some(WarmupShare {
            share: w.share(self.config.iterations),
            factor: w.factor,
        })
    }

    /// Whether the next step trains on the warm-up's reduced views.
    fn next_step_is_coarse(&self) -> bool {
        let iteration = self.run.iteration + 1;
        self.levels.len() > 1
            && !self.run.warmup_over
            && self
                .config
                .warmup
                .is_some_and(|w| iteration <= self.scheduled(w.until))
    }

    /// `steps` of the configured schedule stretched over [`Trainer::horizon`].
    fn scheduled(&self, steps: u32) -> u32 {
        scale_steps(steps, self.horizon(), self.config.iterations)
    }

    /// The SH degree the schedule has reached at this step (never lower than at an earlier one).
    #[must_use]
    pub fn active_sh_degree(&self) -> u32 {
        let scheduled = sh_degree_at(
            self.run.iteration,
            self.scheduled(self.config.sh_degree_interval),
            self.max_sh_degree,
        );
        scheduled.max(self.run.sh_reached.min(self.max_sh_degree))
    }

    /// How this step renders: over `background`, at the SH degree the schedule has reached.
    fn render_options(&self, background: Vec3) -> RenderOptions {
        RenderOptions {
            background,
            active_sh_degree: self.active_sh_degree(),
            antialiased: self.config.antialiased,
            linear_colour: false,
        }
    }

    /// Runs one optimisation step.
    pub fn step(&mut self) -> StepStats {
        let iteration = self.run.iteration + 1;
        let plan = self.plan_step();
        let scored = self.forward_and_loss(&plan);
        let refine = if scored.total.is_finite() {
            self.backward_and_update(iteration, &plan, scored.use_alpha)
        } else {
            self.run.non_finite.skipped_steps += 1;
            RefineReport::default()
        };
        self.timings.steps += 1;
        self.run.iteration = iteration;
        let stats = StepStats {
            iteration,
            view: plan.view,
            loss: scored.total,
            psnr: psnr_from_mse(scored.mse),
            splats: self.state.len(),
            refine,
            coarse: plan.coarse,
        };
        self.record_history(&stats);
        stats
    }

    /// What the next step trains on: its view, its level (the warm-up's reduced views or the
    /// full ones), its camera and how it renders; the loss buffers are sized for that camera.
    fn plan_step(&mut self) -> StepPlan {
        let view = self.next_view();
        let background = self.background();
        let opts = self.render_options(background);
        self.run.sh_reached = opts.active_sh_degree;
        let coarse = self.next_step_is_coarse();
        self.run.warmup_over |= !coarse && self.config.warmup.is_some();
        let cam = self.levels[usize::from(coarse)].cameras[view];
        if self
            .loss
            .as_ref()
            .is_none_or(|l| l.width() != cam.width || l.height() != cam.height)
        {
            self.loss = Some(Loss::new(cam.width, cam.height));
        }
        StepPlan {
            view,
            coarse,
            cam,
            opts,
        }
    }

    /// Renders the step's view and scores it: the photometric loss (its pixel gradient left
    /// in the loss buffers) and, where the view has a mask, the alpha term (its gradient in
    /// `d_alpha`).
    fn forward_and_loss(&mut self, plan: &StepPlan) -> StepScore {
        let Some(loss) = self.loss.as_mut() else {
            unreachable!("plan_step sizes the loss buffers")
        };
        // Target: the photo over this step's background, expanded to f32 (views hold 16-bit
        // fractions; the pass is one read of the view and one write of the buffer).
        let view = &self.levels[usize::from(plan.coarse)].views[plan.view];
        view.target_into(&mut self.target, plan.opts.background.to_array());

        let t0 = Instant::now();
        let out = self
            .rasterizer
            .forward(&self.state.splats, &plan.cam, &plan.opts);
        let t1 = Instant::now();
        let value = loss.evaluate(
            &out.rgb,
            &self.target,
            self.config.photometric,
            self.config.ssim_weight,
        );
        let mut total = value.total;
        let use_alpha = self.config.alpha_loss_weight > 0.0 && view.mask.is_some();
        if let (true, Some(mask)) = (use_alpha, &view.mask) {
            self.d_alpha.resize(mask.len(), 0.0);
            let e = alpha_l1(
                &out.alpha,
                mask,
                self.config.alpha_loss_weight,
                &mut self.d_alpha,
            );
            total += f64::from(self.config.alpha_loss_weight) * e;
        }
        self.timings.forward += t1 - t0;
        self.timings.loss += t1.elapsed();
        StepScore {
            total,
            mse: value.mse,
            use_alpha,
        }
    }

    /// The step's backward pass, Adam update and refinement, from the pixel gradients
    /// [`Trainer::forward_and_loss`] left; returns what the refinement did.
    fn backward_and_update(
        &mut self,
        iteration: u32,
        plan: &StepPlan,
        use_alpha: bool,
    ) -> RefineReport {
        let Some(loss) = self.loss.as_ref() else {
            unreachable!("plan_step sizes the loss buffers")
        };
        let d_alpha = use_alpha.then_some(&self.d_alpha[..]);
        let t2 = Instant::now();
        let t3;
        let outcome = if self.strategy.is_none() && self.chained_update {
            // No strategy observes the gradients: the update takes them chunk by chunk from
            // the rasteriser's chain (the whole-model arrays are never written).
            self.rasterizer.backward_sums(
                &self.state.splats,
                &plan.cam,
                &plan.opts,
                loss.d_rgb(),
                d_alpha,
                None,
            );
            t3 = Instant::now();
            self.timings.backward += t3 - t2;
            let update_plan = self.update_plan(iteration, true);
            update_chained(&update_plan, &mut self.state, &self.rasterizer)
        } else {
            // The last update left the gradients zero; they need it again only if the model
            // has changed shape since (refinement, repair) or no update has run yet.
            if !(self.grads_zeroed && self.grads.fits(&self.state.splats)) {
                self.grads.reset(&self.state.splats);
            }
            self.grads_zeroed = false;
            self.rasterizer.backward(
                &self.state.splats,
                &plan.cam,
                &plan.opts,
                loss.d_rgb(),
                d_alpha,
                None,
                &mut self.grads,
            );
            t3 = Instant::now();
            self.timings.backward += t3 - t2;
            // With a strategy observing the gradients, the check runs before it; otherwise
            // the update does it chunk by chunk.
            let observed = self.strategy.is_some();
            if let Some(s) = self.strategy.as_mut() {
                self.run.non_finite.zeroed_gradients += zero_non_finite_grads(&mut self.grads);
                s.observe(iteration, &self.grads, self.rasterizer.radii());
            }
            let update_plan = self.update_plan(iteration, !observed);
            let outcome = update(&update_plan, &mut self.state, &mut self.grads);
            self.grads_zeroed = true;
            outcome
        };
        self.run.non_finite.zeroed_gradients += outcome.zeroed_gradients;
        if outcome.non_finite_parameters {
            self.sanitize();
        }
        let t4 = Instant::now();
        self.timings.adam += t4 - t3;
        let mut refine = RefineReport::default();
        if let Some(s) = self.strategy.as_mut() {
            refine = s.refine(
                iteration,
                RefineContext {
                    state: &mut self.state,
                    extent: self.extent,
                    rng: &mut self.run.rng,
                },
            );
            self.run.refine.add(&refine);
        }
        self.timings.refine += t4.elapsed();
        refine
    }

    /// Keeps every `history_every`-th step, and the last of the schedule, in the history.
    fn record_history(&mut self, stats: &StepStats) {
        if stats.iteration.is_multiple_of(self.config.history_every)
            || stats.iteration >= self.horizon()
        {
            // Elapsed time is filled in by `run`, which owns the clock.
            self.run.history.push(HistoryEntry {
                iteration: stats.iteration,
                elapsed_s: self.run.elapsed_s,
                loss: stats.loss,
                psnr: stats.psnr,
                splats: stats.splats,
            });
        }
    }

    /// This step's update: Adam's rates for every group that is not frozen, and the clamps.
    fn update_plan(&self, iteration: u32, check_gradients: bool) -> UpdatePlan {
        let c = &self.config;
        let f = c.frozen;
        let position_lr = {
            let max_steps = c.lr.position_max_steps.unwrap_or(self.horizon());
            exponential_lr(
                c.lr.position_init,
                c.lr.position_final,
                iteration - 1,
                max_steps,
            ) * self.extent
        };
        let k = self.state.splats.coeffs_per_splat();
        let sh = Rates::Split {
            stride: 3 * k,
            head: 3,
            head_rate: c.lr.sh_dc,
            tail_rate: c.lr.sh_dc / c.lr.sh_rest_divisor,
        };
        let unless = |frozen: bool, r: Rates| (!frozen).then_some(r);
        let (lo, hi) = self.log_scale_bounds();
        UpdatePlan {
            adam: AdamStep::new(&c.adam, u64::from(iteration)),
            rates: [
                unless(f.positions, Rates::All(position_lr)),
                unless(f.scales, Rates::All(c.lr.scale)),
                unless(f.rotations, Rates::All(c.lr.rotation)),
                unless(f.opacities, Rates::All(c.lr.opacity)),
                unless(f.colors, sh),
            ],
            check_gradients,
            log_scale_bounds: (!f.scales).then_some((lo, hi)),
            opacity_logit_bound: (!f.opacities).then_some(MAX_OPACITY_LOGIT),
        }
    }

    /// The log-scales' clamp: a fixed share of the scene's extent either way.
    fn log_scale_bounds(&self) -> (f32, f32) {
        (
            (MIN_SCALE_OF_EXTENT * self.extent).ln(),
            (MAX_SCALE_OF_EXTENT * self.extent).ln(),
        )
    }

    /// Resets or removes splats whose parameters are no longer finite, then clamps scales and
    /// opacities to sane ranges.
    fn sanitize(&mut self) {
        self.handle_non_finite();
        let (lo, hi) = self.log_scale_bounds();
        let s = &mut self.state.splats;
        if !self.config.frozen.scales {
            s.log_scales
                .par_iter_mut()
                .for_each(|ls| *ls = ls.clamp(Vec3::splat(lo), Vec3::splat(hi)));
        }
        if !self.config.frozen.opacities {
            s.opacity_logits
                .par_iter_mut()
                .for_each(|o| *o = o.clamp(-MAX_OPACITY_LOGIT, MAX_OPACITY_LOGIT));
        }
    }

    /// Resets (positions frozen) or removes splats with a non-finite parameter. Runs before the
    /// clamps, which would turn NaN into a bound and hide it.
    fn handle_non_finite(&mut self) {
        let s = &self.state.splats;
        if all_finite(&[
            bytemuck::cast_slice(&s.means),
            bytemuck::cast_slice(&s.log_scales),
            s.rotations.as_flattened(),
            &s.opacity_logits,
            s.sh.as_flattened(),
        ]) {
            return;
        }
        let bad: Vec<usize> = (0..s.len())
            .into_par_iter()
            .filter(|&i| !splat_is_finite(s, i))
            .collect();
        if bad.is_empty() {
            return;
        }
        if self.config.frozen.positions {
            for &i in &bad {
                self.reset_splat(i);
            }
            self.run.non_finite.reset_splats += bad.len() as u64;
        } else {
            let mut keep = vec![true; s.len()];
            for &i in &bad {
                keep[i] = false;
            }
            if bad.len() == keep.len() {
                // Removing every splat would leave nothing to train: reset the first instead.
                keep[0] = true;
            }
            self.state.retain(&keep);
            if let Some(s) = self.strategy.as_mut() {
                s.retain(&keep);
            }
            self.run.non_finite.removed_splats += bad.len() as u64;
            if let Some(i) = first_non_finite(&self.state.splats) {
                self.state.splats.means[i] = Vec3::ZERO;
                self.reset_splat(i);
            }
        }
    }

    /// Gives splat `i` safe attributes (keeping its mean) and fresh moments.
    fn reset_splat(&mut self, i: usize) {
        let s = &mut self.state.splats;
        let k = s.coeffs_per_splat();
        s.log_scales[i] = Vec3::splat(self.run.reset_log_scale);
        s.rotations[i] = [1.0, 0.0, 0.0, 0.0];
        s.opacity_logits[i] = logit(RESET_OPACITY);
        s.sh[i * k..(i + 1) * k].fill([0.0; 3]);
        self.state.reset_moments(i);
    }

    /// Trains until the configured iteration count or time budget, calling `on_progress` after
    /// every step.
    pub fn run(&mut self, on_progress: impl FnMut(&Progress)) -> TrainReport {
        self.run_until(self.config.iterations, on_progress)
    }

    /// Like [`Trainer::run`] but pauses once `until` steps are done (to evaluate or checkpoint
    /// outside the timed steps); calling it again continues the same run.
    pub fn run_until(&mut self, until: u32, mut on_progress: impl FnMut(&Progress)) -> TrainReport {
        let mut stopped_by_budget = false;
        let until = until.min(self.config.iterations);
        while self.run.iteration < until {
            // Out of time, or at the end of the schedule the time budget allows.
            if let Some(b) = self.config.time_budget
                && (self.run.elapsed_s >= b.as_secs_f64() || self.run.iteration >= self.horizon())
            {
                stopped_by_budget = true;
                break;
            }
            // Only the step is timed: the callback (progress display, evaluation) is not training.
            let at_initial_size =
                self.state.splats.len() as u64 == self.timings.at_initial_size.splats;
            let start = Instant::now();
            let s = self.step();
            let wall = start.elapsed();
            let took = wall.as_secs_f64();
            self.run.elapsed_s += took;
            self.timings.step_wall += wall;
            self.timings.walled_steps += 1;
            if s.coarse {
                self.timings.coarse_wall += wall;
                self.timings.coarse_steps += 1;
            }
            if at_initial_size {
                self.timings.at_initial_size.add(wall, s.coarse);
            }
            let warm = &mut self.warm[usize::from(s.coarse)];
            if *warm {
                self.run.pace.observe(took, s.coarse);
            }
            *warm = true;
            let elapsed = self.run.elapsed_s;
            if let Some(h) = self.run.history.last_mut()
                && h.iteration == s.iteration
            {
                h.elapsed_s = elapsed;
            }
            on_progress(&Progress {
                step: s,
                total: self.horizon(),
                elapsed: Duration::from_secs_f64(elapsed),
            });
        }
        self.report(stopped_by_budget)
    }

    /// The summary of the run so far.
    #[must_use]
    pub fn report(&self, stopped_by_budget: bool) -> TrainReport {
        TrainReport {
            iterations: self.run.iteration,
            elapsed_s: self.run.elapsed_s,
            stopped_by_budget,
            splats: self.state.len(),
            history: self.run.history.clone(),
            non_finite: self.run.non_finite,
            refine: self.run.refine,
            timings: self.timings,
        }
    }

    /// The whole training state in memory (parameters, moments, run state, strategy
    /// statistics), to come back to with [`Trainer::restore_snapshot`]: a budget search tries a
    /// pruned branch and a kept branch from the same point.
    #[must_use]
    pub fn snapshot(&self) -> Snapshot {
        Snapshot {
            state: self.state.clone(),
            run: self.run.clone(),
            strategy: self
                .strategy
                .as_ref()
                .map(|s| s.export_state())
                .unwrap_or_default(),
        }
    }

    /// Returns to `snapshot`, keeping the training time spent since it (the time of a branch
    /// that is thrown away still counts against the time budget: the budget is wall time).
    ///
    /// # Errors
    /// A message when the snapshot's strategy statistics do not fit this trainer's strategy
    /// (a snapshot of another trainer).
    pub fn restore_snapshot(&mut self, snapshot: Snapshot) -> Result<(), String> {
        self.swap_snapshot(snapshot).map(drop)
    }

    /// Returns to `snapshot` as [`Trainer::restore_snapshot`] does and hands back the state it
    /// leaves as a snapshot, moved rather than copied: a caller that keeps both branches holds
    /// two copies of the model and its moments instead of three (at 250k splats of degree 3,
    /// 177 MB less at the moment of the swap).
    ///
    /// # Errors
    /// A message when the snapshot's strategy statistics do not fit this trainer's strategy;
    /// the trainer is then unchanged.
    pub fn swap_snapshot(&mut self, snapshot: Snapshot) -> Result<Snapshot, String> {
        let strategy = self
            .strategy
            .as_ref()
            .map(|s| s.export_state())
            .unwrap_or_default();
        let run = self.run.clone();
        let state = std::mem::take(&mut self.state);
        let spent = run.elapsed_s;
        if let Err(e) = self.restore(snapshot.state, snapshot.run, &snapshot.strategy) {
            self.state = state;
            return Err(e);
        }
        self.run.elapsed_s = self.run.elapsed_s.max(spent);
        Ok(Snapshot {
            state,
            run,
            strategy,
        })
    }

    /// The splats and their moments, to edit in place between steps.
    pub(crate) fn state_mut(&mut self) -> &mut ParamState {
        &mut self.state
    }

    /// Removes the splats whose `keep` flag is false, with their moments and strategy
    /// statistics; the removals count as pruned in the run's refinement totals.
    ///
    /// # Errors
    /// [`Error::Splats`] when `keep` does not have one flag per splat or would keep none.
    pub fn prune(&mut self, keep: &[bool]) -> Result<usize, Error> {
        if keep.len() != self.state.len() {
            return Err(Error::Splats(format!(
                "{} keep flags for {} splats",
                keep.len(),
                self.state.len()
            )));
        }
        let removed = keep.iter().filter(|&&k| !k).count();
        if removed == keep.len() {
            return Err(Error::Splats("pruning would remove every splat".into()));
        }
        self.state.retain(keep);
        if let Some(s) = self.strategy.as_mut() {
            s.retain(keep);
        }
        // Reshaped by the next step that needs it.
        self.grads = SplatGrads::default();
        self.run.refine.pruned += removed;
        Ok(removed)
    }

    /// Each splat's summed blending weight over the full-resolution training views, rendered on
    /// black at the current SH degree ([`Rasterizer::accumulate_contributions`]): how much of
    /// the training images it carries.
    #[must_use]
    pub fn contributions(&mut self) -> Vec<f64> {
        let opts = self.render_options(Vec3::ZERO);
        let mut sums = vec![0.0; self.state.len()];
        for cam in &self.levels[0].cameras {
            if let Err(e) =
                self.rasterizer
                    .accumulate_contributions(&self.state.splats, cam, &opts, &mut sums)
            {
                unreachable!("the trainer's splats and views were checked: {e}");
            }
        }
        sums
    }

    /// Replaces the parameters, optimiser and run state (used when resuming).
    pub(crate) fn restore(
        &mut self,
        state: ParamState,
        run: RunState,
        strategy_state: &[f32],
    ) -> Result<(), String> {
        match self.strategy.as_mut() {
            Some(s) => s.import_state(strategy_state, state.len())?,
            None if !strategy_state.is_empty() => {
                return Err(
                    "the checkpoint holds densification statistics but this run has none".into(),
                );
            }
            None => {}
        }
        self.grads = SplatGrads::default();
        self.state = state;
        self.run = run;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::to_unorm16;
    use camera_model::{Camera, Intrinsics, Pose};
    use glam::DVec3;

    /// Taking the gradients chunk by chunk from the rasteriser's chain into the update
    /// (`update_chained`) trains the same model, bit for bit, parameters and moments, as the
    /// gradients written whole and then applied (`update`): with every SH band, an alpha loss
    /// and masked views.
    #[test]
    fn the_chained_update_trains_the_model_the_whole_gradients_train() {
        let mut state = 7_u64;
        let mut r = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut splats = Splats::new(3);
        for _ in 0..1_500 {
            let sh: Vec<[f32; 3]> = (0..16).map(|_| [r() - 0.5, r() - 0.5, r() - 0.5]).collect();
            splats.push(
                Vec3::new(r() - 0.5, r() - 0.5, r() - 0.5),
                Vec3::splat(-3.5) + Vec3::new(r(), r(), r()),
                [r() - 0.5, r() - 0.5, r() - 0.5, r() - 0.5],
                2.0 * r() - 1.0,
                &sh,
            );
        }
        let views: Vec<View> = (0..4)
            .map(|i| {
                let a = f64::from(i) * 1.3;
                let eye = DVec3::new(3.0 * a.cos(), 0.7, 3.0 * a.sin());
                let camera = Camera::new(
                    Intrinsics::from_fov_y(48, 40, 45.0),
                    Pose::look_at(eye, DVec3::ZERO, DVec3::Y),
                );
                let n = 48 * 40;
                View {
                    name: format!("v{i}"),
                    camera,
                    image: (0..3 * n)
                        .map(|j| to_unorm16(((j * 7 + i) % 11) as f32 / 10.0))
                        .collect(),
                    mask: Some(
                        (0..n)
                            .map(|j| if j % 5 != 0 { u16::MAX } else { 0 })
                            .collect(),
                    ),
                }
            })
            .collect();
        let config = TrainConfig {
            iterations: 40,
            densify: None,
            sh_degree_interval: 10,
            alpha_loss_weight: 0.1,
            ..TrainConfig::default()
        };
        let train = |chained: bool| {
            let mut t = Trainer::new(splats.clone(), views.clone(), config.clone()).unwrap();
            t.chained_update = chained;
            for _ in 0..config.iterations {
                t.step();
            }
            (t.state.clone(), t.run.non_finite.zeroed_gradients)
        };
        let (chained, zeroed_chained) = train(true);
        let (whole, zeroed_whole) = train(false);
        assert!(
            chained.splats.sh != splats.sh,
            "training must move the model"
        );
        assert_eq!(zeroed_chained, zeroed_whole);
        let bits = |s: &ParamState| -> Vec<u32> {
            let p = &s.splats;
            let m = &s.moments;
            bytemuck::cast_slice::<Vec3, f32>(&p.means)
                .iter()
                .chain(bytemuck::cast_slice::<Vec3, f32>(&p.log_scales))
                .chain(p.rotations.as_flattened())
                .chain(&p.opacity_logits)
                .chain(p.sh.as_flattened())
                .chain(
                    [
                        &m.means,
                        &m.log_scales,
                        &m.rotations,
                        &m.opacity_logits,
                        &m.sh,
                    ]
                    .iter()
                    .flat_map(|g| g.m.iter().chain(&g.v)),
                )
                .map(|x| x.to_bits())
                .collect()
        };
        assert_eq!(bits(&chained), bits(&whole));
    }
}
