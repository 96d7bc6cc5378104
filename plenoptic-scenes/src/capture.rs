//! The capture rig of a synthetic frame: camera directions, rig matrices and 8-bit colour levels.

use camera_model::Pose;
use camera_model::rig::{Ring, WORLD_UP, rings};
use glam::DVec3;
use plenoptic_io::CaptureCamera;

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
