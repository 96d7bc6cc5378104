//! The transcoder: turn plenoptic point clouds and meshes into 3D Gaussian Splatting models.
//!
//! This crate composes the workspace's crates into the pipeline (load, rig, reference views,
//! COLMAP dataset, initialisation, training, export, evaluation, report) and holds the policy
//! and defaults; the `transcode` binary is its command-line face.

pub mod config;
pub mod pipeline;
pub mod progress;
pub mod report;
pub mod resume;
