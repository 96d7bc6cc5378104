//! The pipeline's error: each variant names the stage, and the file where there is one.

use std::path::{Path, PathBuf};

use plenoptic_render as views;
use splat_init as init;

use crate::resume::ResumeError;

/// How far the nearest camera must stand from the input's bounding sphere, in near planes.
pub(super) const NEAR_PLANE_CLEARANCE: f64 = 1.25;

/// Errors of the pipeline, each naming the stage and the file.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The input could not be read.
    #[error("cannot load the input: {0}")]
    Load(Box<plenoptic_io::Error>),
    /// The input lies where the run deletes or overwrites files before reading it.
    #[error(
        "the input {input} lies in {folder}, which a run in this output folder clears before it \
         reads its input: move the input out of it, or choose another --out"
    )]
    InputInOutput {
        /// The input, resolved.
        input: PathBuf,
        /// The folder the run clears (the output folder itself for its saved state).
        folder: PathBuf,
    },
    /// The output folder names something that is not a folder.
    #[error(
        "the output {0} is a file, not a folder: a run writes a folder (model/, report/, dataset/)"
    )]
    OutputNotFolder(PathBuf),
    /// Another process is writing the output folder.
    #[error(transparent)]
    Lock(#[from] crate::lock::LockError),
    /// The input is a 3DGS model, not a cloud or a mesh.
    #[error(
        "{0} is a 3DGS splat model (its vertices have f_dc_0, opacity, scale_0 and rot_0), not a \
         point cloud or a mesh: the pipeline makes splats from clouds and meshes; `transcode \
         render`, `eval`, `view` and `convert` take splat models"
    )]
    SplatModelInput(PathBuf),
    /// The input holds nothing to render.
    #[error("the input {0} holds no points or triangles")]
    EmptyInput(PathBuf),
    /// The input cannot make a model (no extent, too few points, no area, nothing visible).
    #[error("{0}")]
    Degenerate(#[from] plenoptic_render::degenerate::DegenerateError),
    /// The input is so small that the cameras framing it stand within the near plane of it.
    #[error(
        "the input is {:.3e} units across, so the cameras that frame it stand {gap:.3e} units \
         from it: splat renderers (this one and the viewers of 3DGS files) cull every splat \
         nearer than {near} units to the camera, so its near side, or all of it, would not be \
         drawn. Scale the input up (its units are the file's: a model in metres of an object a \
         few millimetres wide is this small) to at least {:.3} units across",
        2.0 * radius,
        2.0 * radius * NEAR_PLANE_CLEARANCE * f64::from(*near) / gap
    )]
    TooSmall {
        /// Radius of the input's bounding sphere.
        radius: f64,
        /// The nearest camera's distance from that sphere.
        gap: f64,
        /// The near plane.
        near: f32,
    },
    /// The input lies beyond what the SPZ model and the report's viewer can place.
    #[error(
        "the input's bounding sphere (centre {centre:?}, radius {radius:.6e}), with the 1 % \
         margin its splats may move into, reaches {largest:.0} units from the origin: the SPZ \
         model and the report's viewer store positions as 24-bit fixed point, at most \
         {limit:.0} units out, and 32-bit floats there are {ulp} units apart. {}",
        if *radius * 1.01 >= f64::from(*limit) {
            "The input itself is wider than that: scale it down (a model in millimetres of an \
             object metres wide is this large) before converting it".to_owned()
        } else {
            format!("Move the input near the origin (subtract its centre, {centre:?}) before converting it")
        }
    )]
    TooFar {
        /// The largest coordinate magnitude the model may reach: the bounding sphere's farthest
        /// coordinate with a 1 % margin.
        largest: f64,
        /// The input's bounding-sphere radius.
        radius: f64,
        /// SPZ's limit.
        limit: f32,
        /// The spacing of f32 values at `largest`.
        ulp: f32,
        /// The input's bounding-sphere centre.
        centre: [f64; 3],
    },
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

pub(super) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> PipelineError + '_ {
    move |source| PipelineError::Io {
        path: path.to_path_buf(),
        source,
    }
}
