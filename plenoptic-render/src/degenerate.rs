//! Input that cannot make a model is refused before anything is trained: too few distinct points,
//! no extent, a mesh without area, views in which nothing is visible. Training on such input
//! "succeeds" with a model of nothing and metrics that look perfect (an empty render matches an
//! empty reference: PSNR ∞, SSIM 1), so the run stops with a message instead.
//! The thresholds and their reasons are listed in `docs/pipeline.md` ("Degenerate input").

use std::borrow::Cow;
use std::collections::HashSet;
use std::path::{Path, PathBuf};

use glam::{DVec3, Vec3};
use plenoptic_io::Model;

/// Fewest distinct points a cloud needs: each splat is sized from its 3 nearest neighbours
/// (`splat_train::init::scales_from_knn`), which needs 3 other distinct points.
pub const MIN_DISTINCT_POINTS: usize = 4;

/// The input's extent (largest side of its bounding box) must span at least this many f32 steps
/// (ε = 2⁻²³ relative) of its largest coordinate: below it the positions, stored and projected
/// as f32, take only a handful of distinct values per axis.
pub const MIN_EXTENT_STEPS: f64 = 16.0;

/// Smallest extent accepted in any units: √(f32::MIN_POSITIVE) ≈ 1.1e-19, below which squared
/// lengths (covariances, distances) underflow f32.
pub const MIN_EXTENT: f64 = 1.084_202_172_485_504_4e-19;

/// A mesh's total triangle area must exceed this share of its extent squared (the area of a
/// square one millionth of the object's size on a side); below it every face is a sliver or a
/// point, and the renderer draws nothing.
pub const MIN_RELATIVE_AREA: f64 = 1e-12;

/// Largest share of views allowed to see nothing (no pixel with coverage > 0). A few empty views
/// are harmless (they teach the background); a majority means the object is too small or too
/// thin for the cameras to see, and a model trained on them learns to be empty.
pub const MAX_EMPTY_VIEW_SHARE: f64 = 0.5;

/// Why an input cannot make a model.
#[derive(Debug, thiserror::Error)]
pub enum DegenerateError {
    /// All points (nearly) coincide.
    #[error(
        "{}: the input has no extent: its {points} point(s) lie within {extent:e} of each other around ({}, {}, {}), \
         below the {min:e} needed (16 f32 steps of its largest coordinate); nothing can be framed or rendered. \
         Coordinates are read as 32-bit floats, so a file holding an object much smaller than its distance \
         from the origin (geo-referenced coordinates in `double`) loses it: subtract the centre first",
        path.display(), center[0], center[1], center[2]
    )]
    NoExtent {
        /// The input file.
        path: PathBuf,
        /// Points considered (a cloud's points, a mesh's referenced vertices).
        points: usize,
        /// Largest side of their bounding box.
        extent: f64,
        /// The smallest extent accepted for these coordinates.
        min: f64,
        /// Centre of the bounding box.
        center: [f64; 3],
    },
    /// A cloud with fewer than [`MIN_DISTINCT_POINTS`] distinct points.
    #[error(
        "{}: only {distinct} distinct point(s) among {points}; a model needs at least {MIN_DISTINCT_POINTS} \
         (each splat is sized from its 3 nearest neighbours)",
        path.display()
    )]
    TooFewPoints {
        /// The input file.
        path: PathBuf,
        /// Distinct positions found.
        distinct: usize,
        /// Points in the file.
        points: usize,
    },
    /// A mesh whose faces all have (nearly) zero area.
    #[error(
        "{}: all {triangles} triangle(s) have zero area (total {area:e}, below {min:e} = 1e-12 × extent²); \
         a mesh without area renders nothing",
        path.display()
    )]
    NoArea {
        /// The input file.
        path: PathBuf,
        /// Number of triangles.
        triangles: usize,
        /// Their total area.
        area: f64,
        /// The smallest total area accepted.
        min: f64,
    },
    /// Most views of the rig see nothing.
    #[error(
        "{}: nothing is visible in {empty} of the {total} {kind} views ({names}); more than half are empty, \
         so the object is too small or too thin for the cameras, or its points are drawn at a size \
         that hides them (check the point size, `views --point-size` or `[renderer] point_size`, \
         or raise the resolution)",
        path.display()
    )]
    NothingVisible {
        /// The input file.
        path: PathBuf,
        /// `training` or `held-out`.
        kind: &'static str,
        /// Views without a covered pixel.
        empty: usize,
        /// All views.
        total: usize,
        /// The first empty views' names.
        names: String,
    },
}

/// The points whose spread matters: a cloud's points, or the vertices a mesh's triangles use.
/// The corners of the box around `points`, in f64 (infinite for none): the one fold of
/// [`check_model`], [`rig_doubt`] and the rig's bounding sphere.
pub(crate) fn bounds(points: &[Vec3]) -> (DVec3, DVec3) {
    points
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.as_dvec3()), hi.max(p.as_dvec3()))
        })
}

fn used_points(model: &Model) -> Cow<'_, [Vec3]> {
    match model {
        Model::Cloud(c) => Cow::Borrowed(&c.positions),
        Model::Mesh(m) => {
            let mut used = vec![false; m.positions.len()];
            for &v in m.triangles.iter().flatten() {
                if let Some(u) = used.get_mut(v as usize) {
                    *u = true;
                }
            }
            Cow::Owned(
                m.positions
                    .iter()
                    .zip(used)
                    .filter_map(|(p, u)| u.then_some(*p))
                    .collect(),
            )
        }
    }
}

/// Refuses a model with no extent, a cloud with fewer than [`MIN_DISTINCT_POINTS`] distinct
/// points, or a mesh without area. `path` names the input in the message.
pub fn check_model(path: &Path, model: &Model) -> Result<(), DegenerateError> {
    let points = used_points(model);
    if points.is_empty() {
        // The caller reports an empty input with its own message.
        return Ok(());
    }
    let (lo, hi) = bounds(&points);
    let extent = (hi - lo).max_element();
    let largest = lo.abs().max(hi.abs()).max_element();
    let min = (MIN_EXTENT_STEPS * f64::from(f32::EPSILON) * largest).max(MIN_EXTENT);
    // The readers refuse non-finite positions, so neither side is NaN.
    if extent < min {
        return Err(DegenerateError::NoExtent {
            path: path.to_path_buf(),
            points: points.len(),
            extent,
            min,
            center: (0.5 * (lo + hi)).to_array(),
        });
    }
    match model {
        Model::Cloud(c) => {
            let distinct = count_distinct(&c.positions, MIN_DISTINCT_POINTS);
            if distinct < MIN_DISTINCT_POINTS {
                return Err(DegenerateError::TooFewPoints {
                    path: path.to_path_buf(),
                    distinct,
                    points: c.len(),
                });
            }
        }
        Model::Mesh(m) => {
            let area: f64 = m
                .triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|v| m.positions[v as usize].as_dvec3());
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum();
            let min = MIN_RELATIVE_AREA * extent * extent;
            if area <= min {
                return Err(DegenerateError::NoArea {
                    path: path.to_path_buf(),
                    triangles: m.triangles.len(),
                    area,
                    min,
                });
            }
        }
    }
    Ok(())
}

/// Distinct positions among `points`, counted up to `enough` (−0 and +0 are the same).
fn count_distinct(points: &[Vec3], enough: usize) -> usize {
    let mut seen = HashSet::with_capacity(enough);
    for p in points {
        seen.insert((*p + Vec3::ZERO).to_array().map(f32::to_bits));
        if seen.len() >= enough {
            break;
        }
    }
    seen.len()
}

/// Refuses a set of views of which more than [`MAX_EMPTY_VIEW_SHARE`] have no pixel with
/// coverage above 0. `coverage[i]` is view i's alpha, `name(i)` its name for the message.
pub fn check_views<'a>(
    path: &Path,
    kind: &'static str,
    coverage: impl ExactSizeIterator<Item = &'a [f32]>,
    name: impl Fn(usize) -> String,
) -> Result<(), DegenerateError> {
    let covered: Vec<bool> = coverage
        .map(|alpha| alpha.iter().any(|&a| a > 0.0))
        .collect();
    check_coverage(path, kind, &covered, name)
}

/// [`check_views`] of views already reduced to whether any pixel of each is covered
/// (`covered[i]`), for callers that do not keep the images.
pub fn check_coverage(
    path: &Path,
    kind: &'static str,
    covered: &[bool],
    name: impl Fn(usize) -> String,
) -> Result<(), DegenerateError> {
    let total = covered.len();
    let empty: Vec<usize> = covered
        .iter()
        .enumerate()
        .filter(|(_, covered)| !**covered)
        .map(|(i, _)| i)
        .collect();
    if total == 0 || empty.len() as f64 <= MAX_EMPTY_VIEW_SHARE * total as f64 {
        return Ok(());
    }
    let mut names: Vec<String> = empty.iter().take(3).map(|&i| name(i)).collect();
    if empty.len() > 3 {
        names.push("…".into());
    }
    Err(DegenerateError::NothingVisible {
        path: path.to_path_buf(),
        kind,
        empty: empty.len(),
        total,
        names: names.join(", "),
    })
}

/// Narrowest spread of a capture rig, seen from the input's centre, that is taken as a rig
/// around the object: the half-angle (degrees) of the cone from that centre holding every
/// capture camera. A capture rig surrounds or at least faces its subject from several sides;
/// one whose cameras all lie within a few degrees of one direction is a rig in another frame
/// than the points (moved, scaled or in other units), and the view colours then come from those
/// few directions alone.
pub const MIN_RIG_SPREAD_DEGREES: f64 = 10.0;

/// Why a plenoptic input's capture cameras look misplaced against its points. Not an error: the
/// model trains, but on view colours that do not vary as the capture did.
#[derive(Debug, Clone, PartialEq)]
pub enum RigDoubt {
    /// Every camera stands within `half_angle_degrees` (under [`MIN_RIG_SPREAD_DEGREES`]) of one
    /// direction from the points' centre, a median `distance_radii` radii of the points' bounding
    /// sphere away.
    OneDirection {
        /// Capture cameras.
        cameras: usize,
        /// Half-angle of the narrowest cone round their mean direction that holds them all.
        half_angle_degrees: f64,
        /// Median distance from the points' centre, in radii of their bounding sphere.
        distance_radii: f64,
    },
    /// More than half the cameras stand inside the points' bounding box.
    Inside {
        /// Cameras inside the box.
        inside: usize,
        /// Capture cameras.
        cameras: usize,
    },
}

impl std::fmt::Display for RigDoubt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::OneDirection {
                cameras,
                half_angle_degrees,
                distance_radii,
            } => write!(
                f,
                "all {cameras} capture cameras stand within {half_angle_degrees:.2}° of one \
                 direction from the points, {distance_radii:.3e} radii away, so every point's view \
                 colour comes from about one side"
            ),
            Self::Inside { inside, cameras } => write!(
                f,
                "{inside} of the {cameras} capture cameras stand inside the points' bounding box"
            ),
        }?;
        write!(
            f,
            "; the rig_matrix comments are read in the frame of the points (voxel units after \
             frame_to_world_scale and frame_to_world_translation): check that the rig was moved \
             and scaled with the points"
        )
    }
}

/// Whether a plenoptic input's capture rig looks misplaced against its points (see
/// [`RigDoubt`]); `None` for plain inputs, rigs of fewer than three cameras and rigs that look
/// right.
#[must_use]
pub fn rig_doubt(model: &Model) -> Option<RigDoubt> {
    let cameras = match model {
        Model::Cloud(c) => &c.cameras,
        Model::Mesh(m) => &m.cameras,
    };
    if cameras.len() < 3 {
        return None;
    }
    let points = used_points(model);
    let (lo, hi) = bounds(&points);
    let radius = 0.5 * (hi - lo).length();
    if points.is_empty() || radius <= 0.0 {
        return None;
    }
    let centre = 0.5 * (lo + hi);
    let inside = cameras
        .iter()
        .filter(|c| c.position.cmpge(lo).all() && c.position.cmple(hi).all())
        .count();
    if 2 * inside > cameras.len() {
        return Some(RigDoubt::Inside {
            inside,
            cameras: cameras.len(),
        });
    }
    let directions: Vec<DVec3> = cameras
        .iter()
        .map(|c| (c.position - centre).normalize_or_zero())
        .collect();
    let mean = directions.iter().sum::<DVec3>().normalize_or_zero();
    if mean == DVec3::ZERO || directions.contains(&DVec3::ZERO) {
        return None;
    }
    let half_angle_degrees = directions
        .iter()
        .map(|d| d.dot(mean).clamp(-1.0, 1.0).acos().to_degrees())
        .fold(0.0, f64::max);
    if half_angle_degrees >= MIN_RIG_SPREAD_DEGREES {
        return None;
    }
    let mut distances: Vec<f64> = cameras
        .iter()
        .map(|c| (c.position - centre).length() / radius)
        .collect();
    distances.sort_by(f64::total_cmp);
    Some(RigDoubt::OneDirection {
        cameras: cameras.len(),
        half_angle_degrees,
        distance_radii: distances[distances.len() / 2],
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use plenoptic_io::{Mesh, PlenopticCloud};

    fn cloud(points: &[[f32; 3]]) -> Model {
        Model::Cloud(PlenopticCloud {
            positions: points.iter().map(|&p| Vec3::from(p)).collect(),
            colors: vec![[0.5; 3]; points.len()],
            ..Default::default()
        })
    }

    #[test]
    fn clouds_need_extent_and_four_distinct_points() {
        let p = Path::new("in.ply");
        let e = check_model(p, &cloud(&[[1.0, 2.0, 3.0]; 1000])).unwrap_err();
        assert!(
            matches!(e, DegenerateError::NoExtent { points: 1000, .. }),
            "{e}"
        );
        assert!(
            e.to_string().starts_with("in.ply: the input has no extent"),
            "{e}"
        );
        // Three distinct points, repeated: extent but too few to size a splat.
        let three = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let many: Vec<[f32; 3]> = three.iter().cycle().take(30).copied().collect();
        let e = check_model(p, &cloud(&many)).unwrap_err();
        assert!(
            matches!(
                e,
                DegenerateError::TooFewPoints {
                    distinct: 3,
                    points: 30,
                    ..
                }
            ),
            "{e}"
        );
        // −0 and +0 are one point.
        let signed = [
            [0.0, 0.0, 0.0],
            [-0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        assert!(check_model(p, &cloud(&signed)).is_err());
        let four = [
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
        ];
        check_model(p, &cloud(&four)).unwrap();
        // A flat (planar) cloud is fine: extent on two axes.
        let flat = [
            [0.0, 0.0, 5.0],
            [1.0, 0.0, 5.0],
            [0.0, 1.0, 5.0],
            [1.0, 1.0, 5.0],
        ];
        check_model(p, &cloud(&flat)).unwrap();
    }

    #[test]
    fn extent_is_measured_in_f32_steps_of_the_coordinates() {
        let p = Path::new("in.ply");
        // Far from the origin, points one f32 step apart are distinct but have no usable extent.
        let base = 1.0e6f32;
        // About two f32 steps (0.0625 each near 1e6): 8 points spread over 0.83.
        let step = base * f32::EPSILON;
        let near: Vec<[f32; 3]> = (0..8)
            .map(|i| [base + i as f32 * step, base, base])
            .collect();
        let e = check_model(p, &cloud(&near)).unwrap_err();
        assert!(matches!(e, DegenerateError::NoExtent { .. }), "{e}");
        // The same shape at the origin is fine: its steps are far finer there.
        let origin: Vec<[f32; 3]> = (0..8)
            .map(|i| {
                [
                    i as f32 * step,
                    (i % 2) as f32 * step,
                    (i % 3) as f32 * step,
                ]
            })
            .collect();
        check_model(p, &cloud(&origin)).unwrap();
        // Tiny objects at the origin are refused only below √(f32::MIN_POSITIVE).
        let tiny: Vec<[f32; 3]> = (0..8)
            .map(|i| [i as f32 * 1e-20, (i % 2) as f32 * 1e-20, 0.0])
            .collect();
        assert!(check_model(p, &cloud(&tiny)).is_err());
    }

    #[test]
    fn meshes_need_area() {
        let p = Path::new("m.obj");
        let mesh = |positions: Vec<Vec3>, triangles: Vec<[u32; 3]>| {
            Model::Mesh(Mesh {
                positions,
                triangles,
                ..Default::default()
            })
        };
        // Three collinear vertices and a repeated vertex: both triangles have zero area.
        let line = vec![Vec3::ZERO, Vec3::X, 2.0 * Vec3::X, Vec3::Y];
        let e = check_model(p, &mesh(line.clone(), vec![[0, 1, 2], [3, 3, 0]])).unwrap_err();
        assert!(
            matches!(e, DegenerateError::NoArea { triangles: 2, .. }),
            "{e}"
        );
        assert!(
            e.to_string()
                .contains("m.obj: all 2 triangle(s) have zero area"),
            "{e}"
        );
        // One real triangle is enough, even with few vertices.
        check_model(p, &mesh(line, vec![[0, 1, 3]])).unwrap();
        // Unused vertices do not give a mesh extent.
        let far = vec![Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::splat(100.0)];
        let e = check_model(p, &mesh(far, vec![[0, 1, 2]])).unwrap_err();
        assert!(
            matches!(e, DegenerateError::NoExtent { points: 3, .. }),
            "{e}"
        );
    }

    #[test]
    fn more_than_half_empty_views_are_refused() {
        let seen = [0.0, 0.25, 0.0];
        let empty = [0.0; 3];
        let views = |k: usize, n: usize| -> Vec<&[f32]> {
            (0..n)
                .map(|i| if i < k { &empty[..] } else { &seen[..] })
                .collect()
        };
        let name = |i: usize| format!("view_{i:03}");
        check_views(
            Path::new("a.ply"),
            "training",
            views(2, 4).into_iter(),
            name,
        )
        .unwrap();
        let e = check_views(
            Path::new("a.ply"),
            "training",
            views(3, 4).into_iter(),
            name,
        )
        .unwrap_err();
        assert_eq!(
            e.to_string().split(';').next().unwrap(),
            "a.ply: nothing is visible in 3 of the 4 training views (view_000, view_001, view_002)"
        );
        let e = check_views(
            Path::new("a.ply"),
            "held-out",
            views(5, 5).into_iter(),
            name,
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("5 of the 5 held-out views (view_000, view_001, view_002, …)"),
            "{e}"
        );
    }

    /// A rig moved with its points is trusted; one left behind when the points moved (all its
    /// cameras then in one direction), or written in other units (inside the object), is doubted.
    #[test]
    fn a_rig_that_did_not_move_with_its_points_is_doubted() {
        use plenoptic_io::CaptureCamera;
        let ring = |r: f64, at: DVec3| -> Vec<CaptureCamera> {
            (0..13)
                .map(|k| {
                    let a = f64::from(k) * std::f64::consts::TAU / 13.0;
                    CaptureCamera {
                        position: at + DVec3::new(r * a.cos(), 0.3 * r, r * a.sin()),
                        matrix: None,
                    }
                })
                .collect()
        };
        let with_rig = |offset: f32, cameras: Vec<CaptureCamera>| {
            let mut points = Vec::new();
            for i in 0..10 {
                for j in 0..10 {
                    for k in [0.0, 9.0] {
                        points.push(Vec3::new(i as f32, j as f32, k) + offset);
                    }
                }
            }
            Model::Cloud(PlenopticCloud {
                colors: vec![[0.5; 3]; points.len()],
                positions: points,
                num_cameras: cameras.len(),
                cameras,
                ..Default::default()
            })
        };
        let centre = DVec3::splat(4.5);
        assert_eq!(rig_doubt(&with_rig(0.0, ring(40.0, centre))), None);
        // A rig far off but spread wide enough (a 60-radius ring seen from 100 radii) is kept.
        assert_eq!(
            rig_doubt(&with_rig(0.0, ring(400.0, centre + DVec3::X * 700.0))),
            None
        );
        // The points moved 10^5 units, the rig left at the origin.
        let Some(RigDoubt::OneDirection {
            cameras: 13,
            half_angle_degrees,
            distance_radii,
        }) = rig_doubt(&with_rig(1e5, ring(40.0, centre)))
        else {
            panic!("a rig left behind is doubted")
        };
        assert!(half_angle_degrees < 0.1, "{half_angle_degrees}");
        assert!((distance_radii - 1e5 * 3f64.sqrt() / (0.5 * 243f64.sqrt())).abs() < 200.0);
        // A rig in metres beside points in voxels: the cameras inside the object.
        let doubt = rig_doubt(&with_rig(0.0, ring(2.0, centre))).expect("doubted");
        assert_eq!(
            doubt,
            RigDoubt::Inside {
                inside: 13,
                cameras: 13
            }
        );
        assert!(
            doubt
                .to_string()
                .contains("13 of the 13 capture cameras stand inside")
        );
        // Plain clouds and one- or two-camera rigs are not judged.
        assert_eq!(rig_doubt(&cloud(&[[0.0; 3], [1.0; 3]])), None);
        assert_eq!(
            rig_doubt(&with_rig(1e5, ring(40.0, centre)[..2].to_vec())),
            None
        );
    }
}
