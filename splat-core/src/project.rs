//! Per-splat projection: covariance from scale and rotation, EWA projection to the image
//! (Zwicker et al. 2002, as in Inria's `forward.cu::computeCov2D`), conic, 3σ extent, colour;
//! its exact backward is [`crate::project_backward`]'s.
//!
//! The forward runs eight splats at a time in vector lanes ([`project8`]), lane by lane the IEEE
//! operations of a projection one splat at a time (kept in the tests as `reference::project`,
//! which checks the bits, and `reference::project_backward` the backward's); what the backward
//! needs of it is stored in lanes too ([`ChainLanes`]).

use glam::{Mat3, Vec3};
#[cfg(test)]
use glam::{Quat, Vec2};

use crate::constants::{DILATION, EXTENT_SIGMAS, FOV_CLAMP_MARGIN, MIN_ALPHA, NEAR_PLANE};
use crate::lanes::{D8, F8, Mask, Real, WIDTH, and, array, rows_to_lanes};
use crate::projected::{Projected, quad_bound};
use crate::splats::exp;
use crate::{
    MIN_QUAT_NORM, RenderCamera, RenderOptions, Splats, all_finite, num_sh_coeffs, sh, sigmoid,
};

/// Why a splat was not drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Cull {
    /// Not drawn for a geometric or opacity reason (behind the near plane, off screen, invisible).
    Hidden,
    /// An input or an intermediate was NaN or infinite.
    NonFinite,
}

/// Per-view constants of the projection.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ViewConsts {
    pub rot: Mat3,
    pub trans: Vec3,
    pub center: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// Jacobian clamp limits for x/z: [−lim_x_neg, lim_x_pos] (gsplat's form of Inria's 1.3·tan).
    pub lim_x: (f32, f32),
    pub lim_y: (f32, f32),
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub degree: u32,
    pub antialiased: bool,
    pub linear_colour: bool,
}

impl ViewConsts {
    pub fn new(cam: &RenderCamera, opts: &RenderOptions, splats: &Splats) -> Self {
        let (tx, ty) = cam.tan_half_fov();
        let (w, h) = (cam.width as f32, cam.height as f32);
        Self {
            rot: cam.rotation,
            trans: cam.translation,
            center: cam.center(),
            fx: cam.fx,
            fy: cam.fy,
            cx: cam.cx,
            cy: cam.cy,
            lim_x: (
                cam.cx / cam.fx + FOV_CLAMP_MARGIN * tx,
                (w - cam.cx) / cam.fx + FOV_CLAMP_MARGIN * tx,
            ),
            lim_y: (
                cam.cy / cam.fy + FOV_CLAMP_MARGIN * ty,
                (h - cam.cy) / cam.fy + FOV_CLAMP_MARGIN * ty,
            ),
            tiles_x: cam.width.div_ceil(crate::TILE_SIZE),
            tiles_y: cam.height.div_ceil(crate::TILE_SIZE),
            degree: opts.active_sh_degree.min(splats.sh_degree),
            antialiased: opts.antialiased,
            linear_colour: opts.linear_colour,
        }
    }
}

/// What the tiles draw of a splat, and where.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Drawn {
    pub out: Projected,
    /// Tile rectangle [x0, x1) × [y0, y1).
    pub rect: [u32; 4],
    pub radius: u32,
}

/// One splat's projection: what the tiles draw, where, and what the backward pass chains through.
#[cfg(test)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Intermediates {
    pub out: Projected,
    /// Tile rectangle [x0, x1) × [y0, y1).
    pub rect: [u32; 4],
    pub radius: u32,
    pub chain: Chain,
}

/// The intermediates of a splat's projection that its backward needs (the tests' one-splat form
/// of a lane of [`ChainLanes`]).
#[cfg(test)]
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Chain {
    quat: Quat,
    quat_norm: f32,
    quat_zero: bool,
    scale: Vec3,
    rot: Mat3,
    /// M_c = W·R·S, so Σ_cam = M_c·M_cᵀ.
    mc: Mat3,
    p_cam: Vec3,
    /// x/z and y/z after the clamp, and whether each clamp acted.
    u: Vec2,
    clamped: [bool; 2],
    /// Rows of J·M_c (2×3), so Σ₂ = T·Tᵀ before dilation.
    t_rows: [Vec3; 2],
    comp: f32,
    sigmoid_o: f32,
    dir: Vec3,
    dir_len: f32,
    color_raw: Vec3,
}

/// What the backward needs of eight consecutive splats' projections, field by field in lanes
/// (splat 8·g + l in lane l of group g): the projection stores whole vectors and the backward
/// reads them back as vectors (storing each splat's record from lanes cost the projection about
/// as much as its arithmetic). The rotation, M_c and T are not kept: the backward recomputes
/// them in lanes for less than reading them back cost.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ChainLanes {
    /// (x, y, z, w).
    pub(crate) quat: [F8; 4],
    pub(crate) quat_norm: F8,
    pub(crate) quat_zero: Mask,
    pub(crate) scale: [F8; 3],
    pub(crate) p_cam: [F8; 3],
    pub(crate) u: [F8; 2],
    pub(crate) clamped: [Mask; 2],
    pub(crate) comp: F8,
    pub(crate) sigmoid_o: F8,
    pub(crate) dir: [F8; 3],
    pub(crate) dir_len: F8,
    pub(crate) color_raw: [F8; 3],
    /// The colour's Jacobian with respect to `dir` (`sh::dir_jacobian_terms`), so that the
    /// chain's dL/d(dir) needs neither the SH coefficients nor the basis derivatives.
    pub(crate) dir_jac: [[F8; 3]; 3],
}

impl ChainLanes {
    /// The unit directions from the camera to the splats.
    #[inline(always)]
    pub(crate) fn dir(&self) -> &[F8; 3] {
        &self.dir
    }

    /// The colour's Jacobian with respect to [`Self::dir`], row by colour channel.
    #[inline(always)]
    pub(crate) fn dir_jac(&self) -> &[[F8; 3]; 3] {
        &self.dir_jac
    }
}

#[cfg(test)]
impl ChainLanes {
    /// The chain of lane `l` in view `v`.
    #[inline(always)]
    pub(crate) fn lane(&self, v: &ViewConsts, l: usize) -> Chain {
        let v3 = |a: &[F8; 3]| Vec3::new(a[0].0[l], a[1].0[l], a[2].0[l]);
        let m3 = |m: &[[F8; 3]; 3]| Mat3::from_cols(v3(&m[0]), v3(&m[1]), v3(&m[2]));
        let (rot, mc) = cov_factor(v, self.quat, self.scale);
        let t = t_rows(&mc, &jacobian(v, self.p_cam[2], self.u));
        let q = &self.quat;
        Chain {
            quat: Quat::from_xyzw(q[0].0[l], q[1].0[l], q[2].0[l], q[3].0[l]),
            quat_norm: self.quat_norm.0[l],
            quat_zero: self.quat_zero[l],
            scale: v3(&self.scale),
            rot: m3(&rot),
            mc: m3(&mc),
            p_cam: v3(&self.p_cam),
            u: Vec2::new(self.u[0].0[l], self.u[1].0[l]),
            clamped: [self.clamped[0][l], self.clamped[1][l]],
            t_rows: [v3(&t[0]), v3(&t[1])],
            comp: self.comp.0[l],
            sigmoid_o: self.sigmoid_o.0[l],
            dir: v3(&self.dir),
            dir_len: self.dir_len.0[l],
            color_raw: v3(&self.color_raw),
        }
    }
}

/// The 2-D covariance Σ₂ = T·Tᵀ + 0.3·I of a splat and its determinants, in f64.
///
/// For a thin splat that is long on screen, a·c − b² cancels: with σ = 3000 px by 0.3 px, a·c is
/// about 10¹³ while the determinant is about 3·10⁶, below the f32 rounding of a·c, so it came out
/// wrong by more than itself, often negative (the splat vanished). Here det(T·Tᵀ) is the sum of
/// squares of the 2×2 minors of T (Cauchy–Binet; the Lagrange identity |t₀|²|t₁|² − (t₀·t₁)² =
/// |t₀ × t₁|² with t₀, t₁ the rows of T): each minor involves two of the splat's scaled axes and
/// scales with their product, so nothing large cancels, and the dilated determinant is
/// det₀ + 0.3·(s₀₀ + s₁₁) + 0.3², a sum of non-negative terms. The products of f32 entries are
/// exact in f64, and the f64 range holds the determinant of splats whose axes are up to ~10³⁸ px
/// (f32 overflowed at ~10¹⁰ px). About twenty f64 operations per splat and view, against the
/// per-pixel work of the tiles: no measurable cost.
pub(crate) struct Cov2<T> {
    /// Σ₂ before dilation: s₀₀, s₀₁, s₁₁.
    s: [T; 3],
    /// det(T·Tᵀ).
    det0: T,
    /// det(T·Tᵀ + 0.3·I).
    det: T,
}

impl<T: Real<Scalar = f64>> Cov2<T> {
    /// From the rows t₀, t₁ of T, widened to f64 (one splat, or eight in lanes).
    #[inline(always)]
    pub(crate) fn new([t0, t1]: [[T; 3]; 2]) -> Self {
        let dot = |a: [T; 3], b: [T; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let s = [dot(t0, t0), dot(t0, t1), dot(t1, t1)];
        let cross = [
            t0[1] * t1[2] - t1[1] * t0[2],
            t0[2] * t1[0] - t1[2] * t0[0],
            t0[0] * t1[1] - t1[0] * t0[1],
        ];
        let det0 = dot(cross, cross);
        let d = T::splat(f64::from(DILATION));
        Self {
            s,
            det0,
            det: det0 + d * (s[0] + s[2]) + d * d,
        }
    }

    /// The conic Σ₂⁻¹ (a, b, c) of the dilated covariance.
    #[inline(always)]
    pub(crate) fn conic(&self) -> [T; 3] {
        let d = T::splat(f64::from(DILATION));
        let [s00, s01, s11] = self.s;
        [(s11 + d) / self.det, -s01 / self.det, (s00 + d) / self.det]
    }

    /// The inverse of the covariance before dilation (infinite when it is singular).
    #[inline(always)]
    pub(crate) fn conic0(&self) -> [T; 3] {
        let [s00, s01, s11] = self.s;
        [s11 / self.det0, -s01 / self.det0, s00 / self.det0]
    }

    /// The larger eigenvalue of the dilated covariance (Inria floors the discriminant at 0.1).
    #[inline(always)]
    fn lambda_max(&self) -> T {
        let d = T::splat(f64::from(DILATION));
        let mid = T::splat(0.5) * (self.s[0] + self.s[2]) + d;
        mid + (mid * mid - self.det).max(T::splat(0.1)).sqrt()
    }
}

/// Narrows the tile rectangle `rect` ([x0, x1) × [y0, y1) in tiles, Inria's 3σ square) to
/// the tiles that the splat's alpha ≥ 1/255 ellipse, q(d) = dᵀ·conic·d ≤ `q_max` around `xy`,
/// reaches: the ellipse's axis-aligned box, half-widths √(q_max·Σₓₓ) and √(q_max·Σᵧᵧ) with Σ
/// the inverse of the (f32) conic the tile loops use. Every pixel that can pass the 1/255 test
/// lies in that box (`quad_bound`, and the row spans are its rows), so the tiles dropped are
/// ones where the splat would composite nothing: the images and gradients do not change, the
/// (tile, splat) pairs fall. A surface splat seen at a slant is a thin ellipse whose 3σ square
/// is mostly empty.
#[inline(always)]
fn within_reach(
    rect: [u32; 4],
    xy: [f32; 2],
    conic: [f32; 3],
    q_max: f32,
    [tiles_x, tiles_y]: [u32; 2],
) -> [u32; 4] {
    let [a, b, c] = conic.map(f64::from);
    let det = a * c - b * b;
    let q = f64::from(q_max);
    let (hx, hy) = ((q * c / det).sqrt(), (q * a / det).sqrt());
    if !(det > 0.0 && hx.is_finite() && hy.is_finite()) {
        return rect;
    }
    let (x0, x1) = tiles_reached(xy[0], hx, tiles_x);
    let (y0, y1) = tiles_reached(xy[1], hy, tiles_y);
    [
        rect[0].max(x0),
        rect[1].min(x1),
        rect[2].max(y0),
        rect[3].min(y1),
    ]
}

/// The tiles [first, end) of a row of `n` whose pixel centres can fall within `h` of `centre`;
/// half a pixel of margin beyond that keeps a tile whose edge pixel sits on the bound. (A
/// function, not a closure, so it inlines into the AVX2 projection and its floors become
/// instructions rather than library calls.)
#[inline(always)]
fn tiles_reached(centre: f32, h: f64, n: u32) -> (u32, u32) {
    let ts = f64::from(crate::TILE_SIZE);
    let (lo, hi) = (f64::from(centre) - h - 0.5, f64::from(centre) + h + 0.5);
    let first = (lo / ts).floor().clamp(0.0, f64::from(n)) as u32;
    let end = ((hi / ts).floor() + 1.0).clamp(0.0, f64::from(n)) as u32;
    (first, end)
}

/// The tile rectangle [x0, x1) × [y0, y1) of Inria's square of half-width `radius` (pixels)
/// around `xy`, clamped to the view's `tiles`.
#[inline(always)]
fn square_tiles(xy: [f32; 2], radius: f32, [tiles_x, tiles_y]: [u32; 2]) -> [u32; 4] {
    let ts = crate::TILE_SIZE as f32;
    let coord = |p: f32, lo: bool, n: u32| -> u32 {
        let t = if lo {
            ((p - radius) / ts).floor()
        } else {
            ((p + radius + ts - 1.0) / ts).floor()
        };
        t.clamp(0.0, n as f32) as u32
    };
    [
        coord(xy[0], true, tiles_x),
        coord(xy[0], false, tiles_x),
        coord(xy[1], true, tiles_y),
        coord(xy[1], false, tiles_y),
    ]
}

/// `m·p` for one matrix and a vector in lanes, in glam's order of operations
/// (`Mat3::mul_vec3`).
#[inline(always)]
pub(crate) fn mat_vec(m: Mat3, p: [F8; 3]) -> [F8; 3] {
    array(|c| {
        F8::splat(m.x_axis[c]) * p[0]
            + F8::splat(m.y_axis[c]) * p[1]
            + F8::splat(m.z_axis[c]) * p[2]
    })
}

/// The rotation R (columns) of eight splats' unit quaternions (x, y, z, w), as glam's
/// `Mat3::from_quat` computes it, and the covariance factor M_c = W·(R·S) with S their scales,
/// column by column: the forward computes it, and the backward again rather than storing 18
/// floats a splat.
#[inline(always)]
pub(crate) fn cov_factor(
    v: &ViewConsts,
    [x, y, z, w]: [F8; 4],
    scale: [F8; 3],
) -> ([[F8; 3]; 3], [[F8; 3]; 3]) {
    let one = F8::splat(1.0);
    let (x2, y2, z2) = (x + x, y + y, z + z);
    let (xx, xy, xz) = (x * x2, x * y2, x * z2);
    let (yy, yz, zz) = (y * y2, y * z2, z * z2);
    let (wx, wy, wz) = (w * x2, w * y2, w * z2);
    let rot = [
        [one - (yy + zz), xy + wz, xz - wy],
        [xy - wz, one - (xx + zz), yz + wx],
        [xz + wy, yz - wx, one - (xx + yy)],
    ];
    let mc = array(
        #[inline(always)]
        |j| mat_vec(v.rot, array(|c| rot[j][c] * scale[j])),
    );
    (rot, mc)
}

/// The rows of the EWA Jacobian J at depth `z` and the clamped x/z, y/z `u`.
#[inline(always)]
pub(crate) fn jacobian(v: &ViewConsts, z: F8, u: [F8; 2]) -> [[F8; 3]; 2] {
    let (fx, fy, zero) = (F8::splat(v.fx), F8::splat(v.fy), F8::splat(0.0));
    [
        [fx / z, zero, -fx * u[0] / z],
        [zero, fy / z, -fy * u[1] / z],
    ]
}

/// T's rows M_cᵀ·j_r (so Σ₂ = T·Tᵀ before dilation), in glam's order (`mct * j`).
#[inline(always)]
pub(crate) fn t_rows(mc: &[[F8; 3]; 3], j: &[[F8; 3]; 2]) -> [[F8; 3]; 2] {
    array(
        #[inline(always)]
        |r| array(|c| mc[c][0] * j[r][0] + mc[c][1] * j[r][1] + mc[c][2] * j[r][2]),
    )
}

/// Why each lane is not drawn so far: the first reason found wins, as the early returns of a
/// projection one splat at a time would have it.
struct Culls([Option<Cull>; WIDTH]);

impl Culls {
    /// Marks `why` on the lanes not yet culled where `fails` holds.
    #[inline(always)]
    fn mark(&mut self, fails: Mask, why: Cull) {
        for (c, f) in self.0.iter_mut().zip(fails) {
            if c.is_none() && f {
                *c = Some(why);
            }
        }
    }

    /// Marks `why` on the lanes not yet culled where `holds` does not.
    #[inline(always)]
    fn unless(&mut self, holds: Mask, why: Cull) {
        self.mark(holds.map(|h| !h), why);
    }
}

/// Working memory [`project8`] reuses from group to group: zeroed once by the caller rather
/// than once a group (the zeroing was a library call, and the loads that followed could not
/// take their data from its stores).
pub(crate) struct Scratch {
    /// The SH coefficients in lanes: coefficient kk's channel ch is vector 3·kk + ch.
    sh: [F8; 3 * 16],
}

impl Default for Scratch {
    fn default() -> Self {
        Self {
            sh: [F8::default(); 3 * 16],
        }
    }
}

/// Projects the splats `idx` (eight, repeats allowed) at once in vector lanes: lane by lane the
/// same IEEE operations in the same order as the projection of one splat at a time
/// (`reference::project` in the tests, which checks the bits), with the tile rectangle left
/// scalar (the opacity's and scales' exponentials and the alpha bound's logarithm are
/// branch-free functions, computed as vectors). Stores the eight chains in `chain` and hands
/// `emit` what the tiles draw of each of the first `lanes_used` lanes, or why the splat is
/// culled (straight into the caller's arrays: an array of results in between cost a copy).
/// `AVX2` (asked for only by callers compiled with AVX2) moves the SH coefficients into lanes
/// with AVX2 shuffles; `scratch` is the caller's, reused from group to group.
#[inline(always)]
#[allow(clippy::too_many_lines)]
#[allow(clippy::needless_range_loop)] // a lane's index reads several arrays of lanes
pub(crate) fn project8<const AVX2: bool>(
    splats: &Splats,
    idx: [usize; WIDTH],
    lanes_used: usize,
    v: &ViewConsts,
    chain: &mut ChainLanes,
    scratch: &mut Scratch,
    mut emit: impl FnMut(usize, Result<Drawn, Cull>),
) {
    let k = splats.coeffs_per_splat();
    let n_coeffs = num_sh_coeffs(v.degree);
    let coeffs = |l: usize| &splats.sh[idx[l] * k..idx[l] * k + n_coeffs];
    let mean: [F8; 3] = array(|c| F8::from_fn(|l| splats.means[idx[l]][c]));
    let ls: [F8; 3] = array(|c| F8::from_fn(|l| splats.log_scales[idx[l]][c]));
    // (w, x, y, z), as stored.
    let q: [F8; 4] = array(|c| F8::from_fn(|l| splats.rotations[idx[l]][c]));
    let logit = F8::from_fn(|l| splats.opacity_logits[idx[l]]);

    let (zero, one, half) = (F8::splat(0.0), F8::splat(1.0), F8::splat(0.5));
    let mut culls = Culls([None; WIDTH]);
    let mut inputs_finite: Mask = array(|l| all_finite(coeffs(l).as_flattened()));
    for x in mean.iter().chain(&ls).chain(&q).chain([&logit]) {
        inputs_finite = and(inputs_finite, x.finite());
    }
    culls.unless(inputs_finite, Cull::NonFinite);
    let p_cam: [F8; 3] = {
        let r = mat_vec(v.rot, mean);
        array(|c| r[c] + F8::splat(v.trans[c]))
    };
    culls.unless(
        and(and(p_cam[0].finite(), p_cam[1].finite()), p_cam[2].finite()),
        Cull::NonFinite,
    );
    let z = p_cam[2];
    culls.mark(z.test(F8::splat(NEAR_PLANE), |a, b| a <= b), Cull::Hidden);
    let sigmoid_o = logit.map(sigmoid);
    culls.mark(
        sigmoid_o.test(F8::splat(MIN_ALPHA), |a, b| a < b),
        Cull::Hidden,
    );

    // `normalize_quat`: divided by the largest magnitude, then by the length, whose sum of
    // squares glam's SSE2 `Quat::length` groups as (x² + z²) + (y² + w²).
    let mut largest = F8::splat(0.0);
    for c in q {
        largest = largest.max(c.map(f32::abs));
    }
    let has_largest = and(largest.finite(), largest.test(F8::splat(0.0), |a, b| a > b));
    let [uw, ux_q, uy_q, uz_q] = array(|c| q[c] / largest);
    let length = ((ux_q * ux_q + uz_q * uz_q) + (uy_q * uy_q + uw * uw)).sqrt();
    let norm = largest * length;
    let normal = and(
        has_largest,
        norm.test(F8::splat(MIN_QUAT_NORM), |a, b| a > b),
    );
    let identity = [one, zero, zero, zero];
    let [w, x, y, zq] =
        array(|c| F8::select(normal, [uw, ux_q, uy_q, uz_q][c] / length, identity[c]));
    let quat_norm = F8::select(normal, norm, F8::splat(0.0));

    let scale: [F8; 3] = array(|c| ls[c].map(exp));
    let quat = [x, y, zq, w];
    let mc = cov_factor(v, quat, scale).1;

    let ux_raw = p_cam[0] / z;
    let uy_raw = p_cam[1] / z;
    let u = [
        ux_raw.map(|u| u.clamp(-v.lim_x.0, v.lim_x.1)),
        uy_raw.map(|u| u.clamp(-v.lim_y.0, v.lim_y.1)),
    ];
    let clamped = [
        u[0].test(ux_raw, |a, b| a != b),
        u[1].test(uy_raw, |a, b| a != b),
    ];
    let t_rows = t_rows(&mc, &jacobian(v, z, u));
    let mut t_finite = [true; WIDTH];
    for c in t_rows.as_flattened() {
        t_finite = and(t_finite, c.finite());
    }
    culls.unless(t_finite, Cull::NonFinite);
    let cov = Cov2::<D8>::new(array(|r| array(|c| t_rows[r][c].to_f64())));
    culls.mark(cov.det.test(D8::splat(0.0), |a, b| a <= b), Cull::Hidden);
    let comp = if v.antialiased {
        (cov.det0 / cov.det).sqrt().to_f32()
    } else {
        one
    };
    let opacity = sigmoid_o * comp;
    culls.mark(
        opacity.test(F8::splat(MIN_ALPHA), |a, b| a < b),
        Cull::Hidden,
    );
    let conic: [F8; 3] = {
        let c = cov.conic();
        array(|k| c[k].to_f32())
    };

    let radius_f = (D8::splat(f64::from(EXTENT_SIGMAS)) * cov.lambda_max().sqrt())
        .map(f64::ceil)
        .to_f32();
    let xy = [
        F8::splat(v.fx) * ux_raw + F8::splat(v.cx) - half,
        F8::splat(v.fy) * uy_raw + F8::splat(v.cy) - half,
    ];
    culls.unless(
        and(and(xy[0].finite(), xy[1].finite()), radius_f.finite()),
        Cull::NonFinite,
    );
    let q_max = opacity.map(quad_bound);
    let tiles = [v.tiles_x, v.tiles_y];
    let mut rect = [[0_u32; 4]; WIDTH];
    for (l, rect) in rect.iter_mut().enumerate() {
        let xy_l = [xy[0].0[l], xy[1].0[l]];
        let square = square_tiles(xy_l, radius_f.0[l], tiles);
        let conic_l = [conic[0].0[l], conic[1].0[l], conic[2].0[l]];
        *rect = within_reach(square, xy_l, conic_l, q_max.0[l], tiles);
    }
    let empty: Mask =
        array(|l| radius_f.0[l] <= 0.0 || rect[l][0] >= rect[l][1] || rect[l][2] >= rect[l][3]);
    culls.mark(empty, Cull::Hidden);

    // Colour from SH towards the viewer: dir = normalize(mean − camera centre), + 0.5, clamp at 0.
    let d: [F8; 3] = array(|c| mean[c] - F8::splat(v.center[c]));
    let dir_len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let dir: [F8; 3] = array(|c| d[c] / dir_len);
    let lane_coeffs = &mut scratch.sh;
    rows_to_lanes::<AVX2>(
        array(|l| coeffs(l).as_flattened()),
        &mut lane_coeffs[..3 * n_coeffs],
    );
    let lane_coeff = |kk: usize| array(|ch| lane_coeffs[3 * kk + ch]);
    let sh = sh::eval_terms(v.degree, n_coeffs, dir, lane_coeff);
    let dir_jac = sh::dir_jacobian_terms(v.degree, n_coeffs, dir, lane_coeff);
    let (color_raw, color) = if v.linear_colour {
        (sh, sh)
    } else {
        let raw: [F8; 3] = array(|c| sh[c] + half);
        let shown = array(|c| F8::select(raw[c].test(zero, |a, b| a > b), raw[c], zero));
        (raw, shown)
    };
    culls.unless(
        and(and(color[0].finite(), color[1].finite()), color[2].finite()),
        Cull::NonFinite,
    );

    *chain = ChainLanes {
        quat,
        quat_norm,
        quat_zero: normal.map(|n| !n),
        scale,
        p_cam,
        u,
        clamped,
        comp,
        sigmoid_o,
        dir,
        dir_len,
        color_raw,
        dir_jac,
    };
    for l in 0..lanes_used {
        if let Some(why) = culls.0[l] {
            emit(l, Err(why));
            continue;
        }
        emit(
            l,
            Ok(Drawn {
                out: Projected {
                    xy: [xy[0].0[l], xy[1].0[l]],
                    conic: [conic[0].0[l], conic[1].0[l], conic[2].0[l]],
                    opacity: opacity.0[l],
                    color: [color[0].0[l], color[1].0[l], color[2].0[l]],
                    depth: z.0[l],
                    q_max: q_max.0[l],
                },
                rect: rect[l],
                radius: radius_f.0[l] as u32,
            }),
        );
    }
}

#[cfg(test)]
pub(crate) mod reference {
    use glam::{Mat3, Quat, Vec2, Vec3};

    use super::{Chain, Cov2, Cull, Intermediates, ViewConsts, square_tiles, within_reach};
    use crate::constants::{EXTENT_SIGMAS, MIN_ALPHA, NEAR_PLANE};
    use crate::project_backward::{ProjectedGrad, quat_backward_terms, sandwich};
    use crate::projected::{Projected, quad_bound};
    use crate::splats::exp;
    use crate::{Splats, all_finite, normalize_quat, num_sh_coeffs, sh, sigmoid};

    fn finite3(v: Vec3) -> bool {
        v.is_finite()
    }

    /// The parameter gradients of one splat.
    pub(crate) struct ParamGrad {
        pub mean: Vec3,
        pub log_scale: Vec3,
        pub rotation: [f32; 4],
        pub opacity_logit: f32,
        pub screen_norm: f32,
    }

    /// Projects splat `i`; returns its intermediates or why it is culled.
    pub(crate) fn project(
        splats: &Splats,
        i: usize,
        v: &ViewConsts,
    ) -> Result<Intermediates, Cull> {
        let mean = splats.means[i];
        let ls = splats.log_scales[i];
        let [qw, qx, qy, qz] = splats.rotations[i];
        let logit = splats.opacity_logits[i];
        let k = splats.coeffs_per_splat();
        let coeffs = &splats.sh[i * k..i * k + num_sh_coeffs(v.degree)];
        let inputs_finite = finite3(mean)
            && finite3(ls)
            && [qw, qx, qy, qz, logit].iter().all(|x| x.is_finite())
            && all_finite(coeffs.as_flattened());
        if !inputs_finite {
            return Err(Cull::NonFinite);
        }
        let p_cam = v.rot * mean + v.trans;
        if !finite3(p_cam) {
            return Err(Cull::NonFinite);
        }
        if p_cam.z <= NEAR_PLANE {
            return Err(Cull::Hidden);
        }
        let sigmoid_o = sigmoid(logit);
        // A splat with o < 1/255 can never pass the alpha threshold anywhere: skip it early.
        if sigmoid_o < MIN_ALPHA {
            return Err(Cull::Hidden);
        }

        // Σ = R S Sᵀ Rᵀ (Inria `computeCov3D`), carried as the factor M_c = W R S in camera space.
        // A zero quaternion carries no rotation: it is drawn as the identity, with no gradient.
        let (quat, quat_norm, quat_zero) = match normalize_quat([qw, qx, qy, qz]) {
            Some((q, n)) => (q, n, false),
            None => (Quat::IDENTITY, 0.0, true),
        };
        let rot = Mat3::from_quat(quat);
        let scale = ls.map(exp);
        let m = Mat3::from_cols(
            rot.x_axis * scale.x,
            rot.y_axis * scale.y,
            rot.z_axis * scale.z,
        );
        let mc = v.rot * m;

        // EWA: J evaluated at the clamped x/z, y/z (Inria clamps to 1.3·tan(fov/2)).
        let z = p_cam.z;
        let ux_raw = p_cam.x / z;
        let uy_raw = p_cam.y / z;
        let ux = ux_raw.clamp(-v.lim_x.0, v.lim_x.1);
        let uy = uy_raw.clamp(-v.lim_y.0, v.lim_y.1);
        let clamped = [ux != ux_raw, uy != uy_raw];
        let j0 = Vec3::new(v.fx / z, 0.0, -v.fx * ux / z);
        let j1 = Vec3::new(0.0, v.fy / z, -v.fy * uy / z);
        let mct = mc.transpose();
        let t_rows = [mct * j0, mct * j1];
        if !(finite3(t_rows[0]) && finite3(t_rows[1])) {
            return Err(Cull::NonFinite);
        }
        let cov = Cov2::<f64>::new(t_rows.map(|t| t.as_dvec3().to_array()));
        if cov.det <= 0.0 {
            return Err(Cull::Hidden);
        }
        let comp = if v.antialiased {
            (cov.det0 / cov.det).sqrt() as f32
        } else {
            1.0
        };
        let opacity = sigmoid_o * comp;
        if opacity < MIN_ALPHA {
            return Err(Cull::Hidden);
        }
        let conic = cov.conic().map(|x| x as f32);

        // Inria's extent: 3·√λmax with λ from the dilated covariance, and its tile rectangle.
        let radius_f = (f64::from(EXTENT_SIGMAS) * cov.lambda_max().sqrt()).ceil() as f32;
        let xy = [v.fx * ux_raw + v.cx - 0.5, v.fy * uy_raw + v.cy - 0.5];
        if !(xy[0].is_finite() && xy[1].is_finite() && radius_f.is_finite()) {
            return Err(Cull::NonFinite);
        }
        let rect = square_tiles(xy, radius_f, [v.tiles_x, v.tiles_y]);
        let rect = within_reach(rect, xy, conic, quad_bound(opacity), [v.tiles_x, v.tiles_y]);
        if radius_f <= 0.0 || rect[0] >= rect[1] || rect[2] >= rect[3] {
            return Err(Cull::Hidden);
        }

        // Colour from SH towards the viewer: dir = normalize(mean − camera centre), + 0.5, clamp at 0.
        let d = mean - v.center;
        let dir_len = d.length();
        let dir = d / dir_len;
        let (color_raw, color) = if v.linear_colour {
            let c = sh::eval(v.degree, dir, coeffs);
            (c, c)
        } else {
            let raw = sh::eval(v.degree, dir, coeffs) + 0.5;
            (raw, raw.max(Vec3::ZERO))
        };
        if !finite3(color) {
            return Err(Cull::NonFinite);
        }
        Ok(Intermediates {
            out: Projected {
                xy,
                conic,
                opacity,
                color: color.into(),
                depth: z,
                q_max: quad_bound(opacity),
            },
            rect,
            radius: radius_f as u32,
            chain: Chain {
                quat,
                quat_norm,
                quat_zero,
                scale,
                rot,
                mc,
                p_cam,
                u: Vec2::new(ux, uy),
                clamped,
                t_rows,
                comp,
                sigmoid_o,
                dir,
                dir_len,
                color_raw,
            },
        })
    }

    /// Backward of [`project`]: chains `g` (summed over pixels) to the parameters of the splat whose
    /// SH coefficients are `coeffs`; their gradients are added into `d_sh`.
    pub(crate) fn project_backward(
        coeffs: &[[f32; 3]],
        v: &ViewConsts,
        it: &Chain,
        g: &ProjectedGrad,
        image_size: (u32, u32),
        d_sh: &mut [[f32; 3]],
    ) -> ParamGrad {
        let mut d_mean = Vec3::ZERO;

        // Colour: clamped channels pass no gradient (Inria's `clamped` flags).
        let mut d_raw = Vec3::from(g.color);
        for ch in 0..3 {
            if !v.linear_colour && it.color_raw[ch] < 0.0 {
                d_raw[ch] = 0.0;
            }
        }
        let d_dir = sh::eval_backward(v.degree, it.dir, coeffs, d_raw, d_sh);
        // dir = d/|d| with d = mean − centre.
        d_mean += (d_dir - it.dir * it.dir.dot(d_dir)) / it.dir_len;

        // Opacity: o_eff = sigmoid(l)·comp.
        let d_logit = g.opacity * it.comp * it.sigmoid_o * (1.0 - it.sigmoid_o);
        let d_comp = g.opacity * it.sigmoid_o;

        // Conic = Σ₂⁻¹ → dL/dΣ₂ = −Q·G_Q·Q with G_Q the symmetric matrix gradient (b appears
        // twice), then Σ₂ = T·Tᵀ → G_T = 2·G_Σ·T. In f64 with the forward's `Cov2`: for a thin splat
        // long on screen, Q·T's long column (≈ the axis / λ_max) is far smaller than Q's entries, and
        // f32 lost it (needles' gradients were off by percents).
        let cov = Cov2::<f64>::new(it.t_rows.map(|t| t.as_dvec3().to_array()));
        let q = cov.conic();
        let gq = [
            f64::from(g.conic[0]),
            0.5 * f64::from(g.conic[1]),
            f64::from(g.conic[2]),
        ];
        let qgq = sandwich(q, gq);
        let mut gs = [-qgq[0], -qgq[1], -qgq[2]];
        if v.antialiased && it.comp > 0.0 {
            // comp = √(det₀/det₁): d comp = comp/2·tr((Σ₀⁻¹ − Σ₁⁻¹)·dΣ), Σ₀ = Σ₁ − 0.3·I
            // (comp > 0 implies det₀ > 0 and a finite Σ₀⁻¹).
            let f = f64::from(d_comp * it.comp * 0.5);
            let q0 = cov.conic0();
            for kk in 0..3 {
                gs[kk] += f * (q0[kk] - q[kk]);
            }
        }
        let [t0, t1] = it.t_rows.map(Vec3::as_dvec3);
        let gt0 = (2.0 * (gs[0] * t0 + gs[1] * t1)).as_vec3();
        let gt1 = (2.0 * (gs[1] * t0 + gs[2] * t1)).as_vec3();
        // T rows = M_cᵀ·j_r → G_j_r = M_c·G_t_r; G_M_c = Σ_r j_r·G_t_rᵀ.
        let z = it.p_cam.z;
        let j0 = Vec3::new(v.fx / z, 0.0, -v.fx * it.u.x / z);
        let j1 = Vec3::new(0.0, v.fy / z, -v.fy * it.u.y / z);
        let gj0 = it.mc * gt0;
        let gj1 = it.mc * gt1;
        // G_M_c (column c = Σ_r j_r·gt_r[c]).
        let gmc = Mat3::from_cols(
            j0 * gt0.x + j1 * gt1.x,
            j0 * gt0.y + j1 * gt1.y,
            j0 * gt0.z + j1 * gt1.z,
        );

        // J → camera-space point. J00 = fx/z, J02 = −fx·u/z with u = x/z unless clamped (then fixed).
        let mut d_p = Vec3::ZERO;
        d_p.z += -v.fx / (z * z) * gj0.x - v.fy / (z * z) * gj1.y;
        let (fx, fy) = (v.fx, v.fy);
        // J02 = −fx·u_x/z.
        d_p.z += fx * it.u.x / (z * z) * gj0.z;
        if !it.clamped[0] {
            // u_x = x/z: ∂J02/∂x = −fx/z², ∂J02/∂z (via u) = fx·x/z³.
            d_p.x += -fx / (z * z) * gj0.z;
            d_p.z += fx * it.p_cam.x / (z * z * z) * gj0.z;
        }
        d_p.z += fy * it.u.y / (z * z) * gj1.z;
        if !it.clamped[1] {
            d_p.y += -fy / (z * z) * gj1.z;
            d_p.z += fy * it.p_cam.y / (z * z * z) * gj1.z;
        }
        // Projected centre: x_pix = fx·x/z + cx (unclamped).
        d_p.x += g.xy[0] * fx / z;
        d_p.y += g.xy[1] * fy / z;
        d_p.z += -g.xy[0] * fx * it.p_cam.x / (z * z) - g.xy[1] * fy * it.p_cam.y / (z * z);
        d_p.z += g.depth;
        d_mean += v.rot.transpose() * d_p;

        // M_c = W·R·S.
        let gm = v.rot.transpose() * gmc;
        let r = it.rot;
        let d_scale = Vec3::new(
            gm.x_axis.dot(r.x_axis),
            gm.y_axis.dot(r.y_axis),
            gm.z_axis.dot(r.z_axis),
        );
        let d_log_scale = d_scale * it.scale;
        let g_r = Mat3::from_cols(
            gm.x_axis * it.scale.x,
            gm.y_axis * it.scale.y,
            gm.z_axis * it.scale.z,
        );
        let rotation = if it.quat_zero {
            [0.0; 4]
        } else {
            quat_backward(it.quat, it.quat_norm, &g_r)
        };

        let (w, h) = image_size;
        let ndc = Vec2::new(g.xy[0] * 0.5 * w as f32, g.xy[1] * 0.5 * h as f32);
        ParamGrad {
            mean: d_mean,
            log_scale: d_log_scale,
            rotation,
            opacity_logit: d_logit,
            screen_norm: ndc.length(),
        }
    }

    /// Gradient of R(q/|q|) with respect to the stored quaternion (w, x, y, z), given G_R.
    fn quat_backward(q: Quat, norm: f32, g: &Mat3) -> [f32; 4] {
        let cols = [g.x_axis, g.y_axis, g.z_axis].map(|c| c.to_array());
        quat_backward_terms([q.w, q.x, q.y, q.z], norm, &cols)
    }

    /// The view of the lane tests: 200×150, 50° vertical field of view, 4 units out.
    pub(crate) fn lanes_camera() -> crate::RenderCamera {
        use camera_model::{Camera, Intrinsics, Pose};
        use glam::DVec3;
        crate::RenderCamera::try_from(&Camera::new(
            Intrinsics::from_fov_y(200, 150, 50.0),
            Pose::look_at(DVec3::new(0.3, 0.2, 4.0), DVec3::ZERO, DVec3::Y),
        ))
        .unwrap()
    }

    /// The options the lane tests cover at SH degree `degree`: plain, antialiased, and
    /// antialiased with linear colour.
    pub(crate) fn lanes_options(degree: u32) -> [crate::RenderOptions; 3] {
        [(false, false), (true, false), (true, true)].map(|(antialiased, linear_colour)| {
            crate::RenderOptions {
                active_sh_degree: degree,
                antialiased,
                linear_colour,
                ..crate::RenderOptions::default()
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use rand::{RngExt, SeedableRng};

    use glam::Vec3;

    use super::reference::{lanes_camera, lanes_options};
    use super::{
        ChainLanes, Cull, Intermediates, Scratch, ViewConsts, project8, reference, within_reach,
    };
    use crate::TILE_SIZE;
    use crate::lanes::WIDTH;
    use crate::projected::{quad_bound, random_footprint};

    /// Every field of a projection result as bits, so −0 and NaN payloads count.
    fn bits(r: &Result<Intermediates, Cull>) -> Vec<u32> {
        let it = match r {
            Err(Cull::Hidden) => return vec![1],
            Err(Cull::NonFinite) => return vec![2],
            Ok(it) => it,
        };
        let c = &it.chain;
        let mut f: Vec<f32> = Vec::new();
        let o = &it.out;
        f.extend(o.xy);
        f.extend(o.conic);
        f.extend([o.opacity, o.depth, o.q_max]);
        f.extend(o.color);
        f.extend(c.quat.to_array());
        f.extend([c.quat_norm, c.comp, c.sigmoid_o, c.dir_len]);
        for v in [
            c.scale,
            c.p_cam,
            c.dir,
            c.color_raw,
            c.t_rows[0],
            c.t_rows[1],
        ] {
            f.extend(v.to_array());
        }
        f.extend(c.rot.to_cols_array());
        f.extend(c.mc.to_cols_array());
        f.extend(c.u.to_array());
        let mut b: Vec<u32> = f.iter().map(|x| x.to_bits()).collect();
        b.extend(it.rect);
        b.extend([
            it.radius,
            u32::from(c.quat_zero),
            u32::from(c.clamped[0]),
            u32::from(c.clamped[1]),
        ]);
        b
    }

    /// The projection in lanes gives every splat the bits of the one-splat reference,
    /// culls included: random splats with edge cases mixed in (behind the camera, off screen,
    /// near-invisible, zero and huge quaternions, needles, NaN and infinite inputs, colours
    /// below zero), for each SH degree, with and without antialiasing and linear colour, and
    /// group starts that are not multiples of eight (repeated lanes).
    #[test]
    fn eight_lanes_give_the_bits_of_one_splat_at_a_time() {
        use crate::Splats;

        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let cam = lanes_camera();
        let specials = [
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            0.0,
            -0.0,
            1e-30,
            1e30,
        ];
        // Drawn, hidden, not finite.
        let mut outcomes = [0_usize; 3];
        for degree in 0..=3 {
            let mut splats = Splats::new(3);
            for i in 0..2_003 {
                let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
                let mut mean = Vec3::new(r(-3.0, 3.0), r(-3.0, 3.0), r(-6.0, 3.9));
                let mut ls = Vec3::new(r(-9.0, 1.0), r(-9.0, 1.0), r(-9.0, 1.0));
                let mut q = [r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)];
                let mut logit = r(-8.0, 8.0);
                let mut sh: Vec<[f32; 3]> = (0..16)
                    .map(|_| [r(-1.5, 1.5), r(-1.5, 1.5), r(-1.5, 1.5)])
                    .collect();
                match i % 13 {
                    0 => q = q.map(|c| c * 1e-30),
                    1 => q = [0.0; 4],
                    2 => q = q.map(|c| c * 1e25),
                    3 => ls = Vec3::new(r(2.0, 9.0), -12.0, r(-3.0, 0.0)),
                    4 => mean.z = 3.995,
                    5 => logit = -9.0,
                    _ => {}
                }
                if i % 29 == 7 {
                    let bad = specials[(i / 29) % specials.len()];
                    match (i / 7) % 5 {
                        0 => mean.x = bad,
                        1 => ls.y = bad,
                        2 => q[2] = bad,
                        3 => logit = bad,
                        _ => sh[(i / 3) % 16][1] = bad,
                    }
                }
                splats.push(mean, ls, q, logit, &sh);
            }
            for opts in lanes_options(degree) {
                let v = ViewConsts::new(&cam, &opts, &splats);
                let (antialiased, linear_colour) = (opts.antialiased, opts.linear_colour);
                let n = splats.len();
                for start in (0..n).step_by(5) {
                    let idx = std::array::from_fn(|l| (start + l).min(n - 1));
                    let mut drawn = [Err(Cull::Hidden); WIDTH];
                    let mut chain = ChainLanes::default();
                    project8::<false>(
                        &splats,
                        idx,
                        WIDTH,
                        &v,
                        &mut chain,
                        &mut Scratch::default(),
                        |l, r| drawn[l] = r,
                    );
                    let lanes: [_; WIDTH] = std::array::from_fn(|l| {
                        drawn[l].map(|d| Intermediates {
                            out: d.out,
                            rect: d.rect,
                            radius: d.radius,
                            chain: chain.lane(&v, l),
                        })
                    });
                    for l in 0..WIDTH {
                        let one = reference::project(&splats, idx[l], &v);
                        outcomes[match one {
                            Ok(_) => 0,
                            Err(Cull::Hidden) => 1,
                            Err(Cull::NonFinite) => 2,
                        }] += 1;
                        assert_eq!(
                            bits(&lanes[l]),
                            bits(&one),
                            "degree {degree}, antialiased {antialiased}, linear \
                             {linear_colour}: splat {} in lane {l}",
                            idx[l]
                        );
                    }
                }
            }
        }
        assert!(
            outcomes[0] > 10_000 && outcomes[1] > 10_000 && outcomes[2] > 200,
            "every outcome must occur often: {outcomes:?}"
        );
    }

    /// Narrowing a splat's tiles must keep every tile holding a pixel with alpha ≥ 1/255
    /// (checked in f64 over a 256² view, around random rotated, stretched splats, some near
    /// or past the edges), and must actually drop tiles of the 3σ square for slanted splats.
    #[test]
    fn narrowed_tiles_keep_every_pixel_that_can_reach_the_alpha_threshold() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(3);
        let (n, ts) = (16_u32, TILE_SIZE as i32);
        let size = n as i32 * ts;
        let (mut reached, mut narrower) = (0, 0);
        let cases = 4_000;
        for case in 0..cases {
            let ([cxx, cyy, cxy], conic) = random_footprint(&mut rng, 30.0);
            let det = cxx * cyy - cxy * cxy;
            let conic = conic.map(|v| v as f32);
            let opacity: f32 = rng.random_range(0.004..1.0);
            let xy = [
                rng.random_range(-40.0..size as f32 + 40.0),
                rng.random_range(-40.0..size as f32 + 40.0),
            ];
            // Inria's 3σ square, as the projection makes it.
            let mid = 0.5 * (cxx + cyy);
            let radius = (3.0 * (mid + (mid * mid - det).max(0.1).sqrt()).sqrt()).ceil();
            let tile_of = |p: f64, n: u32| (p / f64::from(ts)).floor().clamp(0.0, f64::from(n));
            let square = [
                tile_of(f64::from(xy[0]) - radius, n) as u32,
                tile_of(f64::from(xy[0]) + radius + f64::from(ts) - 1.0, n) as u32,
                tile_of(f64::from(xy[1]) - radius, n) as u32,
                tile_of(f64::from(xy[1]) + radius + f64::from(ts) - 1.0, n) as u32,
            ];
            let rect = within_reach(square, xy, conic, quad_bound(opacity), [n, n]);
            let area = |r: [u32; 4]| r[1].saturating_sub(r[0]) * r[3].saturating_sub(r[2]);
            narrower += usize::from(area(rect) < area(square));
            let [a, b, cc] = conic.map(f64::from);
            for y in 0..size {
                for x in 0..size {
                    let dx = f64::from(xy[0]) - f64::from(x);
                    let dy = f64::from(xy[1]) - f64::from(y);
                    let power = -0.5 * (a * dx * dx + cc * dy * dy) - b * dx * dy;
                    if f64::from(opacity) * power.exp() < 1.0 / 255.0 {
                        continue;
                    }
                    let (tx, ty) = ((x / ts) as u32, (y / ts) as u32);
                    let in_square =
                        square[0] <= tx && tx < square[1] && square[2] <= ty && ty < square[3];
                    if !in_square {
                        continue; // beyond Inria's square: never drawn, before or after
                    }
                    reached += 1;
                    assert!(
                        rect[0] <= tx && tx < rect[1] && rect[2] <= ty && ty < rect[3],
                        "case {case}: pixel ({x}, {y}) reaches 1/255 but its tile ({tx}, {ty}) \
                         is outside {rect:?} (square {square:?})"
                    );
                }
            }
        }
        assert!(
            reached > 100_000,
            "the cases must reach many pixels: {reached}"
        );
        assert!(
            narrower > cases / 4,
            "slanted splats must lose tiles: {narrower} of {cases}"
        );
    }
}
