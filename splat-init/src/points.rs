//! The input's surface as a set of coloured points: a cloud's own points, or points on a mesh
//! (its vertices, face centres, or area-uniform samples), each with the plenoptic colours it has.

use glam::Vec3;
use plenoptic_io::{Mesh, Model, PlenopticCloud};
use rand::{RngExt, SeedableRng};

use crate::config::MeshPoints;

/// Points on the input's surface with their colours, the data every initialiser and the
/// surface-distance metric work from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SurfacePoints {
    /// Positions in file units.
    pub positions: Vec<Vec3>,
    /// Unit normals, when the input has them (mesh samples always do).
    pub normals: Option<Vec<Vec3>>,
    /// View-independent ("main") colour per point.
    pub colors: Vec<[f32; 3]>,
    /// Capture cameras' positions (empty when not plenoptic).
    pub camera_positions: Vec<Vec3>,
    /// Per-camera colours, point-major: `camera_colors[i * camera_positions.len() + k]`.
    pub camera_colors: Vec<[f32; 3]>,
}

impl SurfacePoints {
    /// Number of points.
    #[must_use]
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there are no points.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// True when every point has one colour per capture camera.
    #[must_use]
    pub fn is_plenoptic(&self) -> bool {
        !self.camera_positions.is_empty()
            && self.camera_colors.len() == self.len() * self.camera_positions.len()
    }

    /// The per-camera colours of point `i` (empty when not plenoptic).
    #[must_use]
    pub fn camera_colors_of(&self, i: usize) -> &[[f32; 3]] {
        if !self.is_plenoptic() {
            return &[];
        }
        let n = self.camera_positions.len();
        &self.camera_colors[i * n..(i + 1) * n]
    }

    /// The points at `indices`, in that order.
    #[must_use]
    pub fn subset(&self, indices: &[usize]) -> Self {
        let n = self.camera_positions.len();
        Self {
            positions: indices.iter().map(|&i| self.positions[i]).collect(),
            normals: self
                .normals
                .as_ref()
                .map(|v| indices.iter().map(|&i| v[i]).collect()),
            colors: indices.iter().map(|&i| self.colors[i]).collect(),
            camera_positions: self.camera_positions.clone(),
            camera_colors: if self.is_plenoptic() {
                indices
                    .iter()
                    .flat_map(|&i| self.camera_colors[i * n..(i + 1) * n].iter().copied())
                    .collect()
            } else {
                Vec::new()
            },
        }
    }

    /// A cloud's own points.
    #[must_use]
    pub fn from_cloud(cloud: &PlenopticCloud) -> Self {
        Self::from_owned_cloud(cloud.clone())
    }

    /// A cloud's own points, taking its columns instead of copying them: a paper-scale frame's
    /// per-camera colours alone are 0.5 GB.
    #[must_use]
    pub fn from_owned_cloud(cloud: PlenopticCloud) -> Self {
        let plenoptic = cloud.num_cameras > 0 && cloud.cameras.len() == cloud.num_cameras;
        Self {
            camera_positions: if plenoptic {
                cloud.camera_positions()
            } else {
                Vec::new()
            },
            camera_colors: if plenoptic {
                cloud.camera_colors
            } else {
                Vec::new()
            },
            positions: cloud.positions,
            normals: cloud.normals,
            colors: cloud.colors,
        }
    }

    /// Points of a mesh: `which` kind, `samples` of them for area-uniform sampling.
    #[must_use]
    pub fn from_mesh(mesh: &Mesh, which: MeshPoints, samples: usize, seed: u64) -> Self {
        let spots: Vec<(usize, [f32; 3])> = match which {
            MeshPoints::Vertices => vertex_spots(mesh),
            MeshPoints::Faces => (0..mesh.triangles.len())
                .map(|t| (t, [1.0 / 3.0; 3]))
                .collect(),
            MeshPoints::Samples => sample_spots(mesh, samples, seed),
        };
        at_spots(mesh, &spots)
    }

    /// The points of any input model; meshes as `which`/`samples` say.
    #[must_use]
    pub fn from_model(model: &Model, which: MeshPoints, samples: usize, seed: u64) -> Self {
        match model {
            Model::Cloud(c) => Self::from_cloud(c),
            Model::Mesh(m) => Self::from_mesh(m, which, samples, seed),
        }
    }

    /// [`SurfacePoints::from_model`] taking a cloud's columns instead of copying them
    /// ([`SurfacePoints::from_owned_cloud`]).
    #[must_use]
    pub fn from_owned_model(model: Model, which: MeshPoints, samples: usize, seed: u64) -> Self {
        match model {
            Model::Cloud(c) => Self::from_owned_cloud(c),
            Model::Mesh(m) => Self::from_mesh(&m, which, samples, seed),
        }
    }
}

/// Area-uniform samples on a mesh's triangles.
#[must_use]
pub fn sample_mesh(mesh: &Mesh, n: usize, seed: u64) -> SurfacePoints {
    at_spots(mesh, &sample_spots(mesh, n, seed))
}

/// A (triangle, barycentrics) spot for each vertex: the first triangle using it.
fn vertex_spots(mesh: &Mesh) -> Vec<(usize, [f32; 3])> {
    let mut spot = vec![None; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for (corner, &v) in tri.iter().enumerate() {
            if let Some(s) = spot.get_mut(v as usize)
                && s.is_none()
            {
                let mut b = [0.0; 3];
                b[corner] = 1.0;
                *s = Some((t, b));
            }
        }
    }
    spot.into_iter().flatten().collect()
}

/// `n` area-uniform (triangle, barycentrics) spots (inverse-CDF over triangle areas, then the
/// square-root warp of Osada et al. 2002 for a uniform point in a triangle).
fn sample_spots(mesh: &Mesh, n: usize, seed: u64) -> Vec<(usize, [f32; 3])> {
    let areas: Vec<f64> = mesh
        .triangles
        .iter()
        .map(|t| match corners(mesh, t) {
            Some([a, b, c]) => f64::from(0.5 * (b - a).cross(c - a).length()),
            None => 0.0,
        })
        .map(|a| if a.is_finite() { a } else { 0.0 })
        .collect();
    let mut cdf = Vec::with_capacity(areas.len());
    let mut total = 0.0f64;
    for a in &areas {
        total += a;
        cdf.push(total);
    }
    if total <= 0.0 {
        return Vec::new();
    }
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    (0..n)
        .map(|_| {
            let u: f64 = rng.random::<f64>() * total;
            let t = cdf.partition_point(|&c| c <= u).min(areas.len() - 1);
            let (r1, r2): (f32, f32) = (rng.random(), rng.random());
            let s = r1.sqrt();
            (t, [1.0 - s, s * (1.0 - r2), s * r2])
        })
        .collect()
}

/// The three corners of a triangle, `None` if it names a missing vertex.
fn corners(mesh: &Mesh, t: &[u32; 3]) -> Option<[Vec3; 3]> {
    Some([
        *mesh.positions.get(t[0] as usize)?,
        *mesh.positions.get(t[1] as usize)?,
        *mesh.positions.get(t[2] as usize)?,
    ])
}

/// Positions, normals and colours of a mesh at (triangle, barycentrics) spots.
fn at_spots(mesh: &Mesh, spots: &[(usize, [f32; 3])]) -> SurfacePoints {
    let ncam = if mesh.num_cameras > 0
        && mesh.cameras.len() == mesh.num_cameras
        && mesh.camera_colors.len() == mesh.num_cameras * mesh.positions.len()
    {
        mesh.num_cameras
    } else {
        0
    };
    let mut out = SurfacePoints {
        camera_positions: mesh.cameras.iter().map(|c| c.position.as_vec3()).collect(),
        ..SurfacePoints::default()
    };
    if ncam == 0 {
        out.camera_positions.clear();
    }
    let mut normals = Vec::with_capacity(spots.len());
    for &(t, b) in spots {
        let tri = mesh.triangles[t];
        let Some(p) = corners(mesh, &tri) else {
            continue;
        };
        out.positions.push(b[0] * p[0] + b[1] * p[1] + b[2] * p[2]);
        let face = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        let n = match &mesh.normals {
            Some(vn) if vn.len() == mesh.positions.len() => (b[0] * vn[tri[0] as usize]
                + b[1] * vn[tri[1] as usize]
                + b[2] * vn[tri[2] as usize])
                .try_normalize()
                .unwrap_or(face),
            _ => face,
        };
        normals.push(n);
        out.colors.push(mesh.albedo_at(t, b));
        for k in 0..ncam {
            let c = tri.map(|v| mesh.camera_colors[v as usize * ncam + k]);
            out.camera_colors.push(std::array::from_fn(|ch| {
                b[0] * c[0][ch] + b[1] * c[1][ch] + b[2] * c[2][ch]
            }));
        }
    }
    out.normals = Some(normals);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(0.0, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(2.0, 1.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
            ],
            colors: Some(vec![[1.0, 0.0, 0.0]; 4]),
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            ..Mesh::default()
        }
    }

    #[test]
    fn samples_lie_on_the_mesh_uniformly_with_face_normals() {
        let s = sample_mesh(&quad(), 4000, 1);
        assert_eq!(s.len(), 4000);
        for p in &s.positions {
            assert!(p.z.abs() < 1e-6 && (0.0..=2.0).contains(&p.x) && (0.0..=1.0).contains(&p.y));
        }
        // Uniform over the 2×1 rectangle: the left half holds about half of the points.
        let left = s.positions.iter().filter(|p| p.x < 1.0).count() as f64 / 4000.0;
        assert!((left - 0.5).abs() < 0.04, "{left}");
        assert!(
            s.normals
                .as_ref()
                .unwrap()
                .iter()
                .all(|n| (n.z.abs() - 1.0).abs() < 1e-6)
        );
        assert!(
            s.colors
                .iter()
                .all(|c| (c[0] - 1.0).abs() < 1e-5 && c[1] == 0.0 && c[2] == 0.0)
        );
        assert!(!s.is_plenoptic());
    }

    #[test]
    fn vertices_and_faces() {
        let v = SurfacePoints::from_mesh(&quad(), MeshPoints::Vertices, 0, 0);
        assert_eq!(v.positions, quad().positions);
        let f = SurfacePoints::from_mesh(&quad(), MeshPoints::Faces, 0, 0);
        assert_eq!(f.len(), 2);
        assert!((f.positions[0] - Vec3::new(4.0 / 3.0, 1.0 / 3.0, 0.0)).length() < 1e-6);
    }
}
