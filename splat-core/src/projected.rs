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
/// ⇔ q ≤ 2·ln(255·o); with a small relative margin so float rounding never drops a pixel.
#[inline]
pub(crate) fn quad_bound(opacity: f32) -> f32 {
    2.0 * (255.0 * opacity).ln() * 1.001 + 1e-3
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
