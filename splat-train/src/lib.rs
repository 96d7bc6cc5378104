//! CPU trainer for 3D Gaussian splats: L1 + D-SSIM, Adam, schedules, densification, checkpoints.
//!
//! - [`Trainer`]: the loop (one view per step: render, [`loss`], backward, [`adam`], refine).
//! - [`TrainConfig`]: Inria's defaults; [`schedule`]: learning-rate and SH-degree schedules.
//! - [`strategy`]: the replaceable densification policy ([`InriaDensify`]).
//! - [`ssim`], [`metrics`], [`evaluate`]: image quality; [`init`]: kNN scale initialisation.
//! - [`checkpoint`]: save and resume a run exactly.

pub mod adam;
pub mod checkpoint;
pub mod config;
pub mod error;
mod eval;
pub mod init;
pub mod loss;
pub mod metrics;
pub mod schedule;
pub mod ssim;
pub mod state;
pub mod strategy;
mod trainer;
mod view;

pub use config::{Background, DensifyConfig, Frozen, LearningRates, TrainConfig, Warmup};
pub use error::Error;
pub use eval::{Evaluation, ViewScore, evaluate, evaluate_with};
pub use strategy::{DensifyStrategy, InriaDensify, RefineContext, RefineReport};
pub use trainer::{HistoryEntry, NonFinite, Progress, StepStats, Timings, TrainReport, Trainer};
pub use view::{View, load_view, scale_intrinsics};
