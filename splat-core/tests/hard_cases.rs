//! Degenerate and extreme inputs: outputs stay finite and sensible, gradients stay finite.
#![allow(clippy::needless_range_loop)] // index loops mirror the maths in these checks

mod common;

use common::{Rng, look_at, random_splats};
use glam::{Mat3, Vec3};
use splat_core::{
    Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats, logit, rgb_to_sh_dc,
};

fn cam(w: u32, h: u32) -> RenderCamera {
    RenderCamera {
        width: w,
        height: h,
        fx: w as f32,
        fy: w as f32,
        cx: w as f32 / 2.0,
        cy: h as f32 / 2.0,
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
    }
}

/// Renders and back-propagates a unit loss; checks every output and gradient is finite and in
/// range, and returns the output.
fn render_checked(
    s: &Splats,
    c: &RenderCamera,
    opts: &RenderOptions,
) -> (
    splat_core::RenderOutput,
    SplatGrads,
    splat_core::RenderStats,
) {
    let mut r = Rasterizer::new();
    let out = r.forward(s, c, opts).clone();
    for v in out.rgb.iter().chain(&out.alpha).chain(&out.depth) {
        assert!(v.is_finite(), "non-finite output");
    }
    assert!(out.alpha.iter().all(|a| (0.0..=1.0).contains(a)));
    let n = (c.width * c.height) as usize;
    let d_rgb = vec![1.0; 3 * n];
    let d_alpha = vec![0.5; n];
    let d_depth = vec![0.01; n];
    let mut g = SplatGrads::zeros_like(s);
    r.backward(s, c, opts, &d_rgb, Some(&d_alpha), Some(&d_depth), &mut g);
    let all = g
        .means
        .iter()
        .chain(&g.log_scales)
        .flat_map(|v| v.to_array())
        .chain(g.rotations.iter().flatten().copied())
        .chain(g.opacity_logits.iter().copied())
        .chain(g.sh.iter().flatten().copied())
        .chain(g.screen_grad_norm.iter().copied());
    for v in all {
        assert!(v.is_finite(), "non-finite gradient");
    }
    (out, g, r.stats())
}

fn one(mean: Vec3, log_scale: Vec3, rot: [f32; 4], logit_o: f32) -> Splats {
    let mut s = Splats::new(0);
    s.push(
        mean,
        log_scale,
        rot,
        logit_o,
        &[rgb_to_sh_dc([0.8, 0.3, 0.2])],
    );
    s
}

#[test]
fn needle_and_pancake_splats_with_scale_ratio_1e6() {
    let mut s = Splats::new(0);
    let q = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.3, 0.7, -0.2);
    let rot = [q.w, q.x, q.y, q.z];
    s.push(
        Vec3::new(-0.5, 0.0, 5.0),
        Vec3::new(0.0, -13.8, -13.8),
        rot,
        2.0,
        &[[0.5; 3]],
    );
    s.push(
        Vec3::new(0.5, 0.0, 5.0),
        Vec3::new(0.0, 0.0, -13.8),
        rot,
        2.0,
        &[[0.5; 3]],
    );
    // Seen exactly edge-on: the pancake's thin axis along the view ray's perpendicular.
    s.push(
        Vec3::new(0.0, 0.5, 5.0),
        Vec3::new(0.0, -13.8, 0.0),
        [1.0, 0.0, 0.0, 0.0],
        2.0,
        &[[0.5; 3]],
    );
    let (out, _, stats) = render_checked(&s, &cam(64, 48), &RenderOptions::default());
    assert_eq!(stats.visible, 3);
    assert!(out.alpha.iter().any(|&a| a > 0.5));
}

#[test]
fn splats_behind_the_camera_or_crossing_the_near_plane() {
    let mut s = Splats::new(0);
    s.push(
        Vec3::new(0.0, 0.0, -2.0),
        Vec3::splat(0.0),
        [1.0, 0.0, 0.0, 0.0],
        3.0,
        &[[1.0; 3]],
    );
    s.push(
        Vec3::new(0.0, 0.0, 0.005),
        Vec3::splat(0.0),
        [1.0, 0.0, 0.0, 0.0],
        3.0,
        &[[1.0; 3]],
    );
    // Centre in front of the near plane by a hair, extent crossing it by a lot.
    s.push(
        Vec3::new(0.1, 0.0, 0.02),
        Vec3::splat(0.5),
        [1.0, 0.0, 0.0, 0.0],
        3.0,
        &[[1.0; 3]],
    );
    let (out, _, stats) = render_checked(&s, &cam(32, 32), &RenderOptions::default());
    assert_eq!(
        stats.visible, 1,
        "only the splat in front of the near plane is drawn"
    );
    assert!(out.alpha.iter().all(|&a| a <= 0.99 + 1e-6));
    let behind = one(
        Vec3::new(0.0, 0.0, -2.0),
        Vec3::ZERO,
        [1.0, 0.0, 0.0, 0.0],
        3.0,
    );
    let (out, _, stats) = render_checked(
        &behind,
        &cam(16, 16),
        &RenderOptions {
            background: Vec3::new(0.1, 0.2, 0.3),
            ..RenderOptions::default()
        },
    );
    assert_eq!(stats.visible, 0);
    assert!(out.rgb.chunks(3).all(|p| p == [0.1, 0.2, 0.3]));
}

#[test]
fn splats_at_the_image_corners_where_the_clamp_acts() {
    let mut s = Splats::new(1);
    for (x, y) in [
        (-1.0, -1.0),
        (1.0, -1.0),
        (-1.0, 1.0),
        (1.0, 1.0),
        (3.0, 0.0),
    ] {
        s.push(
            Vec3::new(x * 2.0, y * 1.5, 2.0),
            Vec3::new(-0.5, -1.0, 0.0),
            [0.9, 0.1, 0.3, 0.2],
            1.0,
            &[[0.2; 3], [0.1; 3]],
        );
    }
    let (out, _, stats) = render_checked(&s, &cam(40, 30), &RenderOptions::default());
    assert!(stats.visible >= 4);
    // Corner pixels are covered by the corner splats (centred far outside the image).
    for p in [0, 39, 40 * 29, 40 * 30 - 1] {
        assert!(
            out.alpha[p] > 0.02,
            "corner pixel {p} alpha {}",
            out.alpha[p]
        );
    }
}

#[test]
fn extreme_opacity_logits() {
    let hi = one(
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::splat(0.0),
        [1.0, 0.0, 0.0, 0.0],
        30.0,
    );
    let (out, g, _) = render_checked(&hi, &cam(32, 32), &RenderOptions::default());
    let centre = 16 * 32 + 16;
    assert!(
        (out.alpha[centre] - 0.99).abs() < 1e-6,
        "alpha clamps at 0.99: {}",
        out.alpha[centre]
    );
    assert!(
        g.opacity_logits[0].abs() < 1e-3,
        "sigmoid'(30) ≈ 1e-13 and the clamp masks alpha"
    );
    let lo = one(
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::splat(-1.0),
        [1.0, 0.0, 0.0, 0.0],
        -30.0,
    );
    let (out, _, stats) = render_checked(&lo, &cam(32, 32), &RenderOptions::default());
    assert_eq!(stats.visible, 0);
    assert!(out.alpha.iter().all(|&a| a == 0.0));
}

#[test]
fn zero_quaternion_renders_as_identity() {
    let z = one(
        Vec3::new(0.1, 0.0, 3.0),
        Vec3::new(-1.0, -2.0, -1.5),
        [0.0; 4],
        1.0,
    );
    let id = one(
        Vec3::new(0.1, 0.0, 3.0),
        Vec3::new(-1.0, -2.0, -1.5),
        [1.0, 0.0, 0.0, 0.0],
        1.0,
    );
    let (a, g, _) = render_checked(&z, &cam(32, 32), &RenderOptions::default());
    let (b, _, _) = render_checked(&id, &cam(32, 32), &RenderOptions::default());
    assert_eq!(a.rgb, b.rgb);
    assert_eq!(g.rotations[0], [0.0; 4]);
}

#[test]
fn a_splat_covering_the_whole_image() {
    let s = one(
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::splat(3.0),
        [1.0, 0.0, 0.0, 0.0],
        0.0,
    );
    let (out, _, _) = render_checked(&s, &cam(48, 40), &RenderOptions::default());
    assert!(
        out.alpha.iter().all(|&a| (a - 0.5).abs() < 0.01),
        "uniform alpha ≈ sigmoid(0)"
    );
}

#[test]
fn a_one_by_one_image() {
    let mut rng = Rng::new(3);
    let s = random_splats(
        &mut rng,
        50,
        Vec3::new(0.0, 0.0, 4.0),
        0.5,
        (-2.0, -1.0),
        (0.2, 0.9),
        2,
    );
    let (out, _, _) = render_checked(&s, &cam(1, 1), &RenderOptions::default());
    assert_eq!(out.rgb.len(), 3);
    assert!(out.alpha[0] > 0.0);
}

#[test]
fn ten_thousand_splats_stacked_on_one_pixel() {
    let mut s = Splats::new(0);
    for i in 0..10_000 {
        s.push(
            Vec3::new(0.0, 0.0, 3.0 + i as f32 * 1e-4),
            Vec3::splat(-4.0),
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            &[rgb_to_sh_dc([0.9, 0.1, 0.1])],
        );
    }
    let (out, g, stats) = render_checked(&s, &cam(16, 16), &RenderOptions::default());
    assert_eq!(stats.visible, 10_000);
    let centre = 8 * 16 + 8;
    // Compositing stops as soon as T would drop below 1e-4: alpha just under 1 − 1e-4.
    assert!(out.alpha[centre] > 0.999 && out.alpha[centre] < 1.0);
    assert!((out.rgb[3 * centre] - 0.9).abs() < 1e-3);
    // Splats after the stop receive no gradient.
    assert_eq!(g.opacity_logits[9_999], 0.0);
}

#[test]
fn nan_and_infinite_inputs_are_culled_and_counted() {
    let mut rng = Rng::new(4);
    let mut s = random_splats(
        &mut rng,
        20,
        Vec3::new(0.0, 0.0, 4.0),
        0.8,
        (-2.0, -1.0),
        (0.3, 0.9),
        1,
    );
    let clean = s.clone();
    s.means[0].x = f32::NAN;
    s.log_scales[1].y = f32::INFINITY;
    s.rotations[2][3] = f32::NAN;
    s.opacity_logits[3] = f32::NAN;
    s.sh[4 * 4 + 2][1] = f32::NEG_INFINITY;
    s.log_scales[5] = Vec3::splat(200.0); // overflows to an infinite covariance
    let (out, g, stats) = render_checked(&s, &cam(40, 40), &RenderOptions::default());
    assert_eq!(stats.culled_non_finite, 6);
    for i in 0..6 {
        assert_eq!(g.means[i], Vec3::ZERO);
    }
    let mut r = Rasterizer::new();
    let mut without = clean;
    for i in (0..6).rev() {
        without.means.remove(i);
        without.log_scales.remove(i);
        without.rotations.remove(i);
        without.opacity_logits.remove(i);
        without.sh.drain(i * 4..i * 4 + 4);
    }
    assert_eq!(
        r.forward(&without, &cam(40, 40), &RenderOptions::default())
            .rgb,
        out.rgb
    );
}

/// 8iVSLF voxel units: a 1024-voxel object seen from thousands of units away renders like the
/// same scene scaled down by 1000 (the projection is scale-invariant) up to f32 rounding.
#[test]
fn coordinates_in_the_thousands() {
    let mut rng = Rng::new(8);
    let small = random_splats(&mut rng, 200, Vec3::ZERO, 0.5, (-4.0, -2.5), (0.3, 0.9), 1);
    let mut big = small.clone();
    let offset = Vec3::new(512.0, 512.0, 512.0);
    for i in 0..big.len() {
        big.means[i] = big.means[i] * 1000.0 + offset;
        big.log_scales[i] += Vec3::splat(1000.0_f32.ln());
    }
    let c_small = look_at(
        Vec3::new(0.4, 0.3, -3.0),
        Vec3::ZERO,
        64,
        64,
        70.0,
        32.0,
        32.0,
    );
    let c_big = look_at(
        Vec3::new(400.0, 300.0, -3000.0) + offset,
        offset,
        64,
        64,
        70.0,
        32.0,
        32.0,
    );
    let (a, _, _) = render_checked(&small, &c_small, &RenderOptions::default());
    let (b, _, _) = render_checked(&big, &c_big, &RenderOptions::default());
    let max = a
        .rgb
        .iter()
        .zip(&b.rgb)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0_f32, f32::max);
    assert!(max < 2e-3, "max difference {max}");
    let d = a
        .depth
        .iter()
        .zip(&b.depth)
        .filter(|(x, _)| **x > 0.0)
        .map(|(x, y)| (x * 1000.0 - y).abs() / y)
        .fold(0.0_f32, f32::max);
    assert!(d < 1e-3, "relative depth difference {d}");
}

/// Gradients are bit-for-bit identical whatever the number of threads.
#[test]
fn results_do_not_depend_on_the_thread_count() {
    let mut rng = Rng::new(12);
    let s = random_splats(&mut rng, 2000, Vec3::ZERO, 1.0, (-3.5, -2.0), (0.2, 0.9), 3);
    let c = look_at(
        Vec3::new(0.3, 0.2, -3.5),
        Vec3::ZERO,
        96,
        80,
        90.0,
        48.0,
        40.0,
    );
    let n = 96 * 80;
    let d_rgb: Vec<f32> = (0..3 * n)
        .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.5)
        .collect();
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut r = Rasterizer::new();
            let out = r.forward(&s, &c, &RenderOptions::default()).clone();
            let mut g = SplatGrads::zeros_like(&s);
            r.backward(
                &s,
                &c,
                &RenderOptions::default(),
                &d_rgb,
                None,
                None,
                &mut g,
            );
            (out, g)
        })
    };
    let (o1, g1) = run(1);
    let (o3, g3) = run(3);
    assert_eq!(o1, o3);
    assert_eq!(g1, g3);
}

#[test]
fn grads_are_resized_when_shaped_for_another_model() {
    let s = one(
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::splat(-1.0),
        [1.0, 0.0, 0.0, 0.0],
        0.0,
    );
    let c = cam(8, 8);
    let mut r = Rasterizer::new();
    r.forward(&s, &c, &RenderOptions::default());
    let mut g = SplatGrads::default();
    r.backward(
        &s,
        &c,
        &RenderOptions::default(),
        &vec![1.0; 192],
        None,
        None,
        &mut g,
    );
    assert_eq!(g.means.len(), 1);
    assert!(g.opacity_logits[0] > 0.0);
    let _ = logit(0.5);
}
