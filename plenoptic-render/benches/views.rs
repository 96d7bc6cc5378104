//! Reference renderer speed on an 8iVSLF-sized frame: 3 million voxels with 13 per-camera
//! colours, 44 Fibonacci views at 1024×1024 (the target: under a minute on 2 cores).
#![allow(clippy::print_stderr)] // benches print their measurements

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{DVec3, Vec3};
use plenoptic_io::{CaptureCamera, Model, PlenopticCloud};
use plenoptic_render::RigConfig;
use plenoptic_render::{self as views, PixelFilter, ViewOptions};
use rand::{RngExt, SeedableRng};

/// A closed voxelised sphere shell of radius `r` (voxels inside the ball with a 6-neighbour
/// outside), built column by column, centred in a 12-bit grid: ≈ 3.0 million points at r = 536.
fn voxel_sphere(r: i32) -> Vec<Vec3> {
    let r2 = i64::from(r) * i64::from(r);
    // Half-height of the column (x, y), or −1 when the column is empty.
    let top = |x: i32, y: i32| -> i64 {
        let d = r2 - i64::from(x) * i64::from(x) - i64::from(y) * i64::from(y);
        if d < 0 { -1 } else { (d as f64).sqrt() as i64 }
    };
    let mut out = Vec::new();
    for x in -r..=r {
        for y in -r..=r {
            let t = top(x, y);
            if t < 0 {
                continue;
            }
            let side = top(x - 1, y)
                .min(top(x + 1, y))
                .min(top(x, y - 1))
                .min(top(x, y + 1));
            for z in -t..=t {
                if z.abs() == t || z.abs() > side {
                    out.push(Vec3::new(x as f32, y as f32, z as f32) + Vec3::splat(2048.0));
                }
            }
        }
    }
    out
}

fn frame() -> PlenopticCloud {
    let positions = voxel_sphere(536);
    let n = positions.len();
    let cams = 13;
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(1);
    let mut color = || {
        [
            rng.random::<f32>(),
            rng.random::<f32>(),
            rng.random::<f32>(),
        ]
    };
    let colors = (0..n).map(|_| color()).collect();
    let camera_colors = (0..n * cams).map(|_| color()).collect();
    let cameras = (0..cams)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / cams as f64;
            let e: f64 = if k % 2 == 0 { 0.2 } else { 0.7 };
            let d = DVec3::new(a.cos() * e.cos(), e.sin(), a.sin() * e.cos());
            CaptureCamera {
                position: DVec3::splat(2048.0) + 3000.0 * d,
                matrix: None,
            }
        })
        .collect();
    PlenopticCloud {
        positions,
        colors,
        num_cameras: cams,
        camera_colors,
        cameras,
        ..Default::default()
    }
}

fn bench(c: &mut Criterion) {
    let cloud = frame();
    eprintln!(
        "frame: {} points, {} cameras",
        cloud.len(),
        cloud.num_cameras
    );
    let model = Model::Cloud(cloud);
    let (center, radius) = views::bounding_sphere(&model).unwrap();
    let rig = RigConfig {
        cameras: 44,
        width: 1024,
        height: 1024,
        ..RigConfig::default()
    };
    let cameras = views::fibonacci_rig(center, radius, &rig).unwrap();
    let opts = ViewOptions::default();

    let mut g = c.benchmark_group("views_3m_1024");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(20));
    // One view at each anti-aliasing setting: the default (3× Gaussian), 3× box and one sample
    // a pixel, so the default's cost is on record beside the aliased render's.
    let variants = [
        ("1_view", opts.clone()),
        (
            "1_view_box3",
            ViewOptions {
                pixel_filter: PixelFilter::Box,
                ..ViewOptions::default()
            },
        ),
        ("1_view_single_sample", ViewOptions::single_sample()),
    ];
    for (name, o) in &variants {
        g.bench_function(*name, |b| {
            b.iter(|| black_box(views::render_model(&model, &cameras[0], o).unwrap()))
        });
    }
    g.bench_function("44_views", |b| {
        b.iter(|| {
            views::render_each(&model, &cameras, &opts, |_, img| {
                black_box(img);
                Ok(())
            })
            .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
