//! Options of the reference renderer.

use crate::Error;

/// How a point of a cloud is drawn (PccAppRenderer `--type`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PointShape {
    /// Axis-aligned cube of side `point_size` voxels centred on the point (`--type 0`, the default).
    Cube,
    /// View-aligned disc of radius √ln 2 · `point_size` (`--type 1`: a quad of half-size
    /// `point_size` whose fragments with exp(−|c|²) < 0.5 are discarded).
    Disc,
}

/// How supersampled pixels are filtered down to the view's pixels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum PixelFilter {
    /// Average of the pixel's own k×k sub-pixels: exact area coverage.
    Box,
    /// A Gaussian of variance [`PIXEL_FILTER_VARIANCE`] px² around the pixel centre, truncated at
    /// 3σ: the low-pass filter every 3DGS rasteriser applies to each splat (its 0.3 px²
    /// dilation), so that a reference edge is as sharp as a splat model can draw it and the
    /// two are compared under one image-formation model.
    Gaussian,
}

/// Variance in px² of [`PixelFilter::Gaussian`]: the 3DGS rasteriser's dilation
/// (`splat_core::constants::DILATION`; the workspace tests check the two agree).
pub const PIXEL_FILTER_VARIANCE: f32 = 0.3;

/// Options of the reference renderer.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewOptions {
    /// Shape of a point.
    pub point_shape: PointShape,
    /// Point size in voxel (file) units: the cube side, or the disc's quad half-size.
    pub point_size: f32,
    /// Grow the points of a cloud that samples its surface more sparsely than one point per
    /// `point_size`-wide cell until the surface is closed, and draw a cloud that does not lie on
    /// a grid of `point_size` at its own measured spacing ([`crate::point_sizing`]); a dense
    /// voxelised cloud is drawn at `point_size` either way.
    pub close_surface: bool,
    /// Exponent n of the view interpolation weight max(0, cos)^n.
    pub exponent: i32,
    /// Background colour of pixels no primitive covers.
    pub background: [f32; 3],
    /// Supersampling factor k: render at k×k the resolution and filter down with
    /// `pixel_filter` (1 = one sample at each pixel centre: aliased edges).
    pub supersample: u32,
    /// The filter from sub-pixels to pixels (used when `supersample` > 1).
    pub pixel_filter: PixelFilter,
    /// Whether views carry their depth ([`crate::ViewImage::depth`], empty otherwise). A caller
    /// that keeps only colour and coverage (a trainer's views) saves the depth's pass over the
    /// sub-pixels and its image: about 2 % of a paper-scale frame's views. What a caller asks
    /// of the renderer rather than a setting of the references, so not read from or written to
    /// a configuration file.
    #[serde(skip, default = "with_depth")]
    pub depth: bool,
}

/// [`ViewOptions::depth`]'s default: views carry their depth.
fn with_depth() -> bool {
    true
}

/// Default supersampling: 3×3 sub-pixels a pixel. Edges and the texture of a cloud's point
/// pattern alias at one sample a pixel, and a model trained on aliased views learns the aliasing
/// (docs/BENCHMARKS.md: about +4 dB held-out on the demo); 3 is the smallest odd factor, so a
/// sub-pixel sits on each pixel centre.
pub const DEFAULT_SUPERSAMPLE: u32 = 3;

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            point_shape: PointShape::Cube,
            point_size: 1.0,
            close_surface: true,
            exponent: plenoptic_io::view_color::DEFAULT_EXPONENT,
            background: [0.0; 3],
            supersample: DEFAULT_SUPERSAMPLE,
            pixel_filter: PixelFilter::Gaussian,
            depth: with_depth(),
        }
    }
}

impl ViewOptions {
    /// The defaults with one sample at each pixel centre (no supersampling) and points at their
    /// configured size: every pixel is exactly one primitive or the background, as
    /// PccAppRenderer draws it. The geometry tests and the synthetic frames' capture renders
    /// use it.
    #[must_use]
    pub fn single_sample() -> Self {
        Self {
            supersample: 1,
            close_surface: false,
            ..Self::default()
        }
    }

    /// These options with the point size chosen for `cloud` ([`ViewOptions::close_surface`])
    /// and the choice switched off, so the many views of one cloud measure its spacing once.
    #[must_use]
    pub fn for_cloud(&self, cloud: &plenoptic_io::PlenopticCloud) -> Self {
        self.sized(self.cloud_sizing(cloud))
    }

    /// [`ViewOptions::for_cloud`] for a model; a mesh has no points and keeps the options.
    #[must_use]
    pub fn for_model(&self, model: &plenoptic_io::Model) -> Self {
        self.sized(self.point_sizing(model))
    }

    /// How these options size the points of `model` ([`crate::point_sizing`] when
    /// [`ViewOptions::close_surface`] is set and the model is a cloud), for the caller to
    /// apply with [`ViewOptions::sized`] and tell its user about.
    #[must_use]
    pub fn point_sizing(&self, model: &plenoptic_io::Model) -> crate::PointSizing {
        match model {
            plenoptic_io::Model::Cloud(cloud) => self.cloud_sizing(cloud),
            plenoptic_io::Model::Mesh(_) => crate::PointSizing::AsConfigured,
        }
    }

    fn cloud_sizing(&self, cloud: &plenoptic_io::PlenopticCloud) -> crate::PointSizing {
        if self.close_surface {
            crate::point_sizing(&cloud.positions, self.point_size)
        } else {
            crate::PointSizing::AsConfigured
        }
    }

    /// These options with `sizing` applied and the choice switched off.
    #[must_use]
    pub fn sized(&self, sizing: crate::PointSizing) -> Self {
        Self {
            point_size: sizing.size(self.point_size),
            close_surface: false,
            ..self.clone()
        }
    }

    /// Checks the options, naming the first bad one.
    pub fn validate(&self) -> Result<(), Error> {
        if !(self.point_size > 0.0 && self.point_size.is_finite()) {
            return Err(Error::InvalidOption(format!(
                "point_size must be positive and finite, got {}",
                self.point_size
            )));
        }
        if !(1..=8).contains(&self.supersample) {
            return Err(Error::InvalidOption(format!(
                "supersample must be in 1..=8, got {}",
                self.supersample
            )));
        }
        if self.exponent < 0 {
            return Err(Error::InvalidOption(format!(
                "exponent must be non-negative, got {}",
                self.exponent
            )));
        }
        if !self.background.iter().all(|c| (0.0..=1.0).contains(c)) {
            return Err(Error::InvalidOption(format!(
                "background must be a colour with channels in [0, 1], got {:?}",
                self.background
            )));
        }
        Ok(())
    }
}
