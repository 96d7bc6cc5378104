//! Stage 1: the input, and its surface as initialisation and the distance metric use it.

use std::path::Path;

use plenoptic_io::Model;
use splat_init::{self as init, SurfacePoints};
use splat_train::init::SurfaceIndex;

use super::STAGES;
use super::error::PipelineError;
use crate::config::Config;
use crate::progress::{Event, Observer};
use crate::report::InputInfo;

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
    refuse_splat_model(input)?;
    let model = plenoptic_io::load(input)?;
    let info = input_info(input, &model);
    if info.points == 0 {
        return Err(PipelineError::EmptyInput(input.to_path_buf()));
    }
    plenoptic_render::degenerate::check_model(input, &model)?;
    if let Some(doubt) = plenoptic_render::degenerate::rig_doubt(&model) {
        observer(Event::Note(format!("{}: {doubt}", input.display())));
    }
    Ok(Loaded { model, info })
}

/// Refuses a 3DGS PLY as input: its vertices would be read as a grey point cloud (their colour
/// is in `f_dc_*`), and a model of a model is not what anyone asks for.
///
/// # Errors
/// [`PipelineError::SplatModelInput`] naming the file.
pub fn refuse_splat_model(input: &Path) -> Result<(), PipelineError> {
    let is_ply = input
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    if is_ply && plenoptic_io::ply::read_header(input).is_ok_and(|h| h.holds_gaussian_splats()) {
        return Err(PipelineError::SplatModelInput(input.to_path_buf()));
    }
    Ok(())
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
    pub(super) fn release_init(&mut self) {
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
