//! The eigen-decomposition of symmetric 3 × 3 matrices: a merged splat's axes
//! ([`super::merge_group`]) and how flat a merge group lies ([`super::clusters`]).

use glam::{Mat3, Quat, Vec3};

/// The eigen-decomposition of a symmetric 3×3 matrix by Jacobi rotations: the rotation whose
/// columns are the eigenvectors (a proper rotation) and the eigenvalues. Written out because
/// it is a dozen lines and the crate has no linear-algebra dependency; merges call it once per
/// group.
pub(super) fn symmetric_eigen(m: Mat3) -> (Quat, Vec3) {
    let mut a = widened(m);
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0_f64]];
    diagonalise(&mut a, Some(&mut v));
    let col = |j: usize| Vec3::new(v[0][j] as f32, v[1][j] as f32, v[2][j] as f32);
    let (x, y) = (col(0), col(1));
    // A proper rotation: the third axis from the first two.
    let z = x.cross(y);
    let rot = Mat3::from_cols(x, y, z);
    (Quat::from_mat3(&rot), eigenvalues_of(&a))
}

/// The eigenvalues of a symmetric 3×3 matrix, as [`symmetric_eigen`] finds them (the same
/// rotations, without keeping the eigenvectors).
pub(super) fn symmetric_eigenvalues(m: Mat3) -> Vec3 {
    let mut a = widened(m);
    diagonalise(&mut a, None);
    eigenvalues_of(&a)
}

/// `m` as rows of f64.
fn widened(m: Mat3) -> [[f64; 3]; 3] {
    [
        [m.x_axis.x, m.y_axis.x, m.z_axis.x],
        [m.x_axis.y, m.y_axis.y, m.z_axis.y],
        [m.x_axis.z, m.y_axis.z, m.z_axis.z],
    ]
    .map(|r| r.map(f64::from))
}

/// The diagonal of a diagonalised matrix, narrowed to f32.
fn eigenvalues_of(a: &[[f64; 3]; 3]) -> Vec3 {
    Vec3::new(a[0][0] as f32, a[1][1] as f32, a[2][2] as f32)
}

/// Jacobi rotations on the symmetric `a` until it is diagonal, applied to `v` as well where
/// given (the rotations do not depend on `v`, so the eigenvalues are the same either way).
fn diagonalise(a: &mut [[f64; 3]; 3], mut v: Option<&mut [[f64; 3]; 3]>) {
    for _ in 0..32 {
        let off = a[0][1].abs() + a[0][2].abs() + a[1][2].abs();
        let scale = a[0][0].abs() + a[1][1].abs() + a[2][2].abs();
        if off <= 1e-15 * scale.max(f64::MIN_POSITIVE) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for row in a.iter_mut() {
                let (x, y) = (row[p], row[q]);
                row[p] = c * x - s * y;
                row[q] = s * x + c * y;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for col in 0..3 {
                a[p][col] = c * row_p[col] - s * row_q[col];
                a[q][col] = s * row_p[col] + c * row_q[col];
            }
            if let Some(v) = v.as_deref_mut() {
                for row in v.iter_mut() {
                    let (x, y) = (row[p], row[q]);
                    row[p] = c * x - s * y;
                    row[q] = s * x + c * y;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn approx(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    /// The decomposition rebuilds the matrix, its eigenvectors form a proper rotation, and the
    /// eigenvalues of a diagonal matrix turned by a known rotation are its diagonal.
    #[test]
    fn symmetric_eigen_rebuilds_the_matrix() {
        let turn = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 0.7);
        let r = Mat3::from_quat(turn);
        let d = Vec3::new(4.0, 0.25, 1.5);
        let m = r * Mat3::from_diagonal(d) * r.transpose();
        let (q, values) = symmetric_eigen(m);
        let e = Mat3::from_quat(q);
        let rebuilt = e * Mat3::from_diagonal(values) * e.transpose();
        for c in 0..3 {
            for k in 0..3 {
                assert!(
                    approx(rebuilt.col(c)[k], m.col(c)[k], 1e-5),
                    "{rebuilt} vs {m}"
                );
            }
        }
        assert!(approx(e.determinant(), 1.0, 1e-5));
        let mut got = values.to_array();
        got.sort_by(f32::total_cmp);
        for (g, want) in got.iter().zip([0.25, 1.5, 4.0]) {
            assert!(approx(*g, want, 1e-5), "{got:?}");
        }
        // Already diagonal (no rotation to find) and all equal (any axes will do).
        let (_, v) = symmetric_eigen(Mat3::from_diagonal(Vec3::new(2.0, 3.0, 5.0)));
        assert_eq!(v, Vec3::new(2.0, 3.0, 5.0));
        let (q, v) = symmetric_eigen(Mat3::IDENTITY * 7.0);
        assert_eq!(v, Vec3::splat(7.0));
        assert!(q.is_normalized());
    }
}
