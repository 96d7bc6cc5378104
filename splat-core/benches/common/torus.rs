//! The bench scene shared by `splat-core`'s rasteriser benches and `splat-train`'s step benches
//! (included by path from both, so the two measure the same splats): flat discs on a bumpy
//! torus, the shape of a real trained model (one layer of overlapping surface splats).

use std::f32::consts::TAU;

use glam::Vec3;
use splat_core::Splats;

/// `n` splats on a torus (radii 1 and 0.4, with bumps), discs of about the local spacing with
/// a z scale of 1/8 of it, opacity 0.8, SH degree 3 with only the base colour set.
pub fn torus_scene(n: usize) -> Splats {
    let (big, small) = (1.0_f32, 0.4_f32);
    let area = TAU * big * TAU * small;
    let spacing = (area / n as f32).sqrt();
    let cols = ((TAU * big / spacing).round() as usize).max(1);
    let mut pts = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    let mut colors = Vec::with_capacity(n);
    let mut scales = Vec::with_capacity(n);
    for i in 0..n {
        let u = TAU * (i % cols) as f32 / cols as f32;
        let v = TAU * ((i / cols) as f32 + 0.5 * (i % 2) as f32) / (n / cols).max(1) as f32;
        let r = small * (1.0 + 0.1 * (5.0 * u).sin() * (3.0 * v).cos());
        let nrm = Vec3::new(u.cos() * v.cos(), u.sin() * v.cos(), v.sin());
        pts.push(Vec3::new(u.cos() * big, u.sin() * big, 0.0) + nrm * r);
        normals.push(nrm);
        colors.push([
            0.5 + 0.4 * (3.0 * u).sin(),
            0.5 + 0.4 * v.cos(),
            0.5 + 0.3 * nrm.z,
        ]);
        scales.push(Vec3::new(spacing * 0.8, spacing * 0.8, spacing * 0.1));
    }
    Splats::from_points(&pts, &colors, &scales, Some(&normals), 0.8, 3).expect("consistent inputs")
}
