//! Reading an 8iVSLF-sized plenoptic frame: 3,000,000 points, 13 capture cameras, 66 bytes a
//! point (float xyz, float normal, uchar main colour, 13 × uchar colours), binary little endian.
//! Compares, in the same run, our reader with ply-rs-bw reading the same file into a struct
//! (its fast, allocation-free way), and ply-rs-bw's generic `DefaultElement` on a smaller file
//! (at 3 M points it needs ~17 GB, see docs/reference/crates.md §2).
//!
//! `PLENOPTIC_BENCH_POINTS` overrides the point count.

use std::hint::black_box;
use std::path::{Path, PathBuf};

use criterion::{Criterion, criterion_group, criterion_main};
use glam::{DVec3, Vec3};
use plenoptic_io::{CaptureCamera, PlenopticCloud, read_cloud, write_cloud};
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{DefaultElement, PropertyAccess, PropertyAccessResult};

const CAMERAS: usize = 13;

/// A deterministic frame of `n` points on a voxel grid of width 4095 with 13 cameras.
fn frame(n: usize) -> PlenopticCloud {
    let mut s = 0x2545_F491_4F6C_DD1Du64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let positions = (0..n)
        .map(|_| {
            Vec3::new(
                (next() % 4096) as f32,
                (next() % 4096) as f32,
                (next() % 4096) as f32,
            )
        })
        .collect();
    let normals = Some((0..n).map(|_| Vec3::new(0.0, 1.0, 0.0)).collect());
    let colors = (0..n).map(|_| [(next() % 256) as f32 / 255.0; 3]).collect();
    let camera_colors = (0..n * CAMERAS)
        .map(|_| [(next() % 256) as f32 / 255.0, 0.5, 0.25])
        .collect();
    let cameras = (0..CAMERAS)
        .map(|k| CaptureCamera {
            position: DVec3::new(k as f64 * 300.0, 2048.0, -5000.0),
            matrix: None,
        })
        .collect();
    PlenopticCloud {
        positions,
        normals,
        colors,
        num_cameras: CAMERAS,
        camera_colors,
        cameras,
        frame_to_world_scale: Some(0.179523 / 4.0),
        frame_to_world_translation: Some(DVec3::new(-45.2095, 7.18301, -54.3561)),
        width: Some(4095),
        ..PlenopticCloud::default()
    }
}

/// Writes the frame once (kept between runs) and returns its path.
fn frame_file(n: usize) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"));
    let path = dir.join(format!("plenoptic-bench-{n}.ply"));
    if !path.exists() {
        write_cloud(&path, &frame(n)).unwrap_or_else(|e| panic!("{e}"));
    }
    path
}

/// One 8iVSLF vertex as ply-rs-bw fills it: one name match per property per vertex.
#[derive(Default)]
struct Vertex {
    position: [f32; 3],
    normal: [f32; 3],
    color: [u8; 3],
    cameras: [[u8; 3]; CAMERAS],
}

impl PropertyAccess for Vertex {
    fn new() -> Self {
        Self::default()
    }

    fn set_float(&mut self, name: &str, value: f32) -> PropertyAccessResult {
        match name {
            "x" => self.position[0] = value,
            "y" => self.position[1] = value,
            "z" => self.position[2] = value,
            "nx" => self.normal[0] = value,
            "ny" => self.normal[1] = value,
            "nz" => self.normal[2] = value,
            _ => return PropertyAccessResult::Ignored,
        }
        PropertyAccessResult::Set
    }

    fn set_uchar(&mut self, name: &str, value: u8) -> PropertyAccessResult {
        let (channel, rest) = if let Some(r) = name.strip_prefix("red") {
            (0, r)
        } else if let Some(r) = name.strip_prefix("green") {
            (1, r)
        } else if let Some(r) = name.strip_prefix("blue") {
            (2, r)
        } else {
            return PropertyAccessResult::Ignored;
        };
        if rest.is_empty() {
            self.color[channel] = value;
        } else {
            match rest.parse::<usize>() {
                Ok(k) if k < CAMERAS => self.cameras[k][channel] = value,
                _ => return PropertyAccessResult::Ignored,
            }
        }
        PropertyAccessResult::Set
    }
}

fn ply_rs_bw_struct(path: &Path) -> Vec<Vertex> {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{e}"));
    let mut reader = Reader::new(std::io::BufReader::with_capacity(1 << 20, file));
    let parser = Parser::<Vertex>::new();
    let header = parser
        .read_header(&mut reader)
        .unwrap_or_else(|e| panic!("{e}"));
    parser
        .read_payload_for_element(&mut reader, &header.elements["vertex"], &header)
        .unwrap_or_else(|e| panic!("{e}"))
}

fn bench(c: &mut Criterion) {
    let n: usize = std::env::var("PLENOPTIC_BENCH_POINTS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3_000_000);
    let path = frame_file(n);
    // Both readers must see the same data before being timed against each other.
    let ours = read_cloud(&path).unwrap_or_else(|e| panic!("{e}"));
    let theirs = ply_rs_bw_struct(&path);
    assert_eq!(ours.len(), theirs.len());
    for i in [0, n / 2, n - 1] {
        assert_eq!(ours.positions[i].to_array(), theirs[i].position);
        assert_eq!(
            ours.camera_colors_of(i)[12][0],
            f32::from(theirs[i].cameras[12][0]) / 255.0
        );
    }
    drop((ours, theirs));

    let mut group = c.benchmark_group(format!("read {n} points, {CAMERAS} cameras, 66 B/point"));
    group.sample_size(10);
    group.bench_function("plenoptic_io::read_cloud", |b| {
        b.iter(|| black_box(read_cloud(&path).unwrap_or_else(|e| panic!("{e}"))))
    });
    group.bench_function("ply-rs-bw into a struct", |b| {
        b.iter(|| black_box(ply_rs_bw_struct(&path)))
    });
    group.finish();

    let small = (n / 30).max(1);
    let small_path = frame_file(small);
    let mut group = c.benchmark_group(format!(
        "read {small} points, {CAMERAS} cameras, 66 B/point"
    ));
    group.sample_size(10);
    group.bench_function("plenoptic_io::read_cloud", |b| {
        b.iter(|| black_box(read_cloud(&small_path).unwrap_or_else(|e| panic!("{e}"))))
    });
    group.bench_function("ply-rs-bw DefaultElement (generic)", |b| {
        b.iter(|| {
            let mut reader = std::io::BufReader::new(
                std::fs::File::open(&small_path).unwrap_or_else(|e| panic!("{e}")),
            );
            black_box(
                Parser::<DefaultElement>::new()
                    .read_ply(&mut reader)
                    .unwrap_or_else(|e| panic!("{e}")),
            )
        })
    });
    group.finish();

    let write_dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let cloud = read_cloud(&path).unwrap_or_else(|e| panic!("{e}"));
    let mut group = c.benchmark_group(format!("write {n} points, {CAMERAS} cameras"));
    group.sample_size(10);
    group.bench_function("plenoptic_io::write_cloud", |b| {
        b.iter(|| {
            write_cloud(&write_dir.path().join("w.ply"), &cloud).unwrap_or_else(|e| panic!("{e}"))
        })
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
