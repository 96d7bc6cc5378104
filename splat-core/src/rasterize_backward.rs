//! The backward pass (Inria `backward.cu`): each tile walks its list back to front recovering
//! Tᵢ = Tᵢ₊₁/(1 − αᵢ), writes one gradient record per (tile, splat) pair, the records are summed
//! per splat in a fixed order, and each splat's sum is chained through projection, covariance
//! and SH to its parameters.
//!
//! Reproducibility: every pair owns its own gradient slot (so tiles running on different threads
//! never share an accumulator), and the per-splat sums run over the tile lists in tile order
//! (`Bins::reduce_per_splat`).
//! Every floating-point sum therefore happens in an order that does not depend on the thread
//! count or scheduling: gradients are bit-for-bit identical for any number of threads.

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;

use crate::constants::{MAX_ALPHA, MIN_ALPHA};
use crate::disjoint::DisjointWrites;
use crate::falloff::Falloff;
#[cfg(target_arch = "x86_64")]
use crate::lanes::transpose8_avx2;
use crate::lanes::{F8, WIDTH, array};
use crate::prefetch;
use crate::project::ViewConsts;
use crate::project_backward::{
    ChainView, ProjectedGrad, ProjectedGradLanes, colour_grad8, project_backward8,
};
use crate::rasterize::{DEPTH_MIN_ALPHA, Finish, PREFETCH_AHEAD, tile_extent, tile_major_index};
use crate::spans::RowSpans;
use crate::tiles::{HALF_ROWS, LANES, TILE_PIXELS, TILE_SIZE, half_row_dx};
use crate::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, SplatGradsMut, Splats, sh};

/// Splats per task of the chain phase.
const CHAIN_CHUNK: usize = 256;

/// One tile's list: its splats front to back and the half-rows the forward pass blended each
/// into.
#[derive(Clone, Copy)]
struct Entries<'a> {
    list: &'a [u32],
    rows: &'a [u32],
}

/// Per-pixel loss gradients the tile walk needs, gathered from the row-major inputs.
struct PixelGrads<'a> {
    d_rgb: &'a [f32],
    d_alpha: Option<&'a [f32]>,
    d_depth: Option<&'a [f32]>,
    bg: Vec3,
    width: usize,
    tiles_x: u32,
}

impl PixelGrads<'_> {
    /// Hints the CPU to fetch the loss gradients of `tile`'s pixels (if there is such a tile):
    /// the walk reads them row by row from the row-major images, 16 rows a tile apart, which the
    /// hardware's stream prefetchers do not foresee, so each row was a cache miss; the next tile
    /// a thread walks is usually the one after this.
    #[inline(always)]
    fn prefetch_tile(&self, tile: usize, cam: &RenderCamera) {
        let ts = TILE_SIZE as usize;
        if tile >= self.tiles_x as usize * (cam.height as usize).div_ceil(ts) {
            return;
        }
        let (x0, y0, tw, th) = tile_extent(tile, self.tiles_x, cam.width, cam.height);
        let (x0, tw) = (x0 as usize, tw as usize);
        for y in y0 as usize..(y0 + th) as usize {
            let p = y * self.width + x0;
            prefetch::span(self.d_rgb, 3 * p, 3 * tw);
            if let Some(d) = self.d_alpha {
                prefetch::span(d, p, tw);
            }
            if let Some(d) = self.d_depth {
                prefetch::span(d, p, tw);
            }
        }
    }
}

impl Rasterizer {
    /// Adds into `grads` the gradients of a loss whose derivatives with respect to this view's
    /// outputs are `d_rgb` (3·W·H), `d_alpha` (W·H) and `d_depth` (W·H). Call after
    /// [`Rasterizer::forward`] on the same inputs (it is re-run if the last forward pass was of
    /// another size). `grads` is resized to `splats` (and zeroed) only if its shape differs.
    ///
    /// Gradients of α are zero where o·G is clamped at 0.99 (the exact derivative, as gsplat),
    /// and of the Jacobian's x/z, y/z where the 1.3·tan(fov/2) clamp acts (as Inria).
    ///
    /// This is [`Rasterizer::backward_sums`] followed by [`Rasterizer::chain_into`] over all
    /// the splats.
    ///
    /// # Panics
    /// If the gradient images do not have the view's size.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
        d_rgb: &[f32],
        d_alpha: Option<&[f32]>,
        d_depth: Option<&[f32]>,
        grads: &mut SplatGrads,
    ) {
        self.backward_sums(splats, cam, opts, d_rgb, d_alpha, d_depth);
        if !grads.fits(splats) {
            grads.reset(splats);
        }
        let t2 = Instant::now();
        let this = &*self;
        grads
            .par_chunks_mut(CHAIN_CHUNK)
            .enumerate()
            .for_each(|(c, g)| this.chain_into(c * CHAIN_CHUNK, g));
        self.phases.backward_chain = t2.elapsed();
    }

    /// The first phases of [`Rasterizer::backward`]: the tiles' gradient records and their sums
    /// per splat, with respect to each splat's projected centre, conic, opacity, colour and
    /// depth. [`Rasterizer::chain_into`] then hands each splat's parameter gradients over, range
    /// by range, so a caller can use them while they are in the cache (the trainer's Adam update
    /// runs on them chunk by chunk) instead of storing them all first.
    ///
    /// # Panics
    /// If the gradient images do not have the view's size.
    pub fn backward_sums(
        &mut self,
        splats: &Splats,
        cam: &RenderCamera,
        opts: &RenderOptions,
        d_rgb: &[f32],
        d_alpha: Option<&[f32]>,
        d_depth: Option<&[f32]>,
    ) {
        let (w, h) = (cam.width as usize, cam.height as usize);
        assert_eq!(d_rgb.len(), 3 * w * h, "d_rgb must hold 3·W·H values");
        assert!(
            d_alpha.is_none_or(|a| a.len() == w * h),
            "d_alpha must hold W·H values"
        );
        assert!(
            d_depth.is_none_or(|a| a.len() == w * h),
            "d_depth must hold W·H values"
        );
        if self.last_view != Some((splats.len(), cam.width, cam.height)) {
            self.forward(splats, cam, opts);
        }
        let v = ViewConsts::new(cam, opts, splats);
        let pg = PixelGrads {
            d_rgb,
            d_alpha,
            d_depth,
            bg: opts.background,
            width: w,
            tiles_x: v.tiles_x,
        };
        let t0 = Instant::now();
        // Not zeroed: every tile walk writes each slot of its own range (zero where the splat
        // passed no gradient), so stale records from the last view are all overwritten.
        self.pair_grads
            .resize(self.bins.pairs(), ProjectedGrad::default());
        // Taken out of `self` while the tiles write it, so the walks can borrow the rest.
        let mut pair_grads = std::mem::take(&mut self.pair_grads);
        let slots = DisjointWrites::new(&mut pair_grads);
        let n_tiles = (v.tiles_x * v.tiles_y) as usize;
        let this = &*self;
        let avx2 = this.use_avx2();
        (0..n_tiles).into_par_iter().for_each(|tile| {
            let (s, e) = (this.bins.offsets[tile], this.bins.offsets[tile + 1]);
            // SAFETY: [s, e) is this tile's own range of `pair_grads`: the tiles' ranges are
            // disjoint (and `run` checks they end inside the vector).
            #[allow(unsafe_code)]
            let out = unsafe { slots.run(s, e) };
            let entries = Entries {
                list: &this.bins.list[s..e],
                rows: &this.pair_rows[s..e],
            };
            this.backward_tile(tile, entries, cam, &pg, out, avx2);
        });
        self.pair_grads = pair_grads;

        let t1 = Instant::now();
        // Sum the pair records per splat in tile order (deterministic).
        self.splat_grads
            .resize(splats.len(), ProjectedGrad::default());
        self.splat_grads
            .par_iter_mut()
            .for_each(|g| *g = ProjectedGrad::default());
        let avx2 = self.use_avx2();
        self.bins.reduce_per_splat(
            &mut self.splat_grads,
            &self.pair_grads,
            ProjectedGrad::add,
            avx2,
        );
        self.chain_view = Some(ChainView {
            v,
            size: (cam.width, cam.height),
            coeffs_per_splat: splats.coeffs_per_splat(),
            splats: splats.len(),
        });
        self.phases.backward_tiles = t1 - t0;
        self.phases.backward_sum = t1.elapsed();
        self.phases.backward_chain = Duration::ZERO;
    }

    /// Adds into `g` the parameter gradients of the splats from `first` on, as many as
    /// `g.means` holds (their SH coefficients' gradients splat-major, as [`Splats::sh`]): the
    /// last phase of [`Rasterizer::backward`] for that range, after
    /// [`Rasterizer::backward_sums`] on the same splats. The ranges may be chained in any order
    /// and on any threads; each splat's gradients are the same as `backward` gives. The
    /// coefficients themselves are not needed: the forward pass kept what the chain uses of
    /// them (the colour's Jacobian with respect to the view direction).
    ///
    /// # Panics
    /// If `backward_sums` has not run since the last forward pass, if the range runs past the
    /// splats it saw, or if `g`'s arrays are not all shaped for the range.
    pub fn chain_into(&self, first: usize, g: SplatGradsMut<'_>) {
        let Some(cv) = &self.chain_view else {
            panic!("Rasterizer::chain_into: backward_sums has not run since the last forward pass");
        };
        let (n, k) = (g.means.len(), cv.coeffs_per_splat);
        assert!(
            first + n <= cv.splats
                && [
                    g.log_scales.len(),
                    g.rotations.len(),
                    g.opacity_logits.len(),
                    g.screen_grad_norm.len()
                ]
                .iter()
                .all(|&m| m == n)
                && g.sh.len() == n * k,
            "Rasterizer::chain_into: gradients not shaped for {n} splats from {first} of {} \
             with {k} SH coefficients each",
            cv.splats
        );
        #[cfg(target_arch = "x86_64")]
        if self.use_avx2() {
            // SAFETY: `use_avx2` is only true when the CPU reports AVX2 (`has_avx2`).
            #[allow(unsafe_code)]
            unsafe {
                self.chain_range_avx2(cv, first, g);
            }
            return;
        }
        self.chain_range(cv, first, g);
    }

    /// [`Rasterizer::chain_range`] compiled with AVX2 (eight f32 lanes an instruction).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn chain_range_avx2(&self, cv: &ChainView, first: usize, g: SplatGradsMut<'_>) {
        self.chain_range(cv, first, g);
    }

    /// The body of [`Rasterizer::chain_into`], its arguments checked.
    #[inline(always)]
    fn chain_range(&self, cv: &ChainView, first: usize, g: SplatGradsMut<'_>) {
        let (n, k) = (g.means.len(), cv.coeffs_per_splat);
        // Group by group of the projection's lanes; a range need not start at a group, and its
        // splats outside the range (or with no gradient record: hidden behind others in every
        // tile it is listed in, so its chain would add exact zeros) are idle lanes.
        let end = first + n;
        for group in first / WIDTH..end.div_ceil(WIDTH) {
            let i0 = group * WIDTH;
            let active: [bool; WIDTH] = array(|l| {
                let i = i0 + l;
                (first..end).contains(&i) && self.visible[i] && !self.splat_grads[i].is_zero()
            });
            if !active.contains(&true) {
                continue;
            }
            let records = std::array::from_fn(|l| {
                if active[l] {
                    self.splat_grads[i0 + l]
                } else {
                    ProjectedGrad::default()
                }
            });
            let it = &self.chain[group];
            // The projection's record of the group after next (22 lane vectors and three masks,
            // a dozen cache lines): the first loads of each group's record were the chain's
            // hottest instructions, and the hint takes a tenth to a sixth off the chain's time.
            prefetch::chain(&self.chain, group + 2);
            let grads = ProjectedGradLanes::gather(&records);
            let d_colour = colour_grad8(&cv.v, it, &grads);
            // The coefficients' gradients basis_k·dL/dc, lane by lane into the model's layout;
            // dL/d(dir) from the colour's Jacobian the projection formed.
            let mut basis = [F8::default(); 16];
            sh::basis_terms(cv.v.degree, *it.dir(), &mut basis);
            let n_coeffs = sh::num_sh_coeffs(cv.v.degree);
            for l in (0..WIDTH).filter(|&l| active[l]) {
                let j = i0 + l - first;
                for (d, b) in g.sh[j * k..j * k + n_coeffs].iter_mut().zip(&basis) {
                    for (dc, c) in d.iter_mut().zip(&d_colour) {
                        *dc += b.0[l] * c.0[l];
                    }
                }
            }
            let d_dir = sh::dir_grad(it.dir_jac(), d_colour);
            let p = project_backward8(&cv.v, it, &grads, cv.size, d_dir);
            for l in (0..WIDTH).filter(|&l| active[l]) {
                let j = i0 + l - first;
                let lane3 = |a: [F8; 3]| Vec3::new(a[0].0[l], a[1].0[l], a[2].0[l]);
                g.means[j] += lane3(p.mean);
                g.log_scales[j] += lane3(p.log_scale);
                for (r, d) in g.rotations[j].iter_mut().zip(p.rotation) {
                    *r += d.0[l];
                }
                g.opacity_logits[j] += p.opacity_logit.0[l];
                g.screen_grad_norm[j] += p.screen_norm.0[l];
            }
        }
    }

    /// Walks one tile back to front: the AVX2 instantiation where the CPU has it, else the
    /// portable one (the same IEEE operations in the same order, so bit-identical gradients).
    fn backward_tile(
        &self,
        tile: usize,
        entries: Entries<'_>,
        cam: &RenderCamera,
        pg: &PixelGrads<'_>,
        out: &mut [ProjectedGrad],
        avx2: bool,
    ) {
        #[cfg(target_arch = "x86_64")]
        if avx2 {
            // SAFETY: `avx2` is only true when `has_avx2()` is, so the CPU supports the enabled features.
            #[allow(unsafe_code)]
            return unsafe { self.backward_tile_avx2(tile, entries, cam, pg, out) };
        }
        let _ = avx2;
        self.backward_tile_impl::<false>(tile, entries, cam, pg, out);
    }

    /// [`Self::backward_tile_impl`] compiled with AVX2 so LLVM vectorises the 8-lane half-rows.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,popcnt")]
    fn backward_tile_avx2(
        &self,
        tile: usize,
        entries: Entries<'_>,
        cam: &RenderCamera,
        pg: &PixelGrads<'_>,
        out: &mut [ProjectedGrad],
    ) {
        self.backward_tile_impl::<true>(tile, entries, cam, pg, out);
    }

    /// The tile walk: per splat, its falloff over the half-rows the forward blended it into (see
    /// `falloff::Falloff`), then the gradients, all 8 lanes of a half-row, each tested against its
    /// pixel's limit.
    /// Per-pixel state is kept as one array per component so each lane view is a plain vector.
    #[inline(always)]
    fn backward_tile_impl<const AVX2: bool>(
        &self,
        tile: usize,
        Entries { list, rows }: Entries<'_>,
        cam: &RenderCamera,
        pg: &PixelGrads<'_>,
        out: &mut [ProjectedGrad],
    ) {
        let (x0, y0, tw, th) = tile_extent(tile, pg.tiles_x, cam.width, cam.height);
        pg.prefetch_tile(tile + 1, cam);
        let ts = TILE_SIZE as usize;
        let base = tile * TILE_PIXELS;
        // Per-pixel state: loss gradients, the background/alpha coefficient, running T and the
        // back-to-front accumulated (colour, depth) of the splats behind, dotted with the
        // pixel's loss gradient (∂L/∂α needs only that dot product, so one value per pixel
        // stands for the four accumulators).
        let mut g_rgb = [[0.0_f32; TILE_PIXELS]; 3];
        let mut g_d = [0.0_f32; TILE_PIXELS];
        let mut k_bg = [0.0_f32; TILE_PIXELS];
        let mut t_cur = [0.0_f32; TILE_PIXELS];
        let mut acc_dot = [0.0_f32; TILE_PIXELS];
        // Per pixel, the first list index not blended into it; 0 (none) outside the image.
        let mut limit = [0_i32; TILE_PIXELS];
        // Row by row, the optional gradients' branches taken once a row rather than once a
        // pixel, so the pixel loop is straight-line code the compiler turns into vectors (the
        // same operations per pixel as one pixel at a time).
        let tw = tw as usize;
        for ly in 0..th as usize {
            let y = y0 as usize + ly;
            // The row's first pixel in the row-major images and in the tile-major buffers.
            let p0 = y * pg.width + x0 as usize;
            let k0 = base + ly * ts;
            debug_assert_eq!(k0, tile_major_index(x0 as usize, y, pg.tiles_x));
            let px_t = &self.px_t[k0..k0 + tw];
            let mut g_a = [0.0_f32; TILE_SIZE as usize];
            let mut gd = [0.0_f32; TILE_SIZE as usize];
            if let Some(d) = pg.d_alpha {
                g_a[..tw].copy_from_slice(&d[p0..p0 + tw]);
            }
            if let Some(dd) = pg.d_depth {
                for lx in 0..tw {
                    let a = 1.0 - px_t[lx];
                    if a > DEPTH_MIN_ALPHA {
                        // depth = D/A: ∂/∂D = 1/A, ∂/∂A = −D/A².
                        gd[lx] = dd[p0 + lx] / a;
                        g_a[lx] -= dd[p0 + lx] * self.px_d[k0 + lx] / (a * a);
                    }
                }
            }
            let d_rgb = &pg.d_rgb[3 * p0..3 * (p0 + tw)];
            let finish = &self.px_finish[k0..k0 + tw];
            let idx0 = ly * ts;
            for lx in 0..tw {
                let idx = idx0 + lx;
                let g = [d_rgb[3 * lx], d_rgb[3 * lx + 1], d_rgb[3 * lx + 2]];
                let t_n = px_t[lx];
                let bg_dot = g[0] * pg.bg.x + g[1] * pg.bg.y + g[2] * pg.bg.z;
                for ch in 0..3 {
                    g_rgb[ch][idx] = g[ch];
                }
                g_d[idx] = gd[lx];
                // ∂C/∂αᵢ has −T_N·bg/(1 − αᵢ); ∂A/∂αᵢ = T_N/(1 − αᵢ).
                k_bg[idx] = (g_a[lx] - bg_dot) * t_n;
                t_cur[idx] = t_n;
                limit[idx] = Finish::limit(finish[lx]);
            }
        }
        // Entries past the last one blended anywhere pass nothing.
        let end = rows.iter().rposition(|&m| m != 0).map_or(0, |k| k + 1);
        for slot in &mut out[end..] {
            *slot = ProjectedGrad::default();
        }
        let mut falloff = Falloff::new();
        // A 1 the compiler cannot see, so `T·1` stays a multiply and a plain store.
        let opaque_one = std::hint::black_box(1.0_f32);
        let mut weight = [[0.0_f32; LANES]; HALF_ROWS];
        let mut moment = [[0.0_f32; LANES]; HALF_ROWS];
        let [g_r, g_g, g_b] = &mut g_rgb;
        for kk in (0..end).rev() {
            if let Some(ahead) = kk.checked_sub(PREFETCH_AHEAD) {
                prefetch::record(&self.proj, list[ahead] as usize);
            }
            let p = &self.proj[list[kk] as usize];
            let [a, b, c] = p.conic;
            let kk_signed = kk as i32;
            // A splat the forward pass blended into no pixel of the tile (every pixel it
            // reaches below 1/255 or already done) passes no gradient and changes no pixel's
            // running state; a third of the pairs at paper scale.
            if rows[kk] == 0 {
                out[kk] = ProjectedGrad::default();
                continue;
            }
            // Per-lane partial sums, added up in a fixed order once the splat is done: of w·∂L/∂c
            // (colour, depth) and, with u = G·∂L/∂α, of u, u·dx, u·dx², u·dy, u·dy², u·dx·dy.
            // The centre and conic gradients are these moments times the splat's constants
            // (see below), which saves their products per lane.
            let mut s_col = [[0.0_f32; LANES]; 3];
            let mut s_dep = [0.0_f32; LANES];
            let mut s_u = [0.0_f32; LANES];
            let mut s_ux = [0.0_f32; LANES];
            let mut s_uxx = [0.0_f32; LANES];
            let mut s_uy = [0.0_f32; LANES];
            let mut s_uyy = [0.0_f32; LANES];
            let mut s_uxy = [0.0_f32; LANES];
            // The half-rows the forward pass blended the splat into, each lane left to the
            // alpha test and the pixel's limit (see `RowSpans::of_rows`): no spans to solve
            // again, and no half-row that would pass nothing.
            let spans = RowSpans::of_rows::<AVX2>(p, rows[kk], y0);
            falloff.compute::<AVX2>(p, &spans, spans.mask, x0);
            // First each half-row's running state and, per lane, the weight w (0 where the
            // splat was not composited) and u = G·∂L/∂α, into `weight` and `moment`; then the
            // sums over them. In one loop the ten sums, the state and the splat's constants
            // did not fit the 16 vector registers, and a fifth of the loop was spills.
            for ((&hr, gs), (wl_out, ul_out)) in falloff
                .hr
                .iter()
                .zip(&falloff.gauss)
                .zip(weight.iter_mut().zip(moment.iter_mut()))
                .take(falloff.n)
            {
                let liml: &[i32; LANES] = hr.lanes(&mut limit);
                let tl: &mut [f32; LANES] = hr.lanes(&mut t_cur);
                let al: &mut [f32; LANES] = hr.lanes(&mut acc_dot);
                let grl: &[f32; LANES] = hr.lanes(g_r);
                let ggl: &[f32; LANES] = hr.lanes(g_g);
                let gbl: &[f32; LANES] = hr.lanes(g_b);
                let gdl: &[f32; LANES] = hr.lanes(&mut g_d);
                let kl: &[f32; LANES] = hr.lanes(&mut k_bg);
                for l in 0..LANES {
                    // Outside the splat's reach alpha fails the 1/255 test; past a partial
                    // tile's last column the limit is 0.
                    let gauss = gs[l];
                    let raw = p.opacity * gauss;
                    let alpha = raw.min(MAX_ALPHA);
                    let valid = (kk_signed < liml[l]) & (alpha >= MIN_ALPHA);
                    let one_m = 1.0 - alpha;
                    let inv = 1.0 / one_m;
                    let t_i = tl[l] * inv;
                    let w = alpha * t_i;
                    // ∂L/∂α = Tᵢ·((cᵢ − C_behind)·g) − T_N·(bg·g − ∂L/∂A)/(1 − αᵢ), the
                    // colour including depth; C_behind·g is the accumulated dot product.
                    let cg = p.color[0] * grl[l]
                        + p.color[1] * ggl[l]
                        + p.color[2] * gbl[l]
                        + p.depth * gdl[l];
                    let behind = al[l];
                    let own = cg - behind;
                    let d_alpha = t_i * own + kl[l] * inv;
                    wl_out[l] = if valid { w } else { 0.0 };
                    // Stores of every lane, written as arithmetic (α of 0, T times 1) rather
                    // than `if valid { new } else { old }`, which LLVM turns into masked stores
                    // that the next splat's loads cannot forward from.
                    let av = if valid { alpha } else { 0.0 };
                    // α·c + (1 − α)·behind, with the difference ∂L/∂α already needed.
                    al[l] = behind + av * own;
                    tl[l] *= if valid { inv } else { opaque_one };
                    // Where o·G is clamped at 0.99, alpha does not depend on o or G.
                    let da = if valid & (raw < MAX_ALPHA) {
                        d_alpha
                    } else {
                        0.0
                    };
                    ul_out[l] = gauss * da;
                }
            }
            // Each lane's dx in the tile's left and right half-rows, the same in every row.
            let mut dx_half = [[0.0_f32; LANES]; 2];
            for (h, dxs) in dx_half.iter_mut().enumerate() {
                let xb = half_row_dx(p.xy[0], x0, h);
                for (l, dx) in dxs.iter_mut().enumerate() {
                    *dx = xb - l as f32;
                }
            }
            for ((&hr, wl), ul) in falloff.hr.iter().zip(&weight).zip(&moment).take(falloff.n) {
                let dy = spans.dy[hr.row()];
                let dxl = &dx_half[hr.half()];
                let grl: &[f32; LANES] = hr.lanes(g_r);
                let ggl: &[f32; LANES] = hr.lanes(g_g);
                let gbl: &[f32; LANES] = hr.lanes(g_b);
                let gdl: &[f32; LANES] = hr.lanes(&mut g_d);
                for l in 0..LANES {
                    let dx = dxl[l];
                    let wv = wl[l];
                    s_col[0][l] += wv * grl[l];
                    s_col[1][l] += wv * ggl[l];
                    s_col[2][l] += wv * gbl[l];
                    s_dep[l] += wv * gdl[l];
                    let u = ul[l];
                    let ux = u * dx;
                    let uy = u * dy;
                    s_u[l] += u;
                    s_ux[l] += ux;
                    s_uxx[l] += ux * dx;
                    s_uy[l] += uy;
                    s_uyy[l] += uy * dy;
                    s_uxy[l] += ux * dy;
                }
            }
            let sum = |v: &[f32; LANES]| v.iter().sum::<f32>();
            let [red, green, blue, depth, su, mx, suxx, my] = lane_sums::<AVX2>([
                &s_col[0], &s_col[1], &s_col[2], &s_dep, &s_u, &s_ux, &s_uxx, &s_uy,
            ]);
            // α = o·G with G = exp(−½(a·dx² + 2b·dx·dy + c·dy²)) and dx = x_c − x (so
            // ∂dx/∂x_c = 1): ∂L/∂x_c = Σ ∂L/∂α·o·G·(−(a·dx + b·dy)), ∂L/∂a = Σ ∂L/∂α·o·G·(−dx²/2),
            // ∂L/∂b = Σ … ·(−dx·dy), ∂L/∂c = Σ … ·(−dy²/2), ∂L/∂o = Σ ∂L/∂α·G.
            let o = p.opacity;
            out[kk] = ProjectedGrad {
                xy: [-o * (a * mx + b * my), -o * (b * mx + c * my)],
                conic: [-0.5 * o * suxx, -o * sum(&s_uxy), -0.5 * o * sum(&s_uyy)],
                opacity: su,
                color: [red, green, blue],
                depth,
            };
        }
    }
}

/// The sums of eight lane vectors, each added lane after lane in order (as `Iterator::sum`,
/// the same bits); with `AVX2` the eight are transposed and added as vectors, about half the
/// instructions of eight sums one lane at a time (which only callers compiled with AVX2 may ask
/// for).
#[inline(always)]
fn lane_sums<const AVX2: bool>(rows: [&[f32; LANES]; 8]) -> [f32; 8] {
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        // SAFETY: only the AVX2 instantiation of the tile walk asks for `AVX2`, and it runs
        // only where `has_avx2()` found the feature.
        #[allow(unsafe_code)]
        return unsafe { lane_sums_avx2(rows) };
    }
    rows.map(|v| v.iter().sum::<f32>())
}

/// [`lane_sums`] as an 8×8 transpose and seven vector additions.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn lane_sums_avx2(rows: [&[f32; LANES]; 8]) -> [f32; 8] {
    use std::arch::x86_64::{_mm256_add_ps, _mm256_loadu_ps, _mm256_storeu_ps};
    // SAFETY: each row is 8 floats.
    #[allow(unsafe_code)]
    let r = rows.map(|v| unsafe { _mm256_loadu_ps(v.as_ptr()) });
    // Column l: lane l of every row.
    let columns = transpose8_avx2(r);
    let mut total = columns[0];
    for &c in &columns[1..] {
        total = _mm256_add_ps(total, c);
    }
    let mut out = [0.0_f32; 8];
    // SAFETY: `out` is 8 floats.
    #[allow(unsafe_code)]
    unsafe {
        _mm256_storeu_ps(out.as_mut_ptr(), total);
    }
    out
}

#[cfg(test)]
mod tests {
    use glam::{Mat3, Vec3};
    use rand::{RngExt, SeedableRng};

    use crate::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, SplatGradsMut, Splats};

    /// Renders and differentiates `splats` with either instantiation of the projection and
    /// tile loops.
    fn run(portable: bool, s: &Splats, cam: &RenderCamera, d_rgb: &[f32]) -> (Vec<u32>, Vec<u32>) {
        run_walking(portable, false, s, cam, d_rgb).0
    }

    /// As [`run`]; with `every_entry`, the backward walks every half-row of every entry of the
    /// tile lists, also those the forward blended nowhere. Also returns how many entries were
    /// not blended.
    fn run_walking(
        portable: bool,
        every_entry: bool,
        s: &Splats,
        cam: &RenderCamera,
        d_rgb: &[f32],
    ) -> ((Vec<u32>, Vec<u32>), usize) {
        let mut r = Rasterizer::new();
        r.portable_only = portable;
        let opts = RenderOptions::default();
        let out = r.forward(s, cam, &opts).clone();
        let not_blended = r.pair_rows.iter().filter(|&&m| m == 0).count();
        if every_entry {
            r.pair_rows.fill(u32::MAX);
        }
        let n_px = (cam.width * cam.height) as usize;
        let d_alpha: Vec<f32> = (0..n_px).map(|i| (i % 7) as f32 * 1e-2 - 0.03).collect();
        let d_depth: Vec<f32> = (0..n_px).map(|i| (i % 5) as f32 * 1e-2 - 0.02).collect();
        let mut g = SplatGrads::zeros_like(s);
        r.backward(s, cam, &opts, d_rgb, Some(&d_alpha), Some(&d_depth), &mut g);
        let img = out.rgb.iter().chain(&out.alpha).chain(&out.depth);
        let grads = g
            .means
            .iter()
            .chain(&g.log_scales)
            .flat_map(|v| v.to_array())
            .chain(g.rotations.iter().flatten().copied())
            .chain(g.opacity_logits.iter().copied())
            .chain(g.sh.iter().flatten().copied());
        let bits = (
            img.map(|x| x.to_bits()).collect(),
            grads.map(f32::to_bits).collect(),
        );
        (bits, not_blended)
    }

    #[test]
    fn simd_and_portable_tile_loops_agree_bit_for_bit() {
        let (s, cam, d_rgb) = scene(7);
        let (img_p, grad_p) = run(true, &s, &cam, &d_rgb);
        let (img_v, grad_v) = run(false, &s, &cam, &d_rgb);
        assert!(img_p.iter().any(|&b| b != 0), "the scene must cover pixels");
        assert!(
            grad_p.iter().any(|&b| b != 0),
            "the scene must have gradients"
        );
        assert_eq!(img_p, img_v);
        assert_eq!(grad_p, grad_v);
    }

    /// Skipping the entries the forward blended into no pixel must not change a gradient bit:
    /// their records are zero and they leave every pixel's running state as it was.
    #[test]
    fn skipping_entries_blended_nowhere_changes_no_gradient() {
        for seed in [7, 8, 9] {
            let (s, cam, d_rgb) = scene(seed);
            for portable in [true, false] {
                let (skipping, not_blended) = run_walking(portable, false, &s, &cam, &d_rgb);
                let (walking, _) = run_walking(portable, true, &s, &cam, &d_rgb);
                assert!(
                    not_blended > 20,
                    "seed {seed}: {not_blended} entries not blended"
                );
                assert!(
                    skipping.1.iter().any(|&b| b != 0),
                    "the scene must have gradients"
                );
                assert_eq!(skipping, walking, "seed {seed}, portable {portable}");
            }
        }
    }

    /// The transposed lane sums must be the lane-by-lane sums bit for bit: random magnitudes
    /// that round differently in another order, signed zeros, infinities.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn transposed_lane_sums_are_the_sequential_sums() {
        if !crate::has_avx2() {
            return;
        }
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        for case in 0..5_000 {
            let rows: [[f32; 8]; 8] = std::array::from_fn(|_| {
                std::array::from_fn(|_| match rng.random_range(0..10) {
                    0 => -0.0,
                    1 => 0.0,
                    2 if case % 7 == 0 => f32::INFINITY,
                    _ => rng.random_range(-1.0_f32..1.0) * 10f32.powi(rng.random_range(-8..8)),
                })
            });
            let refs = std::array::from_fn(|j| &rows[j]);
            let vector = super::lane_sums::<true>(refs);
            let scalar = super::lane_sums::<false>(refs);
            assert_eq!(
                vector.map(f32::to_bits),
                scalar.map(f32::to_bits),
                "{rows:?}"
            );
            for (j, row) in rows.iter().enumerate() {
                assert_eq!(scalar[j].to_bits(), row.iter().sum::<f32>().to_bits());
            }
        }
    }

    /// Chaining the sums range by range, in any order, into per-range buffers gives each splat
    /// the gradients `backward` gives it, bit for bit; a range past the splats is refused.
    #[test]
    fn chained_ranges_give_the_gradients_of_the_whole_backward() {
        let (s, cam, d_rgb) = scene(5);
        let opts = RenderOptions::default();
        let mut r = Rasterizer::new();
        r.forward(&s, &cam, &opts);
        let mut whole = SplatGrads::default();
        r.backward(&s, &cam, &opts, &d_rgb, None, None, &mut whole);
        assert!(
            whole.sh.iter().flatten().any(|&g| g != 0.0),
            "the scene must have gradients"
        );

        let mut r = Rasterizer::new();
        r.forward(&s, &cam, &opts);
        r.backward_sums(&s, &cam, &opts, &d_rgb, None, None);
        let k = s.coeffs_per_splat();
        let mut ranged = SplatGrads::zeros_like(&s);
        // Uneven ranges, last first.
        let bounds = [0, 7, 100, 101, 333, s.len()];
        for w in bounds.windows(2).rev() {
            let (a, b) = (w[0], w[1]);
            let g = SplatGradsMut {
                means: &mut ranged.means[a..b],
                log_scales: &mut ranged.log_scales[a..b],
                rotations: &mut ranged.rotations[a..b],
                opacity_logits: &mut ranged.opacity_logits[a..b],
                sh: &mut ranged.sh[a * k..b * k],
                screen_grad_norm: &mut ranged.screen_grad_norm[a..b],
            };
            r.chain_into(a, g);
        }
        let bits = |g: &SplatGrads| -> Vec<u32> {
            g.means
                .iter()
                .chain(&g.log_scales)
                .flat_map(|v| v.to_array())
                .chain(g.rotations.iter().flatten().copied())
                .chain(g.opacity_logits.iter().copied())
                .chain(g.sh.iter().flatten().copied())
                .chain(g.screen_grad_norm.iter().copied())
                .map(f32::to_bits)
                .collect()
        };
        assert_eq!(bits(&ranged), bits(&whole));

        let past = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            let mut g = SplatGrads {
                means: vec![Vec3::ZERO; 2],
                log_scales: vec![Vec3::ZERO; 2],
                rotations: vec![[0.0; 4]; 2],
                opacity_logits: vec![0.0; 2],
                sh: vec![[0.0; 3]; 2 * k],
                screen_grad_norm: vec![0.0; 2],
            };
            r.chain_into(s.len() - 1, g.as_mut());
        }));
        assert!(past.is_err(), "a range past the splats must be refused");
    }

    /// Overlapping splats of many sizes (sub-pixel to several tiles) and opacities, some
    /// reaching the partial tiles at the right and bottom edges of a 70×45 image, and a loss
    /// gradient for its pixels.
    fn scene(seed: u64) -> (Splats, RenderCamera, Vec<f32>) {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let n = 400;
        let pts: Vec<Vec3> = (0..n)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-1.4..1.4),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(2.0..4.0),
                )
            })
            .collect();
        let colors: Vec<[f32; 3]> = (0..n)
            .map(|_| [rng.random(), rng.random(), rng.random()])
            .collect();
        let scales: Vec<Vec3> = (0..n)
            .map(|_| Vec3::splat(rng.random_range(0.005..0.3)) * Vec3::new(1.0, 0.4, 1.0))
            .collect();
        let normals: Vec<Vec3> = (0..n)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    -1.0,
                )
            })
            .collect();
        let mut s = Splats::from_points(&pts, &colors, &scales, Some(&normals), 0.5, 1)
            .expect("consistent inputs");
        for o in &mut s.opacity_logits {
            *o = rng.random_range(-3.0..5.0);
        }
        let cam = RenderCamera {
            width: 70,
            height: 45,
            fx: 50.0,
            fy: 50.0,
            cx: 35.0,
            cy: 22.5,
            rotation: Mat3::IDENTITY,
            translation: Vec3::ZERO,
        };
        let d_rgb: Vec<f32> = (0..3 * 70 * 45)
            .map(|_| rng.random_range(-1.0..1.0))
            .collect();
        (s, cam, d_rgb)
    }
}
