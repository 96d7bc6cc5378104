//! Initialisation settings: the transcoder's `[init]` table.

use std::fmt;
use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// The fewest splats `init.splats` may ask for: each splat's initial size comes from its 3
/// nearest neighbours.
pub const MIN_SPLATS: usize = 4;

/// Where initial splats come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum InitMode {
    /// On the input's surface, SH fitted to its colours, positions frozen.
    Surface,
    /// From sparse points (COLMAP points3D or random in the bounds), with densification.
    Sparse,
}

impl fmt::Display for InitMode {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Surface => "surface",
            Self::Sparse => "sparse",
        })
    }
}

/// How a subset of K points is chosen from the input.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sampling {
    /// One point per cell of a voxel grid sized to give about K cells.
    Voxel,
    /// Farthest-point sampling (O(N·K): for moderate inputs).
    Farthest,
}

/// Which points of a mesh carry the surface splats.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MeshPoints {
    /// The vertices.
    Vertices,
    /// The face centres.
    Faces,
    /// Area-uniform samples on the faces (`init.splats` of them, or `init.mesh_samples`).
    Samples,
}

/// SH degree: fixed, or chosen from the fit errors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ShDegree {
    /// A fixed degree 0..=3.
    Fixed(u32),
    /// The lowest degree whose fit error is within `init.sh_tolerance` of degree 3's.
    Auto,
}

impl fmt::Display for ShDegree {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Fixed(d) => write!(f, "{d}"),
            Self::Auto => f.write_str("auto"),
        }
    }
}

impl std::str::FromStr for ShDegree {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(Self::Auto);
        }
        match s.parse::<u32>() {
            Ok(d) if d <= 3 => Ok(Self::Fixed(d)),
            _ => Err(format!("SH degree must be 0, 1, 2, 3 or auto, got {s:?}")),
        }
    }
}

impl Serialize for ShDegree {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Fixed(d) => s.serialize_u32(*d),
            Self::Auto => s.serialize_str("auto"),
        }
    }
}

impl<'de> Deserialize<'de> for ShDegree {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Int(i64),
            Str(String),
        }
        match Raw::deserialize(d)? {
            Raw::Int(i) if (0..=3).contains(&i) => Ok(Self::Fixed(i as u32)),
            Raw::Int(i) => Err(serde::de::Error::custom(format!(
                "SH degree must be 0..=3 or \"auto\", got {i}"
            ))),
            Raw::Str(s) => s.parse().map_err(serde::de::Error::custom),
        }
    }
}

/// Initialisation settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InitConfig {
    /// Surface or sparse initialisation.
    pub mode: InitMode,
    /// Number of splats K (a subset of the input points); all points when absent.
    pub splats: Option<usize>,
    /// How the subset of K points is chosen.
    pub sampling: Sampling,
    /// Which mesh points carry splats.
    pub mesh_points: MeshPoints,
    /// Surface samples on a mesh when `splats` is absent and `mesh_points` is `samples`.
    pub mesh_samples: usize,
    /// SH degree of the model.
    pub sh_degree: ShDegree,
    /// For `sh_degree = "auto"`: accepted excess RMS fit error over degree 3 (colour units).
    pub sh_tolerance: f64,
    /// View directions on the sphere used by the SH fit.
    pub fit_directions: usize,
    /// Ridge weight on the non-constant SH coefficients (per mean squared residual).
    pub ridge: f64,
    /// Neighbours for normals by PCA when the input has none.
    pub normal_neighbours: usize,
    /// In-plane σ of a surface splat where the input's colour is even, as a share of its local
    /// spacing (Inria's √(mean of the 3 nearest squared distances)): Inria's own size, 1.0.
    pub scale_ratio: f32,
    /// In-plane σ, as a share of the local spacing, of a surface splat whose colour differs
    /// from one of its 8 nearest neighbours' by `edge_contrast` or more (a texture edge); in
    /// between the share goes linearly from `scale_ratio` to this. Discs of Inria's size blur
    /// a texture that the points resolve: on the demo this starts training 6 dB higher and
    /// ends 1,200 steps 0.5 / 0.3 dB higher; on the thin-legged spider, which wants coverage
    /// more than sharpness, it costs 0.1–0.3 dB (docs/benchmarks/fidelity.md §7).
    pub edge_scale_ratio: f32,
    /// The largest per-channel colour difference (0–1) to a neighbour at which a splat takes
    /// `edge_scale_ratio` in full.
    pub edge_contrast: f32,
    /// Thickness of a surface splat along its normal, as a share of its in-plane scale.
    pub thin_ratio: f32,
    /// Initial opacity of surface splats.
    pub surface_opacity: f32,
    /// Initial opacity of sparse splats (Inria: 0.1).
    pub sparse_opacity: f32,
    /// Sparse init: a COLMAP model folder whose points3D seed the splats.
    pub points3d: Option<PathBuf>,
    /// Sparse init without `points3d`: random points in the input's bounding box.
    pub random_points: usize,
    /// Let surface splats move (the default). Frozen at the input's points they score 0.5 dB
    /// lower on the demo and 1.6 / 2.8 dB (black / white) lower on a paper-scale frame, and
    /// the splat budget's merged splats cannot move to where their members' images need them
    /// (docs/BENCHMARKS.md).
    pub free_positions: bool,
    /// Densify surface splats too (sparse init always densifies).
    pub densify_surface: bool,
    /// Surface init: conjugate-gradient iterations of the least-squares colour solve against
    /// the training views after the per-camera SH fit (`colour_solve`); 0 (the default) keeps
    /// the fit. The solve starts training higher (demo: +2.5 dB held-out on black at step 0)
    /// but training from the fit catches up within a few hundred steps, and each iteration
    /// costs a forward and a backward pass over every view (docs/BENCHMARKS.md).
    pub colour_solve_iterations: u32,
}

impl InitConfig {
    /// Checks the ranges the types do not.
    ///
    /// # Errors
    /// The offending key (`init.…`, as the transcode configuration names it) and what is wrong
    /// with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |key: &str, problem: String| Err((format!("init.{key}"), problem));
        if let Some(k) = self.splats.filter(|&k| k < MIN_SPLATS) {
            return bad(
                "splats",
                format!(
                    "must be at least {MIN_SPLATS}, got {k}: a splat's initial size is the \
                     distance to its 3 nearest neighbours (fewer made one vanishing splat)"
                ),
            );
        }
        // A mesh's splats start from this many samples of its faces: none leaves nothing to
        // initialise from, found only after the reference views were rendered.
        if self.mesh_samples == 0 {
            return bad("mesh_samples", "must be at least 1".into());
        }
        if self.fit_directions < 16 {
            return bad(
                "fit_directions",
                format!(
                    "must be at least 16 (degree 3 has 16 coefficients), got {}",
                    self.fit_directions
                ),
            );
        }
        if !(self.ridge >= 0.0 && self.ridge.is_finite()) {
            return bad("ridge", format!("must be ≥ 0, got {}", self.ridge));
        }
        if !(self.sh_tolerance >= 0.0 && self.sh_tolerance.is_finite()) {
            return bad(
                "sh_tolerance",
                format!("must be ≥ 0, got {}", self.sh_tolerance),
            );
        }
        if self.normal_neighbours < 3 {
            return bad(
                "normal_neighbours",
                format!("must be at least 3, got {}", self.normal_neighbours),
            );
        }
        for (key, r) in [
            ("scale_ratio", self.scale_ratio),
            ("edge_scale_ratio", self.edge_scale_ratio),
        ] {
            if !(r > 0.0 && r <= 10.0) {
                return bad(key, format!("must be in (0, 10], got {r}"));
            }
        }
        for (key, share) in [
            ("edge_contrast", self.edge_contrast),
            ("thin_ratio", self.thin_ratio),
        ] {
            if !(share > 0.0 && share <= 1.0) {
                return bad(key, format!("must be in (0, 1], got {share}"));
            }
        }
        for (key, o) in [
            ("surface_opacity", self.surface_opacity),
            ("sparse_opacity", self.sparse_opacity),
        ] {
            if !(o > 0.0 && o < 1.0) {
                return bad(key, format!("must be in (0, 1), got {o}"));
            }
        }
        if self.mode == InitMode::Sparse && self.points3d.is_none() && self.random_points == 0 {
            return bad("random_points", "must be at least 1".into());
        }
        Ok(())
    }
}

impl Default for InitConfig {
    fn default() -> Self {
        Self {
            mode: InitMode::Surface,
            splats: None,
            sampling: Sampling::Voxel,
            mesh_points: MeshPoints::Samples,
            mesh_samples: 20_000,
            sh_degree: ShDegree::Auto,
            sh_tolerance: 0.002,
            fit_directions: 128,
            ridge: 1e-3,
            normal_neighbours: 12,
            scale_ratio: 1.0,
            edge_scale_ratio: 0.6,
            edge_contrast: 0.15,
            thin_ratio: 0.1,
            surface_opacity: 0.8,
            sparse_opacity: 0.1,
            points3d: None,
            random_points: 5_000,
            free_positions: true,
            densify_surface: false,
            colour_solve_iterations: 0,
        }
    }
}
