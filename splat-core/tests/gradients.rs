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

use common::gradcheck::{check_gradients, mask_depth_weights, weights};
use common::{Rng, look_at, random_splats};
use glam::Vec3;
use splat_core::RenderOptions;

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
        linear_colour: false,
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
        linear_colour: false,
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

/// With `linear_colour` the image over black is a linear map A of the SH coefficients (geometry
/// and opacity fixed), and the backward pass of Σ r·rgb is its adjoint: checked as
/// A(a·x + b·y) = a·Ax + b·Ay and ⟨A p, r⟩ = ⟨p, Aᵀ r⟩ in f64, for SH degree 3 with signs that
/// would be clamped in an ordinary render.
#[test]
fn linear_colour_renders_are_linear_in_sh_and_backward_is_their_adjoint() {
    let mut rng = Rng::new(31);
    let mut s = random_splats(&mut rng, 16, Vec3::ZERO, 0.8, (-2.6, -1.4), (0.2, 0.9), 3);
    let cam = look_at(
        Vec3::new(0.3, -0.4, -4.0),
        Vec3::ZERO,
        40,
        34,
        45.0,
        19.5,
        17.0,
    );
    let opts = RenderOptions {
        background: Vec3::ZERO,
        active_sh_degree: 3,
        antialiased: false,
        linear_colour: true,
    };
    let mut random_sh = |s: &mut splat_core::Splats| {
        for c in &mut s.sh {
            *c = [rng.normal(), rng.normal(), rng.normal()];
        }
        s.sh.clone()
    };
    let mut raster = splat_core::Rasterizer::new();
    let mut render = |s: &splat_core::Splats| raster.forward(s, &cam, &opts).rgb.clone();
    let x = random_sh(&mut s);
    let ax = render(&s);
    let y = random_sh(&mut s);
    let ay = render(&s);
    let (a, b) = (0.7f32, -1.3f32);
    for (k, c) in s.sh.iter_mut().enumerate() {
        *c = [0, 1, 2].map(|ch| a * x[k][ch] + b * y[k][ch]);
    }
    let mixed = render(&s);
    let scale = ax.iter().chain(&ay).fold(0.0f32, |m, v| m.max(v.abs()));
    assert!(scale > 0.1, "the test image is empty");
    for ((m, p), q) in mixed.iter().zip(&ax).zip(&ay) {
        assert!(
            (m - (a * p + b * q)).abs() <= 1e-5 * scale,
            "{m} vs {}",
            a * p + b * q
        );
    }
    // Adjoint: ⟨A p, r⟩ = ⟨p, Aᵀ r⟩ with p = y (the coefficients now set back) and random r.
    for (c, v) in s.sh.iter_mut().zip(&y) {
        *c = *v;
    }
    let r: Vec<f32> = (0..ay.len()).map(|_| rng.normal()).collect();
    let mut grads = splat_core::SplatGrads::zeros_like(&s);
    let mut raster = splat_core::Rasterizer::new();
    raster.forward(&s, &cam, &opts);
    raster.backward(&s, &cam, &opts, &r, None, None, &mut grads);
    let lhs: f64 = ay.iter().zip(&r).map(|(a, r)| f64::from(a * r)).sum();
    let rhs: f64 = grads
        .sh
        .iter()
        .zip(&y)
        .map(|(g, p)| (0..3).map(|ch| f64::from(g[ch] * p[ch])).sum::<f64>())
        .sum();
    assert!(
        (lhs - rhs).abs() <= 1e-4 * lhs.abs().max(1.0),
        "⟨Ap, r⟩ = {lhs}, ⟨p, Aᵀr⟩ = {rhs}"
    );
}
