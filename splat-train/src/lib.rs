//! CPU trainer for 3D Gaussian splats: L1 + D-SSIM, Adam, schedules, densification, checkpoints.
//!
//! - [`Trainer`]: the loop (one view per step: render, [`loss`], backward, [`adam`], refine).
//! - [`TrainConfig`]: Inria's defaults; [`schedule`]: learning-rate, SH-degree and
//!   densification schedules, time-budgeted run lengths, pause points.
//! - [`strategy`]: the replaceable densification policy ([`InriaDensify`]).
//! - [`dataset`]: reading a dataset folder (COLMAP cameras, images, masks) as [`View`]s;
//!   [`View::target_into`]: colour over a background, the one place it is written.
//! - [`ssim`], [`metrics`], [`eval`]: image quality and held-out evaluation; [`init`]: kNN scale
//!   initialisation and the nearest-neighbour index.
//! - [`checkpoint`]: save and resume a run exactly; [`budget`]: the automatic splat budget
//!   (contribution scores, pruning rounds judged on held-out views); [`sh_bands`]: the SH
//!   degree and per-splat bands a model's held-out score needs.
//! - [`Error`], [`DatasetError`]: what a run or a dataset refuses.
//!
//! ```
//! use camera_model::{Camera, Intrinsics, Pose};
//! use glam::{DVec3, Vec3};
//! use splat_core::Splats;
//! use splat_train::{TrainConfig, Trainer, View};
//!
//! // Fit one splat to a uniformly grey 16 × 16 image for a few steps.
//! let camera = Camera::new(
//!     Intrinsics::from_fov_y(16, 16, 40.0),
//!     Pose::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y),
//! );
//! let view = View::from_straight("grey".into(), camera, &[0.5; 3 * 16 * 16], None)?;
//! let splats = Splats::from_points(&[Vec3::ZERO], &[[0.2; 3]], &[Vec3::splat(0.5)], None, 0.5, 0)?;
//! let config = TrainConfig { iterations: 5, ..TrainConfig::default() };
//! let mut trainer = Trainer::new(splats, vec![view], config)?;
//! let first = trainer.step();
//! assert_eq!(first.iteration, 1);
//! assert!(first.loss.is_finite());
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod adam;
pub mod budget;
pub mod checkpoint;
pub mod config;
pub mod dataset;
pub mod error;
pub mod eval;
pub mod init;
pub mod loss;
pub mod metrics;
pub mod schedule;
pub mod sh_bands;
pub mod ssim;
pub mod state;
pub mod strategy;
mod trainer;
mod update;
mod view;

pub use budget::{
    BudgetConfig, BudgetPlan, BudgetRound, BudgetSearch, GENTLER_COST_SHARE, HeldoutPsnr,
    RoundError, RoundSeconds, SCORE_POINTS, SkippedRound,
};
pub use config::{
    Background, DensifyConfig, Frozen, LearningRates, Photometric, TrainConfig, Warmup,
};
pub use dataset::{Dataset, DatasetError, read_dataset};
pub use error::Error;
pub use eval::{
    ErrorBreakdown, EvalError, EvalOptions, Evaluation, Metrics, RegionError, RenderedView,
    SurfaceDistance, ViewMetrics, ViewScore, evaluate, evaluate_views, evaluate_with,
    psnr_black_and_white, psnr_both,
};
pub use strategy::{DensifyStrategy, InriaDensify, RefineContext, RefineReport};
pub use trainer::{
    HistoryEntry, NonFinite, Progress, SizedSteps, Snapshot, StepStats, Timings, TrainReport,
    Trainer,
};
pub use view::{View, composite_into, from_unorm16, over, scale_intrinsics, to_unorm16};
