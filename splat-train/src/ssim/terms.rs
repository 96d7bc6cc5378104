//! The SSIM map and its partials pixel by pixel, and the row kernels around them: the
//! products the window sums need, the map over a row, a row of the gradient.

use super::{C1, C2};

/// Lanes of the per-row sums of the SSIM map.
const LANES: usize = 8;

/// The products x², y², xy of one row's values, into `dst`. The AVX2 instantiation where the
/// CPU has it (as each kernel here: the same operations, so the same values).
pub(super) fn square_products(x: &[f32], y: &[f32], dst: [&mut [f32]; 3], avx2: bool) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { square_products_avx2(x, y, dst) };
    }
    let _ = avx2;
    square_products_impl(x, y, dst);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn square_products_avx2(x: &[f32], y: &[f32], dst: [&mut [f32]; 3]) {
    square_products_impl(x, y, dst);
}

#[inline(always)]
fn square_products_impl(x: &[f32], y: &[f32], [xx, yy, xy]: [&mut [f32]; 3]) {
    for ((((xx, yy), xy), &x), &y) in xx.iter_mut().zip(yy).zip(xy).zip(x).zip(y) {
        *xx = x * x;
        *yy = y * y;
        *xy = x * y;
    }
}

/// The SSIM map over one row's span from its window means `[μx, μy, E[x²], E[y²], E[xy]]`;
/// with `grads`, also writes the map's partials ∂/∂μx (with the chain through σx² and σxy),
/// ∂/∂E[x²] and ∂/∂E[xy]. Returns the map's sum in f64, kept per lane and the lanes added in
/// order (one running sum was a chain of dependent additions that kept the loop scalar).
pub(super) fn map_row(means: [&[f32]; 5], grads: Option<[&mut [f32]; 3]>, avx2: bool) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { map_row_avx2(means, grads) };
    }
    let _ = avx2;
    map_row_impl(means, grads)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn map_row_avx2(means: [&[f32]; 5], grads: Option<[&mut [f32]; 3]>) -> f64 {
    map_row_impl(means, grads)
}

#[inline(always)]
fn map_row_impl(means: [&[f32]; 5], mut grads: Option<[&mut [f32]; 3]>) -> f64 {
    let n = means.iter().map(|m| m.len()).min().unwrap_or(0);
    let mut lanes = [0.0_f64; LANES];
    // Whole groups of lanes through fixed-size copies (vectorised), then the rest one by one.
    let mut j0 = 0;
    while j0 < n {
        let len = LANES.min(n - j0);
        let mut m = [[0.0_f32; LANES]; 5];
        for (m, src) in m.iter_mut().zip(&means) {
            m[..len].copy_from_slice(&src[j0..j0 + len]);
        }
        let mut map = [0.0_f32; LANES];
        let mut partials = [[0.0_f32; LANES]; 3];
        for l in 0..LANES {
            let t = MapTerms::new([m[0][l], m[1][l], m[2][l], m[3][l], m[4][l]]);
            map[l] = t.map;
            [partials[0][l], partials[1][l], partials[2][l]] = t.partials();
        }
        for l in 0..len {
            lanes[l] += f64::from(map[l]);
        }
        if let Some(grads) = grads.as_mut() {
            for (g, p) in grads.iter_mut().zip(&partials) {
                g[j0..j0 + len].copy_from_slice(&p[..len]);
            }
        }
        j0 += LANES;
    }
    lanes.iter().sum()
}

/// The terms of the SSIM map at one value: SSIM = A1·A2 / (B1·B2) with A1 = 2μxμy + C1,
/// A2 = 2σxy + C2, B1 = μx² + μy² + C1, B2 = σx² + σy² + C2, σx² = E[x²] − μx²,
/// σxy = E[xy] − μxμy.
struct MapTerms {
    mu_x: f32,
    mu_y: f32,
    a1: f32,
    a2: f32,
    b1: f32,
    b2: f32,
    map: f32,
}

impl MapTerms {
    /// The terms from the window means `[μx, μy, E[x²], E[y²], E[xy]]`.
    #[inline(always)]
    fn new([mu_x, mu_y, exx, eyy, exy]: [f32; 5]) -> Self {
        let sxx = exx - mu_x * mu_x;
        let syy = eyy - mu_y * mu_y;
        let sxy = exy - mu_x * mu_y;
        let a1 = 2.0 * mu_x * mu_y + C1;
        let a2 = 2.0 * sxy + C2;
        let b1 = mu_x * mu_x + mu_y * mu_y + C1;
        let b2 = sxx + syy + C2;
        Self {
            mu_x,
            mu_y,
            a1,
            a2,
            b1,
            b2,
            map: (a1 * a2) / (b1 * b2),
        }
    }

    /// The map's partials ∂/∂μx (with the chain through σx² and σxy), ∂/∂E[x²], ∂/∂E[xy].
    #[inline(always)]
    fn partials(&self) -> [f32; 3] {
        let Self {
            mu_x,
            mu_y,
            a1,
            a2,
            b1,
            b2,
            map,
        } = *self;
        let inv = 1.0 / (b1 * b2);
        let g_sxx = -map / b2;
        let g_sxy = 2.0 * a1 * inv;
        let g_mu = 2.0 * mu_y * a2 * inv - map * 2.0 * mu_x / b1;
        [g_mu - 2.0 * mu_x * g_sxx - mu_y * g_sxy, g_sxx, g_sxy]
    }
}

/// Adds `k` times the gradient of one row's span into `out`: from the blurred partials
/// `[∂/∂μx, ∂/∂E[x²], ∂/∂E[xy]]` and the images `[x, y]`.
pub(super) fn add_gradient_row(
    out: &mut [f32],
    images: [&[f32]; 2],
    partials: [&[f32]; 3],
    k: f32,
    avx2: bool,
) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { add_gradient_row_avx2(out, images, partials, k) };
    }
    let _ = avx2;
    add_gradient_row_impl(out, images, partials, k);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn add_gradient_row_avx2(out: &mut [f32], images: [&[f32]; 2], partials: [&[f32]; 3], k: f32) {
    add_gradient_row_impl(out, images, partials, k);
}

#[inline(always)]
fn add_gradient_row_impl(
    out: &mut [f32],
    [x, y]: [&[f32]; 2],
    [dm, dxx, dxy]: [&[f32]; 3],
    k: f32,
) {
    for (((((o, &x), &y), &dm), &dxx), &dxy) in
        out.iter_mut().zip(x).zip(y).zip(dm).zip(dxx).zip(dxy)
    {
        *o += k * (dm + 2.0 * x * dxx + y * dxy);
    }
}
