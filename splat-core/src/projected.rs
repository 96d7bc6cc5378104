//! A visible splat as projection leaves it for the tile loops, and the alpha cutoff of its
//! Gaussian.

/// What the compositor needs of a visible splat, packed for the per-tile loop.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Projected {
    /// Centre in pixel-index coordinates (pixel centres at integers: mean2d − 0.5).
    pub xy: [f32; 2],
    /// Inverse 2D covariance (a, b, c) of [[a, b], [b, c]].
    pub conic: [f32; 3],
    /// Effective opacity (sigmoid, times the antialiasing compensation when enabled).
    pub opacity: f32,
    /// View-dependent colour, clamped at 0.
    pub color: [f32; 3],
    /// Camera-space depth.
    pub depth: f32,
    /// Bound on the conic's quadratic form beyond which alpha < 1/255 ([`quad_bound`]).
    pub q_max: f32,
}

/// The bound on the conic's quadratic form beyond which alpha < 1/255: o·e^(−q/2) ≥ 1/255
/// ⇔ q ≤ 2·ln(255·o); with a small relative margin so float rounding (and [`bound_ln`]'s
/// error, below 1e-6) never drops a pixel.
#[inline(always)]
pub(crate) fn quad_bound(opacity: f32) -> f32 {
    2.0 * bound_ln(255.0 * opacity) * 1.001 + 1e-3
}

/// ln x, branch-free and without a library call, so that the projection's lanes compute it as
/// vectors (`logf` was a call per lane, a seventh of the projection's instructions). Absolute
/// error below 1e-6 for x in [1, 255], the arguments the alpha bound sees (opacities of 1/255
/// to 1); other inputs give some finite or non-finite number and no panic.
///
/// x = m·2ᵉ with m in [√½, √2), and ln m = 2·atanh(s) with s = (m − 1)/(m + 1), |s| ≤ 0.172:
/// the series to s⁹ leaves a truncation error below 1e-9.
#[inline(always)]
fn bound_ln(x: f32) -> f32 {
    use std::f32::consts::LN_2;
    /// The bits of √½ rounded down: subtracted from x's bits, the exponent field holds e.
    const SQRT_HALF_BITS: u32 = 0x3f35_04f3;
    let bits = x.to_bits();
    let e = bits.wrapping_sub(SQRT_HALF_BITS).cast_signed() >> 23;
    let m = f32::from_bits(bits.wrapping_sub(e.cast_unsigned() << 23));
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    let series = s2 * (1.0 / 3.0 + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0))));
    (2.0 * s + 2.0 * s * series) + e as f32 * LN_2
}

/// A random screen-space footprint for the tests of the tile bounds: axes of 0.2 to `max_axis`
/// pixels at a random angle, plus the 0.3 px² dilation. Returns the covariance (xx, yy, xy)
/// and its inverse, the conic (a, b, c), both in f64.
#[cfg(test)]
pub(crate) fn random_footprint(rng: &mut impl rand::Rng, max_axis: f64) -> ([f64; 3], [f64; 3]) {
    use rand::RngExt;
    let axes = [
        rng.random_range(0.2..max_axis),
        rng.random_range(0.2..max_axis),
    ];
    footprint(axes, rng.random_range(0.0..std::f64::consts::PI))
}

/// The footprint with standard deviations `axes` (pixels), the first along angle `theta`,
/// plus the 0.3 px² dilation: covariance (xx, yy, xy) and conic (a, b, c), in f64.
#[cfg(test)]
pub(crate) fn footprint([s1, s2]: [f64; 2], theta: f64) -> ([f64; 3], [f64; 3]) {
    let (c, s) = (theta.cos(), theta.sin());
    let cxx = c * c * s1 * s1 + s * s * s2 * s2 + 0.3;
    let cyy = s * s * s1 * s1 + c * c * s2 * s2 + 0.3;
    let cxy = c * s * (s1 * s1 - s2 * s2);
    let det = cxx * cyy - cxy * cxy;
    ([cxx, cyy, cxy], [cyy / det, -cxy / det, cxx / det])
}

#[cfg(test)]
mod tests {
    use super::{bound_ln, quad_bound};

    /// `bound_ln` against f64's logarithm over every argument the alpha bound sees (a dense
    /// sweep of [1, 255] and every f32 just around 1, where the exponent split changes), and the
    /// bound it gives never below the exact 2·ln(255·o) for opacities from 1/255 to 1.
    #[test]
    fn the_alpha_bound_s_logarithm_is_accurate_and_the_bound_conservative() {
        let mut worst = 0.0_f64;
        let near_one = (0..2000).map(|i| f32::from_bits(1.0_f32.to_bits() - 1000 + i));
        let sweep = (0..=1_000_000).map(|i| 1.0 + 254.0 * (i as f32 / 1e6));
        for x in near_one.chain(sweep) {
            let err = (f64::from(bound_ln(x)) - f64::from(x).ln()).abs();
            worst = worst.max(err);
        }
        assert!(worst < 1e-6, "worst absolute error {worst}");
        for i in 0..=100_000 {
            let o = (1.0 / 255.0) + (1.0 - 1.0 / 255.0) * (i as f32 / 1e5);
            let exact = 2.0 * (255.0 * f64::from(o)).ln();
            assert!(f64::from(quad_bound(o)) >= exact + 1e-4, "opacity {o}");
        }
        // Off its range it neither panics nor needs to be right.
        for x in [0.0, -1.0, f32::NAN, f32::INFINITY, 1e-40, 3e38] {
            let _ = bound_ln(x);
        }
    }
}
