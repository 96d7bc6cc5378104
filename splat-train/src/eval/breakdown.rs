//! Where a view's error comes from: the error split by region of the reference's coverage, its
//! alpha part, and the object-only ("masked") PSNR.
//!
//! On a background `b` the reference is `R = C_r + (1 − A_r)·b` and the render
//! `M = C_m + (1 − A_m)·b` (colours premultiplied), so the error is `ΔC − ΔA·b`: on black it is
//! the colour error alone, on white `ΔC − ΔA`. A coverage error that black hides (a dark splat
//! where the reference is empty, a hole in a dark surface) shows on white at full contrast. The
//! split below measures each part per region, so a gap between the two backgrounds can be traced
//! to the silhouette, the interior or free space, and to alpha or colour.

use serde::{Deserialize, Serialize};

use crate::metrics::psnr_from_mse;

/// Coverage above which a pixel counts as showing something, for the masked PSNR: the smallest
/// step an 8-bit image can show.
pub const MASKED_ALPHA: f32 = 1.0 / 255.0;

/// Coverage below which a reference pixel counts as empty, and above `1 − EMPTY` as full, when
/// pixels are put in regions.
const EMPTY: f32 = 1e-3;

/// A region's share of a view's error. The `mse_*` fields are contributions to the whole
/// image's mean squared error (the region's summed squared error divided by the image's value
/// count), so the three regions of a view add up to its MSE.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionError {
    /// Pixels in the region.
    pub pixels: usize,
    /// Contribution to the MSE on black (colour error).
    pub mse_black: f64,
    /// Contribution to the MSE on white.
    pub mse_white: f64,
    /// Contribution of the coverage error alone, `Σ (A_m − A_r)² / N` over the region's pixels:
    /// what the white MSE would gain if the colour were exact.
    pub mse_alpha: f64,
    /// Signed coverage error `Σ (A_m − A_r) / N` over the region's pixels: negative when the
    /// render covers less than the reference (eroded edges, holes), positive when more (halos).
    #[serde(default)]
    pub alpha_bias: f64,
}

/// A view's error by region of the reference's coverage in each pixel's 3×3 neighbourhood.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ErrorBreakdown {
    /// Fully covered neighbourhoods: the object's inside.
    pub interior: RegionError,
    /// Neighbourhoods with both covered and uncovered or partly covered pixels: the
    /// silhouette, and the rims of any holes in the reference.
    pub silhouette: RegionError,
    /// Empty neighbourhoods: free space, where any rendered coverage is a floater or a halo.
    pub background: RegionError,
}

impl ErrorBreakdown {
    /// The three regions.
    #[must_use]
    pub fn regions(&self) -> [(&'static str, &RegionError); 3] {
        [
            ("interior", &self.interior),
            ("silhouette", &self.silhouette),
            ("background", &self.background),
        ]
    }

    /// Element-wise mean of several breakdowns (pixel counts are summed).
    #[must_use]
    pub fn mean<'a>(all: impl IntoIterator<Item = &'a ErrorBreakdown>) -> ErrorBreakdown {
        let mut sum = ErrorBreakdown::default();
        let mut n = 0usize;
        for b in all {
            n += 1;
            for (s, r) in [
                (&mut sum.interior, &b.interior),
                (&mut sum.silhouette, &b.silhouette),
                (&mut sum.background, &b.background),
            ] {
                s.pixels += r.pixels;
                s.mse_black += r.mse_black;
                s.mse_white += r.mse_white;
                s.mse_alpha += r.mse_alpha;
                s.alpha_bias += r.alpha_bias;
            }
        }
        let n = n.max(1) as f64;
        for s in [&mut sum.interior, &mut sum.silhouette, &mut sum.background] {
            s.mse_black /= n;
            s.mse_white /= n;
            s.mse_alpha /= n;
            s.alpha_bias /= n;
        }
        sum
    }
}

/// One view on both backgrounds, as the breakdown and the masked PSNR need it.
pub(crate) struct Pair<'a> {
    /// Width of the images.
    pub width: usize,
    /// Reference coverage (W·H).
    pub reference_alpha: &'a [f32],
    /// Rendered coverage (W·H).
    pub rendered_alpha: &'a [f32],
    /// Reference over black and over white (3·W·H each).
    pub reference: [&'a [f32]; 2],
    /// Render over black and over white (3·W·H each).
    pub rendered: [&'a [f32]; 2],
}

/// The breakdown of one view, and its masked PSNR on black and on white: the PSNR over the
/// pixels where the reference or the render has coverage above [`MASKED_ALPHA`] (infinite when
/// there is no such pixel).
pub(crate) fn analyse(p: &Pair<'_>) -> (ErrorBreakdown, [f64; 2]) {
    let n = p.reference_alpha.len();
    let w = p.width.max(1);
    let h = n / w;
    let values = (3 * n).max(1) as f64;
    let mut out = ErrorBreakdown::default();
    let mut masked = [0.0f64; 2];
    let mut masked_values = 0usize;
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for ny in y.saturating_sub(1)..(y + 2).min(h) {
                for nx in x.saturating_sub(1)..(x + 2).min(w) {
                    let a = p.reference_alpha[ny * w + nx];
                    lo = lo.min(a);
                    hi = hi.max(a);
                }
            }
            let region = if lo >= 1.0 - EMPTY {
                &mut out.interior
            } else if hi <= EMPTY {
                &mut out.background
            } else {
                &mut out.silhouette
            };
            let sq = |k: usize| -> f64 {
                (3 * i..3 * i + 3)
                    .map(|j| f64::from(p.rendered[k][j] - p.reference[k][j]).powi(2))
                    .sum()
            };
            let (black, white) = (sq(0), sq(1));
            let da = f64::from(p.rendered_alpha[i] - p.reference_alpha[i]);
            region.pixels += 1;
            region.mse_black += black / values;
            region.mse_white += white / values;
            region.mse_alpha += da * da / n as f64;
            region.alpha_bias += da / n as f64;
            if p.reference_alpha[i] > MASKED_ALPHA || p.rendered_alpha[i] > MASKED_ALPHA {
                masked[0] += black;
                masked[1] += white;
                masked_values += 3;
            }
        }
    }
    let masked_psnr = masked.map(|sse| {
        psnr_from_mse(if masked_values == 0 {
            0.0
        } else {
            sse / masked_values as f64
        })
    });
    (out, masked_psnr)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 4×3 image, hand-computed: the regions, their contributions adding up to the MSE, and
    /// the masked PSNR over the covered pixels only.
    #[test]
    fn regions_add_up_to_the_mse_and_the_mask_keeps_covered_pixels() {
        // Reference coverage of a 5×3 image: columns 0 and 1 empty, 2 to 4 full.
        let w = 5;
        let ra: Vec<f32> = (0..15)
            .map(|i| if i % w >= 2 { 1.0 } else { 0.0 })
            .collect();
        // The render matches colour everywhere but misses coverage at pixel (4, 1) by 0.5 and
        // has a faint 0.1 halo at (0, 0).
        let mut ma = ra.clone();
        ma[w + 4] = 0.5;
        ma[0] = 0.1;
        let grey = 0.4f32;
        let on = |alpha: &[f32], bg: f32| -> Vec<f32> {
            alpha
                .iter()
                .flat_map(|&a| [grey * a + bg * (1.0 - a); 3])
                .collect()
        };
        let (rb, rw, mb, mw) = (on(&ra, 0.0), on(&ra, 1.0), on(&ma, 0.0), on(&ma, 1.0));
        let (b, masked) = analyse(&Pair {
            width: w,
            reference_alpha: &ra,
            rendered_alpha: &ma,
            reference: [&rb, &rw],
            rendered: [&mb, &mw],
        });
        // Column 0 sees only empty pixels, columns 1 and 2 both kinds, 3 and 4 only full ones.
        assert_eq!(
            (b.background.pixels, b.silhouette.pixels, b.interior.pixels),
            (3, 6, 6)
        );
        // Interior miss at (4,1): black error 0.4·0.5 per channel, white (0.4 − 1)·0.5.
        let n = 15.0f64;
        let close = |a: f64, b: f64| (a - b).abs() < 1e-7;
        assert!(close(b.interior.mse_black, 3.0 * 0.04 / (3.0 * n)));
        assert!(close(b.interior.mse_white, 3.0 * 0.09 / (3.0 * n)));
        assert!(close(b.interior.mse_alpha, 0.25 / n));
        assert!(close(b.interior.alpha_bias, -0.5 / n));
        assert!(close(b.background.alpha_bias, 0.1 / n));
        // Halo at (0, 0): 0.4·0.1 on black, (0.4 − 1)·0.1 on white.
        assert!(close(b.background.mse_black, 3.0 * 0.0016 / (3.0 * n)));
        assert!(close(b.background.mse_white, 3.0 * 0.0036 / (3.0 * n)));
        assert_eq!(b.silhouette.mse_black, 0.0);
        // The regions add up to the images' MSE.
        let total_black: f64 = b.regions().iter().map(|r| r.1.mse_black).sum();
        let mse = crate::metrics::mse(&mb, &rb);
        assert!(close(total_black, mse), "{total_black} {mse}");
        // Masked: pixels with coverage in either, 9 full + (0,0) = 10 pixels, 30 values.
        let expected_black = psnr_from_mse((3.0 * 0.04 + 3.0 * 0.0016) / 30.0);
        assert!((masked[0] - expected_black).abs() < 1e-5, "{masked:?}");
        // The mean of one breakdown is itself.
        assert_eq!(ErrorBreakdown::mean([&b]), b);
    }
}
