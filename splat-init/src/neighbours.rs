//! Nearest neighbours of input points: a k-d tree, the point spacing and PCA normals.

use glam::Vec3;
use rayon::prelude::*;
// The k-d tree is splat-train's: its kNN scales and the evaluator's surface distance use it too.
use splat_train::init::PointIndex;

// The median spacing lives beside the k-d tree in splat-train (its splat budget uses it too).
pub use splat_train::init::point_spacing;

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
