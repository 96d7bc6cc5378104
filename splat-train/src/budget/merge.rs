//! A round's merges: which splats become one (grown by [`super::clusters`]) and the Gaussian
//! that takes each group's place.

use glam::{Mat3, Vec3};
use splat_core::Splats;

use super::clusters;
use super::eigen::symmetric_eigen;
use crate::init::point_spacing;
use crate::state::ParamState;

/// Groups of splats to merge into one each: the plan of a round's pruned branch.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Merges {
    /// Each group's members (at least two), the first of which takes the merged splat's place.
    pub groups: Vec<Vec<usize>>,
}

impl Merges {
    /// Splats the merges remove.
    #[must_use]
    pub fn removed(&self) -> usize {
        self.groups.iter().map(|g| g.len() - 1).sum()
    }

    /// Replaces each group's first member by the group's merged splat ([`merge_group`]) with
    /// the members' optimiser moments blended the same way ([`ParamState::blend_moments`]);
    /// returns the keep flags that then remove the other members.
    pub fn apply(&self, state: &mut ParamState, weights: &[f64]) -> Vec<bool> {
        let mut keep = vec![true; state.len()];
        for g in &self.groups {
            merge_group(&mut state.splats, g, weights);
            state.blend_moments(g, &member_shares(g, weights));
            for &j in &g[1..] {
                keep[j] = false;
            }
        }
        keep
    }
}

/// Plans merges that bring `splats` down to `target` splats, cheapest first.
///
/// Groups grow from single splats by uniting neighbours (each splat joined to its nearest
/// few), the cheapest union first. A union costs what flattening its colours would add: the
/// members' `weights` (contributions) times the squared distance of their colours from the
/// union's weighted mean, less what its two parts already cost (Ward's criterion). A colour is
/// all of a splat's SH coefficients, so two colours' distance is their squared difference
/// integrated over all directions (the real SH basis is orthonormal), and glossy splats whose
/// highlights face different ways are told apart. Colours are not scaled by opacity: the
/// contribution already is the splat's blending weight summed over the views' pixels, and
/// scaled once more, the splats of a uniform surface, whose opacities training spreads (where
/// they overlap, a half-transparent splat draws the same colour as an opaque one), looked as
/// different as texture (docs/benchmarks/budget.md, session 38). No group grows longer than `reach` median nearest-neighbour spacings
/// (the standard deviation of its member positions along its longest axis), and unions that
/// would take in an edge or a corner of the surface (members more than 0.375 spacings off
/// their best-fitting plane) come after every flat one. So a uniform region merges into few
/// large splats, a checker's squares into groups inside each square and along its edges, and a
/// detailed or glossy region keeps its splats. Nested cubic cells did the same job before
/// session 39 and lost more of the images at a quarter of the splats: a cell's fixed place
/// cuts across a texture's edges; and the colour was the SH DC with the higher bands' norm
/// only, which lost more at a quarter too (docs/benchmarks/budget.md).
#[must_use]
pub fn plan_merges(splats: &Splats, weights: &[f64], target: usize, reach: f32) -> Merges {
    let n = splats.len();
    if n <= target || n < 2 {
        return Merges::default();
    }
    let spacing = point_spacing(&splats.means);
    if !(spacing.is_finite() && spacing > 0.0) {
        return Merges::default();
    }
    let limits = clusters::Limits {
        reach: reach * spacing,
        flat: FLAT_SPACINGS * spacing,
    };
    let groups = clusters::grow_groups(splats, weights, target, limits);
    Merges { groups }
}

/// How far (in median spacings, as a standard deviation) a group's members may lie off their
/// best-fitting plane before a union counts as bent: a quarter of the old finest merge cell
/// (1.5 spacings), where a cell across a surface's edge stood out.
const FLAT_SPACINGS: f32 = 0.375;

/// Each member's share of a merged group: its weight over the group's (negative weights
/// count as 0), or equal shares when no member has weight.
fn member_shares(group: &[usize], weights: &[f64]) -> Vec<f32> {
    let raw: Vec<f64> = group.iter().map(|&j| weights[j].max(0.0)).collect();
    let sum: f64 = raw.iter().sum();
    if sum > 0.0 {
        raw.iter().map(|&v| (v / sum) as f32).collect()
    } else {
        vec![1.0 / group.len() as f32; group.len()]
    }
}

/// Replaces splat `group[0]` by one Gaussian with the group's moments: the `weights`-weighted
/// mean of the members' positions, and their mean covariance plus the spread of their
/// positions (moment matching of a Gaussian mixture); SH the weighted mean of theirs; opacity
/// the largest of theirs (the group covered at least as much as its most opaque member).
pub fn merge_group(splats: &mut Splats, group: &[usize], weights: &[f64]) {
    let w = member_shares(group, weights);
    let mean: Vec3 = group
        .iter()
        .zip(&w)
        .map(|(&j, &wj)| wj * splats.means[j])
        .sum();
    let mut second = Mat3::ZERO;
    for (&j, &wj) in group.iter().zip(&w) {
        let r = Mat3::from_quat(splats.rotation(j));
        let s2 = Mat3::from_diagonal(splats.scale(j) * splats.scale(j));
        let d = splats.means[j] - mean;
        let outer = Mat3::from_cols(d * d.x, d * d.y, d * d.z);
        second += (r * s2 * r.transpose() + outer) * wj;
    }
    let (rotation, variances) = symmetric_eigen(second);
    let k = splats.coeffs_per_splat();
    let mut sh = vec![[0.0_f32; 3]; k];
    for (&j, &wj) in group.iter().zip(&w) {
        for (acc, member) in sh.iter_mut().zip(&splats.sh[j * k..(j + 1) * k]) {
            for (a, m) in acc.iter_mut().zip(member) {
                *a += wj * m;
            }
        }
    }
    let opacity = group
        .iter()
        .map(|&j| splats.opacity_logits[j])
        .fold(f32::NEG_INFINITY, f32::max);
    let i = group[0];
    let floor = splats.log_scales[i].min_element();
    splats.means[i] = mean;
    splats.log_scales[i] = variances.max(Vec3::ZERO).map(|v| (0.5 * v.ln()).max(floor));
    let q = rotation.normalize();
    splats.rotations[i] = [q.w, q.x, q.y, q.z];
    splats.opacity_logits[i] = opacity;
    splats.sh[i * k..(i + 1) * k].copy_from_slice(&sh);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn approx(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    /// Two equal axis-aligned splats at ±d on x merge, by moment matching, into one at the
    /// origin with variance s² + d² along x and s² across; the colour is the weights' mean and
    /// the opacity the larger one.
    #[test]
    fn a_merge_matches_the_moments_of_its_members() {
        let (s, d) = (0.1_f32, 0.3_f32);
        let means = [Vec3::new(-d, 0.0, 0.0), Vec3::new(d, 0.0, 0.0)];
        let mut splats = Splats::from_points(
            &means,
            &[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
            &[Vec3::splat(s); 2],
            None,
            0.5,
            1,
        )
        .unwrap();
        splats.opacity_logits[1] = 2.0;
        let dc = [splats.sh[0][0], splats.sh[4][0]];
        merge_group(&mut splats, &[0, 1], &[3.0, 1.0]);
        assert!(
            splats.means[0].length() < 1e-6 + 0.5 * d,
            "{}",
            splats.means[0]
        );
        // Weighted 3:1, the mean sits at −d/2 and the spread is the weighted variance.
        let mean_x = 0.75 * -d + 0.25 * d;
        assert!(approx(splats.means[0].x, mean_x, 1e-5));
        let var_x = s * s + 0.75 * (-d - mean_x).powi(2) + 0.25 * (d - mean_x).powi(2);
        let scale = splats.scale(0);
        let axis_x = Mat3::from_quat(splats.rotation(0)) * Vec3::X;
        let mut sorted = scale.to_array();
        sorted.sort_by(f32::total_cmp);
        assert!(
            approx(sorted[2] * sorted[2], var_x, 1e-4),
            "{scale} vs {var_x}"
        );
        assert!(approx(sorted[0], s, 1e-4) && approx(sorted[1], s, 1e-4));
        // The widest axis is x (up to sign).
        let widest = (0..3)
            .max_by(|&a, &b| scale[a].total_cmp(&scale[b]))
            .unwrap();
        let col = Mat3::from_quat(splats.rotation(0)).col(widest);
        assert!(col.x.abs() > 0.999, "{col} {axis_x}");
        assert!(approx(splats.sh[0][0], 0.75 * dc[0] + 0.25 * dc[1], 1e-6));
        assert_eq!(splats.opacity_logits[0], 2.0);
    }

    /// A xorshift64 stream of numbers in [0, 1) from `seed` (not 0): test colours.
    fn xorshift(mut x: u64) -> impl FnMut() -> f32 {
        move || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    /// A flat single-colour sheet beside a sheet of random colours: the plan merges the flat
    /// sheet first and reaches the target.
    #[test]
    fn merges_take_flat_regions_first() {
        let mut means = Vec::new();
        let mut colours = Vec::new();
        let mut rand = xorshift(1);
        for i in 0..40 {
            for j in 0..40 {
                // Left half (x < 0) flat grey, right half random colours.
                let p = Vec3::new(i as f32 * 0.05 - 1.0, j as f32 * 0.05, 0.0);
                let c = if p.x < 0.0 {
                    [0.5; 3]
                } else {
                    [rand(), rand(), rand()]
                };
                means.push(p);
                colours.push(c);
            }
        }
        let n = means.len();
        let splats =
            Splats::from_points(&means, &colours, &vec![Vec3::splat(0.03); n], None, 0.8, 0)
                .unwrap();
        let weights = vec![1.0; n];
        let plan = plan_merges(&splats, &weights, n * 3 / 4, 7.0);
        assert!(plan.removed() >= n / 4, "removed {}", plan.removed());
        assert!(plan.removed() < n / 4 + 8, "removed {}", plan.removed());
        let flat_removed: usize = plan
            .groups
            .iter()
            .flat_map(|g| &g[1..])
            .filter(|&&j| means[j].x < 0.0)
            .count();
        assert_eq!(flat_removed, plan.removed(), "only the flat half merges");
        // Deterministic.
        assert_eq!(plan, plan_merges(&splats, &weights, n * 3 / 4, 7.0));
        // Applying it keeps each group's first member and drops the rest.
        let mut state = ParamState::new(splats);
        let keep = plan.apply(&mut state, &weights);
        assert_eq!(keep.iter().filter(|&&k| !k).count(), plan.removed());
        assert!(plan.groups.iter().all(|g| keep[g[0]]));
    }

    /// A uniform sheet folded at a right angle, with a small patch of random colours on one
    /// face: asked for an eighth, the plan merges the uniform faces into large groups (a round
    /// can shrink a flat region far more than twofold), keeps every splat of the patch, and no
    /// group larger than a pair takes in both faces of the fold.
    #[test]
    fn flat_regions_merge_into_large_cells_and_detail_stays() {
        let mut means = Vec::new();
        let mut colours = Vec::new();
        let mut rand = xorshift(7);
        let h = 0.05;
        for i in 0..64 {
            for j in 0..64 {
                // The floor (y = 0) and a wall (x = 0) meeting at the fold.
                let floor = Vec3::new(i as f32 * h + h, 0.0, j as f32 * h);
                let detail = i < 8 && (28..36).contains(&j);
                means.push(floor);
                colours.push(if detail {
                    [rand(), rand(), rand()]
                } else {
                    [0.5; 3]
                });
                means.push(Vec3::new(0.0, i as f32 * h, j as f32 * h));
                colours.push([0.5; 3]);
            }
        }
        let n = means.len();
        let splats =
            Splats::from_points(&means, &colours, &vec![Vec3::splat(0.03); n], None, 0.8, 0)
                .unwrap();
        let weights = vec![1.0; n];
        let target = n / 8;
        let plan = plan_merges(&splats, &weights, target, 7.0);
        let removed = plan.removed();
        assert!(removed >= n - target, "removed {removed} of {n}");
        assert!(removed < n - target + n / 50, "removed {removed} of {n}");
        let mean_group =
            plan.groups.iter().map(Vec::len).sum::<usize>() as f64 / plan.groups.len() as f64;
        assert!(mean_group >= 8.0, "mean group {mean_group}");
        // The detail patch sits on the floor (x > 0) at x < 0.45, z in [1.4, 1.8).
        let is_detail =
            |p: Vec3| p.y == 0.0 && p.x > 0.0 && p.x < 8.5 * h && p.z >= 1.39 && p.z < 1.76;
        assert_eq!(means.iter().filter(|&&p| is_detail(p)).count(), 64);
        let merged: Vec<usize> = plan.groups.iter().flatten().copied().collect();
        assert!(
            merged.iter().all(|&j| !is_detail(means[j])),
            "a splat of the detail patch was merged"
        );
        // A group that takes in both faces lies flat (the fold's two rows, which share a
        // plane), so its merged splat does not stick out of the surface.
        let mut straddling = 0;
        for g in plan.groups.iter().filter(|g| g.len() > 2) {
            let on_wall = g.iter().filter(|&&j| means[j].x == 0.0).count();
            if on_wall == 0 || on_wall == g.len() {
                continue;
            }
            straddling += 1;
            let mean = g.iter().map(|&j| means[j]).sum::<Vec3>() / g.len() as f32;
            let cov = g
                .iter()
                .map(|&j| {
                    let d = means[j] - mean;
                    Mat3::from_cols(d * d.x, d * d.y, d * d.z)
                })
                .fold(Mat3::ZERO, |a, b| a + b)
                / g.len() as f32;
            let across = symmetric_eigen(cov).1.min_element().max(0.0).sqrt();
            assert!(
                across <= 0.375 * h * 1.001,
                "a group of {} straddles the fold {across} off its plane",
                g.len()
            );
        }
        assert!(
            straddling < plan.groups.len() / 20,
            "{straddling} groups at the fold"
        );
        // No splat is in two groups.
        let mut seen = merged.clone();
        seen.sort_unstable();
        seen.dedup();
        assert_eq!(seen.len(), merged.len());
        // Groups no longer than about a spacing (pairs and triples) cannot get near an eighth.
        let short = plan_merges(&splats, &weights, target, 0.4).removed();
        assert!(
            short < n * 5 / 8,
            "removed {short} of {n} with a short reach"
        );
    }

    /// A checker of squares nine splats wide, placed off any grid: asked for a quarter, the
    /// plan groups splats inside each square (no group takes in both colours) and no group is
    /// longer than its reach.
    #[test]
    fn groups_keep_to_a_checker_s_squares_and_their_reach() {
        let h = 0.05;
        let square = |i: i32| (i + 4).div_euclid(9);
        let mut means = Vec::new();
        let mut colours = Vec::new();
        let mut black = Vec::new();
        for i in 0..60 {
            for j in 0..60 {
                means.push(Vec3::new(i as f32 * h, 0.0, j as f32 * h));
                let dark = (square(i) + square(j)).rem_euclid(2) == 1;
                black.push(dark);
                colours.push(if dark {
                    [0.1, 0.2, 0.5]
                } else {
                    [0.9, 0.85, 0.7]
                });
            }
        }
        let n = means.len();
        let splats =
            Splats::from_points(&means, &colours, &vec![Vec3::splat(0.03); n], None, 0.8, 0)
                .unwrap();
        let weights = vec![1.0; n];
        let reach = 3.0;
        let plan = plan_merges(&splats, &weights, n / 4, reach);
        assert_eq!(plan.removed(), n - n / 4);
        // The same plan on one thread as on several.
        let one_thread = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| plan_merges(&splats, &weights, n / 4, reach));
        assert_eq!(plan, one_thread);
        for g in &plan.groups {
            assert!(
                g.iter().all(|&j| black[j] == black[g[0]]),
                "a group of {} takes in both colours",
                g.len()
            );
            let mean = g.iter().map(|&j| means[j]).sum::<Vec3>() / g.len() as f32;
            let var_x = g
                .iter()
                .map(|&j| (means[j].x - mean.x).powi(2))
                .sum::<f32>();
            let var_z = g
                .iter()
                .map(|&j| (means[j].z - mean.z).powi(2))
                .sum::<f32>();
            let longest = (var_x.max(var_z) / g.len() as f32).sqrt();
            assert!(longest <= reach * h * 1.001, "a group {longest} long");
        }
    }

    /// Stripes of one colour whose view dependence faces alternately +x and −x (equal SH
    /// coefficients but the sign of one band-1 term: the same DC and the same norm of the
    /// higher bands, which is all the planner compared before session 39): brought to a quarter,
    /// no group takes in both kinds, since what a colour looks like from every direction counts.
    #[test]
    fn glossy_splats_facing_different_ways_do_not_merge() {
        let h = 0.05;
        let mut means = Vec::new();
        let mut east = Vec::new();
        for i in 0..48 {
            for j in 0..48 {
                means.push(Vec3::new(i as f32 * h, 0.0, j as f32 * h));
                east.push((j / 6) % 2 == 0);
            }
        }
        let n = means.len();
        let mut splats = Splats::from_points(
            &means,
            &vec![[0.5, 0.4, 0.3]; n],
            &vec![Vec3::splat(0.03); n],
            None,
            0.8,
            1,
        )
        .unwrap();
        let k = splats.coeffs_per_splat();
        assert_eq!(k, 4);
        for (i, &e) in east.iter().enumerate() {
            // Band 1's x term (the fourth coefficient).
            splats.sh[i * k + 3] = [if e { 0.3 } else { -0.3 }; 3];
        }
        let weights = vec![1.0; n];
        let plan = plan_merges(&splats, &weights, n / 4, 7.0);
        assert_eq!(plan.removed(), n - n / 4);
        for g in &plan.groups {
            assert!(
                g.iter().all(|&j| east[j] == east[g[0]]),
                "a group of {} takes in both",
                g.len()
            );
        }
    }

    /// A uniform sheet whose splats' opacities are spread, as training leaves an overlapping
    /// surface, beside a small patch of random colours that carries little of the images: the
    /// sheet merges first, as its colour is one, and the patch keeps its splats. Opacity
    /// weighted signatures would charge the sheet's spread opacities as texture (with these
    /// figures they merged every splat of the patch).
    #[test]
    fn spread_opacities_of_a_uniform_surface_do_not_count_as_texture() {
        let mut means = Vec::new();
        let mut colours = Vec::new();
        let mut rand = xorshift(3);
        let h = 0.05;
        for i in 0..48 {
            for j in 0..48 {
                means.push(Vec3::new(i as f32 * h, 0.0, j as f32 * h));
                colours.push([0.8; 3]);
            }
        }
        let sheet = means.len();
        for i in 0..16 {
            for j in 0..16 {
                means.push(Vec3::new(3.0 + i as f32 * h, 0.0, j as f32 * h));
                colours.push([rand(), rand(), rand()]);
            }
        }
        let n = means.len();
        let mut splats =
            Splats::from_points(&means, &colours, &vec![Vec3::splat(0.03); n], None, 0.8, 0)
                .unwrap();
        for logit in &mut splats.opacity_logits {
            let o = 0.3 + 0.69 * rand();
            *logit = (o / (1.0 - o)).ln();
        }
        // The patch is a small object: each of its splats carries a twentieth of a sheet
        // splat's share of the images.
        let weights: Vec<f64> = (0..n).map(|i| if i < sheet { 1.0 } else { 0.05 }).collect();
        let plan = plan_merges(&splats, &weights, n / 2, 7.0);
        assert!(plan.removed() >= n - n / 2, "removed {}", plan.removed());
        let patch_merged = plan
            .groups
            .iter()
            .flatten()
            .filter(|&&j| j >= sheet)
            .count();
        assert_eq!(
            patch_merged, 0,
            "{patch_merged} of the patch's splats merged"
        );
    }
}
