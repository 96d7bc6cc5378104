//! The virtual camera rig that frames an input: where the reference views are taken from.

use camera_model::rig::{WORLD_UP, fibonacci_sphere, framing_distance, look_at_rig};
use camera_model::{Camera, Intrinsics};
use glam::DVec3;
use plenoptic_io::Model;
use serde::{Deserialize, Serialize};

use crate::Error;

/// Training and held-out camera rigs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RigConfig {
    /// Training cameras on a Fibonacci sphere around the object.
    pub cameras: usize,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Vertical field of view in degrees (PccAppRenderer's default is 20°).
    pub fov_y_deg: f64,
    /// Share of the half image left free around the object's bounding sphere.
    pub margin: f64,
    /// Held-out cameras (evaluation only), on directions between the training ones.
    pub heldout_cameras: usize,
    /// Distances of the held-out cameras as multiples of the training distance, used in turn.
    pub heldout_distances: Vec<f64>,
    /// The sphere the cameras frame; `None`: the input's bounding sphere. A sequence fixes it so
    /// that every frame is seen from the same cameras.
    pub sphere: Option<FramingSphere>,
}

/// A sphere for the rig to frame, in the input's units.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FramingSphere {
    /// Centre.
    pub center: [f64; 3],
    /// Radius (positive).
    pub radius: f64,
}

impl FramingSphere {
    /// The smallest sphere containing both `self` and `other`.
    #[must_use]
    pub fn union(self, other: Self) -> Self {
        let (a, b) = (DVec3::from(self.center), DVec3::from(other.center));
        let d = a.distance(b);
        if d + other.radius <= self.radius {
            return self;
        }
        if d + self.radius <= other.radius {
            return other;
        }
        let radius = (d + self.radius + other.radius) / 2.0;
        // The new centre lies on the line from a to b, `radius - self.radius` from a.
        let center = a + (b - a) * ((radius - self.radius) / d);
        Self {
            center: center.to_array(),
            radius,
        }
    }
}

/// The most cameras a rig may have, training or held-out: over two hundred times the 44 of the
/// default rig. A rig and its views are held in memory, and a mistyped count (10⁸) would fill
/// it before the first view is drawn.
pub const MAX_CAMERAS: usize = 10_000;

impl RigConfig {
    /// Checks the ranges: cameras and a size, a field of view in (0°, 170°), a margin in
    /// [0, 0.9), held-out distances (when there are held-out cameras) and a framing sphere that
    /// are usable.
    ///
    /// # Errors
    /// The offending key (`rig.…`, as the transcode configuration names it) and what is wrong
    /// with it.
    pub fn validate(&self) -> Result<(), (String, String)> {
        let bad = |key: &str, problem: String| Err((format!("rig.{key}"), problem));
        if !(1..=MAX_CAMERAS).contains(&self.cameras) {
            return bad(
                "cameras",
                format!("must be in 1..={MAX_CAMERAS}, got {}", self.cameras),
            );
        }
        if self.heldout_cameras > MAX_CAMERAS {
            return bad(
                "heldout_cameras",
                format!(
                    "must be at most {MAX_CAMERAS}, got {}",
                    self.heldout_cameras
                ),
            );
        }
        if !((1..=16_384).contains(&self.width) && (1..=16_384).contains(&self.height)) {
            return bad(
                "width/rig.height",
                format!("must be in 1..=16384, got {}×{}", self.width, self.height),
            );
        }
        if !(self.fov_y_deg > 0.0 && self.fov_y_deg < 170.0) {
            return bad(
                "fov_y_deg",
                format!("must be in (0, 170), got {:?}", self.fov_y_deg),
            );
        }
        if !(0.0..0.9).contains(&self.margin) {
            return bad(
                "margin",
                // (Debug: 1e300 as `1e300`, not its 301 digits.)
                format!("must be in [0, 0.9), got {:?}", self.margin),
            );
        }
        if self.heldout_cameras > 0
            && (self.heldout_distances.is_empty()
                || self
                    .heldout_distances
                    .iter()
                    .any(|d| !(*d > 0.3 && *d < 100.0)))
        {
            return bad(
                "heldout_distances",
                format!(
                    "must be a non-empty list of factors in (0.3, 100), got {:?}",
                    self.heldout_distances
                ),
            );
        }
        if let Some(sphere) = self.sphere
            && !(sphere.center.iter().all(|c| c.is_finite())
                && sphere.radius.is_finite()
                && sphere.radius > 0.0)
        {
            return bad(
                "sphere",
                format!("needs a finite centre and a positive radius, got {sphere:?}"),
            );
        }
        Ok(())
    }
}

impl Default for RigConfig {
    fn default() -> Self {
        Self {
            cameras: 44,
            width: 512,
            height: 512,
            fov_y_deg: camera_model::DEFAULT_FOV_Y_DEG,
            margin: 0.05,
            heldout_cameras: 8,
            heldout_distances: vec![0.8, 1.25],
            sphere: None,
        }
    }
}

/// The virtual cameras of a run.
#[derive(Debug, Clone)]
pub struct Rig {
    /// Training cameras.
    pub train: Vec<Camera>,
    /// Held-out cameras (evaluation only).
    pub heldout: Vec<Camera>,
    /// Centre of the object's bounding sphere.
    pub center: DVec3,
    /// Radius of the object's bounding sphere.
    pub radius: f64,
}

/// Training cameras from [`fibonacci_rig`] (a Fibonacci sphere framing the object), and
/// held-out cameras on the directions of a second lattice turned by half the golden angle about
/// the up axis (so they fall between the training ones), at the configured multiples of the
/// training distance.
pub fn build_rig(model: &Model, cfg: &RigConfig) -> Result<Rig, Error> {
    cfg.validate().map_err(invalid_rig)?;
    let (center, radius) = match cfg.sphere {
        Some(s) => (DVec3::from(s.center), s.radius),
        None => bounding_sphere(model)?,
    };
    let train = fibonacci_rig(center, radius, cfg)?;
    let intrinsics = Intrinsics::from_fov_y(cfg.width, cfg.height, cfg.fov_y_deg);
    let distance = framing_distance(radius, &intrinsics, cfg.margin)
        .map_err(|e| Error::InvalidOption(e.to_string()))?;
    // Half the golden angle (≈ 68.75°) about +y moves every lattice point off the training ones.
    let turn = glam::DQuat::from_rotation_y(1.199_981_614_864_326_5);
    let heldout = fibonacci_sphere(cfg.heldout_cameras)
        .into_iter()
        .enumerate()
        .flat_map(|(i, d)| {
            let factor = cfg.heldout_distances[i % cfg.heldout_distances.len().max(1)];
            look_at_rig(&[turn * d], center, distance * factor, intrinsics, WORLD_UP)
        })
        .collect();
    Ok(Rig {
        train,
        heldout,
        center,
        radius,
    })
}

/// Centre (of the bounding box) and radius (farthest point from it) of a cloud's points or a
/// mesh's vertices, in the input's own units.
pub fn bounding_sphere(model: &Model) -> Result<(DVec3, f64), Error> {
    let points = match model {
        Model::Cloud(c) => &c.positions,
        Model::Mesh(m) => &m.positions,
    };
    if points.is_empty() {
        return Err(Error::InvalidModel(
            "the input has no points or vertices".into(),
        ));
    }
    let (lo, hi) = crate::degenerate::bounds(points);
    if !(lo.is_finite() && hi.is_finite()) {
        return Err(Error::InvalidModel(
            "the input has non-finite coordinates".into(),
        ));
    }
    let center = 0.5 * (lo + hi);
    let radius = points
        .iter()
        .map(|p| p.as_dvec3().distance(center))
        .fold(0.0f64, f64::max);
    // A single point still needs a sphere to frame. Only it: a floor for every input (it was
    // 10⁻³ units) framed an object smaller than it as a speck in an empty view.
    let radius = if radius > 0.0 {
        radius
    } else {
        1e-3 * center.length().max(1.0)
    };
    Ok((center, radius))
}

/// `rig.cameras` cameras on a Fibonacci sphere around (`center`, `radius`), each looking at the
/// centre with +y up, with `rig.fov_y_deg` over `rig.height` rows, at the distance where the
/// sphere fills the image up to `rig.margin`.
pub fn fibonacci_rig(center: DVec3, radius: f64, rig: &RigConfig) -> Result<Vec<Camera>, Error> {
    rig.validate().map_err(invalid_rig)?;
    let intrinsics = Intrinsics::from_fov_y(rig.width, rig.height, rig.fov_y_deg);
    let distance = framing_distance(radius, &intrinsics, rig.margin)
        .map_err(|e| Error::InvalidOption(e.to_string()))?;
    Ok(look_at_rig(
        &fibonacci_sphere(rig.cameras),
        center,
        distance,
        intrinsics,
        WORLD_UP,
    ))
}

/// A [`RigConfig::validate`] refusal as the renderer's error.
fn invalid_rig((key, problem): (String, String)) -> Error {
    Error::InvalidOption(format!("`{key}` {problem}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use plenoptic_io::PlenopticCloud;

    #[test]
    fn sphere_union_contains_both_and_touches_their_far_sides() {
        let a = FramingSphere {
            center: [0.0, 0.0, 0.0],
            radius: 1.0,
        };
        let b = FramingSphere {
            center: [4.0, 0.0, 0.0],
            radius: 2.0,
        };
        // Far sides at x = -1 and x = 6: centre 2.5, radius 3.5.
        let u = a.union(b);
        assert!((u.radius - 3.5).abs() < 1e-12 && (u.center[0] - 2.5).abs() < 1e-12);
        assert_eq!(b.union(a), u);
        // A sphere inside the other gives the other.
        let inner = FramingSphere {
            center: [4.5, 0.0, 0.0],
            radius: 1.0,
        };
        assert_eq!(b.union(inner), b);
        assert_eq!(inner.union(b), b);
    }

    #[test]
    fn fixed_sphere_overrides_the_inputs_bounds() {
        let cloud = PlenopticCloud {
            positions: vec![Vec3::ZERO, Vec3::ONE],
            colors: vec![[0.0; 3]; 2],
            ..Default::default()
        };
        let cfg = RigConfig {
            sphere: Some(FramingSphere {
                center: [10.0, 20.0, 30.0],
                radius: 5.0,
            }),
            ..RigConfig::default()
        };
        let rig = build_rig(&Model::Cloud(cloud), &cfg).unwrap();
        assert_eq!(
            (rig.center, rig.radius),
            (DVec3::new(10.0, 20.0, 30.0), 5.0)
        );
    }

    /// A library caller's rig settings are checked where they are used: held-out cameras with
    /// no distances to put them at were an index out of bounds in `build_rig`.
    #[test]
    fn bad_rig_settings_are_refused_naming_the_key() {
        let cloud = PlenopticCloud {
            positions: vec![Vec3::ZERO, Vec3::ONE],
            colors: vec![[0.0; 3]; 2],
            ..Default::default()
        };
        let model = Model::Cloud(cloud);
        let cases = [
            (
                RigConfig {
                    heldout_distances: Vec::new(),
                    ..RigConfig::default()
                },
                "`rig.heldout_distances` must be a non-empty list",
            ),
            (
                RigConfig {
                    cameras: 0,
                    ..RigConfig::default()
                },
                "`rig.cameras` must be in 1..=10000, got 0",
            ),
            (
                RigConfig {
                    cameras: 100_000_000,
                    ..RigConfig::default()
                },
                "`rig.cameras` must be in 1..=10000, got 100000000",
            ),
            (
                RigConfig {
                    fov_y_deg: 175.0,
                    ..RigConfig::default()
                },
                "`rig.fov_y_deg` must be in (0, 170), got 175",
            ),
            (
                RigConfig {
                    margin: 1e300,
                    ..RigConfig::default()
                },
                "`rig.margin` must be in [0, 0.9), got 1e300",
            ),
        ];
        for (cfg, expected) in cases {
            let e = build_rig(&model, &cfg).unwrap_err().to_string();
            assert!(e.contains(expected), "{e}");
            let e = fibonacci_rig(DVec3::ZERO, 1.0, &cfg)
                .unwrap_err()
                .to_string();
            assert!(e.contains(expected), "{e}");
        }
        assert!(build_rig(&model, &RigConfig::default()).is_ok());
    }

    #[test]
    fn rig_frames_the_sphere() {
        let cloud = PlenopticCloud {
            positions: vec![Vec3::new(0.0, 0.0, 0.0), Vec3::new(100.0, 50.0, 20.0)],
            colors: vec![[0.0; 3]; 2],
            ..Default::default()
        };
        let (c, r) = bounding_sphere(&Model::Cloud(cloud)).unwrap();
        assert_eq!(c, DVec3::new(50.0, 25.0, 10.0));
        assert!((r - DVec3::new(50.0, 25.0, 10.0).length()).abs() < 1e-9);
        let rig = RigConfig {
            cameras: 10,
            ..RigConfig::default()
        };
        let cams = fibonacci_rig(c, r, &rig).unwrap();
        assert_eq!(cams.len(), 10);
        for cam in &cams {
            let uv = cam.project(c).unwrap();
            assert!(
                (uv.x - f64::from(rig.width) / 2.0).abs() < 1e-6
                    && (uv.y - f64::from(rig.height) / 2.0).abs() < 1e-6
            );
            // Every point of the sphere's surface projects inside the image.
            for d in [
                DVec3::X,
                DVec3::Y,
                DVec3::Z,
                DVec3::NEG_X,
                DVec3::NEG_Y,
                DVec3::NEG_Z,
            ] {
                assert!(cam.intrinsics.contains(cam.project(c + r * d).unwrap()));
            }
        }
    }
}
