//! The forward pass: project, bin into tiles, composite each tile front to back in parallel.

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;

use crate::bins::Bins;
use crate::constants::{MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::disjoint::DisjointWrites;
use crate::falloff::Falloff;
use crate::lanes::WIDTH;
use crate::prefetch;
use crate::project::{ChainLanes, Cull, Scratch, ViewConsts, project8};
use crate::project_backward::ProjectedGrad;
use crate::projected::Projected;
use crate::spans::RowSpans;
use crate::tiles::{HALF_ROWS, LANES, TILE_PIXELS, TILE_SIZE, evaluated_pixels};
use crate::{Error, RenderCamera, RenderOptions, RenderOutput, Splats};

/// The most pixels a view may have, counted after padding to whole 16×16 tiles: 2²⁶, an
/// 8192 × 8192 image. The forward pass keeps 44 bytes per pixel (transmittance, depth sum,
/// colour and where its compositing stopped per tile pixel, then the RGB, alpha and depth
/// images), so this bounds those buffers at 2.75 GiB; a larger view is refused before anything
/// is allocated rather than aborting the process when an allocation fails (and its tile count
/// cannot overflow).
pub const MAX_PIXELS: u64 = 1 << 26;

/// Bytes the forward pass keeps per (tile-padded) pixel.
const BYTES_PER_PIXEL: u64 = 44;

/// Counts from the last forward pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// Splats drawn in at least one tile.
    pub visible: usize,
    /// Splats culled because an input or intermediate was NaN or infinite.
    pub culled_non_finite: usize,
    /// (tile, splat) pairs composited.
    pub pairs: usize,
    /// (pixel, splat) pairs whose Gaussian was evaluated: every pixel in the image of each
    /// half-row a splat reaches (since session 60; before, only the pixels inside its exact
    /// row spans were counted).
    pub pixel_evaluations: u64,
    /// (pixel, splat) pairs that contributed (passed the alpha and transmittance tests).
    pub contributions: u64,
}

/// Wall time of each phase of the last forward and the last backward pass, for benchmarks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RasterPhases {
    /// Projection of every splat (covariance, conic, extent, SH colour).
    pub project: Duration,
    /// Depth sort and binning into tile lists.
    pub bin: Duration,
    /// Front-to-back compositing of every tile, each tile written into the output images.
    pub composite: Duration,
    /// Back-to-front tile walks writing one gradient record per (tile, splat) pair.
    pub backward_tiles: Duration,
    /// The records summed per splat.
    pub backward_sum: Duration,
    /// Each splat's sum chained through projection, covariance and SH to its parameters.
    pub backward_chain: Duration,
}

/// A reusable CPU rasteriser: buffers grow to the largest view seen and are then reused, so the
/// per-view loop does not allocate once warm.
#[derive(Debug, Default)]
pub struct Rasterizer {
    pub(crate) proj: Vec<Projected>,
    pub(crate) rects: Vec<[u32; 4]>,
    pub(crate) radii: Vec<u32>,
    /// What each visible splat's backward chains through, from the projection.
    /// The projection's intermediates for the backward, eight splats a group.
    pub(crate) chain: Vec<ChainLanes>,
    pub(crate) visible: Vec<bool>,
    non_finite: Vec<bool>,
    pub(crate) bins: Bins,
    /// Final transmittance per pixel, tile-major (tile · 256 + row · 16 + column).
    pub(crate) px_t: Vec<f32>,
    /// Accumulated Σ wᵢ zᵢ per pixel, tile-major.
    pub(crate) px_d: Vec<f32>,
    /// Per pixel, tile-major: where the compositing stopped ([`Finish`]).
    pub(crate) px_finish: Vec<u32>,
    /// Per (tile, splat) pair, in list order: the half-rows (bit `2·row + half`) in which the
    /// forward pass blended the splat into at least one pixel, 0 if none. The backward pass
    /// walks exactly these half-rows (no others pass a gradient) and lets the alpha test and
    /// [`Finish`] decide the lanes, instead of solving the spans again.
    pub(crate) pair_rows: Vec<u32>,
    pub(crate) output: RenderOutput,
    pub(crate) stats: RenderStats,
    pub(crate) phases: RasterPhases,
    /// (splat count, width, height) of the last forward pass.
    pub(crate) last_view: Option<(usize, u32, u32)>,
    pub(crate) pair_grads: Vec<ProjectedGrad>,
    pub(crate) splat_grads: Vec<ProjectedGrad>,
    /// The view of the last `backward_sums`, while its sums stand (a forward pass clears it).
    pub(crate) chain_view: Option<crate::project_backward::ChainView>,
    /// Per (tile, splat) pair: its summed blending weight (`accumulate_contributions`).
    pub(crate) pair_weights: Vec<f64>,
    /// Run the portable tile loops even where AVX2 is available (tests compare the two).
    pub(crate) portable_only: bool,
}

/// Per-pixel compositing state of one tile in the forward pass.
struct TileOut<'a> {
    t: &'a mut [f32],
    d: &'a mut [f32],
    rgb: &'a mut [[f32; 3]],
    finish: &'a mut [u32],
    /// Per entry of the tile's list: the half-rows it was blended into.
    rows: &'a mut [u32],
}

/// The pixel extent of tile `tile`: origin and size (partial at the right and bottom edges).
pub(crate) fn tile_extent(
    tile: usize,
    tiles_x: u32,
    width: u32,
    height: u32,
) -> (i32, i32, i32, i32) {
    let tx = tile as u32 % tiles_x;
    let ty = tile as u32 / tiles_x;
    let x0 = tx * TILE_SIZE;
    let y0 = ty * TILE_SIZE;
    (
        x0 as i32,
        y0 as i32,
        (width - x0).min(TILE_SIZE) as i32,
        (height - y0).min(TILE_SIZE) as i32,
    )
}

impl Rasterizer {
    /// Returns a rasteriser with empty buffers.
    #[must_use]
    pub fn new() -> Self {
        Self::default()
    }

    /// Whether this pass runs the AVX2 instantiations of the tile loops.
    pub(crate) fn use_avx2(&self) -> bool {
        !self.portable_only && has_avx2()
    }

    /// Whether this rasteriser runs the AVX2 tile loops (detected on this CPU at run time) rather
    /// than the portable ones.
    #[must_use]
    pub fn uses_avx2(&self) -> bool {
        self.use_avx2()
    }

    /// Returns the counts of the last forward pass.
    #[must_use]
    pub fn stats(&self) -> RenderStats {
        self.stats
    }

    /// Returns the wall time of each phase of the last forward and backward passes.
    #[must_use]
    pub fn phases(&self) -> RasterPhases {
        self.phases
    }

    /// Returns each splat's screen radius in pixels from the last forward pass (0 when culled).
    #[must_use]
    pub fn radii(&self) -> &[u32] {
        &self.radii
    }

    /// Returns the last rendered view.
    #[must_use]
    pub fn output(&self) -> &RenderOutput {
        &self.output
    }

    /// Checks that a `width` × `height` view fits the per-pixel buffers' limit, [`MAX_PIXELS`].
    ///
    /// # Errors
    /// [`Error::ViewTooLarge`] naming the size and the limit.
    pub fn check_view_size(width: u32, height: u32) -> Result<(), Error> {
        let ts = u64::from(TILE_SIZE);
        // At most 2^28 tiles a side, 2^64 padded pixels: saturate rather than wrap.
        let pixels = (u64::from(width).div_ceil(ts) * u64::from(height).div_ceil(ts))
            .saturating_mul(ts * ts);
        if pixels > MAX_PIXELS {
            return Err(Error::ViewTooLarge {
                width,
                height,
                pixels,
                limit: MAX_PIXELS,
                limit_mib: (MAX_PIXELS * BYTES_PER_PIXEL) >> 20,
            });
        }
        Ok(())
    }

    /// Renders `splats` from `cam`: RGB over the background, alpha = 1 − T, expected depth.
    ///
    /// # Panics
    /// If `splats` is inconsistent (see [`Splats::validate`]) or the view is larger than
    /// [`MAX_PIXELS`]; [`Rasterizer::try_forward`] returns these as errors instead.
    pub fn forward(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
    ) -> &RenderOutput {
        if let Err(e) = self.try_forward(splats, cam, opts) {
            panic!("Rasterizer::forward: {e}");
        }
        &self.output
    }

    /// [`Rasterizer::forward`], with inconsistent splats and oversized views refused up front.
    ///
    /// # Errors
    /// [`Error::Inconsistent`] from [`Splats::validate`], [`Error::ViewTooLarge`] from
    /// [`Rasterizer::check_view_size`].
    pub fn try_forward(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
    ) -> Result<&RenderOutput, Error> {
        let v = self.project_and_bin(splats, cam, opts)?;
        let t2 = Instant::now();
        let (evaluations, contributions) =
            self.composite(cam, v.tiles_x, v.tiles_y, opts.background);
        self.phases.composite = t2.elapsed();
        self.stats = RenderStats {
            visible: self.visible.iter().filter(|&&b| b).count(),
            culled_non_finite: self.non_finite.iter().filter(|&&b| b).count(),
            pairs: self.bins.pairs(),
            pixel_evaluations: evaluations,
            contributions,
        };
        self.last_view = Some((splats.len(), cam.width, cam.height));
        Ok(&self.output)
    }

    /// The first half of a forward pass: checks the inputs, projects every splat and bins the
    /// visible ones into tile lists. The compositing state is then stale, so `last_view` is
    /// cleared until a forward pass completes (a backward pass would otherwise use it).
    pub(crate) fn project_and_bin(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
    ) -> Result<ViewConsts, Error> {
        splats.validate()?;
        Self::check_view_size(cam.width, cam.height)?;
        self.last_view = None;
        self.chain_view = None;
        let v = ViewConsts::new(cam, opts, splats);
        let t0 = Instant::now();
        self.project_all(splats, &v);
        let t1 = Instant::now();
        self.bins
            .build(&self.proj, &self.rects, &self.visible, v.tiles_x, v.tiles_y);
        self.phases.project = t1 - t0;
        self.phases.bin = t1.elapsed();
        Ok(v)
    }

    fn project_all(&mut self, splats: &Splats, v: &ViewConsts) {
        let n = splats.len();
        self.proj.resize(n, Projected::default());
        self.rects.resize(n, [0; 4]);
        self.radii.resize(n, 0);
        self.chain.resize(n.div_ceil(WIDTH), ChainLanes::default());
        self.visible.resize(n, false);
        self.non_finite.resize(n, false);
        let avx2 = self.use_avx2();
        const CHUNK: usize = PROJECT_CHUNK;
        self.proj
            .par_chunks_mut(CHUNK)
            .zip(self.rects.par_chunks_mut(CHUNK))
            .zip(self.radii.par_chunks_mut(CHUNK))
            .zip(self.chain.par_chunks_mut(CHUNK / WIDTH))
            .zip(self.visible.par_chunks_mut(CHUNK))
            .zip(self.non_finite.par_chunks_mut(CHUNK))
            .enumerate()
            .for_each(
                |(c, (((((proj, rects), radii), chain), visible), non_finite))| {
                    let out = ProjectOut {
                        proj,
                        rects,
                        radii,
                        chain,
                        visible,
                        non_finite,
                    };
                    project_chunk(splats, v, c * CHUNK, out, avx2);
                },
            );
    }

    /// Composites every tile and writes it into the row-major output images over `bg` (the
    /// tile's colours stay in a thread's scratch: the backward pass reads only the tile-major
    /// transmittance and depth sums, so a whole-image colour buffer and a second pass over
    /// the image to resolve it were memory traffic for nothing). Returns the (pixel, splat)
    /// evaluations and contributions.
    fn composite(
        &mut self,
        cam: &RenderCamera,
        tiles_x: u32,
        tiles_y: u32,
        bg: Vec3,
    ) -> (u64, u64) {
        let n_px = (tiles_x * tiles_y) as usize * TILE_PIXELS;
        self.px_t.resize(n_px, 1.0);
        self.px_d.resize(n_px, 0.0);
        self.px_finish.resize(n_px, 0);
        let bins = &self.bins;
        let proj = &self.proj;
        let (w, h) = (cam.width, cam.height);
        let avx2 = self.use_avx2();
        let images = OutputImages::new(&mut self.output, w, h, bg);
        // Not cleared: each tile's walk writes its whole run.
        self.pair_rows.resize(bins.pairs(), 0);
        let row_runs = DisjointWrites::new(&mut self.pair_rows);
        self.px_t
            .par_chunks_mut(TILE_PIXELS)
            .zip(self.px_d.par_chunks_mut(TILE_PIXELS))
            .zip(self.px_finish.par_chunks_mut(TILE_PIXELS))
            .enumerate()
            .map_init(
                || vec![[0.0_f32; 3]; TILE_PIXELS],
                |rgb, (tile, ((t, d), finish))| {
                    let (start, end) = (bins.offsets[tile], bins.offsets[tile + 1]);
                    let ext = tile_extent(tile, tiles_x, w, h);
                    // SAFETY: [start, end) is this tile's own run of `pair_rows`: the tiles'
                    // runs are disjoint (and `run` checks they end inside the vector).
                    #[allow(unsafe_code)]
                    let rows = unsafe { row_runs.run(start, end) };
                    let o = TileOut {
                        t: &mut *t,
                        d: &mut *d,
                        rgb: rgb.as_mut_slice(),
                        finish,
                        rows,
                    };
                    let list = &bins.list[start..end];
                    // The tile's rows of the output images are written once it is composited,
                    // each a cache miss unless fetched while it is.
                    images.prefetch_tile(ext);
                    let counts = composite_tile(list, proj, ext, o, &mut NoWeights, avx2);
                    images.write_tile(ext, t, d, rgb, avx2);
                    counts
                },
            )
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    }
}

/// The row-major output images (colour over the background, alpha = 1 − T, expected depth),
/// written tile by tile by the compositing's tasks.
struct OutputImages<'a> {
    rgb: DisjointWrites<'a, f32>,
    alpha: DisjointWrites<'a, f32>,
    depth: DisjointWrites<'a, f32>,
    width: usize,
    bg: Vec3,
}

impl<'a> OutputImages<'a> {
    /// Sizes `out` for a `width × height` view and takes its images for the tiles to write.
    fn new(out: &'a mut RenderOutput, width: u32, height: u32, bg: Vec3) -> Self {
        let n = width as usize * height as usize;
        out.width = width;
        out.height = height;
        out.rgb.resize(3 * n, 0.0);
        out.alpha.resize(n, 0.0);
        out.depth.resize(n, 0.0);
        Self {
            rgb: DisjointWrites::new(&mut out.rgb),
            alpha: DisjointWrites::new(&mut out.alpha),
            depth: DisjointWrites::new(&mut out.depth),
            width: width as usize,
            bg,
        }
    }

    /// Hints the CPU to fetch the rows of the tile at `ext` in the three images.
    fn prefetch_tile(&self, (x0, y0, tw, th): (i32, i32, i32, i32)) {
        let (x0, tw) = (x0 as usize, tw as usize);
        for y in y0 as usize..(y0 + th) as usize {
            let first = y * self.width + x0;
            self.rgb.prefetch(3 * first, 3 * tw);
            self.alpha.prefetch(first, tw);
            self.depth.prefetch(first, tw);
        }
    }

    /// Writes the pixels of the tile at `ext` from its tile-major transmittance, depth sums
    /// and colours: the AVX2 instantiation where `avx2` (the CPU has it), else the portable one
    /// (the same IEEE operations, so the images are bit-identical either way).
    fn write_tile(
        &self,
        ext: (i32, i32, i32, i32),
        t: &[f32],
        d: &[f32],
        rgb: &[[f32; 3]],
        avx2: bool,
    ) {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
            #[allow(unsafe_code)]
            return unsafe { self.write_tile_avx2(ext, t, d, rgb) };
        }
        let _ = avx2;
        self.write_tile_impl(ext, t, d, rgb);
    }

    /// [`OutputImages::write_tile_impl`] compiled with AVX2: its per-row loops (a division and
    /// a select per pixel, interleaved colour stores) then run 8 pixels a vector op, where
    /// the portable build does one; as scalar code they were a sixth of the compositing.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn write_tile_avx2(&self, ext: (i32, i32, i32, i32), t: &[f32], d: &[f32], rgb: &[[f32; 3]]) {
        self.write_tile_impl(ext, t, d, rgb);
    }

    #[inline(always)]
    fn write_tile_impl(&self, ext: (i32, i32, i32, i32), t: &[f32], d: &[f32], rgb: &[[f32; 3]]) {
        let (x0, y0, tw, th) = (
            ext.0 as usize,
            ext.1 as usize,
            ext.2 as usize,
            ext.3 as usize,
        );
        let ts = TILE_SIZE as usize;
        let bg = self.bg;
        for ly in 0..th {
            let first = (y0 + ly) * self.width + x0;
            // SAFETY: row `y0 + ly`'s columns `x0..x0 + tw` lie in this tile alone, and the
            // tiles are disjoint, so no other task writes these positions.
            #[allow(unsafe_code)]
            let (rgb_out, alpha_out, depth_out) = unsafe {
                (
                    self.rgb.run(3 * first, 3 * (first + tw)),
                    self.alpha.run(first, first + tw),
                    self.depth.run(first, first + tw),
                )
            };
            let row = ly * ts..ly * ts + tw;
            let (t, d, rgb) = (&t[row.clone()], &d[row.clone()], &rgb[row]);
            for ((o, c), &t) in rgb_out.chunks_exact_mut(3).zip(rgb).zip(t) {
                o[0] = c[0] + t * bg.x;
                o[1] = c[1] + t * bg.y;
                o[2] = c[2] + t * bg.z;
            }
            for ((a_out, z_out), (&t, &d)) in
                alpha_out.iter_mut().zip(depth_out).zip(t.iter().zip(d))
            {
                let a = 1.0 - t;
                *a_out = a;
                *z_out = if a > DEPTH_MIN_ALPHA { d / a } else { 0.0 };
            }
        }
    }
}

/// Below this coverage the expected depth is reported as 0 (and passes no gradient).
pub(crate) const DEPTH_MIN_ALPHA: f32 = 1e-6;

/// Index of pixel (x, y) in the tile-major buffers.
#[inline]
pub(crate) fn tile_major_index(x: usize, y: usize, tiles_x: u32) -> usize {
    let ts = TILE_SIZE as usize;
    let tile = (y / ts) * tiles_x as usize + x / ts;
    tile * TILE_PIXELS + (y % ts) * ts + x % ts
}

/// Whether AVX2 instantiations of hot loops can run on this CPU (detected at run time, so the
/// binary still runs on any x86-64; always false elsewhere): the tile loops here, and the
/// trainer's Adam update. The tile loops also count lanes with POPCNT, which every AVX2 CPU
/// has; both are checked.
#[inline]
#[must_use]
pub fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Splats per projection task (whole groups of [`WIDTH`], so each task writes whole chain groups).
const PROJECT_CHUNK: usize = 1024;
const _: () = assert!(PROJECT_CHUNK.is_multiple_of(WIDTH));

/// One chunk's slices of the projection outputs, from splat `first` on.
struct ProjectOut<'a> {
    proj: &'a mut [Projected],
    rects: &'a mut [[u32; 4]],
    radii: &'a mut [u32],
    chain: &'a mut [ChainLanes],
    visible: &'a mut [bool],
    non_finite: &'a mut [bool],
}

/// Projects the splats of one chunk, eight at a time in vector lanes: the AVX2 instantiation
/// where the CPU has it (eight f32 lanes an instruction; its floor, ceil and square roots single
/// instructions instead of library calls), else the portable one (SSE2, four lanes); the results
/// are bit-identical (those operations are exact or correctly rounded either way, and there is
/// no FMA contraction).
fn project_chunk(splats: &Splats, v: &ViewConsts, first: usize, out: ProjectOut<'_>, avx2: bool) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { project_chunk_avx2(splats, v, first, out) };
    }
    let _ = avx2;
    project_chunk_impl::<false>(splats, v, first, out);
}

/// [`project_chunk_impl`] compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn project_chunk_avx2(splats: &Splats, v: &ViewConsts, first: usize, out: ProjectOut<'_>) {
    project_chunk_impl::<true>(splats, v, first, out);
}

#[inline(always)]
fn project_chunk_impl<const AVX2: bool>(
    splats: &Splats,
    v: &ViewConsts,
    first: usize,
    o: ProjectOut<'_>,
) {
    let len = o.proj.len();
    let mut scratch = Scratch::default();
    for start in (0..len).step_by(WIDTH) {
        // The last group of a model that is not a multiple of eight repeats its last splat in
        // the spare lanes, whose results are dropped.
        let idx = std::array::from_fn(|l| first + (start + l).min(len - 1));
        let chain = &mut o.chain[start / WIDTH];
        project8::<AVX2>(
            splats,
            idx,
            (len - start).min(WIDTH),
            v,
            chain,
            &mut scratch,
            |l, r| {
                let j = start + l;
                match r {
                    Ok(it) => {
                        o.proj[j] = it.out;
                        o.rects[j] = it.rect;
                        o.radii[j] = it.radius;
                        o.visible[j] = true;
                        o.non_finite[j] = false;
                    }
                    Err(c) => {
                        o.radii[j] = 0;
                        o.visible[j] = false;
                        o.non_finite[j] = c == Cull::NonFinite;
                    }
                }
            },
        );
    }
}

/// Where a pixel's compositing stopped, as the tile walks keep it per pixel (a `u32`): `OPEN`
/// while its transmittance lasts; k + 1 ([`Finish::tag`]) once entry k of the tile's list would
/// have taken it below [`MIN_TRANSMITTANCE`] (that entry and every later one are not blended);
/// `OUTSIDE` for the tile's pixels beyond the image, as if stopped at the first entry. The
/// backward pass's test "entry kk was blended into this pixel" is then kk < [`Finish::limit`]
/// and alpha ≥ 1/255 (the forward's own test), so no walk keeps a per-pixel record of the last
/// entry blended: one maximum and one store fewer per half-row of the compositing.
pub(crate) struct Finish;

impl Finish {
    /// Not done.
    pub(crate) const OPEN: u32 = 0;
    /// Outside the image: done before the first entry.
    pub(crate) const OUTSIDE: u32 = 1;

    /// The value of a pixel that entry `k` of its tile's list finished.
    #[inline(always)]
    pub(crate) fn tag(k: usize) -> u32 {
        k as u32 + 1
    }

    /// The first list index not blended into a pixel whose value is `f`; signed, since the
    /// backward's compare of list indices is then one AVX2 instruction (tile lists are far
    /// shorter than 2³¹).
    #[inline(always)]
    pub(crate) fn limit(f: u32) -> i32 {
        if f == Self::OPEN {
            i32::MAX
        } else {
            (f - 1).cast_signed()
        }
    }
}

/// What a tile walk hands on of each splat's blending weights wᵢ = Tᵢ·αᵢ besides compositing
/// them: nothing in the forward pass, their sums per splat in a contribution pass.
pub(crate) trait WeightSink {
    /// Takes the weights of one half-row of list entry `k`, lane by lane (0 where the splat
    /// supplies nothing).
    fn add(&mut self, k: usize, w: &[f32; LANES]);
}

/// The forward pass's sink: the weights are only composited (the calls compile to nothing).
pub(crate) struct NoWeights;

impl WeightSink for NoWeights {
    #[inline(always)]
    fn add(&mut self, _: usize, _: &[f32; LANES]) {}
}

/// Per-pixel compositing state of one tile, in tile-local arrays, for walks that keep none of it
/// (a contribution pass).
pub(crate) struct TileScratch {
    t: [f32; TILE_PIXELS],
    d: [f32; TILE_PIXELS],
    rgb: [[f32; 3]; TILE_PIXELS],
    finish: [u32; TILE_PIXELS],
    rows: Vec<u32>,
}

impl TileScratch {
    pub(crate) fn new() -> Self {
        Self {
            t: [0.0; TILE_PIXELS],
            d: [0.0; TILE_PIXELS],
            rgb: [[0.0; 3]; TILE_PIXELS],
            finish: [0; TILE_PIXELS],
            rows: Vec::new(),
        }
    }
}

/// Composites one tile of a view whose projection and tile lists `r` holds into `scratch`,
/// handing every splat's weights to `sink`.
pub(crate) fn walk_tile<S: WeightSink>(
    r: &Rasterizer,
    tile: usize,
    cam: &RenderCamera,
    scratch: &mut TileScratch,
    sink: &mut S,
) {
    let tiles_x = cam.width.div_ceil(TILE_SIZE);
    let list = &r.bins.list[r.bins.offsets[tile]..r.bins.offsets[tile + 1]];
    let ext = tile_extent(tile, tiles_x, cam.width, cam.height);
    scratch.rows.resize(list.len(), 0);
    let o = TileOut {
        t: &mut scratch.t,
        d: &mut scratch.d,
        rgb: &mut scratch.rgb,
        finish: &mut scratch.finish,
        rows: &mut scratch.rows[..list.len()],
    };
    composite_tile(list, &r.proj, ext, o, sink, r.use_avx2());
}

/// Composites one tile front to back: the AVX2 instantiation where the CPU has it, else the
/// portable one. Both compute the same IEEE operations in the same order (no FMA contraction),
/// so the images are bit-identical either way.
fn composite_tile<S: WeightSink>(
    list: &[u32],
    proj: &[Projected],
    ext: (i32, i32, i32, i32),
    o: TileOut<'_>,
    sink: &mut S,
    avx2: bool,
) -> (u64, u64) {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
        #[allow(unsafe_code)]
        return unsafe { composite_tile_avx2(list, proj, ext, o, sink) };
    }
    let _ = avx2;
    composite_tile_impl::<S, false>(list, proj, ext, o, sink)
}

/// [`composite_tile_impl`] compiled with AVX2 so LLVM turns each 8-lane half-row into one
/// 256-bit vector op per step.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
fn composite_tile_avx2<S: WeightSink>(
    list: &[u32],
    proj: &[Projected],
    ext: (i32, i32, i32, i32),
    o: TileOut<'_>,
    sink: &mut S,
) -> (u64, u64) {
    composite_tile_impl::<S, true>(list, proj, ext, o, sink)
}

/// Composites one tile front to back (Inria `renderCUDA`), splat by splat over the 8-pixel
/// half-rows each can reach (first the falloff of all of them, then the compositing), stopping
/// once every pixel's transmittance is spent. Every half-row runs all 8 lanes with no branches
/// (the alpha test and the pixels' [`Finish`] decide each lane), so it maps onto one SIMD
/// vector. Returns the (pixel, splat)
/// evaluations and contributions.
#[inline(always)]
fn composite_tile_impl<S: WeightSink, const AVX2: bool>(
    list: &[u32],
    proj: &[Projected],
    ext: (i32, i32, i32, i32),
    o: TileOut<'_>,
    sink: &mut S,
) -> (u64, u64) {
    let (x0, y0, tw, th) = ext;
    let ts = TILE_SIZE as usize;
    let mut t = [1.0_f32; TILE_PIXELS];
    let mut cr = [0.0_f32; TILE_PIXELS];
    let mut cg = [0.0_f32; TILE_PIXELS];
    let mut cb = [0.0_f32; TILE_PIXELS];
    let mut d = [0.0_f32; TILE_PIXELS];
    // Per pixel, where it is done ([`Finish`]: 32-bit lanes like the colours', so the masks
    // need no packing to bytes). Pixels outside the image start as done; a half-row whose 8
    // pixels are all done is skipped by every later splat, through one bit each in
    // `done_rows`.
    let mut done = [Finish::OUTSIDE; TILE_PIXELS];
    for ly in 0..th as usize {
        done[ly * ts..ly * ts + tw as usize].fill(Finish::OPEN);
    }
    let mut done_rows = 0_u32;
    for hr in 0..HALF_ROWS {
        if done[hr * LANES..(hr + 1) * LANES]
            .iter()
            .all(|&f| f != Finish::OPEN)
        {
            done_rows |= 1 << hr;
        }
    }
    let (mut evaluations, mut contributions) = (0_u64, 0_u64);
    let mut falloff = Falloff::new();
    // Entries past an early stop (every pixel done) are blended nowhere.
    o.rows.fill(0);
    for (k, &sid) in list.iter().enumerate() {
        if let Some(&ahead) = list.get(k + PREFETCH_AHEAD) {
            prefetch::record(proj, ahead as usize);
        }
        let p = &proj[sid as usize];
        let spans = RowSpans::reach::<AVX2>(p, x0, y0, tw, th);
        let tag = Finish::tag(k);
        let todo = spans.mask & !done_rows;
        evaluations += evaluated_pixels(todo, tw);
        falloff.compute::<AVX2>(p, &spans, todo, x0);
        let mut used = 0_u32;
        for (&hr, g) in falloff.hr.iter().zip(&falloff.gauss).take(falloff.n) {
            // Fixed-size views, no bounds check.
            let donel: &mut [u32; LANES] = hr.lanes(&mut done);
            let tl: &mut [f32; LANES] = hr.lanes(&mut t);
            let rl: &mut [f32; LANES] = hr.lanes(&mut cr);
            let gl: &mut [f32; LANES] = hr.lanes(&mut cg);
            let bl: &mut [f32; LANES] = hr.lanes(&mut cb);
            let dl: &mut [f32; LANES] = hr.lanes(&mut d);
            let mut weights = [0.0_f32; LANES];
            let px = HalfRow {
                t: tl,
                r: rl,
                g: gl,
                b: bl,
                d: dl,
                done: donel,
            };
            let (contributed, all_done) = px.blend::<AVX2>(p, g, tag, &mut weights);
            sink.add(k, &weights);
            let bit = 1_u32 << hr.index();
            if contributed > 0 {
                used |= bit;
            }
            contributions += u64::from(contributed);
            if all_done {
                done_rows |= bit;
            }
        }
        o.rows[k] = used;
        if done_rows == u32::MAX {
            break;
        }
    }
    o.t.copy_from_slice(&t);
    o.d.copy_from_slice(&d);
    o.finish.copy_from_slice(&done);
    for (i, px) in o.rgb.iter_mut().enumerate() {
        *px = [cr[i], cg[i], cb[i]];
    }
    (evaluations, contributions)
}

/// One half-row's compositing state: 8 pixels' transmittance, colour and depth sums, and
/// [`Finish`] values.
struct HalfRow<'a> {
    t: &'a mut [f32; LANES],
    r: &'a mut [f32; LANES],
    g: &'a mut [f32; LANES],
    b: &'a mut [f32; LANES],
    d: &'a mut [f32; LANES],
    done: &'a mut [u32; LANES],
}

impl HalfRow<'_> {
    /// Blends splat `p` of falloff `gauss` (list entry `tag` − 1) into the half-row, writes its
    /// weights wᵢ = Tᵢ·αᵢ (0 where it is not blended) into `weights`, and returns how many
    /// pixels it was blended into and whether all 8 are done after it. With `AVX2` in AVX2
    /// intrinsics (the same IEEE operations in the same order, so the same bits), which only
    /// callers compiled with AVX2 may ask for: LLVM's vectoriser turned the lane loop into scalar code
    /// with a branch per lane once it no longer kept a last-blended index per pixel.
    #[inline(always)]
    fn blend<const AVX2: bool>(
        self,
        p: &Projected,
        gauss: &[f32; LANES],
        tag: u32,
        weights: &mut [f32; LANES],
    ) -> (u32, bool) {
        #[cfg(target_arch = "x86_64")]
        if AVX2 {
            return self.blend_avx2(p, gauss, tag, weights);
        }
        let opaque_one = std::hint::black_box(1.0_f32);
        let opaque_zero = std::hint::black_box(0_u32);
        let mut contributed = 0;
        for l in 0..LANES {
            // Outside the splat's reach alpha fails the 1/255 test; past a partial tile's
            // last column the pixel is done from the start.
            let alpha = (p.opacity * gauss[l]).min(MAX_ALPHA);
            let ti = self.t[l];
            let one_m = 1.0 - alpha;
            let next_t = ti * one_m;
            let valid = (self.done[l] == Finish::OPEN) & (alpha >= MIN_ALPHA);
            let finish = valid & (next_t < MIN_TRANSMITTANCE);
            let add = valid & !finish;
            let w = if add { alpha * ti } else { 0.0 };
            weights[l] = w;
            self.r[l] += w * p.color[0];
            self.g[l] += w * p.color[1];
            self.b[l] += w * p.color[2];
            self.d[l] += w * p.depth;
            // Every lane is stored, written as arithmetic (T times a 1 the compiler cannot
            // see, the tag or a 0 it cannot see kept by a maximum) rather than `if add { new }
            // else { old }`, which LLVM turns into masked stores or branches.
            self.t[l] = ti * if add { one_m } else { opaque_one };
            self.done[l] = self.done[l].max(if finish { tag } else { opaque_zero });
            contributed += u32::from(add);
        }
        (contributed, self.done.iter().all(|&f| f != Finish::OPEN))
    }

    /// [`Self::blend`]'s lanes as AVX2 vectors. Every lane is stored, its new value chosen by
    /// arithmetic (T times 1, the tag under a mask or'ed into an open pixel's 0), not by masked
    /// stores (slow on AMD, and the next splat's loads cannot forward from them).
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    fn blend_avx2(
        self,
        p: &Projected,
        gauss: &[f32; LANES],
        tag: u32,
        weights: &mut [f32; LANES],
    ) -> (u32, bool) {
        use std::arch::x86_64::{
            _CMP_GE_OQ, _CMP_LT_OQ, _mm256_add_ps, _mm256_and_ps, _mm256_and_si256,
            _mm256_andnot_ps, _mm256_blendv_ps, _mm256_castps_si256, _mm256_castsi256_ps,
            _mm256_cmp_ps, _mm256_cmpeq_epi32, _mm256_loadu_ps, _mm256_loadu_si256, _mm256_min_ps,
            _mm256_movemask_ps, _mm256_mul_ps, _mm256_or_si256, _mm256_set1_epi32, _mm256_set1_ps,
            _mm256_setzero_si256, _mm256_storeu_ps, _mm256_storeu_si256, _mm256_sub_ps,
        };
        // SAFETY: only the AVX2 instantiations of the tile walks ask for `AVX2`, and they run
        // only where `has_avx2()` found the feature; every load and store is of 8 lanes of an
        // 8-lane array.
        #[allow(unsafe_code)]
        unsafe {
            let one = _mm256_set1_ps(1.0);
            let alpha = _mm256_min_ps(
                _mm256_mul_ps(_mm256_set1_ps(p.opacity), _mm256_loadu_ps(gauss.as_ptr())),
                _mm256_set1_ps(MAX_ALPHA),
            );
            let ti = _mm256_loadu_ps(self.t.as_ptr());
            let one_m = _mm256_sub_ps(one, alpha);
            let next_t = _mm256_mul_ps(ti, one_m);
            let done = _mm256_loadu_si256(self.done.as_ptr().cast());
            let open = _mm256_castsi256_ps(_mm256_cmpeq_epi32(done, _mm256_setzero_si256()));
            let valid = _mm256_and_ps(
                open,
                _mm256_cmp_ps::<_CMP_GE_OQ>(alpha, _mm256_set1_ps(MIN_ALPHA)),
            );
            let finish = _mm256_and_ps(
                valid,
                _mm256_cmp_ps::<_CMP_LT_OQ>(next_t, _mm256_set1_ps(MIN_TRANSMITTANCE)),
            );
            let add = _mm256_andnot_ps(finish, valid);
            let w = _mm256_and_ps(add, _mm256_mul_ps(alpha, ti));
            _mm256_storeu_ps(weights.as_mut_ptr(), w);
            for (sum, c) in [
                (&mut *self.r, p.color[0]),
                (&mut *self.g, p.color[1]),
                (&mut *self.b, p.color[2]),
                (&mut *self.d, p.depth),
            ] {
                let v = _mm256_add_ps(
                    _mm256_loadu_ps(sum.as_ptr()),
                    _mm256_mul_ps(w, _mm256_set1_ps(c)),
                );
                _mm256_storeu_ps(sum.as_mut_ptr(), v);
            }
            _mm256_storeu_ps(
                self.t.as_mut_ptr(),
                _mm256_mul_ps(ti, _mm256_blendv_ps(one, one_m, add)),
            );
            let tags = _mm256_and_si256(
                _mm256_castps_si256(finish),
                _mm256_set1_epi32(tag.cast_signed()),
            );
            _mm256_storeu_si256(self.done.as_mut_ptr().cast(), _mm256_or_si256(done, tags));
            (
                _mm256_movemask_ps(add).count_ones(),
                _mm256_movemask_ps(_mm256_andnot_ps(finish, open)) == 0,
            )
        }
    }
}

/// How many list entries ahead the tile loops prefetch the projected record: a tile's list is
/// in depth order, so its records are scattered over the whole projection buffer (10 MB at 250 k
/// splats, beyond the L2 cache) and each would otherwise be a cache miss.
pub(crate) const PREFETCH_AHEAD: usize = 8;
