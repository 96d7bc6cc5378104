//! Where a model's splats sit against the input's surface: the distance of their centres to it,
//! and, of the splats far from it, which lie inside the object and which float in free space.
//!
//! Distance alone does not tell a floater: a trained model fills thin parts of an object (a
//! paper-scale frame's legs) with splats inside its volume, many point spacings from the nearest
//! surface point, hidden behind the surface splats. Measured on such a model (session 32), 83 %
//! of the opacity sat beyond two spacings, three quarters of it inside the object, while the
//! rendered coverage where the references are empty was 10⁻⁵. So a far splat is split three
//! ways: inside (behind the nearest surface point, by that point's outward normal, where the
//! input has normals), reaching the surface (its 3σ ellipsoid holds the nearest surface point),
//! or a floater (neither).

use glam::Vec3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use splat_core::Splats;

use crate::init::SurfaceIndex;

/// How many standard deviations of a splat reach the surface: the extent Inria's rasteriser
/// draws a splat to.
pub const REACH_SIGMAS: f32 = 3.0;

/// Opacity-weighted distance of splat centres to the input surface, and what the far splats
/// are.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SurfaceDistance {
    /// Point spacing of the surface points (file units) used as the unit below.
    pub spacing: f64,
    /// Weighted mean distance (file units).
    pub mean: f64,
    /// Weighted 95th percentile distance (file units).
    pub p95: f64,
    /// The distance beyond which a splat is far: `floater_spacings` × spacing.
    pub threshold: f64,
    /// Number of splats farther than `threshold`.
    #[serde(default)]
    pub far: usize,
    /// Share of the total opacity in splats farther than `threshold`. (Reports written before
    /// session 32 called this share "floaters".)
    #[serde(default)]
    pub far_share: f64,
    /// Whether the surface had normals, so that far splats inside the object could be told apart.
    #[serde(default)]
    pub oriented: bool,
    /// Far splats inside the object: behind the nearest surface point's outward normal.
    #[serde(default)]
    pub interior: usize,
    /// Their share of the total opacity.
    #[serde(default)]
    pub interior_share: f64,
    /// Far splats outside the object (or anywhere, without normals) whose 3σ ellipsoid does not
    /// reach the nearest surface point: floaters.
    pub floaters: usize,
    /// Their share of the total opacity.
    pub floater_share: f64,
}

/// Where one splat sits against the surface.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Placement {
    /// Within the threshold of the surface.
    Near,
    /// Far, inside the object.
    Interior,
    /// Far, outside, its ellipsoid reaching the surface.
    Reaching,
    /// Far, outside, not reaching the surface.
    Floater,
}

/// Measures `splats` against `surface`, splats farther than `floater_spacings` of its spacing
/// judged as the module says; `None` without splats.
#[must_use]
pub fn surface_distance(
    splats: &Splats,
    surface: &SurfaceIndex,
    floater_spacings: f64,
) -> Option<SurfaceDistance> {
    if splats.is_empty() {
        return None;
    }
    let spacing = surface.spacing();
    let threshold = floater_spacings * f64::from(spacing);
    // (distance, opacity, placement) per splat.
    let mut d: Vec<(f64, f64, Placement)> = (0..splats.len())
        .into_par_iter()
        .map(|i| {
            let nearest = surface.nearest(splats.means[i]);
            let distance = f64::from(nearest.distance);
            let placement = if distance <= threshold {
                Placement::Near
            } else {
                far_placement(splats, i, nearest.position, nearest.normal)
            };
            let opacity = f64::from(splat_core::sigmoid(splats.opacity_logits[i]));
            (distance, opacity, placement)
        })
        .collect();
    let count = |p: &dyn Fn(Placement) -> bool| d.iter().filter(|x| p(x.2)).count();
    let far = count(&|p| p != Placement::Near);
    let interior = count(&|p| p == Placement::Interior);
    let floaters = count(&|p| p == Placement::Floater);
    let total: f64 = d.iter().map(|x| x.1).sum();
    // Adding 0.0 turns an empty sum's −0.0 into 0.0.
    let share = |p: &dyn Fn(Placement) -> bool| {
        if total > 0.0 {
            d.iter().filter(|x| p(x.2)).map(|x| x.1).sum::<f64>() / total + 0.0
        } else {
            0.0
        }
    };
    let far_share = share(&|p| p != Placement::Near);
    let interior_share = share(&|p| p == Placement::Interior);
    let floater_share = share(&|p| p == Placement::Floater);
    let (mean, p95) = if total > 0.0 {
        let mean = d.iter().map(|x| x.0 * x.1).sum::<f64>() / total;
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut acc = 0.0;
        let mut p95 = d.last().map_or(0.0, |x| x.0);
        for (dist, w, _) in &d {
            acc += w;
            if acc >= 0.95 * total {
                p95 = *dist;
                break;
            }
        }
        (mean, p95)
    } else {
        (0.0, 0.0)
    };
    Some(SurfaceDistance {
        spacing: f64::from(spacing),
        mean,
        p95,
        threshold,
        far,
        far_share,
        oriented: surface.is_oriented(),
        interior,
        interior_share,
        floaters,
        floater_share,
    })
}

/// Where far splat `i` sits, given its nearest surface point and that point's normal.
fn far_placement(splats: &Splats, i: usize, point: Vec3, normal: Option<Vec3>) -> Placement {
    let centre = splats.means[i];
    let to_surface = point - centre;
    // The centre is behind the surface when the surface point lies in front of it along the
    // outward normal.
    if normal.is_some_and(|n| to_surface.dot(n) > 0.0) {
        return Placement::Interior;
    }
    if mahalanobis(splats, i, to_surface) <= REACH_SIGMAS {
        Placement::Reaching
    } else {
        Placement::Floater
    }
}

/// The length of `offset` in the standard deviations of splat `i` (infinite along an axis of
/// zero scale, unless the offset has no component there).
fn mahalanobis(splats: &Splats, i: usize, offset: Vec3) -> f32 {
    // The offset in the splat's own axes (the inverse rotation), divided by its scales.
    let local = splats.rotation(i).inverse() * offset;
    let scales = splats.log_scales[i].exp();
    let per_axis = local / scales;
    // 0 / 0 (no offset along a flat axis) counts as 0.
    let per_axis = Vec3::select(local.cmpeq(Vec3::ZERO), Vec3::ZERO, per_axis);
    per_axis.length()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A splat at `centre` with `scales`, rotated by `rotation` (w, x, y, z), of opacity `o`.
    fn push(s: &mut Splats, centre: Vec3, scales: Vec3, rotation: [f32; 4], o: f32) {
        s.push(
            centre,
            scales.ln(),
            rotation,
            splat_core::logit(o),
            &[[0.0; 3]],
        );
    }

    #[test]
    fn surface_distance_weights_by_opacity() {
        // Surface: points on the x axis at spacing 1; splats at distance 0, 0.5 and 10.
        let surface: Vec<Vec3> = (0..100).map(|i| Vec3::new(i as f32, 0.0, 0.0)).collect();
        let mut s = Splats::new(0);
        for y in [0.0f32, 0.5, 10.0] {
            push(
                &mut s,
                Vec3::new(50.0, y, 0.0),
                Vec3::splat(1.0),
                [1.0, 0.0, 0.0, 0.0],
                0.5,
            );
        }
        let surface = SurfaceIndex::new(&surface, None).unwrap();
        assert_eq!(surface.spacing(), 1.0);
        let d = surface_distance(&s, &surface, 2.0).unwrap();
        assert!((d.mean - 10.5 / 3.0).abs() < 1e-5, "{}", d.mean);
        assert!((d.far_share - 1.0 / 3.0).abs() < 1e-9);
        assert_eq!(d.far, 1);
        // σ = 1: the surface 10σ away is out of reach, and without normals nothing is inside.
        assert!((d.floater_share - 1.0 / 3.0).abs() < 1e-9);
        assert_eq!((d.floaters, d.interior, d.oriented), (1, 0, false));
        assert!((d.p95 - 10.0).abs() < 1e-5);
    }

    #[test]
    fn far_splats_are_inside_reaching_or_floating() {
        // The plane z = 0 sampled at spacing 1 over [0, 40]², outward normal +z.
        let points: Vec<Vec3> = (0..41 * 41)
            .map(|k| Vec3::new((k % 41) as f32, (k / 41) as f32, 0.0))
            .collect();
        let up = vec![Vec3::Z; points.len()];
        let oriented = SurfaceIndex::new(&points, Some(&up)).unwrap();
        let bare = SurfaceIndex::new(&points, None).unwrap();
        // A quarter turn about x: the splat's own y axis points along world z.
        let (h, id) = (std::f32::consts::FRAC_1_SQRT_2, [1.0, 0.0, 0.0, 0.0]);
        let about_x = [h, h, 0.0, 0.0];
        let mut s = Splats::new(0);
        let cases = [
            // (centre, scales, rotation, opacity): what it is on an oriented surface
            (
                Vec3::new(20.0, 20.0, 0.3),
                Vec3::new(2.0, 2.0, 0.1),
                id,
                0.9,
            ), // near
            (Vec3::new(10.0, 10.0, 6.0), Vec3::splat(1.0), id, 0.8), // floater: 6σ
            (
                Vec3::new(10.0, 30.0, 6.0),
                Vec3::new(1.0, 1.0, 2.5),
                id,
                0.6,
            ), // reaching: 2.4σ
            (
                Vec3::new(30.0, 10.0, 6.0),
                Vec3::new(1.0, 2.5, 1.0),
                id,
                0.5,
            ), // floater: 6σ in z
            (
                Vec3::new(30.0, 30.0, 6.0),
                Vec3::new(1.0, 2.5, 1.0),
                about_x,
                0.4,
            ), // reaching
            (Vec3::new(20.0, 5.0, -6.0), Vec3::splat(1.0), id, 0.3), // inside
        ];
        for (c, sc, r, o) in cases {
            push(&mut s, c, sc, r, o);
        }
        let total: f64 = cases.iter().map(|c| f64::from(c.3)).sum();
        let share = |o: &[f32]| o.iter().map(|&o| f64::from(o)).sum::<f64>() / total;
        let close = |a: f64, b: f64| (a - b).abs() < 1e-6;

        let d = surface_distance(&s, &oriented, 2.0).unwrap();
        assert!(d.oriented);
        assert_eq!((d.far, d.interior, d.floaters), (5, 1, 2));
        assert!(close(d.far_share, share(&[0.8, 0.6, 0.5, 0.4, 0.3])));
        assert!(close(d.interior_share, share(&[0.3])));
        assert!(
            close(d.floater_share, share(&[0.8, 0.5])),
            "{}",
            d.floater_share
        );

        // Without normals the splat below the plane is judged by its reach: 6σ, a floater.
        let d = surface_distance(&s, &bare, 2.0).unwrap();
        assert!(!d.oriented);
        assert_eq!((d.far, d.interior, d.floaters), (5, 0, 3));
        assert!(close(d.floater_share, share(&[0.8, 0.5, 0.3])));
    }

    #[test]
    fn mahalanobis_is_the_offset_in_standard_deviations() {
        let mut s = Splats::new(0);
        // Scales 1, 2, 4 along a rotation of 90° about z (its x axis along world y).
        let h = std::f32::consts::FRAC_1_SQRT_2;
        push(
            &mut s,
            Vec3::ZERO,
            Vec3::new(1.0, 2.0, 4.0),
            [h, 0.0, 0.0, h],
            0.5,
        );
        let m = |v: Vec3| mahalanobis(&s, 0, v);
        assert!((m(Vec3::new(0.0, 3.0, 0.0)) - 3.0).abs() < 1e-5); // along its x: σ 1
        assert!((m(Vec3::new(3.0, 0.0, 0.0)) - 1.5).abs() < 1e-5); // along its y: σ 2
        assert!((m(Vec3::new(0.0, 0.0, 4.0)) - 1.0).abs() < 1e-5); // along its z: σ 4
        let diag = Vec3::new(2.0, 1.0, 4.0);
        assert!((m(diag) - (1.0f32 + 1.0 + 1.0).sqrt()).abs() < 1e-5);
        // A flat axis: infinitely far off it, no distance along it.
        let mut flat = Splats::new(0);
        push(
            &mut flat,
            Vec3::ZERO,
            Vec3::new(1.0, 1.0, 0.0),
            [1.0, 0.0, 0.0, 0.0],
            0.5,
        );
        assert_eq!(mahalanobis(&flat, 0, Vec3::new(1.0, 0.0, 0.0)), 1.0);
        assert_eq!(
            mahalanobis(&flat, 0, Vec3::new(0.0, 0.0, 1.0)),
            f32::INFINITY
        );
    }
}
