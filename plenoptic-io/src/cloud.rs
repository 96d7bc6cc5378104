//! The plenoptic point cloud: points with a main colour and one colour per capture camera.

use glam::{DVec3, Vec3};

use ply_core::{PlyFormat, ScalarType};

/// One capture camera of the rig.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureCamera {
    /// Camera centre in voxel (file) units: (world − frame_to_world_translation) / frame_to_world_scale.
    pub position: DVec3,
    /// The 16 numbers of the file's `rig_matrix_k` comment (centre in world units at 12–14), if any.
    pub matrix: Option<[f64; 16]>,
}

/// How a cloud was laid out in its PLY file, so that it can be written back bit-exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct PlyLayout {
    /// ASCII or binary, and the byte order.
    pub format: PlyFormat,
    /// The vertex element's properties, in file order, with their types.
    pub properties: Vec<(String, ScalarType)>,
    /// Header comments other than the rig keys, in file order.
    pub comments: Vec<String>,
}

/// A property of the vertex element that has no role in [`PlenopticCloud`] (e.g. `alpha`, `psz`),
/// kept so that writing reproduces the file. f64 holds every PLY scalar type exactly.
#[derive(Debug, Clone, PartialEq)]
pub struct ExtraProperty {
    /// Property name.
    pub name: String,
    /// One value per point.
    pub values: Vec<f64>,
}

/// A point cloud whose points carry a main colour and, for plenoptic clouds, one colour per capture camera.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PlenopticCloud {
    /// Positions in file (voxel) units.
    pub positions: Vec<Vec3>,
    /// Normals, when the file has nx/ny/nz.
    pub normals: Option<Vec<Vec3>>,
    /// Main colour in [0, 1] (`red/green/blue` or `diffuse_*`; see `docs/formats-input.md` when absent).
    pub colors: Vec<[f32; 3]>,
    /// Number of capture cameras (0 for a plain coloured cloud).
    pub num_cameras: usize,
    /// Per-camera colours, point-major: `[i * num_cameras + k]`.
    pub camera_colors: Vec<[f32; 3]>,
    /// Capture rig; empty when the file has no rig comments.
    pub cameras: Vec<CaptureCamera>,
    /// `comment frame_to_world_scale s`: world = voxel · s + translation.
    pub frame_to_world_scale: Option<f64>,
    /// `comment frame_to_world_translation tx ty tz`.
    pub frame_to_world_translation: Option<DVec3>,
    /// `comment width w`: voxel grid width (1023 for vox10, 4095 for vox12).
    pub width: Option<u32>,
    /// Vertex properties with no role above, kept for writing back.
    pub extra: Vec<ExtraProperty>,
    /// The file layout, when read from a file; `None` writes the default layout.
    pub layout: Option<PlyLayout>,
}

impl PlenopticCloud {
    /// Number of points.
    #[must_use]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when the cloud has no points.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The `num_cameras` colours of point `i` (empty for a plain cloud). Panics if `i >= len()`.
    #[must_use]
    pub fn camera_colors_of(&self, i: usize) -> &[[f32; 3]] {
        &self.camera_colors[i * self.num_cameras..(i + 1) * self.num_cameras]
    }

    /// Capture-camera positions in voxel units as f32, for [`crate::view_color::interpolate`].
    #[must_use]
    pub fn camera_positions(&self) -> Vec<Vec3> {
        self.cameras.iter().map(|c| c.position.as_vec3()).collect()
    }

    /// World position of a voxel-unit point: voxel · scale + translation (identity when absent).
    #[must_use]
    pub fn voxel_to_world(&self, voxel: DVec3) -> DVec3 {
        voxel * self.frame_to_world_scale.unwrap_or(1.0)
            + self.frame_to_world_translation.unwrap_or(DVec3::ZERO)
    }

    /// Voxel position of a world point: (world − translation) / scale (identity when absent).
    #[must_use]
    pub fn world_to_voxel(&self, world: DVec3) -> DVec3 {
        (world - self.frame_to_world_translation.unwrap_or(DVec3::ZERO))
            / self.frame_to_world_scale.unwrap_or(1.0)
    }
}
