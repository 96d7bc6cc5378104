//! The update after each backward pass, in one pass over the model: chunk by chunk of splats,
//! the gradients' finiteness check, Adam on every parameter group, the parameters' finiteness
//! check and clamps, and the zeroing of the gradients for the next step.
//!
//! Done as whole-model passes (zero the gradients, check them, Adam per group, check and clamp
//! the parameters), each pass streamed its arrays from memory again: at a paper-scale frame's
//! 250k splats of degree 3 that was about 0.66 GB a step, and on 16 threads the passes were
//! bound by memory bandwidth. Chunk by chunk, a chunk's gradients and parameters are still in
//! cache for the checks and the zeroing, so each array is read and written once. Every value
//! goes through the same IEEE operations as in the separate passes, so the model is the same.
//!
//! [`update_chained`] goes one step further: it takes each chunk's gradients straight from the
//! rasteriser's last phase ([`Rasterizer::chain_into`]) into a buffer of the chunk's size, so
//! the model-sized gradient arrays are never written, read back and zeroed (at 250k splats of
//! degree 3, 60 MB each way a step). Each splat's gradients are the ones
//! [`Rasterizer::backward`] would have added into zeroed arrays, so the model is the same.

use glam::Vec3;
use rayon::prelude::*;
use splat_core::{Rasterizer, SplatGrads, SplatGradsMut, all_finite};

use crate::adam::{AdamStep, Moments, Rates};
use crate::state::ParamState;

/// Splats per chunk: a chunk's 59 parameters, gradients and two moments a splat (at degree 3)
/// take about 240 KB, which stays in a core's L2 cache between the sub-passes.
const CHUNK_SPLATS: usize = 256;

/// What the update does this step.
#[derive(Clone, Copy)]
pub(crate) struct UpdatePlan {
    /// Adam's constants for this step.
    pub adam: AdamStep,
    /// The rates of each group (means, log-scales, rotations, opacity logits, SH), or `None`
    /// where the group is frozen.
    pub rates: [Option<Rates>; 5],
    /// Whether the gradients still need the finiteness check (false when it has already run).
    pub check_gradients: bool,
    /// Bounds of the log-scales, unless frozen.
    pub log_scale_bounds: Option<(f32, f32)>,
    /// Bound of the opacity logits' magnitude, unless frozen.
    pub opacity_logit_bound: Option<f32>,
}

/// What the update found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct UpdateOutcome {
    /// Splats whose gradients were not finite, zeroed before Adam.
    pub zeroed_gradients: u64,
    /// Whether some parameter is not finite after Adam: the chunks holding one were left
    /// unclamped, and the caller repairs the model and clamps it whole.
    pub non_finite_parameters: bool,
}

impl std::ops::Add for UpdateOutcome {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            zeroed_gradients: self.zeroed_gradients + o.zeroed_gradients,
            non_finite_parameters: self.non_finite_parameters | o.non_finite_parameters,
        }
    }
}

/// One parameter group's share of a chunk: values, gradients and moments.
struct GroupChunk<'a> {
    p: &'a mut [f32],
    g: &'a mut [f32],
    m: &'a mut [f32],
    v: &'a mut [f32],
}

/// One chunk of splats: its five groups and its screen-space gradient norms.
struct Chunk<'a> {
    groups: [GroupChunk<'a>; 5],
    screen_grad_norm: &'a mut [f32],
}

/// One group's share of a chunk before its gradients are paired with it: values and moments.
struct ParamsChunk<'a> {
    p: &'a mut [f32],
    m: &'a mut [f32],
    v: &'a mut [f32],
}

impl<'a> ParamsChunk<'a> {
    /// The group's chunk with its gradients `g`.
    fn with_grads(self, g: &'a mut [f32]) -> GroupChunk<'a> {
        GroupChunk {
            p: self.p,
            g,
            m: self.m,
            v: self.v,
        }
    }
}

/// The float width of each group a splat (means, log-scales, rotations, opacity logits, SH)
/// for `k` SH coefficients a splat.
fn group_widths(k: usize) -> [usize; 5] {
    [3, 3, 4, 1, 3 * k]
}

/// Splits one group's values and moments (`width` floats a splat) into chunks of
/// `CHUNK_SPLATS` splats.
fn params_chunks<'a>(
    p: &'a mut [f32],
    moments: &'a mut Moments,
    width: usize,
) -> impl Iterator<Item = ParamsChunk<'a>> {
    let len = CHUNK_SPLATS * width.max(1);
    p.chunks_mut(len)
        .zip(moments.m.chunks_mut(len).zip(moments.v.chunks_mut(len)))
        .map(|(p, (m, v))| ParamsChunk { p, m, v })
}

/// The model's values and moments, chunk by chunk of `CHUNK_SPLATS` splats, group by group.
fn chunked_state(state: &mut ParamState) -> Vec<[ParamsChunk<'_>; 5]> {
    let s = &mut state.splats;
    let mo = &mut state.moments;
    let n = s.len();
    assert!(
        mo.means.len() == 3 * n && mo.sh.len() == 3 * s.sh.len(),
        "update: moments not shaped like the model"
    );
    let widths = group_widths(s.coeffs_per_splat());
    params_chunks(
        bytemuck::cast_slice_mut(&mut s.means),
        &mut mo.means,
        widths[0],
    )
    .zip(params_chunks(
        bytemuck::cast_slice_mut(&mut s.log_scales),
        &mut mo.log_scales,
        widths[1],
    ))
    .zip(params_chunks(
        s.rotations.as_flattened_mut(),
        &mut mo.rotations,
        widths[2],
    ))
    .zip(params_chunks(
        &mut s.opacity_logits,
        &mut mo.opacity_logits,
        widths[3],
    ))
    .zip(params_chunks(
        s.sh.as_flattened_mut(),
        &mut mo.sh,
        widths[4],
    ))
    .map(|((((means, scales), rotations), opacities), sh)| {
        [means, scales, rotations, opacities, sh]
    })
    .collect()
}

/// A chunk's values and moments paired with its gradients `g` (shaped for the chunk).
fn paired<'a>(groups: [ParamsChunk<'a>; 5], g: SplatGradsMut<'a>) -> Chunk<'a> {
    let [means, scales, rotations, opacities, sh] = groups;
    Chunk {
        groups: [
            means.with_grads(bytemuck::cast_slice_mut(g.means)),
            scales.with_grads(bytemuck::cast_slice_mut(g.log_scales)),
            rotations.with_grads(g.rotations.as_flattened_mut()),
            opacities.with_grads(g.opacity_logits),
            sh.with_grads(g.sh.as_flattened_mut()),
        ],
        screen_grad_norm: g.screen_grad_norm,
    }
}

/// Applies `plan` to `state` with `grads` (shaped like `state.splats`) and leaves `grads` zero.
pub(crate) fn update(
    plan: &UpdatePlan,
    state: &mut ParamState,
    grads: &mut SplatGrads,
) -> UpdateOutcome {
    let k = state.splats.coeffs_per_splat();
    assert!(
        grads.fits(&state.splats),
        "update: gradients not shaped like the model"
    );
    let widths = group_widths(k);
    chunked_state(state)
        .into_par_iter()
        .zip(grads.par_chunks_mut(CHUNK_SPLATS))
        .map(|(groups, g)| update_chunk(plan, &widths, &mut paired(groups, g)))
        .reduce(UpdateOutcome::default, |a, b| a + b)
}

/// Whether every gradient in `g` is zero.
fn all_zero(g: &SplatGrads) -> bool {
    g.float_arrays().iter().all(|f| f.iter().all(|&x| x == 0.0))
}

/// Applies `plan` to `state` with the gradients of the view whose [`Rasterizer::backward_sums`]
/// `raster` last ran on `state.splats`, chained chunk by chunk into a chunk-sized buffer (see
/// the module's documentation). The model comes out as [`update`] leaves it given the
/// gradients [`Rasterizer::backward`] writes.
pub(crate) fn update_chained(
    plan: &UpdatePlan,
    state: &mut ParamState,
    raster: &Rasterizer,
) -> UpdateOutcome {
    let k = state.splats.coeffs_per_splat();
    let widths = group_widths(k);
    chunked_state(state)
        .into_par_iter()
        .enumerate()
        .map_init(SplatGrads::default, |g, (c, groups)| {
            // The buffer is zero: new, or left so by the last chunk's `update_chunk`.
            let len = groups[3].p.len();
            g.means.resize(len, Vec3::ZERO);
            g.log_scales.resize(len, Vec3::ZERO);
            g.rotations.resize(len, [0.0; 4]);
            g.opacity_logits.resize(len, 0.0);
            g.sh.resize(len * k, [0.0; 3]);
            g.screen_grad_norm.resize(len, 0.0);
            debug_assert!(
                all_zero(g),
                "update_chained: a chunk's gradients were left nonzero"
            );
            raster.chain_into(c * CHUNK_SPLATS, g.as_mut());
            update_chunk(plan, &widths, &mut paired(groups, g.as_mut()))
        })
        .reduce(UpdateOutcome::default, |a, b| a + b)
}

/// The update of one chunk, leaving its gradients zero: compiled with AVX2 where Adam's step
/// uses it (its finiteness checks and clamps read every value of the chunk).
fn update_chunk(plan: &UpdatePlan, widths: &[usize; 5], c: &mut Chunk<'_>) -> UpdateOutcome {
    #[cfg(target_arch = "x86_64")]
    if plan.adam.uses_avx2() {
        // SAFETY: `uses_avx2` is only true when the CPU reports AVX2 (`splat_core::has_avx2`).
        #[allow(unsafe_code)]
        return unsafe { update_chunk_avx2(plan, widths, c) };
    }
    update_chunk_impl(plan, widths, c)
}

/// [`update_chunk_impl`] compiled with AVX2 (the same operations, eight lanes an instruction).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn update_chunk_avx2(plan: &UpdatePlan, widths: &[usize; 5], c: &mut Chunk<'_>) -> UpdateOutcome {
    update_chunk_impl(plan, widths, c)
}

/// The body of [`update_chunk`].
#[inline(always)]
fn update_chunk_impl(plan: &UpdatePlan, widths: &[usize; 5], c: &mut Chunk<'_>) -> UpdateOutcome {
    let mut out = UpdateOutcome::default();
    if plan.check_gradients {
        out.zeroed_gradients = zero_non_finite_gradients(widths, c);
    }
    for (group, rates) in c.groups.iter_mut().zip(plan.rates) {
        if let Some(rates) = rates {
            plan.adam.update(group.p, group.g, group.m, group.v, rates);
        }
    }
    // The clamps would turn NaN into a bound and hide it: a chunk with a non-finite parameter
    // is left to the caller's repair.
    if c.groups.iter().all(|g| all_finite(g.p)) {
        let [_, scales, _, opacities, _] = &mut c.groups;
        if let Some((lo, hi)) = plan.log_scale_bounds {
            let scales: &mut [Vec3] = bytemuck::cast_slice_mut(scales.p);
            for ls in scales {
                *ls = ls.clamp(Vec3::splat(lo), Vec3::splat(hi));
            }
        }
        if let Some(bound) = plan.opacity_logit_bound {
            for o in opacities.p.iter_mut() {
                *o = o.clamp(-bound, bound);
            }
        }
    } else {
        out.non_finite_parameters = true;
    }
    for g in &mut c.groups {
        g.g.fill(0.0);
    }
    c.screen_grad_norm.fill(0.0);
    out
}

/// Zeroes every gradient of the chunk's splats that have a non-finite one; returns how many.
fn zero_non_finite_gradients(widths: &[usize; 5], c: &mut Chunk<'_>) -> u64 {
    if c.groups.iter().all(|g| all_finite(g.g)) && all_finite(c.screen_grad_norm) {
        return 0;
    }
    let mut zeroed = 0;
    for i in 0..c.screen_grad_norm.len() {
        let range = |w: usize| i * w..(i + 1) * w;
        let finite = c.screen_grad_norm[i].is_finite()
            && c.groups
                .iter()
                .zip(widths)
                .all(|(g, &w)| g.g[range(w)].iter().all(|v| v.is_finite()));
        if !finite {
            for (g, &w) in c.groups.iter_mut().zip(widths) {
                g.g[range(w)].fill(0.0);
            }
            c.screen_grad_norm[i] = 0.0;
            zeroed += 1;
        }
    }
    zeroed
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::adam::AdamParams;
    use crate::trainer::zero_non_finite_grads;
    use splat_core::Splats;

    /// A xorshift stream of values in [−0.5, 0.5).
    fn stream(seed: u64) -> impl FnMut() -> f32 {
        let mut s = seed;
        move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5
        }
    }

    /// `n` degree-3 splats with random parameters and moments, and random gradients.
    fn random_state(n: usize, seed: u64) -> (ParamState, SplatGrads) {
        let mut r = stream(seed);
        let mut s = Splats::new(3);
        for _ in 0..n {
            let sh: Vec<[f32; 3]> = (0..16).map(|_| [r(), r(), r()]).collect();
            s.push(
                Vec3::new(r(), r(), r()),
                Vec3::new(8.0 * r(), 8.0 * r(), 8.0 * r()),
                [r(), r(), r(), r()],
                60.0 * r(),
                &sh,
            );
        }
        let mut state = ParamState::new(s);
        let mo = &mut state.moments;
        for m in [&mut mo.means, &mut mo.log_scales, &mut mo.rotations] {
            m.m.iter_mut().for_each(|x| *x = 1e-2 * r());
            m.v.iter_mut().for_each(|x| *x = 1e-4 * r().abs());
        }
        let mut g = SplatGrads::zeros_like(&state.splats);
        let mut fill = |v: &mut [f32]| v.iter_mut().for_each(|x| *x = 1e-2 * r());
        fill(bytemuck::cast_slice_mut(&mut g.means));
        fill(bytemuck::cast_slice_mut(&mut g.log_scales));
        fill(g.rotations.as_flattened_mut());
        fill(&mut g.opacity_logits);
        fill(g.sh.as_flattened_mut());
        fill(&mut g.screen_grad_norm);
        (state, g)
    }

    fn plan(step: u64, frozen_scales: bool) -> UpdatePlan {
        UpdatePlan {
            adam: AdamStep::new(&AdamParams::default(), step),
            rates: [
                Some(Rates::All(1.6e-4)),
                (!frozen_scales).then_some(Rates::All(5e-3)),
                Some(Rates::All(1e-3)),
                Some(Rates::All(5e-2)),
                Some(Rates::Split {
                    stride: 48,
                    head: 3,
                    head_rate: 2.5e-3,
                    tail_rate: 1.25e-4,
                }),
            ],
            check_gradients: true,
            log_scale_bounds: (!frozen_scales).then_some((-3.0, 2.0)),
            opacity_logit_bound: Some(20.0),
        }
    }

    /// The separate whole-model passes the update replaces: check, Adam per group, clamps.
    fn separate_passes(p: &UpdatePlan, st: &mut ParamState, g: &mut SplatGrads, step: u64) -> u64 {
        let zeroed = zero_non_finite_grads(g);
        let hp = AdamParams::default();
        let (s, mo) = (&mut st.splats, &mut st.moments);
        let groups: [(&mut Moments, &mut [f32], &[f32]); 5] = [
            (
                &mut mo.means,
                bytemuck::cast_slice_mut(&mut s.means),
                bytemuck::cast_slice(&g.means),
            ),
            (
                &mut mo.log_scales,
                bytemuck::cast_slice_mut(&mut s.log_scales),
                bytemuck::cast_slice(&g.log_scales),
            ),
            (
                &mut mo.rotations,
                s.rotations.as_flattened_mut(),
                g.rotations.as_flattened(),
            ),
            (
                &mut mo.opacity_logits,
                &mut s.opacity_logits,
                &g.opacity_logits,
            ),
            (&mut mo.sh, s.sh.as_flattened_mut(), g.sh.as_flattened()),
        ];
        for ((m, params, grads), rates) in groups.into_iter().zip(p.rates) {
            if let Some(rates) = rates {
                m.step(&hp, step, params, grads, rates);
            }
        }
        if let Some((lo, hi)) = p.log_scale_bounds {
            for ls in &mut s.log_scales {
                *ls = ls.clamp(Vec3::splat(lo), Vec3::splat(hi));
            }
        }
        if let Some(b) = p.opacity_logit_bound {
            for o in &mut s.opacity_logits {
                *o = o.clamp(-b, b);
            }
        }
        zeroed
    }

    #[test]
    fn fused_update_matches_the_separate_passes_bit_for_bit_at_any_thread_count() {
        // Three and a half chunks, with non-finite gradients in two splats of different chunks.
        let n = 3 * CHUNK_SPLATS + CHUNK_SPLATS / 2;
        for frozen_scales in [false, true] {
            let (mut want, mut g_want) = random_state(n, 7);
            g_want.sh[5 * 16 + 9][1] = f32::NAN;
            g_want.screen_grad_norm[2 * CHUNK_SPLATS + 3] = f32::INFINITY;
            let (start, g_start) = (want.clone(), g_want.clone());
            let p = plan(3, frozen_scales);
            let zeroed = separate_passes(&p, &mut want, &mut g_want, 3);
            assert_eq!(zeroed, 2);
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let (mut got, mut g) = (start.clone(), g_start.clone());
                let out = pool.install(|| update(&p, &mut got, &mut g));
                assert_eq!(out.zeroed_gradients, 2, "{threads} threads");
                assert!(!out.non_finite_parameters);
                let bits = |s: &ParamState| {
                    let s = &s.splats;
                    let mut v: Vec<u32> = Vec::new();
                    v.extend(
                        bytemuck::cast_slice::<Vec3, f32>(&s.means)
                            .iter()
                            .map(|x| x.to_bits()),
                    );
                    v.extend(
                        bytemuck::cast_slice::<Vec3, f32>(&s.log_scales)
                            .iter()
                            .map(|x| x.to_bits()),
                    );
                    v.extend(s.rotations.as_flattened().iter().map(|x| x.to_bits()));
                    v.extend(s.opacity_logits.iter().map(|x| x.to_bits()));
                    v.extend(s.sh.as_flattened().iter().map(|x| x.to_bits()));
                    v
                };
                assert_eq!(bits(&got), bits(&want), "{threads} threads");
                assert_eq!(got.moments, want.moments, "{threads} threads");
                assert_eq!(
                    g,
                    SplatGrads::zeros_like(&got.splats),
                    "gradients left zero"
                );
            }
        }
    }

    #[test]
    fn a_non_finite_parameter_is_reported_and_its_chunk_left_unclamped() {
        let (mut st, mut g) = random_state(2 * CHUNK_SPLATS, 11);
        // A log-scale far above the bound in each chunk, and a NaN SH value in the second.
        st.splats.log_scales[3].x = 50.0;
        st.splats.log_scales[CHUNK_SPLATS + 3].x = 50.0;
        st.splats.sh[(CHUNK_SPLATS + 7) * 16][0] = f32::NAN;
        let out = update(&plan(1, false), &mut st, &mut g);
        assert!(out.non_finite_parameters);
        assert!(
            st.splats.log_scales[3].x <= 2.0,
            "a finite chunk is clamped"
        );
        assert!(
            st.splats.log_scales[CHUNK_SPLATS + 3].x > 40.0,
            "the NaN's chunk is not"
        );
        assert!(
            st.splats.sh[(CHUNK_SPLATS + 7) * 16][0].is_nan(),
            "the NaN is kept for the repair"
        );
    }
}
