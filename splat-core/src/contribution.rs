//! Each splat's contribution to a view: the sum over the view's pixels of its blending weight
//! wᵢ = Tᵢ·αᵢ, the share of the pixel's colour it supplies (Mini-Splatting's importance score;
//! LightGaussian's global significance is the same sum without the transmittance). Summed over
//! the training views it says how much of the images each splat carries, which is what a
//! pruning budget ranks splats by.
//!
//! This is a second walk over the tiles of a forward pass with the forward's own tile loop
//! (`rasterize::walk_tile`), which hands each splat's weights to a sink here: the same alphas,
//! the same 1/255 and transmittance tests, so the weights of a pixel sum to its rendered alpha.
//! A splat budget runs it once per training view for every model it scores, so its speed counts
//! (a scalar per-pixel walk took 7× a forward pass at paper scale).

use rayon::prelude::*;

use crate::disjoint::DisjointWrites;
use crate::rasterize::{TileScratch, WeightSink, walk_tile};
use crate::tiles::LANES;
use crate::{Error, Rasterizer, RenderCamera, RenderOptions, Splats};

impl Rasterizer {
    /// Walks the tiles of `splats` seen from `cam` as a forward pass does and adds each splat's
    /// summed blending weight over the view's pixels to `sums[i]` (f64, so totals over many
    /// views stay exact to the last pixel). No image is resolved: [`Rasterizer::output`] keeps
    /// the last forward pass's, and a backward pass after this runs its forward pass again.
    ///
    /// The weights of one pixel sum to its alpha, so `sums` grows by the view's total alpha. The
    /// result does not depend on the thread count: each tile's weights are gathered on its own
    /// and added in tile order.
    ///
    /// # Errors
    /// As [`Rasterizer::try_forward`]; [`Error::Inconsistent`] when `sums` does not have one
    /// entry per splat.
    pub fn accumulate_contributions(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
        sums: &mut [f64],
    ) -> Result<(), Error> {
        if sums.len() != splats.len() {
            return Err(Error::Inconsistent(format!(
                "{} contribution sums for {} splats",
                sums.len(),
                splats.len()
            )));
        }
        // Projection and tile lists only: the walk below composites each tile itself.
        self.project_and_bin(splats, cam, opts)?;
        let tiles = self.bins.offsets.len().saturating_sub(1);
        // Each (tile, splat) pair's weight, written by its tile's walk into the tile's own run.
        let mut weights = std::mem::take(&mut self.pair_weights);
        weights.resize(self.bins.pairs(), 0.0);
        let runs = DisjointWrites::new(&mut weights);
        let this = &*self;
        (0..tiles)
            .into_par_iter()
            .for_each_init(TileScratch::new, |scratch, tile| {
                let (s, e) = (this.bins.offsets[tile], this.bins.offsets[tile + 1]);
                // SAFETY: [s, e) is this tile's own run of `weights`: the tiles' runs are
                // disjoint (and `run` checks they end inside the vector).
                #[allow(unsafe_code)]
                let weights = unsafe { runs.run(s, e) };
                weights.fill(0.0);
                walk_tile(this, tile, cam, scratch, &mut TileSums { weights });
            });
        let add = |sum: &mut f64, &w: &f64| {
            if w > 0.0 {
                *sum += w;
            }
        };
        self.bins
            .reduce_per_splat(sums, &weights, add, self.use_avx2());
        self.pair_weights = weights;
        Ok(())
    }
}

/// The summed weights of each entry of one tile's list, added pixel by pixel in row-major order
/// (f64, so a splat's total over many pixels and views stays exact to the last pixel).
struct TileSums<'a> {
    weights: &'a mut [f64],
}

impl WeightSink for TileSums<'_> {
    #[inline(always)]
    fn add(&mut self, k: usize, w: &[f32; LANES]) {
        let sum = &mut self.weights[k];
        for &x in w {
            *sum += f64::from(x);
        }
    }
}

#[cfg(test)]
mod tests {
    use camera_model::{Camera, Intrinsics, Pose};
    use glam::{DVec3, Vec3};

    use super::*;

    fn camera(size: u32) -> RenderCamera {
        let cam = Camera::new(
            Intrinsics::from_fov_y(size, size, 50.0),
            Pose::look_at(DVec3::new(0.3, 0.2, 4.0), DVec3::ZERO, DVec3::Y),
        );
        RenderCamera::try_from(&cam).unwrap()
    }

    fn random_splats(n: usize, seed: u64) -> Splats {
        // A small SplitMix generator: the test needs varied splats, not a particular stream.
        let mut s = seed;
        let mut next = move || {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
        };
        let means: Vec<Vec3> = (0..n)
            .map(|_| Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 2.0)
            .collect();
        let colours: Vec<[f32; 3]> = (0..n).map(|_| [next(), next(), next()]).collect();
        let scales: Vec<Vec3> = (0..n)
            .map(|_| {
                Vec3::new(
                    0.02 + 0.1 * next(),
                    0.02 + 0.1 * next(),
                    0.02 + 0.1 * next(),
                )
            })
            .collect();
        let mut s = Splats::from_points(&means, &colours, &scales, None, 0.7, 0).unwrap();
        for (i, o) in s.opacity_logits.iter_mut().enumerate() {
            *o += (i % 5) as f32 - 2.0;
        }
        s
    }

    /// The weights of every pixel sum to its alpha, so the splats' sums add up to the alpha
    /// image the (vectorised) forward pass rendered.
    #[test]
    fn contributions_add_up_to_the_rendered_alpha() {
        let splats = random_splats(400, 7);
        let cam = camera(61);
        let opts = RenderOptions::default();
        let mut r = Rasterizer::new();
        let mut sums = vec![0.0; splats.len()];
        r.accumulate_contributions(&splats, &cam, &opts, &mut sums)
            .unwrap();
        let rendered = r.forward(&splats, &cam, &opts);
        let alpha: f64 = rendered.alpha.iter().map(|&a| f64::from(a)).sum();
        let total: f64 = sums.iter().sum();
        assert!(alpha > 100.0, "the view should be well covered: {alpha}");
        assert!(
            (total - alpha).abs() < 1e-4 * alpha,
            "contributions {total} against alpha {alpha}"
        );
        assert!(sums.iter().all(|&w| w >= 0.0));
    }

    /// Each splat's weight against a direct per-pixel walk (every pixel of a tile over its
    /// whole list, in f64, with the forward pass's thresholds), written independently of the
    /// vector tile loop.
    #[test]
    fn each_splat_matches_a_direct_per_pixel_walk() {
        use crate::constants::{MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};
        let splats = random_splats(300, 9);
        let cam = camera(47);
        let opts = RenderOptions::default();
        let mut r = Rasterizer::new();
        let mut sums = vec![0.0; splats.len()];
        r.accumulate_contributions(&splats, &cam, &opts, &mut sums)
            .unwrap();
        r.forward(&splats, &cam, &opts);
        let tiles_x = cam.width.div_ceil(crate::TILE_SIZE);
        let mut truth = vec![0.0_f64; splats.len()];
        for tile in 0..r.bins.offsets.len() - 1 {
            let list = &r.bins.list[r.bins.offsets[tile]..r.bins.offsets[tile + 1]];
            let (x0, y0, tw, th) =
                crate::rasterize::tile_extent(tile, tiles_x, cam.width, cam.height);
            for py in y0..y0 + th {
                for px in x0..x0 + tw {
                    let mut t = 1.0_f64;
                    for &sid in list {
                        let p = &r.proj[sid as usize];
                        let dx = f64::from(p.xy[0]) - f64::from(px);
                        let dy = f64::from(p.xy[1]) - f64::from(py);
                        let [a, b, c] = p.conic.map(f64::from);
                        let power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy;
                        if power > 0.0 {
                            continue;
                        }
                        let alpha = (f64::from(p.opacity) * power.exp()).min(f64::from(MAX_ALPHA));
                        if alpha < f64::from(MIN_ALPHA) {
                            continue;
                        }
                        if t * (1.0 - alpha) < f64::from(MIN_TRANSMITTANCE) {
                            break;
                        }
                        truth[sid as usize] += alpha * t;
                        t *= 1.0 - alpha;
                    }
                }
            }
        }
        let total: f64 = truth.iter().sum();
        assert!(total > 50.0, "the view should be well covered: {total}");
        for (i, (&ours, &want)) in sums.iter().zip(&truth).enumerate() {
            assert!(
                (ours - want).abs() <= 1e-4 * want.max(1e-3),
                "splat {i}: {ours} against {want}"
            );
        }
    }

    /// One splat alone: its contribution is its alpha image's sum. A second, identical splat
    /// straight behind it gets (1 − α) of each of the first's weights, pixel by pixel.
    #[test]
    fn an_occluded_copy_gets_the_transmitted_share() {
        let means = [Vec3::ZERO, Vec3::new(0.0, 0.0, -0.5)];
        let colours = [[1.0, 0.0, 0.0]; 2];
        let scales = [Vec3::splat(0.2); 2];
        let splats = Splats::from_points(&means, &colours, &scales, None, 0.5, 0).unwrap();
        let front =
            Splats::from_points(&means[..1], &colours[..1], &scales[..1], None, 0.5, 0).unwrap();
        let cam = RenderCamera::try_from(&Camera::new(
            Intrinsics::from_fov_y(48, 48, 30.0),
            Pose::look_at(DVec3::new(0.0, 0.0, 3.0), DVec3::ZERO, DVec3::Y),
        ))
        .unwrap();
        let opts = RenderOptions::default();
        let mut r = Rasterizer::new();
        let mut one = [0.0];
        r.accumulate_contributions(&front, &cam, &opts, &mut one)
            .unwrap();
        let rendered = r.forward(&front, &cam, &opts);
        let alpha_front: Vec<f64> = rendered.alpha.iter().map(|&a| f64::from(a)).collect();
        let alone: f64 = alpha_front.iter().sum();
        assert!((one[0] - alone).abs() < 1e-6 * alone);
        let mut two = [0.0; 2];
        r.accumulate_contributions(&splats, &cam, &opts, &mut two)
            .unwrap();
        assert!(
            (two[0] - alone).abs() < 1e-6 * alone,
            "{} vs {alone}",
            two[0]
        );
        // Behind, the copy is a little smaller on screen (farther away), so its alpha per pixel
        // is its own; the closed form per pixel is α₁·(1 − α₀) summed.
        let back =
            Splats::from_points(&means[1..], &colours[1..], &scales[1..], None, 0.5, 0).unwrap();
        let alpha_back: Vec<f64> = r
            .forward(&back, &cam, &opts)
            .alpha
            .iter()
            .map(|&a| f64::from(a))
            .collect();
        let expected: f64 = alpha_front
            .iter()
            .zip(&alpha_back)
            .map(|(a0, a1)| a1 * (1.0 - a0))
            .sum();
        assert!(
            (two[1] - expected).abs() < 1e-4 * expected,
            "{} vs {expected}",
            two[1]
        );
    }

    #[test]
    fn independent_of_the_thread_count() {
        let splats = random_splats(300, 3);
        let cam = camera(64);
        let opts = RenderOptions::default();
        let run = |threads| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut sums = vec![0.0; splats.len()];
                    Rasterizer::new()
                        .accumulate_contributions(&splats, &cam, &opts, &mut sums)
                        .unwrap();
                    sums
                })
        };
        let one = run(1);
        assert_eq!(one, run(3));
    }

    #[test]
    fn refuses_sums_of_the_wrong_length() {
        let splats = random_splats(10, 1);
        let mut sums = vec![0.0; 9];
        let err = Rasterizer::new()
            .accumulate_contributions(&splats, &camera(16), &RenderOptions::default(), &mut sums)
            .unwrap_err();
        assert!(
            err.to_string()
                .contains("9 contribution sums for 10 splats")
        );
    }
}
