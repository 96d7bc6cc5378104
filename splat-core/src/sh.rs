//! Real spherical harmonics of degree 0–3 in Inria's basis, order and signs
//! (`diff-gaussian-rasterization/cuda_rasterizer/forward.cu::computeColorFromSH`), with gradients.
//!
//! The basis is evaluated as polynomials of the components of a unit direction `dir`; the
//! gradients are those of the polynomials with respect to the components (callers chain them
//! through the normalisation of the direction).

use glam::Vec3;

use crate::lanes::Real;

/// Degree-0 constant, 1/(2√π).
pub const C0: f32 = 0.282_094_8;
/// Degree-1 constant, √3/(2√π).
pub const C1: f32 = 0.488_602_52;
/// Degree-2 constants (Inria's `SH_C2`).
pub const C2: [f32; 5] = [
    1.092_548_4,
    -1.092_548_4,
    0.315_391_57,
    -1.092_548_4,
    0.546_274_2,
];
/// Degree-3 constants (Inria's `SH_C3`).
pub const C3: [f32; 7] = [
    -0.590_043_6,
    2.890_611_4,
    -0.457_045_8,
    0.373_176_34,
    -0.457_045_8,
    1.445_305_7,
    -0.590_043_6,
];

/// Writes the `(degree + 1)²` basis values at unit direction `dir` into `out[..]`.
pub fn basis(degree: u32, dir: Vec3, out: &mut [f32]) {
    basis_terms(degree, dir.into(), out);
}

/// [`basis`] on any [`Real`] whose lanes hold f32: a scalar, or eight directions at once.
#[inline(always)]
pub(crate) fn basis_terms<T: Real<Scalar = f32>>(degree: u32, [x, y, z]: [T; 3], out: &mut [T]) {
    let c = T::splat;
    out[0] = c(C0);
    if degree < 1 {
        return;
    }
    out[1] = c(-C1) * y;
    out[2] = c(C1) * z;
    out[3] = c(-C1) * x;
    if degree < 2 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    out[4] = c(C2[0]) * x * y;
    out[5] = c(C2[1]) * y * z;
    out[6] = c(C2[2]) * (c(2.0) * zz - xx - yy);
    out[7] = c(C2[3]) * x * z;
    out[8] = c(C2[4]) * (xx - yy);
    if degree < 3 {
        return;
    }
    out[9] = c(C3[0]) * y * (c(3.0) * xx - yy);
    out[10] = c(C3[1]) * x * y * z;
    out[11] = c(C3[2]) * y * (c(4.0) * zz - xx - yy);
    out[12] = c(C3[3]) * z * (c(2.0) * zz - c(3.0) * xx - c(3.0) * yy);
    out[13] = c(C3[4]) * x * (c(4.0) * zz - xx - yy);
    out[14] = c(C3[5]) * z * (xx - yy);
    out[15] = c(C3[6]) * x * (xx - c(3.0) * yy);
}

/// Writes the basis values into `out` and their gradients with respect to (x, y, z) into `grad`.
pub fn basis_grad(degree: u32, dir: Vec3, out: &mut [f32], grad: &mut [Vec3]) {
    basis(degree, dir, out);
    let Vec3 { x, y, z } = dir;
    grad[0] = Vec3::ZERO;
    if degree < 1 {
        return;
    }
    grad[1] = Vec3::new(0.0, -C1, 0.0);
    grad[2] = Vec3::new(0.0, 0.0, C1);
    grad[3] = Vec3::new(-C1, 0.0, 0.0);
    if degree < 2 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    grad[4] = C2[0] * Vec3::new(y, x, 0.0);
    grad[5] = C2[1] * Vec3::new(0.0, z, y);
    grad[6] = C2[2] * Vec3::new(-2.0 * x, -2.0 * y, 4.0 * z);
    grad[7] = C2[3] * Vec3::new(z, 0.0, x);
    grad[8] = C2[4] * Vec3::new(2.0 * x, -2.0 * y, 0.0);
    if degree < 3 {
        return;
    }
    grad[9] = C3[0] * Vec3::new(6.0 * x * y, 3.0 * xx - 3.0 * yy, 0.0);
    grad[10] = C3[1] * Vec3::new(y * z, x * z, x * y);
    grad[11] = C3[2] * Vec3::new(-2.0 * x * y, 4.0 * zz - xx - 3.0 * yy, 8.0 * y * z);
    grad[12] = C3[3] * Vec3::new(-6.0 * x * z, -6.0 * y * z, 6.0 * zz - 3.0 * xx - 3.0 * yy);
    grad[13] = C3[4] * Vec3::new(4.0 * zz - 3.0 * xx - yy, -2.0 * x * y, 8.0 * x * z);
    grad[14] = C3[5] * Vec3::new(2.0 * x * z, -2.0 * y * z, xx - yy);
    grad[15] = C3[6] * Vec3::new(3.0 * xx - 3.0 * yy, -6.0 * x * y, 0.0);
}

/// Returns `Σ_k basis_k(dir)·coeffs[k]` per channel (no +0.5 offset, no clamp), using the first
/// `(degree + 1)²` coefficients.
#[must_use]
pub fn eval(degree: u32, dir: Vec3, coeffs: &[[f32; 3]]) -> Vec3 {
    let n = num_sh_coeffs(degree).min(coeffs.len());
    eval_terms(degree, n, dir.into(), |k| coeffs[k]).into()
}

/// [`eval`] on any [`Real`] whose lanes hold f32, over the first `n` coefficients, the k-th
/// given by `coeff(k)` (per channel).
#[inline(always)]
pub(crate) fn eval_terms<T: Real<Scalar = f32>>(
    degree: u32,
    n: usize,
    dir: [T; 3],
    coeff: impl Fn(usize) -> [T; 3],
) -> [T; 3] {
    let mut b = [T::splat(0.0); 16];
    basis_terms(degree, dir, &mut b);
    let mut acc = [T::splat(0.0); 3];
    for (k, &w) in b.iter().enumerate().take(n) {
        let c = coeff(k);
        for ch in 0..3 {
            acc[ch] = acc[ch] + w * c[ch];
        }
    }
    acc
}

/// Returns the colour a splat shows towards a viewer: `max(eval + 0.5, 0)` per channel, as
/// Inria's rasteriser computes it; `dir` runs from the camera centre to the splat.
#[must_use]
pub fn color(degree: u32, dir: Vec3, coeffs: &[[f32; 3]]) -> Vec3 {
    (eval(degree, dir, coeffs) + 0.5).max(Vec3::ZERO)
}

/// Backward of [`eval`]: adds `basis_k·d_out` into `d_coeffs[k]` and returns dL/d(dir) (the
/// gradient with respect to the unit-vector components, before normalisation).
pub fn eval_backward(
    degree: u32,
    dir: Vec3,
    coeffs: &[[f32; 3]],
    d_out: Vec3,
    d_coeffs: &mut [[f32; 3]],
) -> Vec3 {
    let mut b = [0.0_f32; 16];
    let mut g = [Vec3::ZERO; 16];
    basis_grad(degree, dir, &mut b, &mut g);
    let n = num_sh_coeffs(degree);
    let mut d_dir = Vec3::ZERO;
    for k in 0..n {
        let dc = b[k] * d_out;
        d_coeffs[k][0] += dc.x;
        d_coeffs[k][1] += dc.y;
        d_coeffs[k][2] += dc.z;
        d_dir += g[k] * Vec3::from(coeffs[k]).dot(d_out);
    }
    d_dir
}

/// Returns the number of SH coefficients per colour channel for a degree: 1, 4, 9, 16.
#[must_use]
#[inline]
pub const fn num_sh_coeffs(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fibonacci(n: usize) -> Vec<glam::DVec3> {
        let golden = std::f64::consts::PI * (3.0 - 5.0_f64.sqrt());
        (0..n)
            .map(|i| {
                let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - y * y).sqrt();
                let t = golden * i as f64;
                glam::DVec3::new(r * t.cos(), y, r * t.sin())
            })
            .collect()
    }

    /// ∫ Y_i Y_j dΩ = δ_ij, integrated with an equal-area Fibonacci rule (error ~1/N).
    #[test]
    fn basis_is_orthonormal_on_the_sphere() {
        let dirs = fibonacci(200_000);
        let mut gram = [[0.0_f64; 16]; 16];
        let mut b = [0.0_f32; 16];
        for d in &dirs {
            basis(3, d.as_vec3(), &mut b);
            for i in 0..16 {
                for j in 0..16 {
                    gram[i][j] += f64::from(b[i]) * f64::from(b[j]);
                }
            }
        }
        let w = 4.0 * std::f64::consts::PI / dirs.len() as f64;
        for (i, row) in gram.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                let expect = if i == j { 1.0 } else { 0.0 };
                assert!((v * w - expect).abs() < 1e-3, "<Y{i},Y{j}> = {}", v * w);
            }
        }
    }

    /// Inria's degree-1 signs: a coefficient on band index 3 (−C1·x) lights splats seen along −x.
    #[test]
    fn degree_one_signs_match_inria() {
        let mut b = [0.0; 4];
        basis(1, Vec3::new(0.0, 0.0, 1.0), &mut b);
        assert_eq!(b, [C0, 0.0, C1, 0.0]);
        basis(1, Vec3::new(1.0, 0.0, 0.0), &mut b);
        assert_eq!(b, [C0, 0.0, 0.0, -C1]);
        basis(1, Vec3::new(0.0, 1.0, 0.0), &mut b);
        assert_eq!(b, [C0, -C1, 0.0, 0.0]);
    }

    /// The polynomial gradients agree with central differences in f64-sized steps.
    #[test]
    fn gradients_match_finite_differences() {
        let dir = Vec3::new(0.3, -0.5, 0.7);
        let mut b = [0.0; 16];
        let mut g = [Vec3::ZERO; 16];
        basis_grad(3, dir, &mut b, &mut g);
        let h = 1e-3;
        for axis in 0..3 {
            let mut e = Vec3::ZERO;
            e[axis] = h;
            let mut bp = [0.0; 16];
            let mut bm = [0.0; 16];
            basis(3, dir + e, &mut bp);
            basis(3, dir - e, &mut bm);
            for k in 0..16 {
                let fd = (bp[k] - bm[k]) / (2.0 * h);
                assert!(
                    (fd - g[k][axis]).abs() < 2e-3,
                    "k {k} axis {axis}: {fd} vs {}",
                    g[k][axis]
                );
            }
        }
    }
}
