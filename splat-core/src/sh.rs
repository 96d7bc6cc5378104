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
    let mut g = [[0.0_f32; 3]; 16];
    basis_grad_terms(degree, dir.into(), out, &mut g);
    let n = num_sh_coeffs(degree).min(grad.len());
    for (d, s) in grad[..n].iter_mut().zip(&g) {
        *d = Vec3::from(*s);
    }
}

/// [`basis_grad`] on any [`Real`] whose lanes hold f32.
#[inline(always)]
pub(crate) fn basis_grad_terms<T: Real<Scalar = f32>>(
    degree: u32,
    [x, y, z]: [T; 3],
    out: &mut [T],
    grad: &mut [[T; 3]],
) {
    basis_terms(degree, [x, y, z], out);
    let c = T::splat;
    let zero = c(0.0);
    // `k·(a, b, c)`, as `f32 * Vec3` computes it.
    let scaled = |k: f32, v: [T; 3]| [c(k) * v[0], c(k) * v[1], c(k) * v[2]];
    grad[0] = [zero; 3];
    if degree < 1 {
        return;
    }
    grad[1] = [zero, c(-C1), zero];
    grad[2] = [zero, zero, c(C1)];
    grad[3] = [c(-C1), zero, zero];
    if degree < 2 {
        return;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    grad[4] = scaled(C2[0], [y, x, zero]);
    grad[5] = scaled(C2[1], [zero, z, y]);
    grad[6] = scaled(C2[2], [c(-2.0) * x, c(-2.0) * y, c(4.0) * z]);
    grad[7] = scaled(C2[3], [z, zero, x]);
    grad[8] = scaled(C2[4], [c(2.0) * x, c(-2.0) * y, zero]);
    if degree < 3 {
        return;
    }
    grad[9] = scaled(C3[0], [c(6.0) * x * y, c(3.0) * xx - c(3.0) * yy, zero]);
    grad[10] = scaled(C3[1], [y * z, x * z, x * y]);
    grad[11] = scaled(
        C3[2],
        [
            c(-2.0) * x * y,
            c(4.0) * zz - xx - c(3.0) * yy,
            c(8.0) * y * z,
        ],
    );
    grad[12] = scaled(
        C3[3],
        [
            c(-6.0) * x * z,
            c(-6.0) * y * z,
            c(6.0) * zz - c(3.0) * xx - c(3.0) * yy,
        ],
    );
    grad[13] = scaled(
        C3[4],
        [
            c(4.0) * zz - c(3.0) * xx - yy,
            c(-2.0) * x * y,
            c(8.0) * x * z,
        ],
    );
    grad[14] = scaled(C3[5], [c(2.0) * x * z, c(-2.0) * y * z, xx - yy]);
    grad[15] = scaled(C3[6], [c(3.0) * xx - c(3.0) * yy, c(-6.0) * x * y, zero]);
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
#[inline(always)]
pub fn eval_backward(
    degree: u32,
    dir: Vec3,
    coeffs: &[[f32; 3]],
    d_out: Vec3,
    d_coeffs: &mut [[f32; 3]],
) -> Vec3 {
    let n = num_sh_coeffs(degree);
    let d_dir = eval_backward_terms(
        degree,
        n,
        dir.into(),
        |k| coeffs[k],
        d_out.into(),
        |k, dc| {
            for (d, v) in d_coeffs[k].iter_mut().zip(dc) {
                *d += v;
            }
        },
    );
    d_dir.into()
}

/// [`eval_backward`] on any [`Real`] whose lanes hold f32, over the first `n` coefficients
/// (the k-th given by `coeff(k)`): hands `d_coeff` each coefficient's gradient
/// `basis_k·d_out` and returns dL/d(dir), through [`dir_jacobian_terms`] and [`dir_grad`] as
/// the rasteriser's chain computes it.
#[inline(always)]
pub(crate) fn eval_backward_terms<T: Real<Scalar = f32>>(
    degree: u32,
    n: usize,
    dir: [T; 3],
    coeff: impl Fn(usize) -> [T; 3],
    d_out: [T; 3],
    d_coeff: impl FnMut(usize, [T; 3]),
) -> [T; 3] {
    coeff_grad_terms(degree, n, dir, d_out, d_coeff);
    dir_grad(&dir_jacobian_terms(degree, n, dir, coeff), d_out)
}

/// Hands `d_coeff` the gradient `basis_k·d_out` of each of the first `n` coefficients.
#[inline(always)]
pub(crate) fn coeff_grad_terms<T: Real<Scalar = f32>>(
    degree: u32,
    n: usize,
    dir: [T; 3],
    d_out: [T; 3],
    mut d_coeff: impl FnMut(usize, [T; 3]),
) {
    let mut b = [T::splat(0.0); 16];
    basis_terms(degree, dir, &mut b);
    for (k, &bk) in b.iter().enumerate().take(n) {
        d_coeff(k, [bk * d_out[0], bk * d_out[1], bk * d_out[2]]);
    }
}

/// The Jacobian of [`eval`]'s colour with respect to the direction: row `ch` is
/// Σ_k coeff(k)\[ch\]·∂basis_k/∂dir over the first `n` coefficients. It depends on the
/// coefficients and the direction only, so the projection forms it in its lanes and the
/// backward needs no coefficients ([`dir_grad`]).
#[inline(always)]
pub(crate) fn dir_jacobian_terms<T: Real<Scalar = f32>>(
    degree: u32,
    n: usize,
    dir: [T; 3],
    coeff: impl Fn(usize) -> [T; 3],
) -> [[T; 3]; 3] {
    let mut b = [T::splat(0.0); 16];
    let mut g = [[T::splat(0.0); 3]; 16];
    basis_grad_terms(degree, dir, &mut b, &mut g);
    let mut j = [[T::splat(0.0); 3]; 3];
    for (k, gk) in g.iter().enumerate().take(n) {
        let c = coeff(k);
        for (row, ck) in j.iter_mut().zip(c) {
            for (e, ga) in row.iter_mut().zip(gk) {
                *e = *e + ck * *ga;
            }
        }
    }
    j
}

/// dL/d(dir) = Jᵀ·d_out for the colour Jacobian `j` of [`dir_jacobian_terms`].
#[inline(always)]
pub(crate) fn dir_grad<T: Real<Scalar = f32>>(j: &[[T; 3]; 3], d_out: [T; 3]) -> [T; 3] {
    std::array::from_fn(|a| j[0][a] * d_out[0] + j[1][a] * d_out[1] + j[2][a] * d_out[2])
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
