//! Merge groups grown pair by pair: agglomerative clustering of the splats over their
//! nearest-neighbour graph, cheapest union first by Ward's criterion on their colours.
//!
//! Written here because what a union costs (colour, weighted by contribution), what it may not
//! become (longer than a reach, or bent across an edge) and how the groups become Gaussians are
//! this crate's; the clustering itself is a priority queue over a graph, a few dozen lines.

use dary_heap::OctonaryHeap;
use std::cmp::Ordering;

use glam::{DVec3, Mat3, Vec3};
use rayon::prelude::*;
use splat_core::Splats;

use super::eigen::symmetric_eigenvalues;
use crate::init::PointIndex;

/// Nearest neighbours each splat is joined to before any union: enough that a surface's graph
/// is connected across its sampling's gaps.
const NEIGHBOURS: usize = 8;

/// What a union may become, in world units.
#[derive(Debug, Clone, Copy)]
pub(super) struct Limits {
    /// The largest standard deviation of a group's member positions along its longest axis.
    pub reach: f32,
    /// The largest across its plane before the union counts as bent (taking in an edge or a
    /// corner of the surface): bent unions come after every flat one.
    pub flat: f32,
}

/// A group's running sums.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    /// Σ w over the members' contributions (negatives as 0).
    w: f64,
    /// Members.
    n: f64,
    /// Σ p and Σ p·pᵀ (xx, xy, xz, yy, yz, zz) over their positions: the group's shape, which
    /// every member counts in alike whatever it contributes.
    p: DVec3,
    pp: [f64; 6],
}

impl Sums {
    fn of(p: Vec3, w: f64) -> Self {
        let p = p.as_dvec3();
        Self {
            w,
            n: 1.0,
            p,
            pp: [
                p.x * p.x,
                p.x * p.y,
                p.x * p.z,
                p.y * p.y,
                p.y * p.z,
                p.z * p.z,
            ],
        }
    }

    fn plus(&self, o: &Self) -> Self {
        let mut pp = self.pp;
        for (a, b) in pp.iter_mut().zip(o.pp) {
            *a += b;
        }
        Self {
            w: self.w + o.w,
            n: self.n + o.n,
            p: self.p + o.p,
            pp,
        }
    }

    /// The covariance of the member positions.
    fn covariance(&self) -> Mat3 {
        let m = self.p / self.n;
        let c = |k: usize, a: f64, b: f64| (self.pp[k] / self.n - a * b) as f32;
        let (xy, xz, yz) = (c(1, m.x, m.y), c(2, m.x, m.z), c(4, m.y, m.z));
        Mat3::from_cols(
            Vec3::new(c(0, m.x, m.x), xy, xz),
            Vec3::new(xy, c(3, m.y, m.y), yz),
            Vec3::new(xz, yz, c(5, m.z, m.z)),
        )
    }

    /// The group against `limits`: `None` when the standard deviation of its member positions
    /// along their longest principal axis passes the reach, else whether it passes the flat
    /// limit along their shortest (bent).
    ///
    /// Decided by the covariance's eigenvalues ([`symmetric_eigenvalues`]), but first by bounds
    /// on them that cost no iteration (the Jacobi sweeps were a fifth of a paper-scale plan):
    /// the largest lies between the largest diagonal entry and tr/3 + √(2/3·‖C − tr/3·I‖²),
    /// the smallest below the least diagonal entry and, for a covariance (no negative
    /// eigenvalue), between det/e₂ and 3·det/e₂ with e₂ the sum of the principal 2×2 minors
    /// (e₂ = λ₁λ₂ + λ₁λ₃ + λ₂λ₃ lies between λ₂λ₃ and 3·λ₂λ₃). A bound decides only with a
    /// margin far above the eigenvalues' rounding, so the answer is the eigenvalues' own.
    fn shape(&self, limits: Limits) -> Option<bool> {
        let cov = self.covariance();
        let [d0, d1, d2] = cov.to_cols_array_2d().map(|col| col.map(f64::from));
        let (a, b, c) = (d0[0], d1[1], d2[2]);
        let (ab, ac, bc) = (d1[0], d2[0], d2[1]);
        let tr = a + b + c;
        let third = tr / 3.0;
        let spread = (a - third).powi(2)
            + (b - third).powi(2)
            + (c - third).powi(2)
            + 2.0 * (ab * ab + ac * ac + bc * bc);
        let (reach2, flat2) = (
            f64::from(limits.reach).powi(2),
            f64::from(limits.flat).powi(2),
        );
        let margin = |limit2: f64| 1e-5 * (tr.abs() + limit2);
        // The standard deviations along the principal axes, least first, from the sweeps.
        let mut exact = None;
        let mut deviations = || {
            *exact.get_or_insert_with(|| {
                let mut v = symmetric_eigenvalues(cov).to_array();
                v.sort_by(f32::total_cmp);
                v.map(|e| e.max(0.0).sqrt())
            })
        };
        let largest_above = third + (2.0 / 3.0 * spread).sqrt();
        let largest_below = a.max(b).max(c).max(third + (spread / 6.0).sqrt());
        let beyond = if largest_above < reach2 - margin(reach2) {
            false
        } else if largest_below > reach2 + margin(reach2) {
            true
        } else {
            deviations()[2] > limits.reach
        };
        if beyond {
            return None;
        }
        let e2 = a * b - ab * ab + a * c - ac * ac + b * c - bc * bc;
        let det = a * (b * c - bc * bc) - ab * (ab * c - bc * ac) + ac * (ab * bc - b * ac);
        let least_above = if e2 > 0.0 {
            a.min(b).min(c).min(3.0 * det / e2)
        } else {
            a.min(b).min(c)
        };
        let least_below = if e2 > 0.0 {
            det / e2
        } else {
            f64::NEG_INFINITY
        };
        Some(if least_above < flat2 - margin(flat2) {
            false
        } else if least_below > flat2 + margin(flat2) {
            true
        } else {
            deviations()[0] > limits.flat
        })
    }
}

/// What uniting two groups costs, or `None` where the union would be longer than the reach.
///
/// `colour_a` and `colour_b` are the groups' contribution-weighted colour sums (Σ w·c). The
/// cost is the rise in the contribution-weighted squared colour error of flattening the union
/// to one colour over flattening each part: wₐw_b/(wₐ+w_b)·‖s̄ₐ − s̄_b‖² (Ward).
fn union_cost(
    a: &Sums,
    b: &Sums,
    colour_a: &[f32],
    colour_b: &[f32],
    limits: Limits,
) -> Option<(bool, f64)> {
    let u = a.plus(b);
    let bent = u.shape(limits)?;
    let cost = if a.w > 0.0 && b.w > 0.0 {
        let d2: f64 = colour_a
            .iter()
            .zip(colour_b)
            .map(|(&x, &y)| (f64::from(x) / a.w - f64::from(y) / b.w).powi(2))
            .sum();
        a.w * b.w / u.w * d2
    } else {
        0.0
    };
    Some((bent, cost))
}

/// A union in the queue, valid while both groups are as they were when it was costed.
#[derive(Debug, PartialEq)]
struct Union {
    bent: bool,
    cost: f64,
    /// Members of the union.
    size: u32,
    a: u32,
    b: u32,
    versions: (u32, u32),
}

impl Eq for Union {}

impl Ord for Union {
    /// The queue's greatest is the next union: flat before bent, cheapest first, at equal cost
    /// the smaller (a uniform region grows into groups of even size instead of one group
    /// swallowing its neighbours one by one until it reaches its limit), then by the pair, so
    /// the plan does not depend on the queue's internal order.
    fn cmp(&self, o: &Self) -> Ordering {
        o.bent
            .cmp(&self.bent)
            .then(o.cost.total_cmp(&self.cost))
            .then(o.size.cmp(&self.size))
            .then(o.a.cmp(&self.a))
            .then(o.b.cmp(&self.b))
    }
}

impl PartialOrd for Union {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// Unites neighbouring splats, cheapest union first, until `target` groups are left or no
/// union is allowed; returns the groups of at least two members, each heaviest member first.
///
/// `weights` are the splats' contributions; a splat's colour is all its SH coefficients.
pub(super) fn grow_groups(
    splats: &Splats,
    weights: &[f64],
    target: usize,
    limits: Limits,
) -> Vec<Vec<usize>> {
    let Some(index) = PointIndex::new(&splats.means) else {
        return Vec::new();
    };
    let mut clustering = Clustering::new(splats, weights, neighbour_graph(splats, &index), limits);
    // A heap of eight children a node (`dary_heap`) rather than std's binary one: the queue
    // holds millions of unions, most of them stale by the time they come up, and popping one
    // walked twenty-odd levels of a 100 MB array; with half as many levels, each reading eight
    // neighbouring entries, a paper-scale plan took a quarter less time. No two unions in the
    // queue compare equal (the same pair queued again has grown in size), so any heap pops
    // them in the same order.
    let mut queue = OctonaryHeap::from(clustering.first_unions());
    let mut groups = splats.len();
    while groups > target {
        let Some(u) = queue.pop() else { break };
        if !clustering.is_current(&u) {
            continue;
        }
        let (a, b) = (u.a as usize, u.b as usize);
        clustering.join(a, b);
        groups -= 1;
        for &k in &clustering.neighbours[a] {
            queue.extend(clustering.union(a, k as usize));
        }
    }
    clustering
        .members
        .into_iter()
        .filter(|m| m.len() > 1)
        .map(|mut m| {
            m.sort_by(|&a, &b| weights[b].total_cmp(&weights[a]).then(a.cmp(&b)));
            m
        })
        .collect()
}

/// Each splat's [`NEIGHBOURS`] nearest, joined both ways: sorted lists without repeats.
fn neighbour_graph(splats: &Splats, index: &PointIndex) -> Vec<Vec<u32>> {
    // The queries on rayon's threads (a paper-scale model's 250k take seconds on one), joined
    // both ways in order after them, so the graph is the same on any number of threads.
    let nearest: Vec<Vec<usize>> = splats
        .means
        .par_iter()
        .map(|&p| index.nearest_n(p, NEIGHBOURS + 1))
        .collect();
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); splats.len()];
    for (i, near) in nearest.into_iter().enumerate() {
        for j in near.into_iter().filter(|&j| j != i) {
            neighbours[i].push(j as u32);
            neighbours[j].push(i as u32);
        }
    }
    for list in &mut neighbours {
        list.sort_unstable();
        list.dedup();
    }
    neighbours
}

/// The groups as they grow: each stands in the place of one member, which holds its sums,
/// colour, version, neighbours and member list; a joined group's place is left empty.
struct Clustering {
    limits: Limits,
    /// SH coefficients a splat (three channels).
    dims: usize,
    sums: Vec<Sums>,
    /// Each group's Σ w·c over its members' SH coefficients, `dims` a group. In f32, half the
    /// memory of f64 (a paper-scale model's 250k splats of degree 3: 48 MB), and its rounding
    /// is far below the colour differences it compares.
    colour: Vec<f32>,
    /// Joins the group has taken in: a queued union of an older version is stale.
    versions: Vec<u32>,
    /// The neighbouring groups (each list a set: its order is never read).
    neighbours: Vec<Vec<u32>>,
    members: Vec<Vec<usize>>,
    alive: Vec<bool>,
}

impl Clustering {
    /// Every splat a group of its own.
    fn new(splats: &Splats, weights: &[f64], neighbours: Vec<Vec<u32>>, limits: Limits) -> Self {
        let n = splats.len();
        let dims = 3 * splats.coeffs_per_splat();
        Self {
            limits,
            dims,
            sums: (0..n)
                .map(|i| Sums::of(splats.means[i], weights[i].max(0.0)))
                .collect(),
            colour: splats
                .sh
                .as_flattened()
                .chunks_exact(dims)
                .zip(weights)
                .flat_map(|(c, &w)| c.iter().map(move |&v| w.max(0.0) as f32 * v))
                .collect(),
            versions: vec![0; n],
            neighbours,
            members: (0..n).map(|i| vec![i]).collect(),
            alive: vec![true; n],
        }
    }

    /// The union of groups `a` and `b` as they are now, or `None` where it is not allowed.
    fn union(&self, a: usize, b: usize) -> Option<Union> {
        let (a, b) = (usize::min(a, b), usize::max(a, b));
        let of = |g: usize| &self.colour[g * self.dims..(g + 1) * self.dims];
        let (sa, sb) = (&self.sums[a], &self.sums[b]);
        union_cost(sa, sb, of(a), of(b), self.limits).map(|(bent, cost)| Union {
            bent,
            cost,
            size: (sa.n + sb.n) as u32,
            a: a as u32,
            b: b as u32,
            versions: (self.versions[a], self.versions[b]),
        })
    }

    /// The unions of every pair of neighbours, costed on rayon's threads; the queue's order is
    /// total, so building it from them in any order gives the same plan.
    fn first_unions(&self) -> Vec<Union> {
        self.neighbours
            .par_iter()
            .enumerate()
            .flat_map_iter(|(a, list)| {
                list.iter()
                    .filter(move |&&b| a < b as usize)
                    .filter_map(move |&b| self.union(a, b as usize))
            })
            .collect()
    }

    /// Whether both of the union's groups are alive and as they were when it was costed.
    fn is_current(&self, u: &Union) -> bool {
        let (a, b) = (u.a as usize, u.b as usize);
        self.alive[a] && self.alive[b] && u.versions == (self.versions[a], self.versions[b])
    }

    /// Group `b` joins group `a`: its sums, colour and members, and its neighbours, which
    /// now neighbour `a` instead.
    fn join(&mut self, a: usize, b: usize) {
        let dims = self.dims;
        self.alive[b] = false;
        self.sums[a] = self.sums[a].plus(&self.sums[b]);
        for d in 0..dims {
            self.colour[a * dims + d] += self.colour[b * dims + d];
        }
        self.versions[a] += 1;
        let joined = std::mem::take(&mut self.members[b]);
        self.members[a].extend(joined);
        let of_b = std::mem::take(&mut self.neighbours[b]);
        for &k in of_b.iter().filter(|&&k| k as usize != a) {
            let list = &mut self.neighbours[k as usize];
            let had_a = list.contains(&(a as u32));
            if let Some(at) = list.iter().position(|&x| x as usize == b) {
                if had_a {
                    list.swap_remove(at);
                } else {
                    list[at] = a as u32;
                }
            }
        }
        let mut of_a: Vec<u32> = self.neighbours[a].iter().copied().chain(of_b).collect();
        of_a.retain(|&k| k as usize != a && k as usize != b);
        of_a.sort_unstable();
        of_a.dedup();
        self.neighbours[a] = of_a;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What [`Sums::shape`] answers without its bounds: the Jacobi eigenvalues' standard
    /// deviations against the limits.
    fn shape_by_eigenvalues(s: &Sums, limits: Limits) -> Option<bool> {
        let mut v = symmetric_eigenvalues(s.covariance()).to_array();
        v.sort_by(f32::total_cmp);
        let sd = v.map(|e| e.max(0.0).sqrt());
        (sd[2] <= limits.reach).then_some(sd[0] > limits.flat)
    }

    #[test]
    fn the_shape_bounds_answer_as_the_eigenvalues_do() {
        let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let (mut decided, mut beyond, mut bent) = (0, 0, 0);
        for case in 0..20_000 {
            // Groups of 2–12 points spread along three random axes with random lengths: lines,
            // discs, bent patches and blobs, at sizes around both limits.
            let axes = [
                Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize_or(Vec3::X),
                Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5).normalize_or(Vec3::Y),
            ];
            let third = axes[0].cross(axes[1]).normalize_or(Vec3::Z);
            let lengths = [
                3.0 * next(),
                3.0 * next(),
                [0.0, 0.5, 2.0][case % 3] * next(),
            ];
            let centre = Vec3::new(100.0 * next(), 100.0 * next(), 100.0 * next());
            let members = 2 + case % 11;
            let mut s: Option<Sums> = None;
            for _ in 0..members {
                let p = centre
                    + axes[0] * lengths[0] * (next() - 0.5)
                    + axes[1] * lengths[1] * (next() - 0.5)
                    + third * lengths[2] * (next() - 0.5);
                let one = Sums::of(p, 1.0);
                s = Some(s.map_or(one, |s| s.plus(&one)));
            }
            let s = s.expect("at least two members");
            let limits = Limits {
                reach: 0.2 + 0.8 * next(),
                flat: 0.05 + 0.3 * next(),
            };
            let want = shape_by_eigenvalues(&s, limits);
            assert_eq!(
                s.shape(limits),
                want,
                "case {case}: {s:?} against {limits:?}"
            );
            decided += 1;
            beyond += usize::from(want.is_none());
            bent += usize::from(want == Some(true));
        }
        // Both answers of both limits came up often enough to be tested.
        assert!(
            beyond > decided / 20 && beyond < decided * 19 / 20,
            "{beyond} of {decided}"
        );
        assert!(bent > decided / 50, "{bent} bent of {decided}");
    }
}
