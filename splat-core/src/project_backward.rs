//! Backward of the per-splat projection ([`crate::project`]): the gradients the tile walks
//! sum for each splat's projected quantities, chained to its parameters eight splats at a time
//! in vector lanes, lane by lane the IEEE operations of the backward one splat at a time (kept in
//! the tests as `project::reference::project_backward`, which checks the bits).

use crate::lanes::{D8, F8, Mask, Real, WIDTH, array};
use crate::project::{ChainLanes, Cov2, ViewConsts, cov_factor, jacobian, mat_vec, t_rows};

/// What the chain to the parameters needs of a view, kept by the backward pass's sums for the
/// chain's ranges (`Rasterizer::chain_into`).
#[derive(Clone, Copy, Debug)]
pub(crate) struct ChainView {
    pub v: ViewConsts,
    /// The image size (for the screen-space gradient norm).
    pub size: (u32, u32),
    pub coeffs_per_splat: usize,
    /// The number of splats of the model it was made for.
    pub splats: usize,
}

/// Gradients of the loss with respect to one splat's projected quantities, summed over pixels.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ProjectedGrad {
    pub xy: [f32; 2],
    pub conic: [f32; 3],
    pub opacity: f32,
    pub color: [f32; 3],
    pub depth: f32,
}

impl ProjectedGrad {
    /// Whether every component is zero (no pixel passed the splat any gradient).
    pub fn is_zero(&self) -> bool {
        self.xy == [0.0; 2]
            && self.conic == [0.0; 3]
            && self.opacity == 0.0
            && self.color == [0.0; 3]
            && self.depth == 0.0
    }

    pub fn add(&mut self, o: &Self) {
        for k in 0..2 {
            self.xy[k] += o.xy[k];
        }
        for k in 0..3 {
            self.conic[k] += o.conic[k];
            self.color[k] += o.color[k];
        }
        self.opacity += o.opacity;
        self.depth += o.depth;
    }
}

/// Product P·G·P of symmetric 2×2 matrices stored as (a, b, c).
#[inline(always)]
pub(crate) fn sandwich<T: Real>(p: [T; 3], g: [T; 3]) -> [T; 3] {
    // P·G
    let pg00 = p[0] * g[0] + p[1] * g[1];
    let pg01 = p[0] * g[1] + p[1] * g[2];
    let pg10 = p[1] * g[0] + p[2] * g[1];
    let pg11 = p[1] * g[1] + p[2] * g[2];
    [
        pg00 * p[0] + pg01 * p[1],
        pg00 * p[1] + pg01 * p[2],
        pg10 * p[1] + pg11 * p[2],
    ]
}

/// Gradients of the loss with respect to eight splats' projected quantities, in lanes.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct ProjectedGradLanes {
    pub xy: [F8; 2],
    pub conic: [F8; 3],
    pub opacity: F8,
    pub color: [F8; 3],
    pub depth: F8,
}

impl ProjectedGradLanes {
    /// The lanes of `grads`.
    #[inline(always)]
    pub(crate) fn gather(grads: &[ProjectedGrad; WIDTH]) -> Self {
        let mut lanes = Self::default();
        for (l, g) in grads.iter().enumerate() {
            for c in 0..2 {
                lanes.xy[c].0[l] = g.xy[c];
            }
            for c in 0..3 {
                lanes.conic[c].0[l] = g.conic[c];
                lanes.color[c].0[l] = g.color[c];
            }
            lanes.opacity.0[l] = g.opacity;
            lanes.depth.0[l] = g.depth;
        }
        lanes
    }
}

/// The parameter gradients of eight splats, in lanes.
pub(crate) struct ParamGradLanes {
    pub mean: [F8; 3],
    pub log_scale: [F8; 3],
    /// (w, x, y, z), as stored.
    pub rotation: [F8; 4],
    pub opacity_logit: F8,
    pub screen_norm: F8,
}

/// `m·p` for a matrix (columns) and a vector both in lanes, in glam's order (`Mat3::mul_vec3`).
#[inline(always)]
fn lanes_mat_vec(m: &[[F8; 3]; 3], p: [F8; 3]) -> [F8; 3] {
    array(|c| m[0][c] * p[0] + m[1][c] * p[1] + m[2][c] * p[2])
}

/// The gradient reaching eight splats' SH colours from that of their shown colours: clamped
/// channels pass none (Inria's `clamped` flags).
#[inline(always)]
pub(crate) fn colour_grad8(v: &ViewConsts, it: &ChainLanes, g: &ProjectedGradLanes) -> [F8; 3] {
    let zero = F8::splat(0.0);
    array(|ch| {
        if v.linear_colour {
            g.color[ch]
        } else {
            F8::select(it.color_raw[ch].test(zero, |a, b| a < b), zero, g.color[ch])
        }
    })
}

/// Backward of [`project8`](crate::project::project8) for the splats of one group: chains `g` (summed over pixels) to
/// their parameters, lane by lane the IEEE operations of the backward one splat at a time
/// (`reference::project_backward` in the tests, which checks the bits). The SH part is the
/// caller's: dL/d(dir) = Jᵀ·dL/dc from the colour's Jacobian the projection kept
/// ([`ChainLanes::dir_jac`], in lanes), handed over as `d_dir`, and the coefficients' gradients
/// basis_k·dL/dc written lane by lane into the model's layout (in lanes, moving 48 gradients a
/// splat between lanes and that layout cost more than the arithmetic saved).
#[inline(always)]
#[allow(clippy::too_many_lines)]
pub(crate) fn project_backward8(
    v: &ViewConsts,
    it: &ChainLanes,
    g: &ProjectedGradLanes,
    image_size: (u32, u32),
    d_dir: [F8; 3],
) -> ParamGradLanes {
    let (zero, half) = (F8::splat(0.0), F8::splat(0.5));
    // dir = d/|d| with d = mean − centre.
    let along = it.dir[0] * d_dir[0] + it.dir[1] * d_dir[1] + it.dir[2] * d_dir[2];
    let d_mean: [F8; 3] = array(|c| zero + (d_dir[c] - it.dir[c] * along) / it.dir_len);

    // Opacity: o_eff = sigmoid(l)·comp.
    let d_logit = g.opacity * it.comp * it.sigmoid_o * (F8::splat(1.0) - it.sigmoid_o);
    let d_comp = g.opacity * it.sigmoid_o;

    // Conic = Σ₂⁻¹ → dL/dΣ₂ = −Q·G_Q·Q (b appears twice in G_Q), then Σ₂ = T·Tᵀ → G_T = 2·G_Σ·T,
    // in f64 with the forward's `Cov2` (for a thin splat long on screen f32 lost Q·T's long
    // column; the tests' `reference::project_backward` says more).
    let (rot, mc) = cov_factor(v, it.quat, it.scale);
    let z = it.p_cam[2];
    let [j0, j1] = jacobian(v, z, it.u);
    let t: [[D8; 3]; 2] = {
        let t = t_rows(&mc, &[j0, j1]);
        array(|r| array(|c| t[r][c].to_f64()))
    };
    let cov = Cov2::<D8>::new(t);
    let q = cov.conic();
    let gq = [
        g.conic[0].to_f64(),
        D8::splat(0.5) * g.conic[1].to_f64(),
        g.conic[2].to_f64(),
    ];
    let qgq = sandwich(q, gq);
    let mut gs = [-qgq[0], -qgq[1], -qgq[2]];
    if v.antialiased {
        let on = it.comp.test(zero, |a, b| a > b);
        let f = (d_comp * it.comp * half).to_f64();
        let q0 = cov.conic0();
        for kk in 0..3 {
            gs[kk] = D8::select(on, gs[kk] + f * (q0[kk] - q[kk]), gs[kk]);
        }
    }
    let two = D8::splat(2.0);
    let gt0: [F8; 3] = array(|c| (two * (gs[0] * t[0][c] + gs[1] * t[1][c])).to_f32());
    let gt1: [F8; 3] = array(|c| (two * (gs[1] * t[0][c] + gs[2] * t[1][c])).to_f32());
    let (fx, fy) = (F8::splat(v.fx), F8::splat(v.fy));
    let gj0 = lanes_mat_vec(&mc, gt0);
    let gj1 = lanes_mat_vec(&mc, gt1);
    let gmc: [[F8; 3]; 3] = array(
        #[inline(always)]
        |col| array(|r| j0[r] * gt0[col] + j1[r] * gt1[col]),
    );

    let zz = z * z;
    let mut dp = [zero; 3];
    dp[2] = dp[2] + (-fx / zz * gj0[0] - fy / zz * gj1[1]);
    dp[2] = dp[2] + fx * it.u[0] / zz * gj0[2];
    // (`array`, not `map`: `map`'s closure was left out of line, compiled without AVX2.)
    let free: [Mask; 2] = array(|a| array(|l| !it.clamped[a][l]));
    dp[0] = F8::select(free[0], dp[0] + -fx / zz * gj0[2], dp[0]);
    dp[2] = F8::select(free[0], dp[2] + fx * it.p_cam[0] / (zz * z) * gj0[2], dp[2]);
    dp[2] = dp[2] + fy * it.u[1] / zz * gj1[2];
    dp[1] = F8::select(free[1], dp[1] + -fy / zz * gj1[2], dp[1]);
    dp[2] = F8::select(free[1], dp[2] + fy * it.p_cam[1] / (zz * z) * gj1[2], dp[2]);
    dp[0] = dp[0] + g.xy[0] * fx / z;
    dp[1] = dp[1] + g.xy[1] * fy / z;
    dp[2] = dp[2] + (-g.xy[0] * fx * it.p_cam[0] / zz - g.xy[1] * fy * it.p_cam[1] / zz);
    dp[2] = dp[2] + g.depth;
    let rt = v.rot.transpose();
    let dm = mat_vec(rt, dp);
    let mean = array(|c| d_mean[c] + dm[c]);

    // M_c = W·R·S.
    let gm: [[F8; 3]; 3] = array(
        #[inline(always)]
        |col| mat_vec(rt, gmc[col]),
    );
    let r = &rot;
    let d_scale: [F8; 3] = array(|a| gm[a][0] * r[a][0] + gm[a][1] * r[a][1] + gm[a][2] * r[a][2]);
    let g_r: [[F8; 3]; 3] = array(|col| array(|rr| gm[col][rr] * it.scale[col]));
    let [x, y, zq, w] = it.quat;
    let rotation = quat_backward_terms([w, x, y, zq], it.quat_norm, &g_r);

    let (width, height) = image_size;
    let ndc = [
        g.xy[0] * half * F8::splat(width as f32),
        g.xy[1] * half * F8::splat(height as f32),
    ];
    ParamGradLanes {
        mean,
        log_scale: array(|a| d_scale[a] * it.scale[a]),
        rotation: array(|c| F8::select(it.quat_zero, zero, rotation[c])),
        opacity_logit: d_logit,
        screen_norm: (ndc[0] * ndc[0] + ndc[1] * ndc[1]).sqrt(),
    }
}

/// Gradient of R(q/|q|) with respect to the stored quaternion q = (w, x, y, z), given G_R
/// (columns), on any [`Real`] whose lanes hold f32.
#[inline(always)]
pub(crate) fn quat_backward_terms<T: Real<Scalar = f32>>(
    [w, x, y, z]: [T; 4],
    norm: T,
    g: &[[T; 3]; 3],
) -> [T; 4] {
    let e = |r: usize, c: usize| g[c][r];
    let (two, m2) = (T::splat(2.0), T::splat(-2.0));
    let gw =
        two * (-z * e(0, 1) + y * e(0, 2) + z * e(1, 0) - x * e(1, 2) - y * e(2, 0) + x * e(2, 1));
    let gx = two
        * (y * e(0, 1) + z * e(0, 2) + y * e(1, 0) - two * x * e(1, 1) - w * e(1, 2)
            + z * e(2, 0)
            + w * e(2, 1)
            - two * x * e(2, 2));
    let gy = two
        * (m2 * y * e(0, 0) + x * e(0, 1) + w * e(0, 2) + x * e(1, 0) + z * e(1, 2) - w * e(2, 0)
            + z * e(2, 1)
            - two * y * e(2, 2));
    let gz = two
        * (m2 * z * e(0, 0) - w * e(0, 1) + x * e(0, 2) + w * e(1, 0) - two * z * e(1, 1)
            + y * e(1, 2)
            + x * e(2, 0)
            + y * e(2, 1));
    // Through the normalisation q/|q|.
    let dot = gw * w + gx * x + gy * y + gz * z;
    [
        (gw - w * dot) / norm,
        (gx - x * dot) / norm,
        (gy - y * dot) / norm,
        (gz - z * dot) / norm,
    ]
}

#[cfg(test)]
mod tests {
    use glam::Vec3;
    use rand::{RngExt, SeedableRng};

    use super::{ProjectedGrad, ProjectedGradLanes, colour_grad8, project_backward8};
    use crate::lanes::WIDTH;
    use crate::project::reference::{self, lanes_camera, lanes_options};
    use crate::project::{ChainLanes, Scratch, ViewConsts, project8};

    /// The backward in lanes gives every splat the bits of the one-splat reference backward:
    /// parameter gradients and SH gradients, from the chains of the projection test's kind of
    /// splats and random gradients of the projected quantities (some zero, some large).
    #[test]
    fn eight_lanes_chain_the_bits_of_one_splat_at_a_time() {
        use crate::Splats;
        use crate::lanes::F8;

        let mut rng = rand_pcg::Pcg64::seed_from_u64(12);
        let cam = lanes_camera();
        let mut compared = 0;
        for degree in 0..=3 {
            let mut splats = Splats::new(3);
            for i in 0..1_600 {
                let mut r = |lo: f32, hi: f32| rng.random_range(lo..hi);
                let mean = Vec3::new(r(-2.0, 2.0), r(-2.0, 2.0), r(-2.0, 2.0));
                let mut ls = Vec3::new(r(-6.0, 0.0), r(-6.0, 0.0), r(-6.0, 0.0));
                let mut q = [r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)];
                match i % 11 {
                    0 => q = [0.0; 4],
                    1 => ls = Vec3::new(r(1.0, 3.0), -9.0, r(-3.0, 0.0)),
                    _ => {}
                }
                let sh: Vec<[f32; 3]> = (0..16)
                    .map(|_| [r(-1.5, 1.5), r(-1.5, 1.5), r(-1.5, 1.5)])
                    .collect();
                splats.push(mean, ls, q, r(-4.0, 6.0), &sh);
            }
            for opts in lanes_options(degree) {
                let v = ViewConsts::new(&cam, &opts, &splats);
                let (antialiased, linear_colour) = (opts.antialiased, opts.linear_colour);
                let k = splats.coeffs_per_splat();
                for start in (0..splats.len()).step_by(WIDTH) {
                    let idx = std::array::from_fn(|l| start + l);
                    let mut chain = ChainLanes::default();
                    let mut drawn = [false; WIDTH];
                    project8::<false>(
                        &splats,
                        idx,
                        WIDTH,
                        &v,
                        &mut chain,
                        &mut Scratch::default(),
                        |l, r| drawn[l] = r.is_ok(),
                    );
                    let mut r = |scale: f32| {
                        if rng.random_range(0..5) == 0 {
                            0.0
                        } else {
                            scale * rng.random_range(-1.0..1.0_f32)
                        }
                    };
                    let grads: [ProjectedGrad; WIDTH] = std::array::from_fn(|_| ProjectedGrad {
                        xy: [r(1.0), r(1.0)],
                        conic: [r(50.0), r(50.0), r(50.0)],
                        opacity: r(1.0),
                        color: [r(1.0), r(1.0), r(1.0)],
                        depth: r(1.0),
                    });
                    let mut d_sh_lanes = [[[0.0_f32; 3]; 16]; WIDTH];
                    let grads_lanes = ProjectedGradLanes::gather(&grads);
                    let d_colour = colour_grad8(&v, &chain, &grads_lanes);
                    let mut d_dir = [F8::default(); 3];
                    for l in 0..WIDTH {
                        let lane = |a: &[F8; 3]| Vec3::new(a[0].0[l], a[1].0[l], a[2].0[l]);
                        let d = crate::sh::eval_backward(
                            v.degree,
                            lane(chain.dir()),
                            &splats.sh[idx[l] * k..(idx[l] + 1) * k],
                            lane(&d_colour),
                            &mut d_sh_lanes[l],
                        );
                        for c in 0..3 {
                            d_dir[c].0[l] = d[c];
                        }
                    }
                    let p = project_backward8(&v, &chain, &grads_lanes, (200, 150), d_dir);
                    for l in (0..WIDTH).filter(|&l| drawn[l]) {
                        let mut d_sh = [[0.0_f32; 3]; 16];
                        let one = reference::project_backward(
                            &splats.sh[idx[l] * k..(idx[l] + 1) * k],
                            &v,
                            &chain.lane(&v, l),
                            &grads[l],
                            (200, 150),
                            &mut d_sh,
                        );
                        let mut want: Vec<f32> = one.mean.to_array().to_vec();
                        want.extend(one.log_scale.to_array());
                        want.extend(one.rotation);
                        want.extend([one.opacity_logit, one.screen_norm]);
                        want.extend(d_sh.as_flattened());
                        let lane = |a: &[F8]| a.iter().map(|x| x.0[l]).collect::<Vec<_>>();
                        let mut got = lane(&p.mean);
                        got.extend(lane(&p.log_scale));
                        got.extend(lane(&p.rotation));
                        got.extend(lane(&[p.opacity_logit, p.screen_norm]));
                        got.extend(d_sh_lanes[l].as_flattened());
                        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(
                            bits(&got),
                            bits(&want),
                            "degree {degree}, antialiased {antialiased}, linear \
                             {linear_colour}: splat {}",
                            idx[l]
                        );
                        compared += 1;
                    }
                }
            }
        }
        assert!(
            compared > 8_000,
            "too few drawn splats compared: {compared}"
        );
    }
}
