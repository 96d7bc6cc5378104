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
         below the {min:e} needed (16 f32 steps of its largest coordinate); nothing can be framed or rendered",
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
    let (lo, hi) = points
        .iter()
        .fold((DVec3::INFINITY, DVec3::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.as_dvec3()), hi.max(p.as_dvec3()))
        });
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
}
