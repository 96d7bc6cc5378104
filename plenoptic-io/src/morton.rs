//! Morton (Z-curve) order of points: points close in space come close in the order, whatever
//! order the file lists them in. The reference renderer draws a cloud in this order so it writes
//! its z-buffer a neighbourhood at a time; initialisation lays splats out in it so a tile's list
//! of splats reads records that lie near each other in memory.

use glam::Vec3;
use rayon::prelude::*;

/// Bits per axis of the quantised positions (3 × 21 = 63 bits of a `u64` code).
const BITS: u32 = 21;

/// The indices of `positions` in Morton order of their positions quantised to 2^21 cells per
/// axis across the bounding box; ties (points in one cell) keep their index order, so the order
/// depends on the positions alone. A NaN coordinate falls into the first cell, an infinite one
/// into the first or last.
#[must_use]
pub fn morton_order(positions: &[Vec3]) -> Vec<u32> {
    let finite = positions.iter().filter(|p| p.is_finite());
    let lo = finite.clone().fold(Vec3::INFINITY, |a, &p| a.min(p));
    let hi = finite.fold(Vec3::NEG_INFINITY, |a, &p| a.max(p));
    let extent = (hi - lo).max_element();
    let scale = if extent > 0.0 && extent.is_finite() {
        ((1u32 << BITS) - 1) as f32 / extent
    } else {
        0.0
    };
    let cell = |v: f32, lo: f32| -> u32 {
        // `as` saturates: NaN and anything below the box go to 0, rounding above it to the top.
        (((v - lo) * scale) as u32).min((1 << BITS) - 1)
    };
    let mut keyed: Vec<(u64, u32)> = positions
        .par_iter()
        .enumerate()
        .map(|(i, p)| {
            let code = spread(cell(p.x, lo.x))
                | (spread(cell(p.y, lo.y)) << 1)
                | (spread(cell(p.z, lo.z)) << 2);
            (code, i as u32)
        })
        .collect();
    keyed.par_sort_unstable();
    keyed.into_iter().map(|(_, i)| i).collect()
}

/// The low 21 bits of `v` spread to every third bit of a `u64` (bit i to bit 3i). Written here:
/// it is five mask-and-shift steps, less than a dependency would cost.
fn spread(v: u32) -> u64 {
    let mut x = u64::from(v) & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit i of v to bit 3i, one bit at a time.
    fn spread_by_bits(v: u32) -> u64 {
        (0..BITS).fold(0, |acc, i| acc | (u64::from((v >> i) & 1) << (3 * i)))
    }

    #[test]
    fn spreading_matches_the_bit_by_bit_form() {
        let mut v = 1u32;
        for _ in 0..10_000 {
            v = v.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            assert_eq!(spread(v), spread_by_bits(v & 0x1f_ffff), "{v:#x}");
        }
        assert_eq!(spread(0x1f_ffff), 0x1249_2492_4924_9249);
    }

    /// On a grid the order is a permutation that visits the eight octants one after another,
    /// each as one contiguous run, recursively: here the first two levels.
    #[test]
    fn order_is_a_permutation_that_visits_octants_in_turn() {
        let n = 8i32;
        let mut points = Vec::new();
        // A scrambled listing of an 8×8×8 grid.
        for i in 0..n * n * n {
            let j = (i * 149) % (n * n * n);
            points.push(Vec3::new(
                (j % n) as f32,
                ((j / n) % n) as f32,
                (j / (n * n)) as f32,
            ));
        }
        let order = morton_order(&points);
        let mut seen = order.clone();
        seen.sort_unstable();
        assert_eq!(seen, (0..points.len() as u32).collect::<Vec<_>>());
        for (level, size) in [(1, 4.0), (2, 2.0)] {
            // Octant of a point at this level: which cell of side `size` it lies in.
            let octant = |p: Vec3| ((p / size).floor()).to_array().map(|c| c as i32);
            let runs = order
                .windows(2)
                .filter(|w| octant(points[w[0] as usize]) != octant(points[w[1] as usize]))
                .count()
                + 1;
            assert_eq!(runs, 8usize.pow(level), "level {level}");
        }
        // x varies fastest: the first two points are (0,0,0) and (1,0,0).
        assert_eq!(points[order[0] as usize], Vec3::ZERO);
        assert_eq!(points[order[1] as usize], Vec3::X);
    }

    #[test]
    fn degenerate_clouds_order_without_panicking() {
        assert!(morton_order(&[]).is_empty());
        assert_eq!(morton_order(&[Vec3::ONE; 3]), vec![0, 1, 2]);
        let odd = [
            Vec3::NAN,
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::INFINITY,
            Vec3::ZERO,
        ];
        let mut order = morton_order(&odd);
        order.sort_unstable();
        assert_eq!(order, vec![0, 1, 2, 3]);
    }
}
