//! What a model holds, in numbers: counts, bounds, frame, rig and colour statistics
//! (what `transcode info` prints; serialisable so scripts can use it).

use rayon::prelude::*;
use serde::Serialize;

use crate::{Mesh, Model, PlenopticCloud};

/// Axis-aligned bounds.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Bounds {
    /// Smallest coordinate on each axis.
    pub min: [f64; 3],
    /// Largest coordinate on each axis.
    pub max: [f64; 3],
}

/// Statistics of one colour channel set over all points/vertices.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ColorStats {
    /// Mean of each channel.
    pub mean: [f64; 3],
    /// Minimum of each channel.
    pub min: [f32; 3],
    /// Maximum of each channel.
    pub max: [f32; 3],
}

/// One capture camera as reported.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CameraSummary {
    /// Index k (the `red{k}` properties).
    pub index: usize,
    /// Centre in voxel units, when the file has rig comments.
    pub position: Option<[f64; 3]>,
    /// Statistics of this camera's colours.
    pub colors: Option<ColorStats>,
}

/// Size of one texture.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TextureSize {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
}

/// Frame-to-world transform of a voxelised cloud: world = voxel · scale + translation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FrameToWorld {
    /// Scale (1 when the file gives only a translation).
    pub scale: f64,
    /// Translation (0 when the file gives only a scale).
    pub translation: [f64; 3],
}

/// Everything `transcode info` reports about a model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Summary {
    /// `plenoptic cloud`, `point cloud` or `mesh`.
    pub kind: &'static str,
    /// Points of a cloud (None for meshes).
    pub points: Option<usize>,
    /// Vertices of a mesh (None for clouds).
    pub vertices: Option<usize>,
    /// Triangles of a mesh.
    pub triangles: Option<usize>,
    /// Materials of a mesh.
    pub materials: Option<usize>,
    /// Texture sizes of a mesh.
    pub textures: Vec<TextureSize>,
    /// Number of capture cameras (per-point or per-vertex colour sets).
    pub capture_cameras: usize,
    /// Whether normals are present.
    pub has_normals: bool,
    /// Whether texture coordinates are present.
    pub has_uvs: bool,
    /// Whether there is a main / vertex colour.
    pub has_colors: bool,
    /// Bounds in file units (None when empty).
    pub bounds: Option<Bounds>,
    /// Voxel grid width (`comment width`).
    pub voxel_width: Option<u32>,
    /// Frame-to-world transform, when the file has one.
    pub frame_to_world: Option<FrameToWorld>,
    /// Bounds in world units, when the file has a frame-to-world transform.
    pub world_bounds: Option<Bounds>,
    /// Statistics of the main (or vertex) colour.
    pub main_colors: Option<ColorStats>,
    /// The capture cameras with their positions and colour statistics.
    pub cameras: Vec<CameraSummary>,
}

impl Summary {
    /// Summarises a model (colour statistics are computed in parallel).
    #[must_use]
    pub fn of(model: &Model) -> Self {
        match model {
            Model::Cloud(c) => cloud_summary(c),
            Model::Mesh(m) => mesh_summary(m),
        }
    }
}

fn cloud_summary(c: &PlenopticCloud) -> Summary {
    let bounds = bounds(&c.positions);
    let frame_to_world = (c.frame_to_world_scale.is_some()
        || c.frame_to_world_translation.is_some())
    .then(|| FrameToWorld {
        scale: c.frame_to_world_scale.unwrap_or(1.0),
        translation: c.frame_to_world_translation.unwrap_or_default().to_array(),
    });
    let world_bounds = frame_to_world.and(bounds).map(|b| {
        let lo = c.voxel_to_world(b.min.into());
        let hi = c.voxel_to_world(b.max.into());
        // A negative scale swaps the corners.
        Bounds {
            min: lo.min(hi).to_array(),
            max: lo.max(hi).to_array(),
        }
    });
    Summary {
        kind: if c.num_cameras > 0 {
            "plenoptic cloud"
        } else {
            "point cloud"
        },
        points: Some(c.len()),
        vertices: None,
        triangles: None,
        materials: None,
        textures: Vec::new(),
        capture_cameras: c.num_cameras,
        has_normals: c.normals.is_some(),
        has_uvs: false,
        has_colors: true,
        bounds,
        voxel_width: c.width,
        frame_to_world,
        world_bounds,
        main_colors: color_stats(&c.colors, 1, 0),
        cameras: cameras(c.num_cameras, &c.camera_colors, |k| {
            c.cameras.get(k).map(|cam| cam.position.to_array())
        }),
    }
}

fn mesh_summary(m: &Mesh) -> Summary {
    Summary {
        kind: "mesh",
        points: None,
        vertices: Some(m.positions.len()),
        triangles: Some(m.triangles.len()),
        materials: Some(m.materials.len()),
        textures: m
            .textures
            .iter()
            .map(|t| TextureSize {
                width: t.width,
                height: t.height,
            })
            .collect(),
        capture_cameras: m.num_cameras,
        has_normals: m.normals.is_some(),
        has_uvs: m.uvs.is_some(),
        has_colors: m.colors.is_some(),
        bounds: bounds(&m.positions),
        voxel_width: None,
        frame_to_world: None,
        world_bounds: None,
        main_colors: m.colors.as_ref().and_then(|c| color_stats(c, 1, 0)),
        cameras: cameras(m.num_cameras, &m.camera_colors, |k| {
            m.cameras.get(k).map(|cam| cam.position.to_array())
        }),
    }
}

fn cameras(
    num: usize,
    colors: &[[f32; 3]],
    position: impl Fn(usize) -> Option<[f64; 3]>,
) -> Vec<CameraSummary> {
    (0..num)
        .map(|k| CameraSummary {
            index: k,
            position: position(k),
            colors: color_stats(colors, num, k),
        })
        .collect()
}

fn bounds(points: &[glam::Vec3]) -> Option<Bounds> {
    if points.is_empty() {
        return None;
    }
    let (lo, hi) = points
        .par_iter()
        .fold(
            || (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
            |(lo, hi), &p| (lo.min(p), hi.max(p)),
        )
        .reduce(
            || (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY),
            |a, b| (a.0.min(b.0), a.1.max(b.1)),
        );
    Some(Bounds {
        min: lo.as_dvec3().to_array(),
        max: hi.as_dvec3().to_array(),
    })
}

/// Statistics of entry `k` of every run of `stride` colours (stride 1, k 0 for a plain column).
fn color_stats(colors: &[[f32; 3]], stride: usize, k: usize) -> Option<ColorStats> {
    let n = colors.len() / stride.max(1);
    if n == 0 {
        return None;
    }
    let empty = || ([0.0f64; 3], [f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    let (sum, min, max) = colors
        .par_chunks(stride.max(1))
        .map(|run| run[k])
        .fold(empty, |(mut s, mut lo, mut hi), c| {
            for i in 0..3 {
                s[i] += f64::from(c[i]);
                lo[i] = lo[i].min(c[i]);
                hi[i] = hi[i].max(c[i]);
            }
            (s, lo, hi)
        })
        .reduce(empty, |a, b| {
            (
                std::array::from_fn(|i| a.0[i] + b.0[i]),
                std::array::from_fn(|i| a.1[i].min(b.1[i])),
                std::array::from_fn(|i| a.2[i].max(b.2[i])),
            )
        });
    Some(ColorStats {
        mean: sum.map(|s| s / n as f64),
        min,
        max,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statistics_of_a_small_cloud() {
        let cloud = PlenopticCloud {
            positions: vec![
                glam::Vec3::new(0.0, 1.0, 2.0),
                glam::Vec3::new(-1.0, 3.0, 2.5),
            ],
            colors: vec![[0.0, 0.5, 1.0], [1.0, 0.5, 0.0]],
            num_cameras: 2,
            camera_colors: vec![
                [0.1, 0.2, 0.3],
                [0.9, 0.9, 0.9],
                [0.3, 0.2, 0.1],
                [0.7, 0.7, 0.7],
            ],
            frame_to_world_scale: Some(2.0),
            frame_to_world_translation: Some(glam::DVec3::new(1.0, 0.0, 0.0)),
            ..PlenopticCloud::default()
        };
        let s = Summary::of(&Model::Cloud(cloud));
        assert_eq!(s.kind, "plenoptic cloud");
        assert_eq!(s.bounds.unwrap().min, [-1.0, 1.0, 2.0]);
        assert_eq!(s.world_bounds.unwrap().max, [1.0, 6.0, 5.0]);
        let cam0 = s.cameras[0].colors.unwrap();
        assert!((cam0.mean[0] - 0.2).abs() < 1e-6 && cam0.min[2] == 0.1 && cam0.max[2] == 0.3);
        assert_eq!(s.cameras[1].colors.unwrap().min, [0.7; 3]);
        assert_eq!(s.cameras[1].position, None);
        assert_eq!(s.main_colors.unwrap().mean, [0.5, 0.5, 0.5]);
    }
}
