//! Per-call cost of the camera maths used in loops: projecting points (f64 and the f32 copy),
//! rotation matrix → quaternion, and look-at.

use std::hint::black_box;

use camera_model::{Camera, Intrinsics, Pose, rotation};
use criterion::{Criterion, criterion_group, criterion_main};
use glam::{DVec3, Vec3};

/// 100,000 deterministic points in a 1024³ voxel grid.
fn points() -> Vec<DVec3> {
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 1024.0
    };
    (0..100_000)
        .map(|_| DVec3::new(next(), next(), next()))
        .collect()
}

fn bench(c: &mut Criterion) {
    let cam = Camera::new(
        Intrinsics::from_fov_y(1920, 1080, 20.0),
        Pose::look_at(
            DVec3::new(4000.0, 900.0, 3000.0),
            DVec3::splat(512.0),
            DVec3::Y,
        ),
    );
    let pts = points();
    c.bench_function("project 100k points (f64)", |b| {
        b.iter(|| {
            pts.iter()
                .filter_map(|&p| cam.project(black_box(p)))
                .fold(0.0, |acc, px| acc + px.x)
        })
    });
    let f = cam.to_f32();
    let pts32: Vec<Vec3> = pts.iter().map(|p| p.as_vec3()).collect();
    c.bench_function("project 100k points (CameraF32)", |b| {
        b.iter(|| {
            pts32
                .iter()
                .map(|&p| {
                    let q = f.rotation * black_box(p) + f.translation;
                    f.fx * q.x / q.z + f.cx
                })
                .sum::<f32>()
        })
    });
    let m = cam.pose.rotation_matrix();
    c.bench_function("quat_from_matrix", |b| {
        b.iter(|| rotation::quat_from_matrix(black_box(&m)))
    });
    c.bench_function("Pose::look_at", |b| {
        b.iter(|| {
            Pose::look_at(
                black_box(DVec3::new(4000.0, 900.0, 3000.0)),
                DVec3::splat(512.0),
                DVec3::Y,
            )
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
