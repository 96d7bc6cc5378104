//! Rasteriser options, outputs and gradients.

use glam::Vec3;
use rayon::prelude::*;

use crate::Splats;

/// How to render.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Colour behind the splats (seen where transmittance remains).
    pub background: Vec3,
    /// SH degree to evaluate (clamped to the model's degree); lower bands are used as stored.
    pub active_sh_degree: u32,
    /// gsplat's antialiased mode: opacity multiplied by √(det Σ₂ / det(Σ₂ + 0.3·I)).
    pub antialiased: bool,
    /// Colour is the SH sum alone, without the +0.5 offset and the clamp at 0, so that with
    /// geometry and opacity fixed the image is a linear function of the SH coefficients (the
    /// least-squares colour solve renders this way). Off for every ordinary render.
    pub linear_colour: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            background: Vec3::ZERO,
            active_sh_degree: 3,
            antialiased: false,
            linear_colour: false,
        }
    }
}

/// One rendered view.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RenderOutput {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Colour, interleaved RGB, row-major, top row first (3·W·H).
    pub rgb: Vec<f32>,
    /// Coverage 1 − T per pixel (W·H).
    pub alpha: Vec<f32>,
    /// Expected camera-space depth Σ wᵢ zᵢ / Σ wᵢ per pixel, 0 where alpha is below 1e-6 (W·H).
    pub depth: Vec<f32>,
}

/// Gradients of a loss with respect to every splat parameter (same layout as [`Splats`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatGrads {
    /// dL/d mean.
    pub means: Vec<Vec3>,
    /// dL/d log-scale.
    pub log_scales: Vec<Vec3>,
    /// dL/d stored (unnormalised) quaternion (w, x, y, z).
    pub rotations: Vec<[f32; 4]>,
    /// dL/d opacity logit.
    pub opacity_logits: Vec<f32>,
    /// dL/d SH coefficient, splat-major like [`Splats::sh`].
    pub sh: Vec<[f32; 3]>,
    /// Σ over backward calls of |dL/d mean2d| in NDC units (pixels × (W/2, H/2)), the quantity
    /// Inria's densification thresholds at 2e-4.
    pub screen_grad_norm: Vec<f32>,
}

impl SplatGrads {
    /// Returns zero gradients shaped like `splats`.
    #[must_use]
    pub fn zeros_like(splats: &Splats) -> Self {
        let mut g = Self::default();
        g.reset(splats);
        g
    }

    /// Whether these gradients are shaped like `splats` (as many splats and SH coefficients).
    #[must_use]
    pub fn fits(&self, splats: &Splats) -> bool {
        let n = splats.len();
        self.means.len() == n
            && self.log_scales.len() == n
            && self.rotations.len() == n
            && self.opacity_logits.len() == n
            && self.sh.len() == splats.sh.len()
            && self.screen_grad_norm.len() == n
    }

    /// Every gradient array as floats, in field order: means, log-scales, rotations, opacity
    /// logits, SH coefficients, screen-space norms.
    #[must_use]
    pub fn float_arrays(&self) -> [&[f32]; 6] {
        [
            bytemuck::cast_slice(&self.means),
            bytemuck::cast_slice(&self.log_scales),
            self.rotations.as_flattened(),
            &self.opacity_logits,
            self.sh.as_flattened(),
            &self.screen_grad_norm,
        ]
    }

    /// Resizes to `splats` and sets every gradient to zero, reusing the allocations (zeroed in
    /// parallel: at 250 k splats of degree 3 these are 60 MB, rewritten before every backward).
    pub fn reset(&mut self, splats: &Splats) {
        let n = splats.len();
        zero_fill(&mut self.means, n, Vec3::ZERO);
        zero_fill(&mut self.log_scales, n, Vec3::ZERO);
        zero_fill(&mut self.rotations, n, [0.0; 4]);
        zero_fill(&mut self.opacity_logits, n, 0.0);
        zero_fill(&mut self.sh, splats.sh.len(), [0.0; 3]);
        zero_fill(&mut self.screen_grad_norm, n, 0.0);
    }
}

/// A range of splats' gradients borrowed from a [`SplatGrads`], array by array: what one task
/// of work chained or updated chunk by chunk writes or reads.
#[derive(Debug)]
pub struct SplatGradsMut<'a> {
    /// dL/d mean.
    pub means: &'a mut [Vec3],
    /// dL/d log-scale.
    pub log_scales: &'a mut [Vec3],
    /// dL/d stored (unnormalised) quaternion (w, x, y, z).
    pub rotations: &'a mut [[f32; 4]],
    /// dL/d opacity logit.
    pub opacity_logits: &'a mut [f32],
    /// dL/d SH coefficient, splat-major.
    pub sh: &'a mut [[f32; 3]],
    /// Σ |dL/d mean2d| in NDC units (see [`SplatGrads::screen_grad_norm`]).
    pub screen_grad_norm: &'a mut [f32],
}

impl SplatGrads {
    /// All of these gradients as one range.
    pub fn as_mut(&mut self) -> SplatGradsMut<'_> {
        SplatGradsMut {
            means: &mut self.means,
            log_scales: &mut self.log_scales,
            rotations: &mut self.rotations,
            opacity_logits: &mut self.opacity_logits,
            sh: &mut self.sh,
            screen_grad_norm: &mut self.screen_grad_norm,
        }
    }

    /// These gradients in ranges of `splats` splats each (the last one shorter when `splats`
    /// does not divide the count), in order, for parallel work.
    ///
    /// # Panics
    /// If `splats` is zero.
    pub fn par_chunks_mut(
        &mut self,
        splats: usize,
    ) -> impl IndexedParallelIterator<Item = SplatGradsMut<'_>> {
        assert!(splats > 0, "SplatGrads::par_chunks_mut: empty ranges");
        // Coefficients a splat (none for an empty model, whose arrays give no ranges anyway).
        let k = self
            .sh
            .len()
            .checked_div(self.means.len())
            .unwrap_or(1)
            .max(1);
        self.means
            .par_chunks_mut(splats)
            .zip(self.log_scales.par_chunks_mut(splats))
            .zip(self.rotations.par_chunks_mut(splats))
            .zip(self.opacity_logits.par_chunks_mut(splats))
            .zip(self.sh.par_chunks_mut(splats * k))
            .zip(self.screen_grad_norm.par_chunks_mut(splats))
            .map(
                |(((((means, log_scales), rotations), opacity_logits), sh), screen_grad_norm)| {
                    SplatGradsMut {
                        means,
                        log_scales,
                        rotations,
                        opacity_logits,
                        sh,
                        screen_grad_norm,
                    }
                },
            )
    }
}

/// Sets `v` to `len` copies of `zero`, the kept part in parallel.
fn zero_fill<T: Copy + Send + Sync>(v: &mut Vec<T>, len: usize, zero: T) {
    v.truncate(len);
    v.par_chunks_mut(1 << 14).for_each(|c| c.fill(zero));
    v.resize(len, zero);
}
