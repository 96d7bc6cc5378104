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
//!
//! - [`demo_scene`]: the built-in demo (a checkered matte slab and a glossy sphere), or its
//!   [`DemoLayout::Floor`] variant (a plain floor and a small checkered ball).
//! - [`synth_from_mesh`]: a plenoptic frame on an 8iVSLF-like voxel grid from a real mesh;
//!   [`synth_in_volume`] the same on a given grid and rig ([`CaptureVolume`]).
//! - [`SequenceSynth`]: a sequence of such frames, the mesh moved and bent by a [`Motion`], on one
//!   grid and rig, named by [`frame_file_name`] as 8iVSLF names its frames.
//! - [`Shading`]: the shading model both use.
//!
//! These are test and demonstration inputs: the transcoder's pipeline does not need them.
//!
//! ```
//! use plenoptic_scenes::{DemoConfig, demo_scene};
//!
//! let cloud = demo_scene(&DemoConfig { grid: 32, ..DemoConfig::default() })?;
//! assert!(!cloud.positions.is_empty());
//! // One colour per point and capture camera, and the rig that took them.
//! assert_eq!(cloud.camera_colors.len(), cloud.len() * cloud.num_cameras);
//! assert_eq!(cloud.cameras.len(), cloud.num_cameras);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

mod capture;
mod demo;
mod sequence;
mod shading;
mod synth;

pub use demo::{DemoConfig, DemoLayout, demo_scene};
pub use sequence::{Motion, SequenceSynth, frame_file_name};
pub use shading::Shading;
pub use synth::{
    AUTO_GRID, CaptureVolume, SynthConfig, auto_grid, synth_from_mesh, synth_in_volume,
};

pub(crate) use capture::{capture_cameras, capture_directions, to_u8_grid};
pub(crate) use shading::Gloss;

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
    View(#[from] plenoptic_render::Error),
    /// The capture rig could not be framed.
    #[error("cannot place the capture cameras: {0}")]
    Camera(#[from] camera_model::Error),
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capture::*;
    use glam::{DVec3, Vec3};

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
