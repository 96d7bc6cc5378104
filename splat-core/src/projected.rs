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
