//! Forward and forward+backward rasteriser benches on a surface scene: splats as flat discs on
//! a bumpy torus (the shape of a real trained model: one layer of overlapping surface splats),
//! seen from a camera that frames it.
//!
//! Run: `cargo bench -p splat-core --bench rasterize`.
#![allow(clippy::print_stderr)] // benches print their measurements

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use splat_core::{Rasterizer, RenderOptions, SplatGrads};

#[path = "common/torus.rs"]
mod torus;
#[path = "common/torus_view.rs"]
mod torus_view;

use torus_view::{camera, torus_scene};

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
