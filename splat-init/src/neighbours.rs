//! Nearest neighbours of input points: a k-d tree, the point spacing and PCA normals.

use std::num::NonZero;

use glam::Vec3;
use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// A k-d tree over points for nearest-neighbour queries.
pub struct PointIndex {
    tree: ImmutableKdTree<f32, 3>,
    len: usize,
}

impl PointIndex {
    /// Builds the index; `None` for an empty or unindexable set.
    #[must_use]
    pub fn new(points: &[Vec3]) -> Option<Self> {
        if points.is_empty() {
            return None;
        }
        let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
        let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&coords).ok()?;
        Some(Self {
            tree,
            len: points.len(),
        })
    }

    /// Distance from `p` to the nearest indexed point.
    #[must_use]
    pub fn nearest_distance(&self, p: Vec3) -> f32 {
        self.tree
            .query(&p.to_array())
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute()
            .distance
            .sqrt()
    }

    /// Indices of the `k` nearest indexed points to `p` (nearest first; includes `p` itself if indexed).
    #[must_use]
    pub fn nearest_n(&self, p: Vec3, k: usize) -> Vec<usize> {
        let want = NonZero::new(k.min(self.len).max(1)).unwrap_or(NonZero::<usize>::MIN);
        self.tree
            .query(&p.to_array())
            .nearest_n::<SquaredEuclidean<f32>>(want)
            .execute()
            .iter()
            .map(|r| r.item as usize)
            .collect()
    }
}

/// Median distance from a point to its nearest other point, on up to 20,000 evenly strided points.
#[must_use]
pub fn point_spacing(points: &[Vec3]) -> f32 {
    let Some(index) = PointIndex::new(points) else {
        return 0.0;
    };
    if points.len() < 2 {
        return 0.0;
    }
    let stride = points.len().div_ceil(20_000).max(1);
    let mut d: Vec<f32> = points
        .par_iter()
        .step_by(stride)
        .map(|&p| {
            let near = index.nearest_n(p, 2);
            near.iter()
                .map(|&j| points[j].distance(p))
                .find(|&d| d > 0.0)
                .unwrap_or(0.0)
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}

/// Unit normals by PCA of each point's `k` nearest neighbours: the eigenvector of the smallest
/// eigenvalue of their covariance (sign arbitrary: a flat splat looks the same from both sides).
#[must_use]
pub fn pca_normals(points: &[Vec3], k: usize) -> Vec<Vec3> {
    let Some(index) = PointIndex::new(points) else {
        return Vec::new();
    };
    points
        .par_iter()
        .map(|&p| {
            let near = index.nearest_n(p, k);
            let mean = near.iter().map(|&j| points[j]).sum::<Vec3>() / near.len() as f32;
            let mut cov = nalgebra::Matrix3::<f32>::zeros();
            for &j in &near {
                let d = points[j] - mean;
                let v = nalgebra::Vector3::new(d.x, d.y, d.z);
                cov += v * v.transpose();
            }
            let eig = nalgebra::SymmetricEigen::new(cov);
            let smallest = eig.eigenvalues.imin();
            let n = eig.eigenvectors.column(smallest);
            let n = Vec3::new(n[0], n[1], n[2]);
            if n.is_finite() && n.length_squared() > 0.0 {
                n.normalize()
            } else {
                Vec3::Z
            }
        })
        .collect()
}
