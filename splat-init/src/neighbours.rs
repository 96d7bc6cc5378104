//! Nearest neighbours of input points: a k-d tree, the point spacing and PCA normals.

use glam::Vec3;
use rayon::prelude::*;
// The k-d tree is splat-train's: its kNN scales and the evaluator's surface distance use it too.
use splat_train::init::PointIndex;

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
