//! Training-step benches at `splat-core`'s two bench sizes (100k splats at 512², 250k at 1024²,
//! the same bumpy-torus surface scene): one full step = forward, loss (L1 + D-SSIM with its
//! gradient), backward, Adam. After the timed runs, the split of time per phase is printed.
//!
//! Run: `cargo bench -p splat-train --bench train_step`.

use std::f32::consts::TAU;
use std::hint::black_box;

use camera_model::{Camera, Intrinsics, Pose};
use criterion::{Criterion, criterion_group, criterion_main};
use glam::{DVec3, Vec3};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, Splats};
use splat_train::{TrainConfig, Trainer, View};

/// `n` splats on a torus (radii 1 and 0.4, with bumps), as `splat-core`'s rasteriser bench.
fn torus_scene(n: usize) -> Splats {
    let (big, small) = (1.0_f32, 0.4_f32);
    let spacing = (TAU * big * TAU * small / n as f32).sqrt();
    let cols = ((TAU * big / spacing).round() as usize).max(1);
    let (mut pts, mut normals, mut colors, mut scales) = (vec![], vec![], vec![], vec![]);
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

/// Four cameras 3.2 units from the origin above the torus plane, 50° field of view.
fn views(model: &Splats, size: u32) -> Vec<View> {
    let f = 0.5 * f64::from(size) / 25.0_f64.to_radians().tan();
    let k = Intrinsics::centered(size, size, f, f);
    let mut r = Rasterizer::new();
    let opts = RenderOptions::default();
    (0..4)
        .map(|i| {
            let a = f64::from(i) * std::f64::consts::FRAC_PI_2;
            let eye = DVec3::new(2.2 * a.sin(), -2.2 * a.cos(), 2.3);
            let camera = Camera::new(k, Pose::look_at(eye, DVec3::ZERO, DVec3::Z));
            let image = r
                .forward(model, &RenderCamera::from(&camera), &opts)
                .rgb
                .clone();
            View {
                name: format!("v{i}"),
                camera,
                image,
                mask: None,
            }
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    for (n, size) in [(100_000, 512), (250_000, 1024)] {
        let truth = torus_scene(n);
        let views = views(&truth, size);
        // Start from the truth with flattened colour so that every step has real gradients.
        let mut start = truth.clone();
        for (j, c) in start.sh.iter_mut().enumerate() {
            if j % 16 == 0 {
                *c = [0.0; 3];
            }
        }
        let cfg = TrainConfig {
            iterations: u32::MAX,
            densify: None,
            sh_degree_interval: 0,
            ..TrainConfig::default()
        };
        let mut t = Trainer::new(start, views, cfg).expect("valid setup");
        let mut group = c.benchmark_group(format!("{}k_{size}", n / 1000));
        group.sample_size(10);
        group.bench_function("train_step", |b| b.iter(|| black_box(t.step().loss)));
        group.finish();
        let tm = t.timings();
        let per = |d: std::time::Duration| 1e3 * d.as_secs_f64() / tm.steps as f64;
        eprintln!(
            "{n} splats, {size}²: per step forward {:.1} ms, loss {:.1} ms, backward {:.1} ms, Adam {:.1} ms over {} steps",
            per(tm.forward),
            per(tm.loss),
            per(tm.backward),
            per(tm.adam),
            tm.steps
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
