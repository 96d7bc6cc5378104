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

/// Options of the reference renderer.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ViewOptions {
    /// Shape of a point.
    pub point_shape: PointShape,
    /// Point size in voxel (file) units: the cube side, or the disc's quad half-size.
    pub point_size: f32,
    /// Exponent n of the view interpolation weight max(0, cos)^n.
    pub exponent: i32,
    /// Background colour of pixels no primitive covers.
    pub background: [f32; 3],
    /// Supersampling factor k: render at k×k the resolution and box-filter down (1 = off).
    pub supersample: u32,
}

impl Default for ViewOptions {
    fn default() -> Self {
        Self {
            point_shape: PointShape::Cube,
            point_size: 1.0,
            exponent: plenoptic_io::view_color::DEFAULT_EXPONENT,
            background: [0.0; 3],
            supersample: 1,
        }
    }
}

impl ViewOptions {
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
        if self.background.iter().any(|c| !c.is_finite()) {
            return Err(Error::InvalidOption(format!(
                "background must be finite, got {:?}",
                self.background
            )));
        }
        Ok(())
    }
}
