//! The training loss (L1 + D-SSIM with its gradient) on a 1024² view of a single object: a disc
//! covering about 40 % of the view where the render differs from the reference by noise, and a
//! background where both are the same colour, as in a paper-scale frame's views (the SSIM passes
//! work only where the images differ, so the share of the view the object covers sets the cost).
//!
//! Run: `cargo bench -p splat-train --bench loss`.

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use splat_train::Photometric;
use splat_train::loss::Loss;

/// A reference and a render of `size`² pixels: the same background, a disc of texture that the
/// render reproduces up to noise.
fn images(size: usize) -> (Vec<f32>, Vec<f32>) {
    let mut state = 0x9E37_79B9_7F4A_7C15_u64;
    let mut noise = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    };
    let (mut reference, mut render) = (vec![0.0; 3 * size * size], vec![0.0; 3 * size * size]);
    let c = size as f32 / 2.0;
    let radius = 0.36 * size as f32;
    for y in 0..size {
        for x in 0..size {
            let (dx, dy) = (x as f32 - c, y as f32 - c);
            let inside = dx * dx + dy * dy < radius * radius;
            for ch in 0..3 {
                let i = 3 * (y * size + x) + ch;
                let texture =
                    0.5 + 0.4 * ((x * (ch + 1)) as f32 * 0.05).sin() * (y as f32 * 0.03).cos();
                reference[i] = if inside { texture } else { 1.0 };
                render[i] = if inside {
                    (texture + 0.05 * noise()).clamp(0.0, 1.0)
                } else {
                    1.0
                };
            }
        }
    }
    (reference, render)
}

fn loss(c: &mut Criterion) {
    let size = 1024;
    let (reference, render) = images(size);
    let mut loss = Loss::new(size as u32, size as u32);
    c.bench_function("loss_l1_dssim_1024", |b| {
        b.iter(|| black_box(loss.evaluate(black_box(&render), &reference, Photometric::L1, 0.2)));
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(30);
    targets = loss
}
criterion_main!(benches);
