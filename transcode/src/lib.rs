//! The transcoder: turn plenoptic point clouds and meshes into 3D Gaussian Splatting models.
//!
//! This crate composes the workspace's crates into the pipeline (load, rig, reference views,
//! COLMAP dataset, initialisation, training, export, evaluation, report) and holds the policy
//! and defaults; the `transcode` binary is its command-line face. The stages' work lives in
//! the other crates (`plenoptic-render`, `splat-init`, `splat-train`, …; `docs/architecture.md`).
//!
//! - [`mod@bench`]: the speed figures of a frame, measured in one run (`transcode bench`).
//! - [`config`]: every setting ([`config::Config`]), with defaults, TOML files and validation.
//! - [`lock`]: one writer at a time in an output folder.
//! - [`pipeline`]: the stages, from an input file to a model, a dataset and a report.
//! - [`plot`]: the reports' inline SVG line plots.
//! - [`progress`]: the events a run reports to its caller (the library never prints).
//! - [`report`]: the run report (JSON and HTML).
//! - [`resume`]: the run state that lets a killed run continue.
//! - [`sequence`]: many frames, warm-started, resumable, sharded for cluster engines.
//! - [`viewer`]: the interactive viewer written beside the report.
//!
//! ```
//! use transcode::config::Config;
//!
//! let mut cfg = Config::default();
//! cfg.training.iterations = 2_000;
//! // Settings round-trip through TOML, as `transcode config --defaults` writes them.
//! let text = cfg.to_toml();
//! assert_eq!(Config::from_toml(&text)?, cfg);
//! cfg.validate()?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod bench;
pub mod config;
pub mod lock;
pub mod pipeline;
pub mod plot;
pub mod progress;
pub mod report;
pub mod resume;
pub mod sequence;
pub mod viewer;
