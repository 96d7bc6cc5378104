//! The view-dependent colour of a plenoptic point, exactly as MPEG's PccAppRenderer computes it.
//!
//! Its vertex shaders weight camera `i` by `max(0, cos∠(C_i − P, V − P))^n` with n = 10 and
//! normalised vectors, and fall back to the main colour when the weights vanish
//! (see `docs/reference/formats.md` §2.3). This is the only implementation in the project.

use glam::Vec3;

/// The renderer's exponent n ("Currently, color interpolation uses n=10", InterDigital slides p. 17).
pub const DEFAULT_EXPONENT: i32 = 10;

/// Below this total weight the renderer uses the main colour (`PccAppRenderer` shader threshold).
pub const MIN_TOTAL_WEIGHT: f32 = 1e-6;

/// w_i = max(0, dot(normalize(C_i − P), normalize(V − P)))^n; colour = Σ w_i c_i / Σ w_i, main colour if Σw ≤ 1e-6.
///
/// `cameras` and `colors` pair up (the shorter length wins). A camera or viewer that sits exactly
/// on the point has no direction and gets weight 0.
#[must_use]
pub fn interpolate(
    point: Vec3,
    viewer: Vec3,
    cameras: &[Vec3],
    colors: &[[f32; 3]],
    main: [f32; 3],
    exponent: i32,
) -> [f32; 3] {
    let [c] = interpolate_lanes([point], [viewer], cameras, [colors], [main], exponent);
    c
}

/// [`interpolate`] for `N` points at once, lane by lane: point `l` seen from `viewers[l]`, with
/// its per-camera colours `colors[l]` and main colour `main[l]` (one point from many viewers, or
/// many points from one). Every lane runs the same operations in the same
/// order as a single point does (this is the one implementation; [`interpolate`] is its one
/// lane), so the colours are the same bits; written as fixed-length loops over the lanes, a
/// caller compiled for 8-wide vectors colours 8 points with each vector operation.
#[inline(always)]
#[must_use]
pub fn interpolate_lanes<const N: usize>(
    points: [Vec3; N],
    viewers: [Vec3; N],
    cameras: &[Vec3],
    colors: [&[[f32; 3]]; N],
    main: [[f32; 3]; N],
    exponent: i32,
) -> [[f32; 3]; N] {
    let view_dir: [Vec3; N] = std::array::from_fn(|l| (viewers[l] - points[l]).normalize_or_zero());
    let pairs = colors.map(|c| c.len().min(cameras.len()));
    let mut sum = [[0.0f32; 3]; N];
    let mut total = [0.0f32; N];
    // Every lane with a colour for every camera (a plenoptic frame's points all have): the
    // lanes' colours sliced to the cameras once, so the loop below has no per-lane condition
    // and no bounds check, and vectorises across the lanes.
    if pairs.iter().all(|&n| n == cameras.len()) {
        let colors: [&[[f32; 3]]; N] = std::array::from_fn(|l| &colors[l][..cameras.len()]);
        for (k, &camera) in cameras.iter().enumerate() {
            let w = powi_lanes(cosines(camera, &points, &view_dir), exponent);
            for l in 0..N {
                let color = colors[l][k];
                total[l] += w[l];
                for c in 0..3 {
                    sum[l][c] += w[l] * color[c];
                }
            }
        }
    } else {
        for (k, &camera) in cameras.iter().enumerate() {
            if pairs.iter().all(|&n| n <= k) {
                break;
            }
            let w = powi_lanes(cosines(camera, &points, &view_dir), exponent);
            for l in 0..N {
                // A lane whose colours have run out adds nothing (not even a zero).
                if k < pairs[l] {
                    let color = colors[l][k];
                    total[l] += w[l];
                    for c in 0..3 {
                        sum[l][c] += w[l] * color[c];
                    }
                }
            }
        }
    }
    let mut out = main;
    for l in 0..N {
        if total[l] <= MIN_TOTAL_WEIGHT {
            continue;
        }
        out[l] = sum[l].map(|s| s / total[l]);
    }
    out
}

/// max(0, cos) between point→`camera` and `view_dir` for each lane: glam's `normalize_or_zero`
/// and `dot` written out component by component (the same operations in the same order, so the
/// same bits) with the zero direction a select instead of a branch, so the lanes vectorise.
#[inline(always)]
fn cosines<const N: usize>(camera: Vec3, points: &[Vec3; N], view_dir: &[Vec3; N]) -> [f32; N] {
    let mut cosine = [0.0f32; N];
    for l in 0..N {
        let d = camera - points[l];
        let rcp = 1.0 / ((d.x * d.x) + (d.y * d.y) + (d.z * d.z)).sqrt();
        let unit = if rcp.is_finite() && rcp > 0.0 {
            d * rcp
        } else {
            Vec3::ZERO
        };
        let v = view_dir[l];
        cosine[l] = ((unit.x * v.x) + (unit.y * v.y) + (unit.z * v.z)).max(0.0);
    }
    cosine
}

/// The weight of one camera from unit directions point→camera and point→viewer.
#[must_use]
pub fn weight(to_camera: Vec3, to_viewer: Vec3, exponent: i32) -> f32 {
    let [w] = powi_lanes([to_camera.dot(to_viewer).max(0.0)], exponent);
    w
}

/// `x` to the integer power `n` by repeated squaring, lane by lane, inlined. `f32::powi` with
/// an exponent known only at run time is a call into the runtime library's `__powisf2` for
/// every camera of every shaded point (3 % of a paper-scale run's reference views); this is the
/// same square-and-multiply sequence, so the results are the same bits (tested against `powi`).
#[inline(always)]
fn powi_lanes<const N: usize>(mut x: [f32; N], n: i32) -> [f32; N] {
    let mut left = n.unsigned_abs();
    let mut acc = [1.0_f32; N];
    loop {
        if left & 1 == 1 {
            for l in 0..N {
                acc[l] *= x[l];
            }
        }
        left >>= 1;
        if left == 0 {
            break;
        }
        for v in &mut x {
            *v *= *v;
        }
    }
    if n < 0 { acc.map(|a| 1.0 / a) } else { acc }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn inline_powers_are_the_bits_of_powi() {
        let mut x = 0.0_f32;
        while x <= 1.0 {
            for n in -3..=24 {
                let ([ours], std) = (powi_lanes([x], n), x.powi(n));
                assert!(
                    ours.to_bits() == std.to_bits() || (ours.is_nan() && std.is_nan()),
                    "{x}^{n}: {ours} against {std}"
                );
            }
            x += 0.000_37;
        }
        assert_eq!(powi_lanes([0.0], 0), [1.0]);
        assert_eq!(
            powi_lanes([0.5], 10)[0].to_bits(),
            0.5_f32.powi(10).to_bits()
        );
    }

    #[test]
    fn single_camera_facing_viewer_gives_its_colour() {
        let c = interpolate(
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, 10.0),
            &[Vec3::new(0.0, 0.0, 2000.0)],
            &[[0.2, 0.4, 0.6]],
            [1.0, 1.0, 1.0],
            DEFAULT_EXPONENT,
        );
        assert_eq!(c, [0.2, 0.4, 0.6]);
    }

    #[test]
    fn viewer_behind_every_camera_gets_main_colour() {
        let c = interpolate(
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, -10.0),
            &[Vec3::new(0.0, 0.0, 5.0), Vec3::new(1.0, 0.0, 5.0)],
            &[[0.2, 0.4, 0.6], [0.1, 0.1, 0.1]],
            [0.9, 0.8, 0.7],
            DEFAULT_EXPONENT,
        );
        assert_eq!(c, [0.9, 0.8, 0.7]);
    }

    #[test]
    fn two_cameras_mix_by_cosine_power() {
        // Cameras at ±30° from the viewer direction in the x-z plane, at very different
        // distances (4000 voxels and 3): normalisation must make the distance irrelevant.
        let a = 30f32.to_radians();
        let cam0 = Vec3::new(a.sin(), 0.0, a.cos()) * 4000.0;
        let cam1 = Vec3::new(-(2.0 * a).sin(), 0.0, (2.0 * a).cos()) * 3.0;
        let c = interpolate(
            Vec3::ZERO,
            Vec3::new(0.0, 0.0, 1.0),
            &[cam0, cam1],
            &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            [0.0, 0.0, 0.0],
            DEFAULT_EXPONENT,
        );
        let w0 = a.cos().powi(10);
        let w1 = (2.0 * a).cos().powi(10);
        assert_relative_eq!(c[0], w0 / (w0 + w1), epsilon = 1e-6);
        assert_relative_eq!(c[1], w1 / (w0 + w1), epsilon = 1e-6);
        assert_eq!(c[2], 0.0);
    }

    /// A viewer on the point has no direction: every weight is 0 and the main colour shows. A
    /// capture camera on the point gets weight 0 and the others share the colour as usual.
    #[test]
    fn viewer_or_camera_exactly_on_the_point() {
        let p = Vec3::new(512.0, 300.0, 700.0);
        let cameras = [p, Vec3::new(512.0, 300.0, 2000.0)];
        let colors = [[1.0, 0.0, 0.0], [0.0, 0.5, 1.0]];
        let c = interpolate(p, p, &cameras, &colors, [0.3, 0.3, 0.3], DEFAULT_EXPONENT);
        assert_eq!(c, [0.3, 0.3, 0.3]);
        let viewer = Vec3::new(512.0, 300.0, 900.0);
        let c = interpolate(
            p,
            viewer,
            &cameras,
            &colors,
            [0.3, 0.3, 0.3],
            DEFAULT_EXPONENT,
        );
        assert_eq!(c, [0.0, 0.5, 1.0]);
    }

    #[test]
    fn lanes_colour_each_point_as_it_alone_is_coloured() {
        // Eight points in one call, against eight one-point calls: points at a camera and at
        // the viewer, one facing no camera, colour lists of different lengths, and a lane with
        // a viewer of its own.
        let cameras: Vec<Vec3> = (0..13)
            .map(|i| {
                let a = i as f32 * 0.48;
                Vec3::new(a.cos() * 3000.0, (i % 3) as f32 * 400.0, a.sin() * 3000.0)
            })
            .collect();
        let colors: Vec<[f32; 3]> = (0..13)
            .map(|i| {
                [
                    i as f32 / 13.0,
                    1.0 - i as f32 / 26.0,
                    (i * 7 % 13) as f32 / 13.0,
                ]
            })
            .collect();
        let viewer = Vec3::new(100.0, 2500.0, -800.0);
        let points = [
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-120.5, 44.25, 300.0),
            cameras[4],
            viewer,
            Vec3::new(0.0, 9000.0, 0.0),
            Vec3::new(511.0, -3.0, 17.5),
            Vec3::new(-7.0, 0.0, -250.0),
            Vec3::new(60.0, 61.0, 62.0),
        ];
        let lens = [13, 13, 13, 13, 13, 5, 0, 12];
        let lists: [&[[f32; 3]]; 8] = std::array::from_fn(|l| &colors[..lens[l]]);
        let mains: [[f32; 3]; 8] = std::array::from_fn(|l| [0.1 * l as f32, 0.5, 0.25]);
        let mut viewers = [viewer; 8];
        viewers[7] = Vec3::new(-3000.0, 10.0, 40.0);
        let lanes = interpolate_lanes(points, viewers, &cameras, lists, mains, DEFAULT_EXPONENT);
        for l in 0..8 {
            let alone = interpolate(points[l], viewers[l], &cameras, lists[l], mains[l], 10);
            assert_eq!(
                lanes[l].map(f32::to_bits),
                alone.map(f32::to_bits),
                "lane {l}"
            );
        }
        // Every lane with all 13 colours takes the loop without per-lane conditions: the same
        // bits again.
        let full: [&[[f32; 3]]; 8] = [&colors; 8];
        let lanes_full =
            interpolate_lanes(points, viewers, &cameras, full, mains, DEFAULT_EXPONENT);
        for l in 0..8 {
            let alone = interpolate(points[l], viewers[l], &cameras, &colors, mains[l], 10);
            assert_eq!(
                lanes_full[l].map(f32::to_bits),
                alone.map(f32::to_bits),
                "lane {l} with every colour"
            );
        }
        // And against the formula written out in f64 for an ordinary lane.
        let (p, v) = (points[1].as_dvec3(), viewer.as_dvec3());
        let (mut sum, mut total) = ([0.0f64; 3], 0.0f64);
        for (c, col) in cameras.iter().zip(&colors) {
            let cos = (c.as_dvec3() - p).normalize().dot((v - p).normalize());
            let w = cos.max(0.0).powi(10);
            total += w;
            for k in 0..3 {
                sum[k] += w * f64::from(col[k]);
            }
        }
        for k in 0..3 {
            assert_relative_eq!(f64::from(lanes[1][k]), sum[k] / total, epsilon = 1e-5);
        }
    }

    #[test]
    fn far_cameras_do_not_overflow() {
        // Unnormalised dot products of ~1e4-voxel vectors raised to 10 overflow f32 (formats.md §2.3).
        let c = interpolate(
            Vec3::new(4000.0, 4000.0, 4000.0),
            Vec3::new(-40000.0, 4000.0, 4000.0),
            &[Vec3::new(-50000.0, 4000.0, 4000.0)],
            &[[0.5, 0.25, 0.125]],
            [0.0, 0.0, 0.0],
            DEFAULT_EXPONENT,
        );
        assert_eq!(c, [0.5, 0.25, 0.125]);
    }
}
