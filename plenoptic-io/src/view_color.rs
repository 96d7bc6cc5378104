//! The view-dependent colour of a plenoptic point, exactly as MPEG's PccAppRenderer computes it.
//!
//! Its vertex shaders weight camera `i` by `max(0, cos∠(C_i − P, V − P))^n` with n = 10 and
//! normalised vectors, and fall back to the main colour when the weights vanish
//! (see `docs/reference/formats.md` §2.3). This is the only implementation in the project:
//! [`interpolate_lanes_by`] defines it, and [`interpolate8_avx2`] is its operations written in
//! AVX2 intrinsics for the reference views' shading, tested bit for bit against it.

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
/// lane, [`interpolate_lanes_by`] the same with the colours read by a function), so the colours
/// are the same bits; written as fixed-length loops over the lanes, a caller compiled for
/// 8-wide vectors colours 8 points with each vector operation.
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
    let pairs = colors.map(|c| c.len().min(cameras.len()));
    let colors: [&[[f32; 3]]; N] = std::array::from_fn(|l| &colors[l][..pairs[l]]);
    interpolate_lanes_by(
        points,
        viewers,
        cameras,
        pairs,
        |k, l| colors[l][k],
        main,
        exponent,
    )
}

/// [`interpolate_lanes`] with lane `l`'s colour for camera `k` read as `color(k, l)`, for
/// `k < counts[l]` only (a lane adds nothing for the cameras past its count, not even a
/// zero; `counts` at most `cameras.len()`). A caller that keeps its lanes' colours camera by
/// camera, lane after lane, lets each camera's colours load as vectors.
#[inline(always)]
#[must_use]
pub fn interpolate_lanes_by<const N: usize>(
    points: [Vec3; N],
    viewers: [Vec3; N],
    cameras: &[Vec3],
    counts: [usize; N],
    color: impl Fn(usize, usize) -> [f32; 3],
    main: [[f32; 3]; N],
    exponent: i32,
) -> [[f32; 3]; N] {
    // Lane-major copies of the points and their directions to the viewers, so that each step
    // below is one operation over the lanes.
    let view_dir: [Vec3; N] = std::array::from_fn(|l| (viewers[l] - points[l]).normalize_or_zero());
    let px = points.map(|p| p.x);
    let py = points.map(|p| p.y);
    let pz = points.map(|p| p.z);
    let vx = view_dir.map(|v| v.x);
    let vy = view_dir.map(|v| v.y);
    let vz = view_dir.map(|v| v.z);
    let mut sum = [[0.0f32; N]; 3];
    let mut total = [0.0f32; N];
    let full = counts.iter().all(|&n| n == cameras.len());
    for (k, &camera) in cameras.iter().enumerate() {
        if !full && counts.iter().all(|&n| n <= k) {
            break;
        }
        let cosine = cosines(camera, [&px, &py, &pz], [&vx, &vy, &vz]);
        let w = powi_lanes(cosine, exponent);
        let colors: [[f32; 3]; N] = std::array::from_fn(|l| {
            if full || k < counts[l] {
                color(k, l)
            } else {
                [0.0; 3]
            }
        });
        for l in 0..N {
            if full || k < counts[l] {
                total[l] += w[l];
                for c in 0..3 {
                    sum[c][l] += w[l] * colors[l][c];
                }
            }
        }
    }
    let mut out = main;
    for l in 0..N {
        if total[l] <= MIN_TOTAL_WEIGHT {
            continue;
        }
        out[l] = [0, 1, 2].map(|c| sum[c][l] / total[l]);
    }
    out
}

/// max(0, cos) between point→`camera` and the unit direction to the viewer for each lane
/// (points and directions lane-major): glam's `normalize_or_zero` and `dot` written out
/// component by component (the same operations in the same order, so the same bits) with the
/// zero direction a select instead of a branch, so the lanes vectorise.
#[inline(always)]
fn cosines<const N: usize>(
    camera: Vec3,
    [px, py, pz]: [&[f32; N]; 3],
    [vx, vy, vz]: [&[f32; N]; 3],
) -> [f32; N] {
    let dx: [f32; N] = std::array::from_fn(|l| camera.x - px[l]);
    let dy: [f32; N] = std::array::from_fn(|l| camera.y - py[l]);
    let dz: [f32; N] = std::array::from_fn(|l| camera.z - pz[l]);
    let rcp: [f32; N] =
        std::array::from_fn(|l| 1.0 / ((dx[l] * dx[l]) + (dy[l] * dy[l]) + (dz[l] * dz[l])).sqrt());
    let mut cosine = [0.0f32; N];
    for l in 0..N {
        let (ux, uy, uz) = if rcp[l].is_finite() && rcp[l] > 0.0 {
            (dx[l] * rcp[l], dy[l] * rcp[l], dz[l] * rcp[l])
        } else {
            (0.0, 0.0, 0.0)
        };
        cosine[l] = ((ux * vx[l]) + (uy * vy[l]) + (uz * vz[l])).max(0.0);
    }
    cosine
}

/// Points [`interpolate8_avx2`] colours at once.
pub const AVX2_LANES: usize = 8;

/// [`interpolate_lanes_by`] of eight points, point `l` seen from `viewers[l]` (many points from
/// one viewer, or one point from many), each with a colour for every camera
/// (`per_camera[k][c][l]`: camera `k`'s channel `c` of lane `l`), in AVX2: lane by lane the
/// same IEEE operations in the same order (no fused multiply-adds), so the same bits (tested
/// against the portable form). Written with intrinsics because LLVM compiled the
/// portable form's lanes four wide, with the zero-direction selects and the powers lane by
/// lane (a paper-scale frame's reference views spent a sixth of their time there).
///
/// # Safety
/// The CPU must have AVX2 (`is_x86_feature_detected!("avx2")`); a caller compiled with AVX2
/// enabled may call it as a safe function.
///
/// # Panics
/// If `per_camera` holds fewer entries than `cameras`.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[must_use]
pub fn interpolate8_avx2(
    points: &[Vec3; AVX2_LANES],
    viewers: &[Vec3; AVX2_LANES],
    cameras: &[Vec3],
    per_camera: &[[[f32; AVX2_LANES]; 3]],
    main: &[[f32; 3]; AVX2_LANES],
    exponent: i32,
) -> [[f32; 3]; AVX2_LANES] {
    use std::arch::x86_64::{
        __m256, _CMP_GT_OQ, _CMP_LE_OQ, _CMP_LT_OQ, _mm256_add_ps, _mm256_and_ps, _mm256_andnot_ps,
        _mm256_blendv_ps, _mm256_cmp_ps, _mm256_div_ps, _mm256_max_ps, _mm256_mul_ps,
        _mm256_set1_ps, _mm256_setzero_ps, _mm256_sqrt_ps, _mm256_sub_ps,
    };
    assert!(
        per_camera.len() >= cameras.len(),
        "a colour for every camera"
    );
    let load = |a: [f32; AVX2_LANES]| -> __m256 {
        // SAFETY: `__m256` is eight f32 with no invalid bit patterns, the size of the array.
        #[allow(unsafe_code)]
        unsafe {
            std::mem::transmute::<[f32; AVX2_LANES], __m256>(a)
        }
    };
    let store = |v: __m256| -> [f32; AVX2_LANES] {
        // SAFETY: as in `load`, the other way round.
        #[allow(unsafe_code)]
        unsafe {
            std::mem::transmute::<__m256, [f32; AVX2_LANES]>(v)
        }
    };
    let zero = _mm256_setzero_ps();
    let one = _mm256_set1_ps(1.0);
    let infinity = _mm256_set1_ps(f32::INFINITY);
    let sign = _mm256_set1_ps(-0.0);
    // glam's `normalize_or_zero` of (dx, dy, dz): the reciprocal of the length where it is
    // finite and positive, else zero (so the direction is the zero vector).
    let recip_length_or_zero = |dx: __m256, dy: __m256, dz: __m256| {
        let squared = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
            _mm256_mul_ps(dz, dz),
        );
        let rcp = _mm256_div_ps(one, _mm256_sqrt_ps(squared));
        let finite = _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_andnot_ps(sign, rcp), infinity);
        let positive = _mm256_cmp_ps::<_CMP_GT_OQ>(rcp, zero);
        (rcp, _mm256_and_ps(finite, positive))
    };
    let px = load(points.map(|p| p.x));
    let py = load(points.map(|p| p.y));
    let pz = load(points.map(|p| p.z));
    let (vx, vy, vz) = {
        let (dx, dy, dz) = (
            _mm256_sub_ps(load(viewers.map(|v| v.x)), px),
            _mm256_sub_ps(load(viewers.map(|v| v.y)), py),
            _mm256_sub_ps(load(viewers.map(|v| v.z)), pz),
        );
        let (rcp, ok) = recip_length_or_zero(dx, dy, dz);
        (
            _mm256_and_ps(ok, _mm256_mul_ps(dx, rcp)),
            _mm256_and_ps(ok, _mm256_mul_ps(dy, rcp)),
            _mm256_and_ps(ok, _mm256_mul_ps(dz, rcp)),
        )
    };
    let mut sum = [zero; 3];
    let mut total = zero;
    for (camera, colours) in cameras.iter().zip(per_camera) {
        let (dx, dy, dz) = (
            _mm256_sub_ps(_mm256_set1_ps(camera.x), px),
            _mm256_sub_ps(_mm256_set1_ps(camera.y), py),
            _mm256_sub_ps(_mm256_set1_ps(camera.z), pz),
        );
        let (rcp, ok) = recip_length_or_zero(dx, dy, dz);
        let (ux, uy, uz) = (
            _mm256_and_ps(ok, _mm256_mul_ps(dx, rcp)),
            _mm256_and_ps(ok, _mm256_mul_ps(dy, rcp)),
            _mm256_and_ps(ok, _mm256_mul_ps(dz, rcp)),
        );
        let dot = _mm256_add_ps(
            _mm256_add_ps(_mm256_mul_ps(ux, vx), _mm256_mul_ps(uy, vy)),
            _mm256_mul_ps(uz, vz),
        );
        // `f32::max(dot, 0.0)`: a NaN dot gives 0, as `maxps` gives its second operand.
        let mut x = _mm256_max_ps(dot, zero);
        // `powi_lanes`: the same square-and-multiply sequence.
        let mut left = exponent.unsigned_abs();
        let mut w = one;
        loop {
            if left & 1 == 1 {
                w = _mm256_mul_ps(w, x);
            }
            left >>= 1;
            if left == 0 {
                break;
            }
            x = _mm256_mul_ps(x, x);
        }
        if exponent < 0 {
            w = _mm256_div_ps(one, w);
        }
        total = _mm256_add_ps(total, w);
        for (s, &c) in sum.iter_mut().zip(colours) {
            *s = _mm256_add_ps(*s, _mm256_mul_ps(w, load(c)));
        }
    }
    // The main colour where the total weight is at most MIN_TOTAL_WEIGHT.
    let fallback = _mm256_cmp_ps::<_CMP_LE_OQ>(total, _mm256_set1_ps(MIN_TOTAL_WEIGHT));
    let channels: [[f32; AVX2_LANES]; 3] = std::array::from_fn(|c| {
        let mixed = _mm256_div_ps(sum[c], total);
        store(_mm256_blendv_ps(mixed, load(main.map(|m| m[c])), fallback))
    });
    std::array::from_fn(|l| [channels[0][l], channels[1][l], channels[2][l]])
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

    /// The AVX2 kernel against the one-lane form, bit for bit: points spread over a frame's
    /// extent and far beyond it, on a capture camera, on the viewer and far below the rig, a
    /// lane with a viewer of its own, 13 cameras near and far (one on the viewer), and
    /// exponents from -3 to 24 (0 and odd ones included).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_kernel_colours_each_point_as_it_alone_is_coloured() {
        // Without AVX2 the renderer never calls the kernel (and it cannot run).
        if !std::arch::is_x86_feature_detected!("avx2") {
            return;
        }
        let viewer = Vec3::new(100.0, 2500.0, -800.0);
        let mut cameras: Vec<Vec3> = (0..12)
            .map(|i| {
                let a = i as f32 * 0.48;
                let r = if i % 4 == 0 { 40_000.0 } else { 3000.0 };
                Vec3::new(a.cos() * r, (i % 3) as f32 * 400.0, a.sin() * r)
            })
            .collect();
        cameras.push(viewer);
        // A reproducible spread of values: a linear congruential sequence.
        let mut state = 0x2545_f491_u32;
        let mut next = move || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        for round in 0..400 {
            let mut points: [Vec3; AVX2_LANES] = std::array::from_fn(|_| {
                Vec3::new(next(), next(), next()) * 4096.0 - Vec3::splat(512.0)
            });
            if round % 4 == 0 {
                points[1] = cameras[3];
                points[2] = viewer;
                points[5] = Vec3::new(0.0, -90_000.0, 0.0);
            }
            let colours: Vec<[[f32; 3]; AVX2_LANES]> = (0..cameras.len())
                .map(|_| std::array::from_fn(|_| [next(), next(), next()]))
                .collect();
            let per_camera: Vec<[[f32; AVX2_LANES]; 3]> = colours
                .iter()
                .map(|lanes| std::array::from_fn(|c| lanes.map(|rgb| rgb[c])))
                .collect();
            let main: [[f32; 3]; AVX2_LANES] = std::array::from_fn(|_| [next(), next(), next()]);
            let exponent = round % 28 - 3;
            let mut viewers = [viewer; AVX2_LANES];
            viewers[6] = Vec3::new(next(), next(), next()) * 9000.0 - Vec3::splat(4500.0);
            // SAFETY: the CPU has AVX2 (checked above).
            #[allow(unsafe_code)]
            let lanes = unsafe {
                interpolate8_avx2(&points, &viewers, &cameras, &per_camera, &main, exponent)
            };
            for l in 0..AVX2_LANES {
                let own: Vec<[f32; 3]> = colours.iter().map(|c| c[l]).collect();
                let alone = interpolate(points[l], viewers[l], &cameras, &own, main[l], exponent);
                assert_eq!(
                    lanes[l].map(f32::to_bits),
                    alone.map(f32::to_bits),
                    "round {round}, lane {l}, exponent {exponent}: {:?} against {alone:?}",
                    lanes[l]
                );
            }
        }
    }
}
