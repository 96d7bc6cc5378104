//! Warm start for a sequence: a frame's fresh surface splats take the corrections that training
//! made to the previous frame's splats.
//!
//! A frame's surface init is already right about most things: place, orientation and size from
//! its own surface, colour from its own plenoptic samples. What it cannot know is what training
//! then changed: the opacity, size and tilt that close holes and soften silhouettes, and the
//! colour corrections for how splats blend. Those depend on the local shape, not on where exactly
//! the object is, so they carry across a frame's motion: each fresh splat adds the correction
//! (trained − initial) of the previous frame's splat nearest to it. Carrying the trained values
//! themselves would instead paste the previous frame's colours onto wherever the object moved.

use glam::Vec3;
use splat_core::{Splats, num_sh_coeffs};
// The k-d tree is splat-train's, as for the kNN scales and point spacing.
use splat_train::init::PointIndex;

/// What a warm start carried, for the report.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CarriedTraining {
    /// Splats that took a previous splat's corrections.
    pub splats: usize,
    /// Median distance from a fresh splat to the previous splat it took them from, after the
    /// rigid motion.
    pub median_distance: f32,
    /// The rigid motion found between the frames (ICP), taken out before pairing splats.
    pub motion: RigidMotion,
}

/// Why the previous frame's corrections cannot be carried.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WarmStartError {
    /// The previous frame's initial and trained splats do not correspond one to one (its
    /// training added or removed splats, or its initialisation is not the one reproduced).
    #[error(
        "the previous frame's trained model has {trained} splats of SH degree {trained_degree}, \
         its initialisation {initial} of degree {initial_degree}: they must correspond one to \
         one (no densification of surface splats)"
    )]
    Mismatch {
        /// Splats of the trained model.
        trained: usize,
        /// Its SH degree.
        trained_degree: u32,
        /// Splats of the reproduced initialisation.
        initial: usize,
        /// Its SH degree.
        initial_degree: u32,
    },
}

/// Adds to every splat of `fresh` the training corrections of the nearest splat of the previous
/// frame: `previous_trained` minus `previous_initial` (the same splats before training) in SH
/// coefficients, opacity logit and log-scales, and the rotation from initial to trained in the
/// splat's own frame. SH bands beyond the previous degree get no correction. `Ok(None)` when the
/// previous frame has no splats.
pub fn carry_training(
    fresh: &mut Splats,
    previous_initial: &Splats,
    previous_trained: &Splats,
) -> Result<Option<CarriedTraining>, WarmStartError> {
    if previous_initial.len() != previous_trained.len()
        || previous_initial.sh_degree != previous_trained.sh_degree
    {
        return Err(WarmStartError::Mismatch {
            trained: previous_trained.len(),
            trained_degree: previous_trained.sh_degree,
            initial: previous_initial.len(),
            initial_degree: previous_initial.sh_degree,
        });
    }
    if previous_initial.is_empty() || fresh.is_empty() {
        return Ok(None);
    }
    // Corresponding splats by nearest neighbour after the rigid motion between the frames is
    // taken out, so that a turning or walking subject does not pair splats across its parts.
    let motion = rigid_motion(&previous_initial.means, &fresh.means);
    let moved: Vec<Vec3> = previous_initial
        .means
        .iter()
        .map(|&p| motion.apply(p))
        .collect();
    let Some(index) = PointIndex::new(&moved) else {
        return Ok(None);
    };
    let (n_new, n_old) = (
        num_sh_coeffs(fresh.sh_degree),
        num_sh_coeffs(previous_initial.sh_degree),
    );
    let shared = n_new.min(n_old);
    let mut distances = Vec::with_capacity(fresh.len());
    for i in 0..fresh.len() {
        let p: Vec3 = fresh.means[i];
        let Some(&j) = index.nearest_n(p, 1).first() else {
            continue;
        };
        distances.push(moved[j].distance(p));
        fresh.opacity_logits[i] +=
            previous_trained.opacity_logits[j] - previous_initial.opacity_logits[j];
        fresh.log_scales[i] += previous_trained.log_scales[j] - previous_initial.log_scales[j];
        // The turn from initial to trained, in the splat's own frame: q_init⁻¹ q_trained.
        let local = previous_initial.rotation(j).inverse() * previous_trained.rotation(j);
        let q = (fresh.rotation(i) * local).normalize();
        fresh.rotations[i] = [q.w, q.x, q.y, q.z];
        for k in 0..shared {
            let (t, s) = (
                previous_trained.sh[j * n_old + k],
                previous_initial.sh[j * n_old + k],
            );
            let c = &mut fresh.sh[i * n_new + k];
            for ch in 0..3 {
                c[ch] += t[ch] - s[ch];
            }
        }
    }
    distances.sort_by(f32::total_cmp);
    Ok(Some(CarriedTraining {
        splats: distances.len(),
        median_distance: distances.get(distances.len() / 2).copied().unwrap_or(0.0),
        motion,
    }))
}

/// A rigid motion x ↦ R x + t.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidMotion {
    /// R.
    pub rotation: glam::DQuat,
    /// t.
    pub translation: glam::DVec3,
}

impl RigidMotion {
    /// No motion.
    pub const IDENTITY: Self = Self {
        rotation: glam::DQuat::IDENTITY,
        translation: glam::DVec3::ZERO,
    };

    /// R p + t.
    #[must_use]
    pub fn apply(&self, p: Vec3) -> Vec3 {
        (self.rotation * p.as_dvec3() + self.translation).as_vec3()
    }

    /// The angle of R, degrees.
    #[must_use]
    pub fn angle_deg(&self) -> f64 {
        self.rotation.to_axis_angle().1.to_degrees()
    }
}

/// Pairs (of at most this many evenly strided points) an ICP iteration aligns.
const ICP_SAMPLES: usize = 20_000;
/// ICP iterations at most.
const ICP_ITERATIONS: usize = 30;

/// The rigid motion taking the points `from` onto the surface sampled by `to`: point-to-point
/// ICP (Besl & McKay 1992) from the identity, each step the least-squares rotation of the
/// nearest-neighbour pairs (Kabsch, by SVD), pairs beyond three times the median distance (or
/// twice the mean, if more) left out. Kept only when it brings the nearest 90 % of the points
/// closer on average than no motion does; the identity otherwise.
#[must_use]
pub fn rigid_motion(from: &[Vec3], to: &[Vec3]) -> RigidMotion {
    let Some(index) = PointIndex::new(to) else {
        return RigidMotion::IDENTITY;
    };
    let stride = from.len().div_ceil(ICP_SAMPLES).max(1);
    let sample: Vec<Vec3> = from.iter().step_by(stride).copied().collect();
    // Mean distance over the nearest 90 %: on a voxel grid most points of a slowly moving
    // subject land on the very same voxels, so a median would say 0 and hide the moved rest.
    let trimmed_mean = |m: &RigidMotion| -> f64 {
        let mut d: Vec<f64> = sample
            .iter()
            .map(|&p| f64::from(index.nearest_distance(m.apply(p))))
            .collect();
        d.sort_by(f64::total_cmp);
        let kept = &d[..(d.len() * 9).div_ceil(10)];
        kept.iter().sum::<f64>() / kept.len() as f64
    };
    let mut motion = RigidMotion::IDENTITY;
    for _ in 0..ICP_ITERATIONS {
        let pairs: Vec<(glam::DVec3, glam::DVec3, f64)> = sample
            .iter()
            .filter_map(|&p| {
                let q = motion.apply(p);
                let j = *index.nearest_n(q, 1).first()?;
                Some((p.as_dvec3(), to[j].as_dvec3(), f64::from(q.distance(to[j]))))
            })
            .collect();
        let mut d: Vec<f64> = pairs.iter().map(|x| x.2).collect();
        d.sort_by(f64::total_cmp);
        let mean = d.iter().sum::<f64>() / d.len() as f64;
        let cut = (3.0 * d[d.len() / 2]).max(2.0 * mean) + 1e-12;
        let kept: Vec<(glam::DVec3, glam::DVec3)> = pairs
            .iter()
            .filter(|x| x.2 <= cut)
            .map(|x| (x.0, x.1))
            .collect();
        let Some(next) = kabsch(&kept) else {
            break;
        };
        let change = next.rotation.angle_between(motion.rotation)
            + (next.translation - motion.translation).length() / cut.max(1e-12);
        motion = next;
        if change < 1e-6 {
            break;
        }
    }
    if trimmed_mean(&motion) < trimmed_mean(&RigidMotion::IDENTITY) {
        motion
    } else {
        RigidMotion::IDENTITY
    }
}

/// The rotation and translation minimising Σ |R a + t − b|² over the pairs (a, b) (Kabsch
/// 1976: SVD of the cross-covariance, the sign fixed so R is a rotation); `None` for fewer than
/// three pairs.
fn kabsch(pairs: &[(glam::DVec3, glam::DVec3)]) -> Option<RigidMotion> {
    if pairs.len() < 3 {
        return None;
    }
    let n = pairs.len() as f64;
    let ca = pairs.iter().map(|p| p.0).sum::<glam::DVec3>() / n;
    let cb = pairs.iter().map(|p| p.1).sum::<glam::DVec3>() / n;
    let mut h = nalgebra::Matrix3::<f64>::zeros();
    for (a, b) in pairs {
        let (a, b) = (*a - ca, *b - cb);
        h += nalgebra::Vector3::new(b.x, b.y, b.z) * nalgebra::RowVector3::new(a.x, a.y, a.z);
    }
    let svd = h.svd(true, true);
    let (u, v_t) = (svd.u?, svd.v_t?);
    let mut d = nalgebra::Matrix3::<f64>::identity();
    if (u * v_t).determinant() < 0.0 {
        d[(2, 2)] = -1.0;
    }
    let r = u * d * v_t;
    let m = glam::DMat3::from_cols_array(&[
        r[(0, 0)],
        r[(1, 0)],
        r[(2, 0)],
        r[(0, 1)],
        r[(1, 1)],
        r[(2, 1)],
        r[(0, 2)],
        r[(1, 2)],
        r[(2, 2)],
    ]);
    let rotation = glam::DQuat::from_mat3(&m).normalize();
    Some(RigidMotion {
        rotation,
        translation: cb - rotation * ca,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    /// `q` as stored in [`Splats::rotations`] (w, x, y, z).
    fn stored(q: Quat) -> [f32; 4] {
        [q.w, q.x, q.y, q.z]
    }

    fn splats(points: &[Vec3], colours: &[[f32; 3]], opacity: f32, degree: u32) -> Splats {
        let scales = vec![Vec3::splat(0.1); points.len()];
        let normals: Vec<Vec3> = points.iter().map(|_| Vec3::Z).collect();
        Splats::from_points(points, colours, &scales, Some(&normals), opacity, degree).unwrap()
    }

    /// The previous frame: two splats at x = 0 and x = 10; trained = initial plus known
    /// corrections (the second splat's larger).
    fn previous() -> (Splats, Splats) {
        let initial = splats(
            &[Vec3::ZERO, Vec3::new(10.0, 0.0, 0.0)],
            &[[0.9, 0.1, 0.1], [0.1, 0.1, 0.9]],
            0.5,
            1,
        );
        let mut trained = initial.clone();
        for j in 0..2 {
            let f = (j + 1) as f32;
            trained.opacity_logits[j] += 0.5 * f;
            trained.log_scales[j] += Vec3::new(0.1, -0.2, 0.3) * f;
            trained.rotations[j] = stored(initial.rotation(j) * Quat::from_rotation_x(0.1 * f));
            for k in 0..4 {
                trained.sh[j * 4 + k][0] += 0.01 * f * (k + 1) as f32;
            }
        }
        (initial, trained)
    }

    #[test]
    fn each_splat_adds_the_nearest_previous_correction() {
        let (initial, trained) = previous();
        let mut fresh = splats(
            &[
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(9.0, 1.0, 0.0),
                Vec3::new(4.0, 0.0, 0.0),
            ],
            &[[0.5; 3]; 3],
            0.1,
            2,
        );
        let before = fresh.clone();
        let carried = carry_training(&mut fresh, &initial, &trained)
            .unwrap()
            .unwrap();
        assert_eq!(carried.splats, 3);
        // Distances 1, √2 and 4: the median is √2.
        assert!((carried.median_distance - 2f32.sqrt()).abs() < 1e-6);
        for (i, j) in [(0usize, 0usize), (1, 1), (2, 0)] {
            let f = (j + 1) as f32;
            assert!((fresh.opacity_logits[i] - before.opacity_logits[i] - 0.5 * f).abs() < 1e-6);
            let ds = fresh.log_scales[i] - before.log_scales[i];
            assert!((ds - Vec3::new(0.1, -0.2, 0.3) * f).length() < 1e-6);
            let expected = before.rotation(i) * Quat::from_rotation_x(0.1 * f);
            assert!(
                fresh.rotation(i).dot(expected).abs() > 1.0 - 1e-6,
                "splat {i}"
            );
            for k in 0..9 {
                let d = fresh.sh[i * 9 + k][0] - before.sh[i * 9 + k][0];
                let want = if k < 4 {
                    0.01 * f * (k + 1) as f32
                } else {
                    0.0
                };
                assert!((d - want).abs() < 1e-6, "splat {i}, coefficient {k}: {d}");
                assert_eq!(fresh.sh[i * 9 + k][1], before.sh[i * 9 + k][1]);
            }
        }
        // Geometry is the fresh surface's own.
        assert_eq!(fresh.means, before.means);
    }

    #[test]
    fn the_same_frame_warm_started_from_itself_is_its_trained_model() {
        let (initial, trained) = previous();
        let mut fresh = initial.clone();
        carry_training(&mut fresh, &initial, &trained).unwrap();
        for j in 0..2 {
            assert!((fresh.opacity_logits[j] - trained.opacity_logits[j]).abs() < 1e-6);
            assert!((fresh.log_scales[j] - trained.log_scales[j]).length() < 1e-6);
            assert!(fresh.rotation(j).dot(trained.rotation(j)).abs() > 1.0 - 1e-6);
        }
        for (a, b) in fresh.sh.iter().zip(&trained.sh) {
            assert!((a[0] - b[0]).abs() < 1e-6);
        }
    }

    #[test]
    fn icp_recovers_a_known_rigid_motion_of_a_curved_surface() {
        // A bumpy ellipsoid (a closed surface, as a captured subject is) of 6000 points, turned
        // 4° about a tilted axis and shifted by about a tenth of its smallest radius.
        let golden = std::f32::consts::PI * (3.0 - 5f32.sqrt());
        let sheet: Vec<Vec3> = (0..6000)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / 6000.0;
                let r = (1.0 - z * z).sqrt();
                let (s, c) = (golden * i as f32).sin_cos();
                let d = Vec3::new(r * c, r * s, z);
                let bump = 1.0 + 0.15 * (5.0 * d.x).sin() * (4.0 * d.y).cos();
                d * Vec3::new(20.0, 12.0, 8.0) * bump
            })
            .collect();
        let truth = RigidMotion {
            rotation: glam::DQuat::from_axis_angle(
                glam::DVec3::new(0.3, 1.0, 0.2).normalize(),
                4f64.to_radians(),
            ),
            translation: glam::DVec3::new(0.6, -0.4, 0.3),
        };
        let moved: Vec<Vec3> = sheet.iter().map(|&p| truth.apply(p)).collect();
        let found = rigid_motion(&sheet, &moved);
        assert!(
            found.rotation.angle_between(truth.rotation) < 1e-3,
            "{found:?}"
        );
        assert!(
            (found.translation - truth.translation).length() < 0.05,
            "{found:?}"
        );
        assert!((found.angle_deg() - 4.0).abs() < 0.05);
        // Kabsch alone on exact pairs is exact.
        let pairs: Vec<_> = sheet
            .iter()
            .zip(&moved)
            .map(|(a, b)| (a.as_dvec3(), b.as_dvec3()))
            .collect();
        let exact = kabsch(&pairs).unwrap();
        assert!(exact.rotation.angle_between(truth.rotation) < 1e-6);
        assert!((exact.translation - truth.translation).length() < 1e-4);
        // The same cloud: no motion.
        assert_eq!(rigid_motion(&sheet, &sheet), RigidMotion::IDENTITY);
    }

    #[test]
    fn corrections_follow_the_motion() {
        // A wavy row of 40 splats with corrections 0, 1, …, 39, moved 2.5 along z: more than
        // the 1-unit spacing, so plain nearest neighbours would pair splats across the row; the
        // motion taken out, each fresh splat takes its own predecessor's correction.
        let xs: Vec<Vec3> = (0..40)
            .map(|i| Vec3::new(i as f32, (i as f32 * 0.7).sin() * 3.0, 0.0))
            .collect();
        let initial = splats(&xs, &vec![[0.5; 3]; 40], 0.5, 0);
        let mut trained = initial.clone();
        for (j, o) in trained.opacity_logits.iter_mut().enumerate() {
            *o += j as f32;
        }
        let shift = Vec3::new(0.0, 0.0, 2.5);
        let moved: Vec<Vec3> = xs.iter().map(|&p| p + shift).collect();
        let mut fresh = splats(&moved, &vec![[0.5; 3]; 40], 0.5, 0);
        let before = fresh.opacity_logits.clone();
        let carried = carry_training(&mut fresh, &initial, &trained)
            .unwrap()
            .unwrap();
        assert!((carried.motion.translation.as_vec3() - shift).length() < 1e-3);
        for (j, (after, before)) in fresh.opacity_logits.iter().zip(&before).enumerate() {
            assert!((after - before - j as f32).abs() < 1e-4, "{j}");
        }
    }

    #[test]
    fn mismatched_previous_models_are_refused() {
        let (initial, mut trained) = previous();
        trained.means.pop();
        trained.log_scales.pop();
        trained.rotations.pop();
        trained.opacity_logits.pop();
        trained.sh.truncate(4);
        let mut fresh = initial.clone();
        let e = carry_training(&mut fresh, &initial, &trained).unwrap_err();
        assert!(e.to_string().contains("1 splats"), "{e}");
        let empty = splats(&[], &[], 0.5, 1);
        assert_eq!(carry_training(&mut fresh, &empty, &empty), Ok(None));
    }
}
