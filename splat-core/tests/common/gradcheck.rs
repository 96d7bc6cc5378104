//! Gradient checks against central finite differences of the f64 reference renderer
//! ([`super::render_ref`]); the tolerances are explained in `gradients.rs`, which holds the
//! general cases (`hard_cases.rs` uses the same checks on degenerate ones).
#![allow(clippy::needless_range_loop)] // index loops mirror the maths in these checks
#![allow(clippy::print_stderr)] // tests report what they measured

use splat_core::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats};

use super::{RefSplats, Rng, render_ref};

/// Per-pixel weights of the loss L = Σ w·rgb + Σ u·alpha + Σ v·depth.
pub struct Weights {
    pub rgb: Vec<f32>,
    pub alpha: Option<Vec<f32>>,
    pub depth: Option<Vec<f32>>,
}

/// The loss of the f64 reference render.
pub fn ref_loss(rs: &RefSplats, cam: &RenderCamera, opts: &RenderOptions, w: &Weights) -> f64 {
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

/// Compares one parameter group (see `gradients.rs` for the tolerances). With `zero`, the
/// function is flat in these parameters (a degenerate case): both sides must be zero instead.
pub fn compare_group(name: &str, analytic: &[f64], numeric: &[f64], zero: bool) {
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
    if zero {
        let a_norm = analytic.iter().map(|v| v * v).sum::<f64>().sqrt();
        assert!(
            norm <= 1e-9 && a_norm <= 1e-6,
            "{name}: expected a flat function, numeric {norm:e}, analytic {a_norm:e}"
        );
        return;
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

/// Checks every parameter group of `s` against finite differences.
pub fn check_gradients(s: &Splats, cam: &RenderCamera, opts: &RenderOptions, w: &Weights) {
    check_gradients_with(s, cam, opts, w, &[], 1e-4);
}

/// [`check_gradients`], where the groups named in `zero` ("means", "log_scales", "rotations",
/// "opacity_logits", "sh") must have zero gradients on both sides, with step `h`. A smaller step
/// suits scenes whose loss varies fast (depths near the near plane) or has many pixels near the
/// 1/255 alpha threshold (long needles), where ±1e-4 often straddles one; f64 rounding stays
/// ~1e-16·|L|/h, far below the tolerances, down to h = 1e-7.
pub fn check_gradients_with(
    s: &Splats,
    cam: &RenderCamera,
    opts: &RenderOptions,
    w: &Weights,
    zero: &[&str],
    h: f64,
) {
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
        let a = central(perturb, h);
        let b = central(perturb, h / 3.0);
        if (a - b).abs() > 1e-5 + 1e-4 * a.abs() {
            if std::env::var("GRAD_DEBUG").is_ok() {
                eprintln!("discontinuity: {a} at h, {b} at h/3");
            }
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
    compare_group("means", &a, &num, zero.contains(&"means"));
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for i in 0..n {
        for c in 0..3 {
            a.push(f64::from(g.log_scales[i][c]));
            num.push(fd(&|p, d| p.log_scales[i][c] += d));
        }
    }
    compare_group("log_scales", &a, &num, zero.contains(&"log_scales"));
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for i in 0..n {
        for c in 0..4 {
            a.push(f64::from(g.rotations[i][c]));
            num.push(fd(&|p, d| p.rots[i][c] += d));
        }
    }
    compare_group("rotations", &a, &num, zero.contains(&"rotations"));
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for i in 0..n {
        a.push(f64::from(g.opacity_logits[i]));
        num.push(fd(&|p, d| p.logits[i] += d));
    }
    compare_group("opacity_logits", &a, &num, zero.contains(&"opacity_logits"));
    let (mut a, mut num) = (Vec::new(), Vec::new());
    for j in 0..s.sh.len() {
        for c in 0..3 {
            a.push(f64::from(g.sh[j][c]));
            num.push(fd(&|p, d| p.sh[j][c] += d));
        }
    }
    compare_group("sh", &a, &num, zero.contains(&"sh"));
}

/// Random loss weights for `cam`, with alpha and depth terms when asked.
pub fn weights(rng: &mut Rng, cam: &RenderCamera, alpha: bool, depth: bool) -> Weights {
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
pub fn mask_depth_weights(w: &mut Weights, s: &Splats, cam: &RenderCamera, opts: &RenderOptions) {
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
