//! Degenerate and extreme inputs: outputs stay finite and sensible, gradients stay finite.
#![allow(clippy::needless_range_loop)] // index loops mirror the maths in these checks
#![allow(clippy::print_stderr)] // tests report what they measured

mod common;

use common::gradcheck::{check_gradients, check_gradients_with, weights};
use common::{RefSplats, Rng, look_at, psnr, random_splats, render_ref};
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

/// A zero quaternion in a 3DGS PLY is not an error at load: it is kept as written and drawn as
/// the identity (the documented fallback of `Splats::rotation` and the projection).
#[test]
fn zero_quaternion_from_a_ply_renders_as_identity() {
    let z = one(
        Vec3::new(0.1, 0.0, 3.0),
        Vec3::new(-1.0, -2.0, -1.5),
        [0.0; 4],
        1.0,
    );
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zero_quaternion.ply");
    splat_core::ply::write_splats(&path, &z).unwrap();
    let back = splat_core::ply::read_splats(&path).unwrap();
    assert_eq!(back.rotations[0], [0.0; 4]);
    assert_eq!(back.rotation(0), glam::Quat::IDENTITY);
    let mut id = back.clone();
    id.rotations[0] = [1.0, 0.0, 0.0, 0.0];
    let (a, g, _) = render_checked(&back, &cam(32, 32), &RenderOptions::default());
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

/// Renders with the crate and the f64 reference; returns the PSNR of the RGB image in dB.
fn psnr_against_reference(s: &Splats, c: &RenderCamera, opts: &RenderOptions) -> f64 {
    let (out, _, _) = render_checked(s, c, opts);
    let reference = render_ref(
        &RefSplats::from(s),
        c,
        opts.background.as_dvec3().to_array(),
        opts.active_sh_degree,
        opts.antialiased,
    );
    psnr(&out.rgb, &reference.rgb)
}

/// Quaternion (w, x, y, z) of a rotation by `angle` about `axis`.
fn quat(axis: Vec3, angle: f32) -> [f32; 4] {
    let q = glam::Quat::from_axis_angle(axis.normalize(), angle);
    [q.w, q.x, q.y, q.z]
}

/// Needles: axis ratio 10⁴, σ = 1000 to 5000 px along (3σ extents of 6000 to 30 000 px) and
/// 0.1 to 0.5 px across, at many in-plane angles and tilted out of the image plane. With the 2-D
/// determinant computed as a·c − b² in f32 (a·c ≈ 10¹³, det ≈ 10⁶) most of them came out with a
/// negative determinant (culled) or a wrong width; now each is drawn and matches the f64
/// reference.
fn needles(tilt: f32) -> Splats {
    let c = cam(128, 96);
    let mut s = Splats::new(0);
    let mut rng = Rng::new(31);
    for i in 0..12 {
        let z = 4.0 + 0.37 * i as f32;
        let sigma_px = [1000.0, 2000.0, 3000.0, 5000.0][i % 4];
        let long = sigma_px * z / c.fx;
        let short = long * 1e-4;
        // Centre somewhere in the image, long axis (local x) at angle θ in the image plane.
        let (px, py) = (rng.uniform(20.0, 108.0), rng.uniform(15.0, 80.0));
        let mean = Vec3::new((px - c.cx) * z / c.fx, (py - c.cy) * z / c.fy, z);
        let theta = 0.13 + 0.51 * i as f32;
        let spin = glam::Quat::from_rotation_z(theta) * glam::Quat::from_rotation_y(tilt);
        let ls = Vec3::new(long.ln(), short.ln(), (short * 1.7).ln());
        let rgb = [
            rng.uniform(0.1, 0.9),
            rng.uniform(0.1, 0.9),
            rng.uniform(0.1, 0.9),
        ];
        s.push(
            mean,
            ls,
            [spin.w, spin.x, spin.y, spin.z],
            2.0,
            &[rgb_to_sh_dc(rgb)],
        );
    }
    s
}

#[test]
fn needles_with_axis_ratio_1e4_and_thousands_of_pixels_long_match_the_f64_reference() {
    let c = cam(128, 96);
    for tilt in [0.0, 0.4] {
        let s = needles(tilt);
        for antialiased in [false, true] {
            let opts = RenderOptions {
                antialiased,
                background: Vec3::new(0.2, 0.3, 0.4),
                ..RenderOptions::default()
            };
            let (_, _, stats) = render_checked(&s, &c, &opts);
            assert_eq!(
                stats.visible,
                s.len(),
                "every needle keeps a positive determinant (tilt {tilt}, antialiased {antialiased})"
            );
            let p = psnr_against_reference(&s, &c, &opts);
            eprintln!("needles, tilt {tilt}, antialiased {antialiased}: PSNR {p:.1} dB");
            assert!(p >= 60.0, "PSNR {p:.1} dB");
        }
    }
}

/// The needles' gradients against finite differences of the f64 reference: three of them on a
/// smaller image (so the differences stay quick), ten times larger so that they are 3000 to
/// 15 000 px (σ) long and 0.3 to 1.5 px wide, where the width matters next to the dilation.
#[test]
fn needle_gradients_match_finite_differences() {
    let all = needles(0.4);
    let mut s = Splats::new(0);
    for i in [0, 5, 10] {
        s.push(
            all.means[i] * Vec3::new(0.35, 0.35, 1.0),
            all.log_scales[i] + Vec3::splat(10.0_f32.ln()),
            all.rotations[i],
            all.opacity_logits[i],
            all.sh_of(i),
        );
    }
    let c = cam(40, 32);
    let mut rng = Rng::new(32);
    for antialiased in [false, true] {
        let opts = RenderOptions {
            antialiased,
            ..RenderOptions::default()
        };
        let w = weights(&mut rng, &c, true, false);
        check_gradients_with(&s, &c, &opts, &w, &[], 1e-6);
    }
}

/// The camera inside a splat (its centre 0.5 in front, σ = 1.6): drawn, a broad veil over the
/// whole image, matching the f64 reference, with gradients matching finite differences.
#[test]
fn camera_inside_a_splat() {
    let s = one(
        Vec3::new(0.1, -0.05, 0.5),
        Vec3::new(0.5, 0.3, 0.4),
        quat(Vec3::new(1.0, 2.0, 0.5), 0.7),
        0.4,
    );
    let c = cam(32, 32);
    let opts = RenderOptions::default();
    let (out, _, stats) = render_checked(&s, &c, &opts);
    assert_eq!(stats.visible, 1);
    assert!(
        out.alpha.iter().all(|&a| a > 0.1),
        "the veil covers the image"
    );
    let p = psnr_against_reference(&s, &c, &opts);
    assert!(p >= 60.0, "PSNR {p:.1} dB");
    let mut rng = Rng::new(41);
    let w = weights(&mut rng, &c, true, false);
    check_gradients(&s, &c, &opts, &w);
}

/// A centre exactly on the near plane (camera z = 0.01) is culled (z ≤ near); one float above
/// it is drawn (huge on screen, the Jacobian clamped) with finite output and gradients.
#[test]
fn splat_exactly_on_the_near_plane() {
    let c = cam(32, 32);
    let on = one(
        Vec3::new(0.0, 0.0, splat_core::constants::NEAR_PLANE),
        Vec3::splat(-3.0),
        [1.0, 0.0, 0.0, 0.0],
        1.0,
    );
    let (out, g, stats) = render_checked(&on, &c, &RenderOptions::default());
    assert_eq!((stats.visible, stats.culled_non_finite), (0, 0));
    assert!(out.alpha.iter().all(|&a| a == 0.0));
    assert_eq!(g.means[0], Vec3::ZERO);
    let mut above = on.clone();
    above.means[0].z = splat_core::constants::NEAR_PLANE.next_up();
    let (out, _, stats) = render_checked(&above, &c, &RenderOptions::default());
    assert_eq!(stats.visible, 1);
    assert!(out.alpha.iter().any(|&a| a > 0.5));
    let p = psnr_against_reference(&above, &c, &RenderOptions::default());
    assert!(p >= 60.0, "PSNR {p:.1} dB");
}

/// Just in front of the near plane and off-axis (so the Jacobian's clamp acts): gradients match
/// finite differences.
#[test]
fn gradients_just_in_front_of_the_near_plane() {
    let s = one(
        Vec3::new(0.004, -0.002, 0.012),
        Vec3::new(-6.0, -5.5, -6.5),
        quat(Vec3::new(0.3, -1.0, 0.2), 1.1),
        1.0,
    );
    let c = cam(32, 32);
    let mut rng = Rng::new(42);
    let w = weights(&mut rng, &c, true, false);
    // Depth 0.012: a step of 1e-4 is 1% of it, too coarse for the differences.
    check_gradients_with(&s, &c, &RenderOptions::default(), &w, &[], 1e-7);
}

/// A splat centred exactly at the camera centre (a rotated, translated camera, so its camera
/// coordinates are rounding noise): culled by the near plane, never reaching the view direction
/// (0/0), and the image is that of the other splats alone.
#[test]
fn splat_centred_at_the_camera_centre() {
    let c = look_at(
        Vec3::new(1.3, -0.7, 2.1),
        Vec3::ZERO,
        48,
        40,
        50.0,
        24.0,
        20.0,
    );
    let mut rng = Rng::new(43);
    let others = random_splats(&mut rng, 30, Vec3::ZERO, 0.6, (-2.5, -1.5), (0.3, 0.9), 2);
    let mut s = others.clone();
    s.push(
        c.center(),
        Vec3::splat(-1.0),
        [0.9, 0.1, 0.2, 0.3],
        2.0,
        &[[0.5; 3], [0.2; 3], [0.1; 3]],
    );
    let (out, g, stats) = render_checked(&s, &c, &RenderOptions::default());
    assert_eq!(stats.culled_non_finite, 0);
    let mut r = Rasterizer::new();
    let alone = r.forward(&others, &c, &RenderOptions::default());
    assert_eq!(alone.rgb, out.rgb);
    assert_eq!(stats.visible, r.stats().visible);
    assert_eq!(g.means[30], Vec3::ZERO);
    assert_eq!(g.opacity_logits[30], 0.0);
}

/// Scale 0 on one axis (log-scale −200: e^−200 underflows to 0 in f32): a flat disc, drawn face
/// on and edge on like the f64 reference (where the scale is 10⁻⁸⁷); on all three axes, a point
/// drawn as the 0.3 px² dilation alone, and culled in antialiased mode (compensation √(0/det) = 0).
/// A log-scale of −∞ is a non-finite input: culled and counted.
#[test]
fn zero_scales() {
    let c = cam(32, 32);
    let mut s = Splats::new(0);
    s.push(
        Vec3::new(-0.3, 0.0, 3.0),
        Vec3::new(-2.0, -2.5, -200.0),
        quat(Vec3::Z, 0.5),
        1.0,
        &[rgb_to_sh_dc([0.9, 0.2, 0.1])],
    );
    s.push(
        Vec3::new(0.3, 0.1, 3.2),
        Vec3::new(-2.0, -2.5, -200.0),
        quat(Vec3::X, std::f32::consts::FRAC_PI_2),
        1.0,
        &[rgb_to_sh_dc([0.1, 0.8, 0.3])],
    );
    let opts = RenderOptions::default();
    let (_, _, stats) = render_checked(&s, &c, &opts);
    assert_eq!(stats.visible, 2);
    let p = psnr_against_reference(&s, &c, &opts);
    assert!(p >= 60.0, "PSNR {p:.1} dB");
    let mut rng = Rng::new(44);
    let w = weights(&mut rng, &c, true, false);
    check_gradients_with(&s, &c, &opts, &w, &[], 1e-6);

    let point = one(
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::splat(-200.0),
        [1.0, 0.0, 0.0, 0.0],
        3.0,
    );
    let (out, g, stats) = render_checked(&point, &c, &opts);
    assert_eq!(stats.visible, 1);
    // The centre, (16, 16) in image coordinates, is the corner of pixels 15 and 16 in x and y:
    // each is 0.5 px away in both axes of a Gaussian of variance 0.3 px² (the dilation alone).
    let expected = splat_core::sigmoid(3.0) * (-0.5_f32 * 0.5 / 0.3).exp();
    for (x, y) in [(15, 15), (16, 15), (15, 16), (16, 16)] {
        let a = out.alpha[y * 32 + x];
        assert!((a - expected).abs() < 1e-5, "({x}, {y}): {a} vs {expected}");
    }
    assert_eq!(g.log_scales[0], Vec3::ZERO, "d/d log-scale = d/d scale · 0");
    let aa = RenderOptions {
        antialiased: true,
        linear_colour: false,
        ..opts
    };
    let (_, _, stats) = render_checked(&point, &c, &aa);
    assert_eq!((stats.visible, stats.culled_non_finite), (0, 0));

    let mut minus_inf = point.clone();
    minus_inf.log_scales[0].z = f32::NEG_INFINITY;
    let (out, _, stats) = render_checked(&minus_inf, &c, &opts);
    assert_eq!((stats.visible, stats.culled_non_finite), (0, 1));
    assert!(out.alpha.iter().all(|&a| a == 0.0));
}

/// Log-scales at ±30: e^30 ≈ 10¹³ world units is a uniform veil of alpha = sigmoid(logit) over
/// the image (its 2-D covariance ≈ 10²⁹ px², its determinant ≈ 10⁵⁸, beyond f32 but within the
/// f64 the determinant is computed in); e^−30 is a point drawn as the dilation. Both match the
/// f64 reference, and the veil's gradient is zero in everything its shape depends on.
#[test]
fn log_scales_at_plus_and_minus_30() {
    let c = cam(32, 32);
    let opts = RenderOptions::default();
    let big = one(
        Vec3::new(0.1, 0.0, 3.0),
        Vec3::new(30.0, 29.0, 30.0),
        quat(Vec3::new(1.0, 1.0, 0.0), 0.6),
        0.5,
    );
    let (out, _, stats) = render_checked(&big, &c, &opts);
    assert_eq!((stats.visible, stats.culled_non_finite), (1, 0));
    let o = splat_core::sigmoid(0.5);
    assert!(out.alpha.iter().all(|&a| (a - o).abs() < 1e-6));
    assert!(psnr_against_reference(&big, &c, &opts) >= 60.0);
    let mut rng = Rng::new(45);
    let w = weights(&mut rng, &c, true, false);
    check_gradients_with(
        &big,
        &c,
        &opts,
        &w,
        &["means", "log_scales", "rotations"],
        1e-4,
    );

    let small = one(
        Vec3::new(0.1, 0.0, 3.0),
        Vec3::new(-30.0, -30.0, -29.0),
        quat(Vec3::new(1.0, 1.0, 0.0), 0.6),
        0.5,
    );
    let (_, _, stats) = render_checked(&small, &c, &opts);
    assert_eq!(stats.visible, 1);
    assert!(psnr_against_reference(&small, &c, &opts) >= 60.0);
}

/// Opacity logits beyond ±88, where e^−x overflows f32 in the sigmoid: +100, +10³⁰ and f32::MAX
/// give opacity 1 (alpha clamped at 0.99, no gradient), −100 and below give 0 (culled); nothing
/// is NaN. Finite differences agree: the loss is flat in these logits.
#[test]
fn opacity_logits_beyond_the_exp_overflow() {
    let c = cam(32, 32);
    let opts = RenderOptions::default();
    for logit_o in [100.0, 1e30, f32::MAX] {
        let s = one(
            Vec3::new(0.0, 0.0, 3.0),
            Vec3::ZERO,
            [1.0, 0.0, 0.0, 0.0],
            logit_o,
        );
        let (out, g, stats) = render_checked(&s, &c, &opts);
        assert_eq!(stats.visible, 1);
        assert!((out.alpha[16 * 32 + 16] - 0.99).abs() < 1e-6);
        assert_eq!(g.opacity_logits[0], 0.0);
    }
    for logit_o in [-100.0, -1e30, f32::MIN] {
        let s = one(
            Vec3::new(0.0, 0.0, 3.0),
            Vec3::splat(-1.0),
            [1.0, 0.0, 0.0, 0.0],
            logit_o,
        );
        let (out, _, stats) = render_checked(&s, &c, &opts);
        assert_eq!((stats.visible, stats.culled_non_finite), (0, 0));
        assert!(out.alpha.iter().all(|&a| a == 0.0));
    }
    let s = one(
        Vec3::new(0.05, 0.0, 3.0),
        Vec3::new(-1.5, -1.2, -1.0),
        [1.0, 0.0, 0.0, 0.0],
        100.0,
    );
    let mut rng = Rng::new(46);
    let w = weights(&mut rng, &c, true, false);
    check_gradients_with(&s, &c, &opts, &w, &["opacity_logits"], 1e-4);
}

/// Unnormalised quaternions render as their normalisation: scaled by 10⁻²⁵ (whose squares
/// underflow f32) or 10²⁰ (whose squares overflow), and by 3.7, all as the unit quaternion, with
/// gradients matching finite differences (they scale as 1/|q|).
#[test]
fn unnormalised_quaternions() {
    let c = cam(32, 32);
    let opts = RenderOptions::default();
    let unit = glam::Quat::from_axis_angle(Vec3::new(0.4, -1.0, 0.7).normalize(), 0.9);
    let base = one(
        Vec3::new(0.1, -0.1, 3.0),
        Vec3::new(-1.0, -2.2, -1.6),
        [unit.w, unit.x, unit.y, unit.z],
        1.0,
    );
    let (reference, _, _) = render_checked(&base, &c, &opts);
    for k in [1e-25_f32, 1e20, 3.7] {
        let mut s = base.clone();
        s.rotations[0] = s.rotations[0].map(|v| v * k);
        let (out, g, _) = render_checked(&s, &c, &opts);
        let diff = out
            .rgb
            .iter()
            .zip(&reference.rgb)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0_f32, f32::max);
        assert!(diff < 1e-5, "scale {k}: max difference {diff}");
        assert!(g.rotations[0].iter().any(|v| *v != 0.0), "scale {k}");
        assert_eq!(
            s.rotation(0).to_array().map(|v| (v * 1e5).round()),
            unit.to_array().map(|v| (v * 1e5).round())
        );
    }
    let mut s = base.clone();
    s.rotations[0] = s.rotations[0].map(|v| v * 3.7);
    let mut rng = Rng::new(47);
    let w = weights(&mut rng, &c, true, false);
    check_gradients(&s, &c, &opts, &w);
}

/// No splats: the background, zero stats, empty gradients.
#[test]
fn no_splats() {
    let s = Splats::new(2);
    let opts = RenderOptions {
        background: Vec3::new(0.25, 0.5, 0.75),
        ..RenderOptions::default()
    };
    let (out, g, stats) = render_checked(&s, &cam(20, 17), &opts);
    assert_eq!(stats, splat_core::RenderStats::default());
    assert!(out.rgb.chunks(3).all(|p| p == [0.25, 0.5, 0.75]));
    assert!(g.means.is_empty() && g.sh.is_empty());
}

/// 400 splats all inside one 16×16 tile of a 64×64 image: each binned once, every other tile
/// the background, and the tile as the f64 reference draws it.
#[test]
fn every_splat_in_one_tile() {
    let c = cam(64, 64);
    let mut rng = Rng::new(48);
    let mut s = Splats::new(1);
    for _ in 0..400 {
        // Pixel centres 20..28 of tile (1, 1) at depth 3..4, σ ≈ 0.3–0.7 px (3σ inside the tile).
        let z = rng.uniform(3.0, 4.0);
        let (px, py) = (rng.uniform(21.0, 27.0), rng.uniform(21.0, 27.0));
        let mean = Vec3::new((px - c.cx) * z / c.fx, (py - c.cy) * z / c.fy, z);
        let sc = rng.uniform(0.3, 0.7) * z / c.fx;
        s.push(
            mean,
            Vec3::splat(sc.ln()),
            [rng.normal(), rng.normal(), rng.normal(), rng.normal()],
            rng.uniform(-1.0, 2.0),
            &[
                [
                    rng.uniform(-1.0, 1.0),
                    rng.uniform(-1.0, 1.0),
                    rng.uniform(-1.0, 1.0),
                ],
                [0.1, -0.1, 0.05],
            ],
        );
    }
    let opts = RenderOptions::default();
    let (out, _, stats) = render_checked(&s, &c, &opts);
    assert_eq!(stats.visible, 400);
    assert_eq!(stats.pairs, 400, "each splat in exactly one tile");
    for y in 0..64 {
        for x in 0..64 {
            if !(16..32).contains(&x) || !(16..32).contains(&y) {
                assert_eq!(out.alpha[y * 64 + x], 0.0, "pixel ({x}, {y})");
            }
        }
    }
    let p = psnr_against_reference(&s, &c, &opts);
    assert!(p >= 60.0, "PSNR {p:.1} dB");
}

/// A view whose per-pixel buffers would exceed the limit is refused before anything is
/// allocated, with an error naming the size and the limit; the largest allowed size passes the
/// check, and sizes whose tile count would overflow u32 are refused, not wrapped.
#[test]
fn views_over_the_pixel_limit_are_refused_up_front() {
    let s = one(
        Vec3::new(0.0, 0.0, 3.0),
        Vec3::ZERO,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
    );
    let mut r = Rasterizer::new();
    for (w, h) in [
        (100_000, 100_000),
        (8193, 8192),
        (u32::MAX, u32::MAX),
        (1, 1 << 27),
    ] {
        let err = r
            .try_forward(&s, &cam(w, h), &RenderOptions::default())
            .unwrap_err();
        let msg = err.to_string();
        assert!(
            matches!(err, splat_core::Error::ViewTooLarge { limit, .. } if limit == splat_core::MAX_PIXELS),
            "{msg}"
        );
        assert!(
            msg.contains(&format!("{w}×{h}")) && msg.contains("67108864"),
            "{msg}"
        );
    }
    assert_eq!(splat_core::MAX_PIXELS, 8192 * 8192);
    Rasterizer::check_view_size(8192, 8192).unwrap();
    // A refused view leaves the rasteriser usable.
    let out = r
        .try_forward(&s, &cam(8, 8), &RenderOptions::default())
        .unwrap();
    assert!(out.alpha[4 * 8 + 4] > 0.4);
}
