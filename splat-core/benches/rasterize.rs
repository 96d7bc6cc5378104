//! Forward and forward+backward rasteriser benches on a surface scene: splats as flat discs on
//! a bumpy torus (the shape of a real trained model: one layer of overlapping surface splats),
//! seen from a camera that frames it.
//!
//! Run: `cargo bench -p splat-core --bench rasterize`.

use std::f32::consts::TAU;
use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{Mat3, Vec3};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats};

/// `n` splats on a torus (radii 1 and 0.4, with bumps), discs of about the local spacing,
/// SH degree 3 with small view-dependent terms.
fn torus_scene(n: usize) -> Splats {
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
    let mut s = Splats::from_points(&pts, &colors, &scales, Some(&normals), 0.8, 3)
        .expect("consistent inputs");
    for (j, c) in s.sh.iter_mut().enumerate() {
        if j % 16 != 0 {
            let t = j as f32 * 0.618;
            *c = [0.05 * t.sin(), 0.05 * t.cos(), 0.03 * (2.0 * t).sin()];
        }
    }
    s
}

/// A camera 3.2 units from the origin looking at it from above the torus plane, 50° field of view.
fn camera(size: u32) -> RenderCamera {
    let eye = Vec3::new(0.0, -2.2, 2.3);
    let z = (-eye).normalize();
    let x = Vec3::Z.cross(z).normalize();
    let y = z.cross(x);
    let rotation = Mat3::from_cols(x, y, z).transpose();
    let f = 0.5 * size as f32 / (25.0_f32.to_radians()).tan();
    RenderCamera {
        width: size,
        height: size,
        fx: f,
        fy: f,
        cx: 0.5 * size as f32,
        cy: 0.5 * size as f32,
        rotation,
        translation: -(rotation * eye),
    }
}

fn bench(c: &mut Criterion) {
    for (n, size) in [(100_000, 512), (250_000, 1024)] {
        let s = torus_scene(n);
        let cam = camera(size);
        let opts = RenderOptions::default();
        let mut r = Rasterizer::new();
        r.forward(&s, &cam, &opts);
        let st = r.stats();
        eprintln!(
            "{n} splats, {size}²: {} visible, {} tile pairs, {} pixel-splat evaluations, {} contributions",
            st.visible, st.pairs, st.pixel_evaluations, st.contributions
        );
        let mut g = SplatGrads::zeros_like(&s);
        let d_rgb = vec![1e-3_f32; 3 * (size * size) as usize];
        let mut group = c.benchmark_group(format!("{}k_{size}", n / 1000));
        group.sample_size(10);
        group.bench_function("forward", |b| {
            b.iter(|| black_box(r.forward(&s, &cam, &opts).rgb[0]));
        });
        group.bench_function("forward_backward", |b| {
            b.iter(|| {
                r.forward(&s, &cam, &opts);
                r.backward(&s, &cam, &opts, &d_rgb, None, None, &mut g);
                black_box(g.means[0])
            });
        });
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
