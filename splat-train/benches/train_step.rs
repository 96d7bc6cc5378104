//! Training-step benches at `splat-core`'s two bench sizes (100k splats at 512², 250k at 1024²,
//! the same bumpy-torus surface scene): one full step = forward, loss (L1 + D-SSIM with its
//! gradient), backward, Adam. After the timed runs, the split of time per phase is printed.
//!
//! Run: `cargo bench -p splat-train --bench train_step`.
#![allow(clippy::print_stderr)] // benches print their measurements

use std::hint::black_box;

use camera_model::{Camera, Intrinsics, Pose};
use criterion::{Criterion, criterion_group, criterion_main};
use glam::DVec3;
use splat_core::{Rasterizer, RenderCamera, RenderOptions, Splats};
use splat_train::{TrainConfig, Trainer, View};

#[path = "../../splat-core/benches/common/torus.rs"]
mod torus;
use torus::torus_scene;

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
            let out = r.forward(model, &RenderCamera::try_from(&camera).unwrap(), &opts);
            View::from_straight(format!("v{i}"), camera, &out.rgb, None).unwrap()
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
