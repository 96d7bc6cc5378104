//! Every gradient of the backward pass against central finite differences.
//!
//! The loss is L = Σ w·rgb + Σ u·alpha + Σ v·depth with fixed random weights. The analytic
//! gradient (the crate's f32 backward) is compared with central differences of the brute-force
//! f64 reference renderer (`common::render_ref`, the same function as the forward pass to
//! ~1e-5, see `forward.rs`), with step h = 1e-4: truncation error O(h²·L''') ≈ 1e-8 and f64
//! rounding ≈ 1e-16·|L|/h ≈ 1e-10, so the numeric side is exact to far below what matters,
//! and a jump across a discrete decision (alpha at 1/255, T at 1e-4) inside ±h is rare at this
//! step. The analytic side sums thousands of f32 terms (relative error ~1e-6 each) and divides
//! T by (1 − α) back to front; measured agreement is ~1e-6 relative. The tolerance: per
//! parameter group, ‖analytic − numeric‖ ≤ 1e-4·‖numeric‖, and every element within
//! 1e-3·max|numeric| — two orders above the f32 noise, and far below what any wrong sign,
//! factor or missing term produces (those give errors of order 1).
#![allow(clippy::needless_range_loop)] // index loops mirror the maths in these checks

mod common;

use common::{RefSplats, Rng, look_at, random_splats, render_ref};
use glam::Vec3;
use splat_core::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats};

struct Weights {
    rgb: Vec<f32>,
    alpha: Option<Vec<f32>>,
    depth: Option<Vec<f32>>,
}

fn ref_loss(rs: &RefSplats, cam: &RenderCamera, opts: &RenderOptions, w: &Weights) -> f64 {
    let img = render_ref(
        rs,
        cam,
        opts.background.as_dvec3().to_array(),
        opts.active_sh_degree,
        opts.antialiased,
    );
    let mut l: f64 = img
        .rgb
        .iter()
        .zip(&w.rgb)
        .map(|(a, b)| a * f64::from(*b))
        .sum();
    if let Some(wa) = &w.alpha {
        l += img
            .alpha
            .iter()
            .zip(wa)
            .map(|(a, b)| a * f64::from(*b))
            .sum::<f64>();
    }
    if let Some(wd) = &w.depth {
        l += img
            .depth
            .iter()
            .zip(wd)
            .map(|(a, b)| a * f64::from(*b))
            .sum::<f64>();
    }
    l
}

fn compare_group(name: &str, analytic: &[f64], numeric: &[f64]) {
    let skipped = numeric.iter().filter(|v| v.is_nan()).count();
    assert!(
        skipped * 10 <= numeric.len(),
        "{name}: {skipped} of {} elements at discontinuities",
        numeric.len()
    );
    let (analytic, numeric): (Vec<f64>, Vec<f64>) = analytic
        .iter()
        .zip(numeric)
        .filter(|(_, n)| !n.is_nan())
        .map(|(a, n)| (*a, *n))
        .unzip();
    let (analytic, numeric) = (&analytic[..], &numeric[..]);
    let norm = numeric.iter().map(|v| v * v).sum::<f64>().sqrt();
    let diff = analytic
        .iter()
        .zip(numeric)
        .map(|(a, n)| (a - n) * (a - n))
        .sum::<f64>()
        .sqrt();
    let max_n = numeric.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    eprintln!(
        "{name}: |numeric| {norm:.4e}, |analytic − numeric| {diff:.3e} ({:.2e} relative), {skipped} skipped",
        diff / norm
    );
    if std::env::var("GRAD_DEBUG").is_ok() {
        for (i, (a, n)) in analytic.iter().zip(numeric).enumerate() {
            eprintln!("{name}[{i}] {a:.6} {n:.6}");
        }
    }
    assert!(
        norm > 1e-6,
        "{name}: gradient is zero, the test would not test anything"
    );
    assert!(
        diff <= 1e-4 * norm,
        "{name}: relative error {}",
        diff / norm
    );
    for (i, (a, n)) in analytic.iter().zip(numeric).enumerate() {
        assert!(
            (a - n).abs() <= 1e-3 * max_n,
            "{name}[{i}]: analytic {a}, numeric {n}"
        );
    }
}

fn check_gradients(s: &Splats, cam: &RenderCamera, opts: &RenderOptions, w: &Weights) {
    let mut r = Rasterizer::new();
    r.forward(s, cam, opts);
    let mut g = SplatGrads::zeros_like(s);
    r.backward(
        s,
        cam,
        opts,
        &w.rgb,
        w.alpha.as_deref(),
        w.depth.as_deref(),
        &mut g,
    );
    for v in [&g.opacity_logits, &g.screen_grad_norm] {
        assert!(v.iter().all(|x| x.is_finite()));
    }

    let base = RefSplats::from(s);
    let central = |perturb: &dyn Fn(&mut RefSplats, f64), h: f64| -> f64 {
        let mut p = base.clone();
        perturb(&mut p, h);
        let lp = ref_loss(&p, cam, opts, w);
        let mut m = base.clone();
        perturb(&mut m, -h);
        let lm = ref_loss(&m, cam, opts, w);
        (lp - lm) / (2.0 * h)
    };
    // Central differences at h and h/3 agree to ~1e-8 where the loss is smooth; where they
    // disagree, ±h straddles a discontinuity of the function itself (a splat's 3σ tile rectangle
    // gaining or losing a tile, an alpha crossing 1/255), so that element has no derivative to
    // compare with and is returned as NaN (skipped, and counted by `compare_group`).
    let fd = |perturb: &dyn Fn(&mut RefSplats, f64)| -> f64 {
        let a = central(perturb, 1e-4);
        let b = central(perturb, 1e-4 / 3.0);
        if (a - b).abs() > 1e-5 + 1e-4 * a.abs() {
            f64::NAN
        } else {
            a
        }
    };
    let n = s.len();
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for i in 0..n {
        for c in 0..3 {
            a.push(f64::from(g.means[i][c]));
            num.push(fd(&|p, d| p.means[i][c] += d));
        }
    }
    compare_group("means", &a, &num);
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for i in 0..n {
        for c in 0..3 {
            a.push(f64::from(g.log_scales[i][c]));
            num.push(fd(&|p, d| p.log_scales[i][c] += d));
        }
    }
    compare_group("log_scales", &a, &num);
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for i in 0..n {
        for c in 0..4 {
            a.push(f64::from(g.rotations[i][c]));
            num.push(fd(&|p, d| p.rots[i][c] += d));
        }
    }
    compare_group("rotations", &a, &num);
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for i in 0..n {
        a.push(f64::from(g.opacity_logits[i]));
        num.push(fd(&|p, d| p.logits[i] += d));
    }
    compare_group("opacity_logits", &a, &num);
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for j in 0..s.sh.len() {
        for c in 0..3 {
            a.push(f64::from(g.sh[j][c]));
            num.push(fd(&|p, d| p.sh[j][c] += d));
        }
    }
    compare_group("sh", &a, &num);
}

fn weights(rng: &mut Rng, cam: &RenderCamera, alpha: bool, depth: bool) -> Weights {
    let n = (cam.width * cam.height) as usize;
    let mut v = |k: usize, a: f32| (0..k).map(|_| rng.uniform(-a, a)).collect::<Vec<f32>>();
    Weights {
        rgb: v(3 * n, 1.0),
        alpha: alpha.then(|| v(n, 1.0)),
        depth: depth.then(|| v(n, 0.2)),
    }
}

/// Keeps depth weights only where the reference coverage exceeds 0.05: expected depth D/A jumps
/// from 0 to a splat's depth where coverage starts (alpha crossing 1/255), which a depth loss
/// must mask and finite differences cannot differentiate.
fn mask_depth_weights(w: &mut Weights, s: &Splats, cam: &RenderCamera, opts: &RenderOptions) {
    let img = render_ref(
        &RefSplats::from(s),
        cam,
        opts.background.as_dvec3().to_array(),
        opts.active_sh_degree,
        opts.antialiased,
    );
    if let Some(d) = &mut w.depth {
        for (v, a) in d.iter_mut().zip(&img.alpha) {
            if *a < 0.05 {
                *v = 0.0;
            }
        }
    }
}

#[test]
fn gradients_rgb_degree3_match_finite_differences() {
    let mut rng = Rng::new(21);
    let s = random_splats(&mut rng, 12, Vec3::ZERO, 0.8, (-2.6, -1.4), (0.2, 0.9), 3);
    let cam = look_at(
        Vec3::new(0.5, -0.3, -4.0),
        Vec3::ZERO,
        41,
        35,
        45.0,
        20.0,
        17.9,
    );
    let opts = RenderOptions {
        background: Vec3::new(0.3, 0.6, 0.1),
        ..RenderOptions::default()
    };
    let w = weights(&mut rng, &cam, false, false);
    check_gradients(&s, &cam, &opts, &w);
}

#[test]
fn gradients_with_alpha_and_depth_losses_match_finite_differences() {
    let mut rng = Rng::new(22);
    let s = random_splats(&mut rng, 12, Vec3::ZERO, 0.8, (-2.6, -1.4), (0.2, 0.9), 1);
    let cam = look_at(
        Vec3::new(-1.0, 0.8, -3.5),
        Vec3::ZERO,
        38,
        36,
        40.0,
        19.0,
        18.0,
    );
    let opts = RenderOptions {
        background: Vec3::new(0.5, 0.5, 0.5),
        active_sh_degree: 1,
        antialiased: false,
    };
    let mut w = weights(&mut rng, &cam, true, true);
    mask_depth_weights(&mut w, &s, &cam, &opts);
    check_gradients(&s, &cam, &opts, &w);
}

#[test]
fn gradients_antialiased_mode_match_finite_differences() {
    let mut rng = Rng::new(23);
    let s = random_splats(&mut rng, 10, Vec3::ZERO, 0.8, (-3.5, -1.8), (0.3, 0.9), 2);
    let cam = look_at(
        Vec3::new(0.2, 0.1, -4.0),
        Vec3::ZERO,
        36,
        32,
        45.0,
        18.0,
        16.0,
    );
    let opts = RenderOptions {
        background: Vec3::ZERO,
        active_sh_degree: 2,
        antialiased: true,
    };
    let w = weights(&mut rng, &cam, true, false);
    check_gradients(&s, &cam, &opts, &w);
}

/// Splats near and beyond the image edges, where the 1.3·tan(fov/2) clamp of the Jacobian acts
/// for some of them (its x/z, y/z derivative is then zero in the function as well).
#[test]
fn gradients_with_the_fov_clamp_active_match_finite_differences() {
    let mut rng = Rng::new(24);
    let s = random_splats(
        &mut rng,
        14,
        Vec3::new(1.6, -1.2, 0.0),
        1.0,
        (-2.0, -1.0),
        (0.3, 0.9),
        1,
    );
    let cam = look_at(
        Vec3::new(0.0, 0.0, -3.0),
        Vec3::ZERO,
        32,
        30,
        30.0,
        16.0,
        15.0,
    );
    let opts = RenderOptions::default();
    let w = weights(&mut rng, &cam, false, false);
    check_gradients(&s, &cam, &opts, &w);
}
