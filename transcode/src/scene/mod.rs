//! Synthetic plenoptic inputs: the built-in demo scene and plenoptic clouds made from real meshes.
//!
//! Both produce what an 8iVSLF frame holds (`docs/reference/formats.md` §1): integer voxel
//! positions, normals, a main colour, one colour per capture camera, the rig as `rig_matrix_k`
//! comments and the frame-to-world transform. Per-camera colours come from one specular shading
//! model ([`Shading`], Blinn–Phong with a fixed directional light) evaluated towards each capture
//! camera that sees the point.
//!
//! A camera that cannot see a point (the point faces away from it, or something is in between)
//! gets the point's main colour, the view-independent (ambient + diffuse) shade: it observed no
//! highlight there, and this keeps such colours plausible where the renderer's interpolation
//! still gives them weight. The main colour is that same diffuse shade.

mod demo;
mod synth;

pub use demo::{DemoConfig, demo_scene};
pub use synth::{AUTO_GRID, SynthConfig, auto_grid, synth_from_mesh};

use camera_model::Pose;
use camera_model::rig::{Ring, WORLD_UP, rings};
use glam::{DVec3, Vec3};
use plenoptic_io::CaptureCamera;

/// Errors of the scene generators.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A configuration value is out of range.
    #[error("invalid scene configuration: {0}")]
    InvalidConfig(String),
    /// The mesh has nothing to sample (no triangles, or zero area).
    #[error("cannot sample the mesh: {0}")]
    EmptyMesh(String),
    /// Rendering the capture cameras' depth maps failed.
    #[error(transparent)]
    View(#[from] crate::views::Error),
    /// The capture rig could not be framed.
    #[error("cannot place the capture cameras: {0}")]
    Camera(#[from] camera_model::Error),
}

/// The specular shading model that makes the per-camera colours (display-space Blinn–Phong).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Shading {
    /// Direction towards the (directional, white) light, world axes; normalised on use.
    pub light_direction: [f32; 3],
    /// Ambient term (fraction of the albedo lit regardless of orientation).
    pub ambient: f32,
    /// Diffuse (Lambert) weight.
    pub diffuse: f32,
}

impl Default for Shading {
    fn default() -> Self {
        Self {
            light_direction: [0.4, 1.0, 0.6],
            ambient: 0.25,
            diffuse: 0.75,
        }
    }
}

/// How shiny a surface is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Gloss {
    /// Specular weight (0 for matte).
    pub specular: f32,
    /// Blinn–Phong exponent.
    pub shininess: f32,
}

impl Shading {
    /// The view-independent shade: albedo · (ambient + diffuse · max(0, n·l)), clamped to [0, 1].
    pub(crate) fn diffuse_color(&self, normal: Vec3, albedo: [f32; 3]) -> [f32; 3] {
        let l = Vec3::from(self.light_direction).normalize_or_zero();
        let k = self.ambient + self.diffuse * normal.dot(l).max(0.0);
        albedo.map(|a| (a * k).clamp(0.0, 1.0))
    }

    /// The colour seen from direction `to_viewer` (unit): the diffuse shade plus the Blinn–Phong
    /// highlight specular · max(0, n·h)^shininess with h = normalize(l + v), clamped to [0, 1].
    /// Two-sided: the normal is turned towards the viewer.
    pub(crate) fn color(
        &self,
        normal: Vec3,
        to_viewer: Vec3,
        albedo: [f32; 3],
        gloss: Gloss,
    ) -> [f32; 3] {
        let n = if normal.dot(to_viewer) < 0.0 {
            -normal
        } else {
            normal
        };
        let base = self.diffuse_color(n, albedo);
        let l = Vec3::from(self.light_direction).normalize_or_zero();
        let h = (l + to_viewer).normalize_or_zero();
        let s = if n.dot(l) > 0.0 {
            gloss.specular * n.dot(h).max(0.0).powf(gloss.shininess)
        } else {
            0.0
        };
        base.map(|c| (c + s).clamp(0.0, 1.0))
    }

    /// Checks the shading parameters.
    pub(crate) fn validate(&self) -> Result<(), Error> {
        let ok = self.light_direction.iter().all(|v| v.is_finite())
            && Vec3::from(self.light_direction).length() > 0.0
            && self.ambient.is_finite()
            && self.diffuse.is_finite();
        if ok {
            Ok(())
        } else {
            Err(Error::InvalidConfig(format!(
                "bad shading parameters {self:?}"
            )))
        }
    }
}

/// Directions of `count` capture cameras on two rings around the object, as the 8iVSLF rigs
/// surround their subject: ⌈count/2⌉ at 10° elevation and the rest at 40°, the upper ring turned
/// by half a step so that the two interleave.
pub(crate) fn capture_directions(count: usize) -> Vec<DVec3> {
    let lower = count.div_ceil(2);
    let upper = count - lower;
    let step = if upper > 0 { 180.0 / upper as f64 } else { 0.0 };
    rings(&[
        Ring {
            elevation_deg: 10.0,
            count: lower,
            azimuth_offset_deg: 0.0,
        },
        Ring {
            elevation_deg: 40.0,
            count: upper,
            azimuth_offset_deg: step,
        },
    ])
}

/// The `rig_matrix_k` of a capture camera at `eye` (world units) looking at `target`: the
/// camera-to-world matrix of an OpenGL camera (looking down −Z, +Y up), column-major, so that the
/// centre is at values 12–14 where PccAppRenderer reads it (formats.md §2.2).
pub(crate) fn rig_matrix(eye: DVec3, target: DVec3) -> [f64; 16] {
    let pose = Pose::look_at(eye, target, WORLD_UP);
    let c2w = pose.rotation_matrix().transpose();
    // COLMAP axes (x right, y down, z forward) to OpenGL (x right, y up, z backward).
    let (x, y, z) = (c2w.x_axis, -c2w.y_axis, -c2w.z_axis);
    [
        x.x, x.y, x.z, 0.0, y.x, y.y, y.z, 0.0, z.x, z.y, z.z, 0.0, eye.x, eye.y, eye.z, 1.0,
    ]
}

/// Capture cameras at voxel positions `voxel_positions` looking at `target_voxel`, with their
/// matrices in world units (world = voxel · scale + translation).
pub(crate) fn capture_cameras(
    voxel_positions: &[DVec3],
    target_voxel: DVec3,
    scale: f64,
    translation: DVec3,
) -> Vec<CaptureCamera> {
    voxel_positions
        .iter()
        .map(|&p| CaptureCamera {
            position: p,
            matrix: Some(rig_matrix(
                p * scale + translation,
                target_voxel * scale + translation,
            )),
        })
        .collect()
}

/// Converts a colour in [0, 1] to what an 8-bit file will hold, so the cloud in memory equals
/// the cloud read back.
pub(crate) fn to_u8_grid(c: [f32; 3]) -> [f32; 3] {
    c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() / 255.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn highlight_follows_the_mirror_direction() {
        let s = Shading {
            light_direction: [0.0, 1.0, 1.0],
            ambient: 0.2,
            diffuse: 0.5,
        };
        let gloss = Gloss {
            specular: 0.5,
            shininess: 50.0,
        };
        let n = Vec3::Z;
        let albedo = [0.4, 0.4, 0.4];
        // Mirror of the light about n: (0, −1, 1)/√2 sees the full highlight.
        let mirror = s.color(n, Vec3::new(0.0, -1.0, 1.0).normalize(), albedo, gloss);
        let diffuse = s.diffuse_color(n, albedo);
        let expected = 0.4 * (0.2 + 0.5 * std::f32::consts::FRAC_1_SQRT_2) + 0.5;
        assert!((mirror[0] - expected).abs() < 1e-5);
        // Far from it, the highlight has faded: cos^50 of 45° is ~3e-8.
        let side = s.color(n, Vec3::new(0.0, 1.0, 0.0).normalize(), albedo, gloss);
        assert!((side[0] - diffuse[0]).abs() < 1e-5);
    }

    #[test]
    fn rig_matrix_puts_the_centre_at_12_to_14_and_looks_down_minus_z() {
        let eye = DVec3::new(100.0, 50.0, -30.0);
        let m = rig_matrix(eye, DVec3::ZERO);
        assert_eq!([m[12], m[13], m[14]], [100.0, 50.0, -30.0]);
        // −Z column points at the target.
        let minus_z = -DVec3::new(m[8], m[9], m[10]);
        assert!((minus_z - (-eye).normalize()).length() < 1e-12);
        // +Y column has a positive world-up component.
        assert!(m[5] > 0.0);
    }

    #[test]
    fn two_interleaved_rings() {
        let d = capture_directions(13);
        assert_eq!(d.len(), 13);
        assert_eq!(
            d.iter()
                .filter(|v| (v.y - 10f64.to_radians().sin()).abs() < 1e-12)
                .count(),
            7
        );
        assert_eq!(
            d.iter()
                .filter(|v| (v.y - 40f64.to_radians().sin()).abs() < 1e-12)
                .count(),
            6
        );
    }
}
