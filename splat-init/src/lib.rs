//! Splat initialisation: from the input's surface (with a closed-form SH fit) or from sparse points.
//!
//! Surface init puts one flat splat at each chosen surface point (all input points, mesh samples,
//! or a subset of K by voxel-grid or farthest-point sampling), turned into the surface plane by its
//! normal (from the file or by k-nearest-neighbour PCA), with its in-plane scale from the local point
//! spacing and a thin normal axis. Its SH coefficients are the ridge-regularised least-squares fit
//! of the plenoptic colour ([`plenoptic_io::view_color::interpolate`]) over many view directions,
//! in `splat_core::sh`'s basis: because the directions are the same for every point, the fit is one
//! precomputed matrix applied to each point's samples.
//!
//! Sparse init follows the usual 3DGS pipeline: COLMAP points3D or random points in the bounds,
//! isotropic scales from the 3 nearest neighbours, low opacity, then densification while training.
//!
//! - [`InitConfig`] and its enums: the settings (serde, as in the transcoder's `[init]` table).
//! - [`SurfacePoints`]: the input's points, normals and colours (cloud points or mesh samples).
//! - [`sampling`]: which K points carry splats; [`neighbours`]: k-d tree, spacing, PCA normals.
//! - [`sh_fit`]: the SH fit and the automatic SH degree.
//! - [`surface_init`], [`sparse_init`], [`initialise`]: the splats (from `initialise`, laid out
//!   [`in_morton_order`] of their centres) and an [`InitSummary`].
//! - [`warm`]: a sequence's warm start, the previous frame's training corrections carried over.
//!
//! ```
//! use glam::Vec3;
//! use plenoptic_io::PlenopticCloud;
//! use splat_init::{InitConfig, SurfacePoints, initialise};
//!
//! // A 10 × 10 grid of grey points on the z = 0 plane.
//! let mut cloud = PlenopticCloud::default();
//! for i in 0..100 {
//!     cloud.positions.push(Vec3::new((i % 10) as f32, (i / 10) as f32, 0.0));
//!     cloud.colors.push([0.5; 3]);
//! }
//! let points = SurfacePoints::from_cloud(&cloud);
//! let (splats, summary) = initialise(&points, &InitConfig::default(), 10, 0)?;
//! assert_eq!(splats.len(), summary.splats);
//! assert!(splats.len() > 0 && splats.len() <= 100);
//! # Ok::<(), splat_init::InitError>(())
//! ```

use std::path::PathBuf;

use serde::Serialize;
use splat_core::Splats;

pub mod colour_solve;
pub mod config;
pub mod neighbours;
pub mod points;
pub mod sampling;
pub mod sh_fit;
mod sparse;
mod surface;
#[cfg(test)]
mod tests;
pub mod warm;

pub use colour_solve::{SolveError, SolveOptions, SolveReport, solve_colours};
pub use config::{InitConfig, InitMode, MeshPoints, Sampling, ShDegree};
pub use neighbours::{pca_normals, point_spacing};
pub use points::{SurfacePoints, sample_mesh};
pub use sampling::{bounds, choose_points, farthest_point_sample, voxel_subsample};
pub use sh_fit::{ShFit, auto_degree, decide_sh_degree, sh_fit_errors};
pub use sparse::{colmap_points, random_points, sparse_init, sparse_splats};
pub use surface::surface_init;
pub use warm::{CarriedTraining, RigidMotion, WarmStartError, carry_training, rigid_motion};

/// Errors of initialisation.
#[derive(Debug, thiserror::Error)]
pub enum InitError {
    /// A setting is out of its range ([`InitConfig::validate`]).
    #[error("invalid init setting: `{key}` {problem}")]
    InvalidConfig {
        /// The offending key (`init.…`).
        key: String,
        /// What is wrong with it.
        problem: String,
    },
    /// The input has no points to put splats on.
    #[error("the input has no points to initialise splats from")]
    Empty,
    /// The COLMAP model given for sparse init could not be read.
    #[error("sparse init from COLMAP points3D: {source}")]
    Colmap {
        /// The model folder.
        path: PathBuf,
        /// The cause (boxed: COLMAP errors are large).
        source: Box<colmap_io::Error>,
    },
    /// The COLMAP model has no 3D points.
    #[error("the COLMAP model in {0} has no 3D points")]
    NoColmapPoints(PathBuf),
    /// splat-core refused the splats (a bug if it happens: the arrays are built together).
    #[error("building splats: {0}")]
    Splats(#[from] splat_core::Error),
}

/// What initialisation did, for the report.
#[derive(Debug, Clone, Serialize, serde::Deserialize)]
pub struct InitSummary {
    /// Surface or sparse.
    pub mode: InitMode,
    /// Number of splats made.
    pub splats: usize,
    /// SH degree of the model.
    pub sh_degree: u32,
    /// RMS error (colour units) of the SH fit at degrees 0..=3 on a sample of points, when fitted.
    pub sh_fit_rms: Option<[f64; 4]>,
    /// Median distance between neighbouring input points (file units).
    pub point_spacing: f32,
    /// Where the normals came from: "file", "pca" or "none".
    pub normals: String,
    /// Where sparse points came from: "surface", "colmap" or "random".
    pub source: String,
    /// A sequence's warm start: the previous frame's model whose appearance the splats took.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub warm_start: Option<PathBuf>,
}

/// Initialises splats from the input's surface points as `cfg.mode` says, laid out by
/// [`in_morton_order`].
pub fn initialise(
    input: &SurfacePoints,
    cfg: &InitConfig,
    exponent: i32,
    seed: u64,
) -> Result<(Splats, InitSummary), InitError> {
    cfg.validate()
        .map_err(|(key, problem)| InitError::InvalidConfig { key, problem })?;
    let (splats, summary) = match cfg.mode {
        InitMode::Surface => surface_init(&choose_points(input, cfg), cfg, exponent),
        InitMode::Sparse => sparse_init(input, cfg, exponent, seed),
    }?;
    Ok((in_morton_order(&splats), summary))
}

/// `splats` laid out in Morton order of their centres ([`plenoptic_io::morton_order`]), the
/// layout initial splats are handed to training in.
///
/// The layout is for the rasteriser: a tile's list holds splats near each other on screen, in
/// depth order, so with the input's order (a file's, or a sampler's) consecutive entries read
/// projection records scattered over the whole buffer, each a cache miss; in Morton order they
/// come from a few runs of neighbouring records. On a 250k-splat model at 1024², 2 threads, the
/// compositing and the backward pass's tile walks took about a fifth less time this way
/// (docs/benchmarks/splat-core.md, §Session 22).
#[must_use]
pub fn in_morton_order(splats: &Splats) -> Splats {
    splats.gather(&plenoptic_io::morton_order(&splats.means))
}
