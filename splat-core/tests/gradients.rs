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
