//! Initial splat scales from point spacing, and the nearest-neighbour index they and the
//! evaluator's surface distance use.

use std::num::NonZero;

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use rayon::prelude::*;

/// Inria's isotropic initial log-scales: log √(max(mean squared distance to the 3 nearest other
/// points, 1e-7)) per point (`distCUDA2` in `gaussian_model.py`). With fewer than 4 points the
/// mean runs over the neighbours there are; a lone point gets the 1e-7 floor.
#[must_use]
pub fn scales_from_knn(points: &[glam::Vec3]) -> Vec<glam::Vec3> {
    if points.is_empty() {
        return Vec::new();
    }
    let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
    let Ok(tree) = ImmutableKdTree::<f32, 3>::new_from_slice(&coords) else {
        return vec![glam::Vec3::splat(0.5 * 1e-7f32.ln()); points.len()];
    };
    let k = points.len().min(4);
    let want = NonZero::new(k).unwrap_or(NonZero::<usize>::MIN);
    coords
        .par_iter()
        .enumerate()
        .map(|(i, q)| {
            let found = tree
                .query(q)
                .nearest_n::<SquaredEuclidean<f32>>(want)
                .execute();
            // The query point itself is among the results (distance 0); skip it by index so that
            // duplicate points still count each other as neighbours at distance 0.
            let mut sum = 0.0f64;
            let mut count = 0usize;
            let mut skipped = false;
            for r in &found {
                if !skipped && r.item as usize == i {
                    skipped = true;
                    continue;
                }
                if count < 3 {
                    sum += f64::from(r.distance);
                    count += 1;
                }
            }
            let mean = if count == 0 { 0.0 } else { sum / count as f64 };
            glam::Vec3::splat((0.5 * mean.max(1e-7).ln()) as f32)
        })
        .collect()
}

/// A k-d tree over points for nearest-neighbour queries.
pub struct PointIndex {
    tree: ImmutableKdTree<f32, 3>,
    len: usize,
}

impl PointIndex {
    /// Builds the index; `None` for an empty or unindexable set.
    #[must_use]
    pub fn new(points: &[glam::Vec3]) -> Option<Self> {
        if points.is_empty() {
            return None;
        }
        let coords: Vec<[f32; 3]> = points.iter().map(|p| p.to_array()).collect();
        let tree = ImmutableKdTree::<f32, 3>::new_from_slice(&coords).ok()?;
        Some(Self {
            tree,
            len: points.len(),
        })
    }

    /// Distance from `p` to the nearest indexed point.
    #[must_use]
    pub fn nearest_distance(&self, p: glam::Vec3) -> f32 {
        self.tree
            .query(&p.to_array())
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute()
            .distance
            .sqrt()
    }

    /// Distance from `p` to the nearest indexed point, and that point's index.
    #[must_use]
    pub fn nearest(&self, p: glam::Vec3) -> (f32, usize) {
        let found = self
            .tree
            .query(&p.to_array())
            .nearest_one::<SquaredEuclidean<f32>>()
            .execute();
        (found.distance.sqrt(), found.item as usize)
    }

    /// Indices of the `k` nearest indexed points to `p` (nearest first; includes `p` itself if
    /// indexed).
    #[must_use]
    pub fn nearest_n(&self, p: glam::Vec3, k: usize) -> Vec<usize> {
        let want = NonZero::new(k.min(self.len).max(1)).unwrap_or(NonZero::<usize>::MIN);
        self.tree
            .query(&p.to_array())
            .nearest_n::<SquaredEuclidean<f32>>(want)
            .execute()
            .iter()
            .map(|r| r.item as usize)
            .collect()
    }
}

/// Median distance from a point to its nearest other point, on up to 20,000 evenly strided points.
#[must_use]
pub fn point_spacing(points: &[glam::Vec3]) -> f32 {
    PointIndex::new(points).map_or(0.0, |index| spacing_in(&index, points))
}

/// [`point_spacing`] of `points` with their `index` already built.
fn spacing_in(index: &PointIndex, points: &[glam::Vec3]) -> f32 {
    if points.len() < 2 {
        return 0.0;
    }
    let stride = points.len().div_ceil(20_000).max(1);
    let mut d: Vec<f32> = points
        .par_iter()
        .step_by(stride)
        .map(|&p| {
            let near = index.nearest_n(p, 2);
            near.iter()
                .map(|&j| points[j].distance(p))
                .find(|&d| d > 0.0)
                .unwrap_or(0.0)
        })
        .collect();
    d.sort_by(f32::total_cmp);
    d[d.len() / 2]
}

/// A surface that splat distances are measured to (`eval::surface_distance`): the
/// nearest-neighbour index of its points, the points themselves and, when the input has them,
/// their outward normals, and their median spacing, built once. A paper-scale cloud's 3M
/// points take most of a second to index on one thread, and a run measures the spacing and two
/// evaluations' distances against the same surface.
///
/// The points are kept beside the tree although the tree holds them too: kiddo 6 hands a
/// query's point back only through its point projection (`with_points`), and a nearest-one
/// query with it spent minutes in `scan_projected_nearest_one` for a paper-scale model's 249k
/// splats against 3.1M points, where the plain query and a lookup take about a second.
pub struct SurfaceIndex {
    index: PointIndex,
    points: Vec<glam::Vec3>,
    normals: Option<Vec<glam::Vec3>>,
    spacing: f32,
}

/// The surface point nearest to a query ([`SurfaceIndex::nearest`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NearestSurfacePoint {
    /// Distance from the query to the point.
    pub distance: f32,
    /// The point.
    pub position: glam::Vec3,
    /// Its normal, where the surface has normals (not necessarily of unit length).
    pub normal: Option<glam::Vec3>,
}

impl std::fmt::Debug for SurfaceIndex {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SurfaceIndex")
            .field("points", &self.points.len())
            .field("oriented", &self.normals.is_some())
            .field("spacing", &self.spacing)
            .finish_non_exhaustive()
    }
}

impl SurfaceIndex {
    /// Indexes `points`, with their outward `normals` where the input has them; `None` for an
    /// empty or unindexable set. Normals that are all zero (how exporters write "none") count as
    /// none: they orient nothing.
    ///
    /// # Panics
    /// If `normals` is not one per point (a caller bug).
    #[must_use]
    pub fn new(points: &[glam::Vec3], normals: Option<&[glam::Vec3]>) -> Option<Self> {
        if let Some(n) = normals {
            assert_eq!(n.len(), points.len(), "SurfaceIndex: one normal per point");
        }
        let normals = normals.filter(|n| n.iter().any(|v| *v != glam::Vec3::ZERO));
        let index = PointIndex::new(points)?;
        let spacing = spacing_in(&index, points);
        Some(Self {
            index,
            points: points.to_vec(),
            normals: normals.map(<[glam::Vec3]>::to_vec),
            spacing,
        })
    }

    /// How many points the surface has.
    #[must_use]
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether the surface has no points (never: [`SurfaceIndex::new`] refuses an empty set).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Whether the surface has normals, so that a side of it can be told from the other.
    #[must_use]
    pub fn is_oriented(&self) -> bool {
        self.normals.is_some()
    }

    /// The median distance from a point to its nearest other point ([`point_spacing`]).
    #[must_use]
    pub fn spacing(&self) -> f32 {
        self.spacing
    }

    /// Distance from `p` to the nearest surface point.
    #[must_use]
    pub fn nearest_distance(&self, p: glam::Vec3) -> f32 {
        self.index.nearest_distance(p)
    }

    /// The surface point nearest to `p`, with its normal where the surface has normals.
    #[must_use]
    pub fn nearest(&self, p: glam::Vec3) -> NearestSurfacePoint {
        let (distance, i) = self.index.nearest(p);
        NearestSurfacePoint {
            distance,
            position: self.points[i],
            normal: self.normals.as_ref().map(|n| n[i]),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// `n` random points in a thin slab [0, 1]² × [0, 0.1].
    fn slab_points(rng: &mut impl rand::Rng, n: usize) -> Vec<glam::Vec3> {
        (0..n)
            .map(|_| glam::Vec3::new(rng.random(), rng.random(), rng.random::<f32>() * 0.1))
            .collect()
    }

    #[test]
    fn surface_index_measures_what_the_free_functions_do() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(11);
        let pts = slab_points(&mut rng, 3_000);
        let surface = SurfaceIndex::new(&pts, None).unwrap();
        assert_eq!(surface.len(), pts.len());
        assert_eq!(surface.spacing().to_bits(), point_spacing(&pts).to_bits());
        for _ in 0..200 {
            let q = glam::Vec3::new(rng.random(), rng.random(), rng.random());
            let brute = pts
                .iter()
                .map(|p| p.distance(q))
                .fold(f32::INFINITY, f32::min);
            assert!((surface.nearest_distance(q) - brute).abs() <= 1e-6 * (1.0 + brute));
            let nearest = surface.nearest(q);
            assert_eq!(
                nearest.distance.to_bits(),
                surface.nearest_distance(q).to_bits()
            );
            assert!((nearest.position.distance(q) - brute).abs() <= 1e-6 * (1.0 + brute));
            assert!(pts.contains(&nearest.position) && nearest.normal.is_none());
        }
        assert!(!surface.is_oriented());
        // Normals are handed back with their own point: here each normal encodes its point.
        let normals: Vec<glam::Vec3> = pts.iter().map(|p| 2.0 * *p + 1.0).collect();
        let oriented = SurfaceIndex::new(&pts, Some(&normals)).unwrap();
        assert!(oriented.is_oriented());
        for _ in 0..50 {
            let q = glam::Vec3::new(rng.random(), rng.random(), rng.random());
            let n = oriented.nearest(q);
            assert_eq!(n.normal, Some(2.0 * n.position + 1.0));
        }
        assert!(SurfaceIndex::new(&[], None).is_none());
        // All-zero normals (an exporter's "none") orient nothing: the report said "oriented".
        let zeros = vec![glam::Vec3::ZERO; pts.len()];
        assert!(!SurfaceIndex::new(&pts, Some(&zeros)).unwrap().is_oriented());
    }

    #[test]
    fn matches_brute_force() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let pts = slab_points(&mut rng, 300);
        let ours = scales_from_knn(&pts);
        for (i, p) in pts.iter().enumerate() {
            let mut d: Vec<f64> = pts
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| f64::from(p.distance_squared(*q)))
                .collect();
            d.sort_by(f64::total_cmp);
            let expect = (0.5 * ((d[0] + d[1] + d[2]) / 3.0).max(1e-7).ln()) as f32;
            assert!(
                (ours[i].x - expect).abs() < 1e-4,
                "point {i}: {} vs {expect}",
                ours[i].x
            );
            assert_eq!(ours[i].x, ours[i].y);
            assert_eq!(ours[i].x, ours[i].z);
        }
    }

    /// The index's answers against a brute-force search over random points.
    #[test]
    fn point_index_matches_brute_force() {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(9);
        let pts: Vec<glam::Vec3> = (0..200)
            .map(|_| glam::Vec3::new(rng.random(), rng.random(), rng.random()))
            .collect();
        let index = PointIndex::new(&pts).unwrap();
        for _ in 0..50 {
            let q = glam::Vec3::new(rng.random(), rng.random(), rng.random()) * 1.5;
            let mut by_distance: Vec<(f32, usize)> = pts
                .iter()
                .enumerate()
                .map(|(i, p)| (p.distance_squared(q), i))
                .collect();
            by_distance.sort_by(|a, b| a.0.total_cmp(&b.0));
            let nearest = by_distance[0].0.sqrt();
            assert!((index.nearest_distance(q) - nearest).abs() < 1e-6);
            let want: Vec<usize> = by_distance[..5].iter().map(|x| x.1).collect();
            assert_eq!(index.nearest_n(q, 5), want);
        }
        // k is clamped to the points there are; an empty set has no index.
        assert_eq!(index.nearest_n(pts[3], 1000).len(), 200);
        assert_eq!(index.nearest_n(pts[3], 1)[0], 3);
        assert!(PointIndex::new(&[]).is_none());
    }

    #[test]
    fn degenerate_inputs() {
        assert!(scales_from_knn(&[]).is_empty());
        let one = scales_from_knn(&[glam::Vec3::ONE]);
        assert!((one[0].x - 0.5 * 1e-7f32.ln()).abs() < 1e-5);
        let dup = scales_from_knn(&[glam::Vec3::ZERO; 5]);
        assert!(dup.iter().all(|s| s.x.is_finite()));
    }
}
