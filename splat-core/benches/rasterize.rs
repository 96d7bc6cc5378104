//! Forward and forward+backward rasteriser benches on a surface scene: splats as flat discs on
//! a bumpy torus (the shape of a real trained model: one layer of overlapping surface splats),
//! seen from a camera that frames it.
//!
//! Run: `cargo bench -p splat-core --bench rasterize`.
#![allow(clippy::print_stderr)] // benches print their measurements

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{Mat3, Vec3};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats};

#[path = "common/torus.rs"]
mod torus;

/// The shared torus scene with small view-dependent SH terms added.
fn torus_scene(n: usize) -> Splats {
    let mut s = torus::torus_scene(n);
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
