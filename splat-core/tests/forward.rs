//! Forward pass against the brute-force f64 reference and closed forms.
#![allow(clippy::needless_range_loop)] // index loops mirror the maths in these checks
#![allow(clippy::print_stderr)] // tests report what they measured

mod common;

use common::{RefSplats, Rng, look_at, random_splats, render_ref};
use glam::Vec3;
use splat_core::{Rasterizer, RenderOptions, Splats, logit, rgb_to_sh_dc};

/// Compares the rasteriser with the reference; returns (max abs error, fraction of pixels whose
/// error exceeds `tol`). f32 against f64 agrees to ~1e-5; a pixel may differ more only where a
/// discrete decision (alpha exactly at 1/255, T exactly at 1e-4, a radius at an integer) falls
/// differently in the two precisions.
fn compare(
    s: &Splats,
    cam: &splat_core::RenderCamera,
    opts: &RenderOptions,
    tol: f64,
) -> (f64, f64) {
    let mut r = Rasterizer::new();
    let out = r.forward(s, cam, opts).clone();
    let bg = opts.background.as_dvec3().to_array();
    let reference = render_ref(
        &RefSplats::from(s),
        cam,
        bg,
        opts.active_sh_degree,
        opts.antialiased,
    );
    let n = (cam.width * cam.height) as usize;
    let mean_alpha = reference.alpha.iter().sum::<f64>() / n as f64;
    assert!(
        mean_alpha > 0.1,
        "test scene too empty: mean alpha {mean_alpha}"
    );
    let mut max_err: f64 = 0.0;
    let mut bad = 0;
    for p in 0..n {
        let mut e: f64 = 0.0;
        for ch in 0..3 {
            e = e.max((f64::from(out.rgb[3 * p + ch]) - reference.rgb[3 * p + ch]).abs());
        }
        e = e.max((f64::from(out.alpha[p]) - reference.alpha[p]).abs());
        let de = (f64::from(out.depth[p]) - reference.depth[p]).abs()
            / reference.depth[p].abs().max(1.0);
        e = e.max(de);
        max_err = max_err.max(e);
        if e > tol {
            bad += 1;
        }
    }
    eprintln!("mean alpha {mean_alpha:.3}, max err {max_err:.2e}, {bad} pixels above {tol}");
    (max_err, bad as f64 / n as f64)
}

#[test]
fn forward_matches_brute_force_reference() {
    for (seed, degree, antialiased, n) in [
        (1, 3, false, 60),
        (2, 1, true, 80),
        (3, 0, false, 200),
        (4, 2, false, 300),
        (6, 3, false, 1500),
    ] {
        let mut rng = Rng::new(seed);
        let s = random_splats(
            &mut rng,
            n,
            Vec3::ZERO,
            1.0,
            (-3.0, -1.0),
            (0.05, 0.99),
            degree,
        );
        let cam = look_at(
            Vec3::new(0.3, -0.4, -4.0),
            Vec3::ZERO,
            75,
            53,
            60.0,
            37.0,
            27.3,
        );
        let opts = RenderOptions {
            background: Vec3::new(0.2, 0.5, 0.9),
            active_sh_degree: 3,
            antialiased,
            linear_colour: false,
        };
        let (max_err, frac_bad) = compare(&s, &cam, &opts, 5e-5);
        assert!(
            frac_bad < 0.002 && max_err < 0.05,
            "seed {seed}: max err {max_err}, {frac_bad} of pixels above 5e-5"
        );
    }
}

#[test]
fn lower_active_degree_ignores_higher_bands() {
    let mut rng = Rng::new(9);
    let s = random_splats(&mut rng, 40, Vec3::ZERO, 1.0, (-2.5, -1.5), (0.3, 0.9), 3);
    let cam = look_at(
        Vec3::new(1.0, 0.5, -4.0),
        Vec3::ZERO,
        48,
        48,
        50.0,
        24.0,
        24.0,
    );
    let opts = RenderOptions {
        active_sh_degree: 1,
        ..RenderOptions::default()
    };
    let (max_err, frac) = compare(&s, &cam, &opts, 2e-4);
    assert!(frac < 0.002 && max_err < 0.05);
}

/// A single isotropic splat facing the camera: σ₂² = (f·σ/z)² + 0.3 and
/// C(d) = o·exp(−|d|²/(2σ₂²))·c + (1 − o·exp(…))·bg, evaluated at pixel centres.
#[test]
fn single_isotropic_splat_profile() {
    let (f, z, sigma, o) = (100.0_f32, 5.0_f32, 0.1_f32, 0.7_f32);
    let color = [0.9, 0.4, 0.1];
    let bg = Vec3::new(0.1, 0.2, 0.3);
    let mut s = Splats::new(0);
    s.push(
        Vec3::new(0.0, 0.0, z),
        Vec3::splat(sigma.ln()),
        [1.0, 0.0, 0.0, 0.0],
        logit(o),
        &[rgb_to_sh_dc(color)],
    );
    let cam = splat_core::RenderCamera {
        width: 64,
        height: 64,
        fx: f,
        fy: f,
        cx: 32.0,
        cy: 32.0,
        rotation: glam::Mat3::IDENTITY,
        translation: Vec3::ZERO,
    };
    let mut r = Rasterizer::new();
    let out = r.forward(
        &s,
        &cam,
        &RenderOptions {
            background: bg,
            ..RenderOptions::default()
        },
    );
    let var = f64::from(f * sigma / z).powi(2) + 0.3;
    let o = f64::from(splat_core::sigmoid(logit(o)));
    for (px, py) in [(32usize, 32usize), (33, 32), (35, 30), (28, 36), (32, 38)] {
        // Pixel centre (px + 0.5, py + 0.5); the splat projects to (32, 32).
        let d2 = (px as f64 + 0.5 - 32.0).powi(2) + (py as f64 + 0.5 - 32.0).powi(2);
        let alpha = o * (-d2 / (2.0 * var)).exp();
        for ch in 0..3 {
            let expect = alpha * f64::from(color[ch]) + (1.0 - alpha) * f64::from(bg[ch]);
            let got = f64::from(out.rgb[3 * (py * 64 + px) + ch]);
            assert!(
                (got - expect).abs() < 2e-5,
                "pixel ({px},{py}) ch {ch}: {got} vs {expect}"
            );
        }
        assert!((f64::from(out.alpha[py * 64 + px]) - alpha).abs() < 2e-6);
        assert!((out.depth[py * 64 + px] - z).abs() < 1e-4);
    }
}

/// Two overlapping splats: the nearer one is composited first whatever their storage order:
/// C = α₁c₁ + (1 − α₁)α₂c₂ + (1 − α₁)(1 − α₂)·bg at the common centre.
#[test]
fn two_splats_composite_front_to_back() {
    let make = |first_near: bool| {
        let mut s = Splats::new(0);
        let near = (Vec3::new(0.0, 0.0, 3.0), [1.0, 0.0, 0.0]);
        let far = (Vec3::new(0.0, 0.0, 6.0), [0.0, 1.0, 0.0]);
        let (a, b) = if first_near { (near, far) } else { (far, near) };
        for (m, c) in [a, b] {
            s.push(
                m,
                Vec3::splat(0.3_f32.ln()),
                [1.0, 0.0, 0.0, 0.0],
                logit(0.6),
                &[rgb_to_sh_dc(c)],
            );
        }
        s
    };
    let cam = splat_core::RenderCamera {
        width: 32,
        height: 32,
        fx: 40.0,
        fy: 40.0,
        cx: 16.5,
        cy: 16.5,
        rotation: glam::Mat3::IDENTITY,
        translation: Vec3::ZERO,
    };
    let opts = RenderOptions {
        background: Vec3::new(0.0, 0.0, 1.0),
        ..RenderOptions::default()
    };
    let mut r = Rasterizer::new();
    let a = r.forward(&make(true), &cam, &opts).clone();
    let b = r.forward(&make(false), &cam, &opts).clone();
    assert_eq!(a.rgb, b.rgb);
    // Pixel (16, 16) has its centre exactly on both projected means: G = 1.
    let p = 16 * 32 + 16;
    let o = f64::from(splat_core::sigmoid(logit(0.6)));
    let expect = [o, (1.0 - o) * o, (1.0 - o) * (1.0 - o)];
    for ch in 0..3 {
        assert!(
            (f64::from(a.rgb[3 * p + ch]) - expect[ch]).abs() < 1e-5,
            "{:?}",
            &a.rgb[3 * p..3 * p + 3]
        );
    }
    let depth = (o * 3.0 + (1.0 - o) * o * 6.0) / (1.0 - (1.0 - o) * (1.0 - o));
    assert!((f64::from(a.depth[p]) - depth).abs() < 1e-4);
}

/// Rendering twice with the same rasteriser (warm buffers) gives the same image.
#[test]
fn warm_rasteriser_is_reusable() {
    let mut rng = Rng::new(5);
    let s1 = random_splats(&mut rng, 100, Vec3::ZERO, 1.0, (-3.0, -1.5), (0.2, 0.9), 1);
    let s2 = random_splats(&mut rng, 30, Vec3::ZERO, 1.0, (-3.0, -1.5), (0.2, 0.9), 1);
    let cam = look_at(
        Vec3::new(0.0, 0.0, -4.0),
        Vec3::ZERO,
        40,
        30,
        40.0,
        20.0,
        15.0,
    );
    let small = look_at(Vec3::new(0.0, 0.0, -4.0), Vec3::ZERO, 17, 9, 20.0, 8.5, 4.5);
    let opts = RenderOptions::default();
    let mut r = Rasterizer::new();
    let first = r.forward(&s1, &cam, &opts).clone();
    r.forward(&s2, &small, &opts);
    let again = r.forward(&s1, &cam, &opts).clone();
    assert_eq!(first, again);
    assert_eq!(
        Rasterizer::new().forward(&s2, &small, &opts).rgb,
        r.forward(&s2, &small, &opts).rgb
    );
}
