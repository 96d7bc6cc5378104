//! Camera rigs: directions spread on a sphere, rings, framing, and capture rigs.
//!
//! Directions use world +y as the polar ("up") axis, as the 8iVSLF data and PccAppRenderer's
//! default up vector (0, 1, 0) do. Elevation is the angle above the x–z plane.

use glam::DVec3;

use crate::{Camera, Error, Intrinsics, Pose};

/// The world up axis of rigs (8iVSLF and PccAppRenderer use +y up).
pub const WORLD_UP: DVec3 = DVec3::Y;

/// The golden angle π·(3 − √5) in radians: successive Fibonacci-lattice points turn by it.
const GOLDEN_ANGLE: f64 = 2.399_963_229_728_653;

/// `n` unit directions spread evenly over the whole sphere (Fibonacci lattice, equal-area rows).
#[must_use]
pub fn fibonacci_sphere(n: usize) -> Vec<DVec3> {
    fibonacci_band(n, -90.0, 90.0)
}

/// `n` unit directions spread evenly over the band of elevations
/// [`min_elevation_deg`, `max_elevation_deg`] (degrees above the x–z plane, towards +y).
///
/// Rows are equally spaced in sin(elevation), which makes them equal in area, and successive
/// points turn by the golden angle (Á. González, "Measurement of areas on a sphere using
/// Fibonacci and latitude–longitude lattices", Math. Geosci. 42, 2010). Bounds are clamped to
/// [−90, 90] and swapped if given in the wrong order.
#[must_use]
pub fn fibonacci_band(n: usize, min_elevation_deg: f64, max_elevation_deg: f64) -> Vec<DVec3> {
    let (lo, hi) = if min_elevation_deg <= max_elevation_deg {
        (min_elevation_deg, max_elevation_deg)
    } else {
        (max_elevation_deg, min_elevation_deg)
    };
    let y_lo = lo.clamp(-90.0, 90.0).to_radians().sin();
    let y_hi = hi.clamp(-90.0, 90.0).to_radians().sin();
    (0..n)
        .map(|i| {
            let y = y_hi - (i as f64 + 0.5) / n as f64 * (y_hi - y_lo);
            let r = (1.0 - y * y).max(0.0).sqrt();
            let phi = i as f64 * GOLDEN_ANGLE;
            DVec3::new(r * phi.cos(), y, r * phi.sin())
        })
        .collect()
}

/// A horizontal ring of directions at one elevation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Ring {
    /// Elevation above the x–z plane in degrees.
    pub elevation_deg: f64,
    /// Number of directions, evenly spaced in azimuth.
    pub count: usize,
    /// Azimuth of the first direction in degrees (0 = +x, 90 = +z).
    pub azimuth_offset_deg: f64,
}

/// Unit directions of several rings, ring after ring.
#[must_use]
pub fn rings(rings: &[Ring]) -> Vec<DVec3> {
    rings
        .iter()
        .flat_map(|ring| {
            let (sin_e, cos_e) = ring.elevation_deg.to_radians().sin_cos();
            (0..ring.count).map(move |k| {
                let az = ring.azimuth_offset_deg.to_radians()
                    + std::f64::consts::TAU * k as f64 / ring.count as f64;
                DVec3::new(cos_e * az.cos(), sin_e, cos_e * az.sin())
            })
        })
        .collect()
}

/// Distance from a sphere's centre at which a camera looking at that centre sees the sphere's
/// silhouette span `1 − margin` of the half-width of the narrower image dimension.
///
/// A sphere of radius r at distance d projects to a disc of radius f·r/√(d² − r²) pixels, so
/// d = r·√(1 + 1/s²) with s = (1 − margin)·min(W/(2fx), H/(2fy)).
pub fn framing_distance(radius: f64, intrinsics: &Intrinsics, margin: f64) -> Result<f64, Error> {
    check_framing(radius, margin)?;
    let s = (1.0 - margin) * half_tan_fov(intrinsics);
    Ok(radius * (1.0 + 1.0 / (s * s)).sqrt())
}

/// Focal length (fx = fy) at which a sphere of `radius` seen from `distance` spans `1 − margin` of
/// the half-width of the narrower image dimension: the inverse of [`framing_distance`].
pub fn framing_focal(
    radius: f64,
    distance: f64,
    width: u32,
    height: u32,
    margin: f64,
) -> Result<f64, Error> {
    check_framing(radius, margin)?;
    if distance <= radius || !distance.is_finite() {
        return Err(Error::InvalidParameter(format!(
            "camera distance {distance} must exceed the sphere radius {radius}"
        )));
    }
    let half = 0.5 * f64::from(width.min(height));
    Ok((1.0 - margin) * half * (distance * distance - radius * radius).sqrt() / radius)
}

fn check_framing(radius: f64, margin: f64) -> Result<(), Error> {
    if !(radius > 0.0 && radius.is_finite()) {
        return Err(Error::InvalidParameter(format!(
            "sphere radius must be positive, got {radius}"
        )));
    }
    if !(0.0..1.0).contains(&margin) {
        return Err(Error::InvalidParameter(format!(
            "margin must be in [0, 1), got {margin}"
        )));
    }
    Ok(())
}

/// tan of the half field of view of the narrower image dimension.
fn half_tan_fov(k: &Intrinsics) -> f64 {
    (0.5 * f64::from(k.width) / k.fx).min(0.5 * f64::from(k.height) / k.fy)
}

/// Cameras at `target + distance·d` for each direction `d`, all looking at `target` with `up`
/// (see [`Pose::look_at`] for the poles) and the same intrinsics.
#[must_use]
pub fn look_at_rig(
    directions: &[DVec3],
    target: DVec3,
    distance: f64,
    intrinsics: Intrinsics,
    up: DVec3,
) -> Vec<Camera> {
    directions
        .iter()
        .map(|d| {
            Camera::new(
                intrinsics,
                Pose::look_at(target + distance * d.normalize(), target, up),
            )
        })
        .collect()
}

/// The capture rig of a plenoptic file: a camera at each capture position (voxel units, from
/// the `rig_matrix_k` comments), looking at `target` (usually the cloud's centre).
#[must_use]
pub fn capture_rig(
    positions: &[DVec3],
    target: DVec3,
    intrinsics: Intrinsics,
    up: DVec3,
) -> Vec<Camera> {
    positions
        .iter()
        .map(|&p| Camera::new(intrinsics, Pose::look_at(p, target, up)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use glam::DVec2;

    fn nearest_neighbour_angles(dirs: &[DVec3]) -> Vec<f64> {
        dirs.iter()
            .enumerate()
            .map(|(i, a)| {
                dirs.iter()
                    .enumerate()
                    .filter(|&(j, _)| j != i)
                    .map(|(_, b)| a.angle_between(*b))
                    .fold(f64::INFINITY, f64::min)
            })
            .collect()
    }

    #[test]
    fn fibonacci_sphere_is_even() {
        for n in [1, 2, 12, 100, 500] {
            let dirs = fibonacci_sphere(n);
            assert_eq!(dirs.len(), n);
            for d in &dirs {
                assert_relative_eq!(d.length(), 1.0, epsilon = 1e-12);
            }
            if n >= 12 {
                // Balanced: the mean direction is near zero.
                let mean = dirs.iter().sum::<DVec3>() / n as f64;
                assert!(mean.length() < 2.0 / n as f64, "n = {n}: {mean}");
                // Even: nearest-neighbour spacing within a factor 2 across the sphere, and close
                // to the spacing √(4π/n) of an ideal equal-area tiling.
                let nn = nearest_neighbour_angles(&dirs);
                let (lo, hi) = nn.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), &a| {
                    (lo.min(a), hi.max(a))
                });
                let ideal = (4.0 * std::f64::consts::PI / n as f64).sqrt();
                assert!(hi / lo < 2.0, "n = {n}: {lo} .. {hi}");
                assert!(
                    lo > 0.5 * ideal && hi < 1.5 * ideal,
                    "n = {n}: {lo} .. {hi} vs {ideal}"
                );
            }
        }
        // Half of the directions in each hemisphere (equal areas).
        let up = fibonacci_sphere(1000).iter().filter(|d| d.y > 0.0).count();
        assert_eq!(up, 500);
    }

    #[test]
    fn band_respects_elevation_limits() {
        let dirs = fibonacci_band(300, -10.0, 60.0);
        assert_eq!(dirs.len(), 300);
        for d in &dirs {
            let elev = d.y.asin().to_degrees();
            assert!((-10.0..=60.0).contains(&elev), "{elev}");
        }
        // Equal area: the fraction above the equator matches sin 60° / (sin 60° + sin 10°).
        let above = dirs.iter().filter(|d| d.y > 0.0).count() as f64 / 300.0;
        let s60 = 60f64.to_radians().sin();
        let expected = s60 / (s60 + 10f64.to_radians().sin());
        assert!(
            (above - expected).abs() < 1.0 / 300.0 + 1e-12,
            "{above} vs {expected}"
        );
        assert_eq!(
            fibonacci_band(5, 60.0, -10.0),
            fibonacci_band(5, -10.0, 60.0)
        );
    }

    #[test]
    fn rings_are_level_and_evenly_spaced() {
        let dirs = rings(&[
            Ring {
                elevation_deg: 0.0,
                count: 8,
                azimuth_offset_deg: 0.0,
            },
            Ring {
                elevation_deg: 45.0,
                count: 4,
                azimuth_offset_deg: 45.0,
            },
        ]);
        assert_eq!(dirs.len(), 12);
        assert_relative_eq!(dirs[0], DVec3::X, epsilon = 1e-15);
        assert_relative_eq!(dirs[2], DVec3::Z, epsilon = 1e-15);
        for pair in dirs[..8].windows(2) {
            assert_relative_eq!(
                pair[0].angle_between(pair[1]),
                std::f64::consts::FRAC_PI_4,
                epsilon = 1e-12
            );
        }
        for d in &dirs[8..] {
            assert_relative_eq!(d.y, 45f64.to_radians().sin(), epsilon = 1e-15);
        }
        assert_relative_eq!(
            dirs[8],
            DVec3::new(0.5, 0.5f64.sqrt(), 0.5),
            epsilon = 1e-15
        );
    }

    #[test]
    fn framing_fits_the_sphere_with_the_margin() {
        let k = Intrinsics::from_fov_y(640, 480, 30.0);
        let (radius, margin, target) = (512.0, 0.1, DVec3::new(100.0, 200.0, 300.0));
        let d = framing_distance(radius, &k, margin).unwrap();
        for dir in fibonacci_sphere(20) {
            let cam = look_at_rig(&[dir], target, d, k, WORLD_UP)[0];
            // Brute force: the farthest projected point of the sphere from the principal point.
            let centre = DVec2::new(k.cx, k.cy);
            let mut worst = 0.0f64;
            for p in fibonacci_sphere(20_000) {
                if let Some(px) = cam.project(target + radius * p) {
                    worst = worst.max((px - centre).length());
                }
            }
            // The silhouette disc's radius is (1 − margin)·H/2 (H is the narrower side).
            let expected = (1.0 - margin) * 240.0;
            assert!(
                worst <= expected + 1e-6 && worst > expected * 0.995,
                "{worst} vs {expected}"
            );
        }
        let f = framing_focal(radius, d, 640, 480, margin).unwrap();
        assert_relative_eq!(f, k.fy, epsilon = 1e-9);
        assert!(framing_distance(-1.0, &k, 0.1).is_err());
        assert!(framing_distance(1.0, &k, 1.0).is_err());
        assert!(framing_focal(2.0, 1.0, 640, 480, 0.1).is_err());
    }

    #[test]
    fn rigs_look_at_the_target_with_image_up_towards_world_up() {
        let k = Intrinsics::from_fov_y(100, 80, 40.0);
        let target = DVec3::splat(512.0);
        for cam in look_at_rig(&fibonacci_sphere(64), target, 3000.0, k, WORLD_UP) {
            assert_relative_eq!(
                cam.project(target).unwrap(),
                DVec2::new(50.0, 40.0),
                epsilon = 1e-9
            );
            assert_relative_eq!((cam.center() - target).length(), 3000.0, epsilon = 1e-9);
            // World up never points down in the image (it is at most perpendicular at the poles).
            assert!(cam.pose.down().dot(WORLD_UP) <= 1e-12);
        }
        let positions = [
            DVec3::new(-2000.0, 500.0, 1000.0),
            DVec3::new(3000.0, 800.0, -400.0),
        ];
        let rig = capture_rig(&positions, target, k, WORLD_UP);
        for (cam, p) in rig.iter().zip(positions) {
            assert_relative_eq!(cam.center(), p, epsilon = 1e-9);
            assert_relative_eq!(
                cam.project(target).unwrap(),
                DVec2::new(50.0, 40.0),
                epsilon = 1e-9
            );
        }
    }
}
