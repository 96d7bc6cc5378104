//! Times each phase of the rasteriser's forward and backward passes on a trained model, from
//! one camera that frames it, and prints the minimum and the median over the repeats.
//!
//! ```text
//! cargo run --release -p splat-core --example phases -- MODEL.ply|torus [REPEATS] [THREADS]
//! ```
//!
//! `torus` times the criterion bench's scene instead (`benches/rasterize.rs`: 250k splats on a
//! bumpy torus, its camera, 1024²), so a change to the tile walks can be judged phase by phase
//! on the figure issue 14 sets.
//!
//! The minimum is what to compare between builds on a shared machine: other work only ever adds
//! time, so the fastest repeat is the one least disturbed (on the project's machine, one thread,
//! the projection's minimum came out 23.27 and 23.17 ms in two runs, its median 33.3 and 25.9);
//! alternate the builds, round after round, all the same. The camera looks down +z at the
//! model's bounding box from a distance that fits it in a 20° field of view, 1024² pixels;
//! the loss gradient is a fixed pseudo-random pattern on colour and alpha.

// A program whose output is its report (the library crates themselves never print).
#![allow(clippy::print_stdout, clippy::print_stderr)]

use std::path::Path;
use std::time::Duration;

use glam::{Mat3, Vec3};
use splat_core::{Rasterizer, RenderCamera, RenderOptions, SplatGrads, Splats};

#[path = "../benches/common/torus.rs"]
mod torus;
#[path = "../benches/common/torus_view.rs"]
mod torus_view;

fn main() {
    if let Err(e) = run() {
        eprintln!("phases: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        return Err("usage: phases MODEL.ply|torus [REPEATS] [THREADS]".into());
    };
    let repeats: usize = args.get(2).map_or(Ok(30), |s| s.parse())?;
    let threads: usize = args.get(3).map_or(Ok(2), |s| s.parse())?;
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()?;
    let (splats, cam) = if path == "torus" {
        (torus_view::torus_scene(250_000), torus_view::camera(1024))
    } else {
        let splats = splat_core::ply::read_splats(Path::new(path))?;
        let cam = framing_camera(&splats).ok_or_else(|| format!("{path} holds no splats"))?;
        (splats, cam)
    };
    let size = cam.width;
    let opts = RenderOptions::default();
    let pixels = (size * size) as usize;
    let pattern = |i: usize, k: usize| ((i.wrapping_mul(k)) % 1000) as f32 * 1e-9 - 5e-7;
    let d_rgb: Vec<f32> = (0..3 * pixels).map(|i| pattern(i, 2_654_435_761)).collect();
    let d_alpha: Vec<f32> = (0..pixels).map(|i| pattern(i, 40_503)).collect();
    let mut grads = SplatGrads::default();
    let mut r = Rasterizer::new();
    let names = [
        "project",
        "bin",
        "composite",
        "backward tiles",
        "backward sums",
        "chain",
    ];
    let mut times: Vec<[Duration; 6]> = Vec::with_capacity(repeats);
    let mut walls: Vec<f64> = Vec::with_capacity(repeats);
    for _ in 0..repeats.max(1) {
        let start = std::time::Instant::now();
        r.try_forward(&splats, &cam, &opts)?;
        r.backward(
            &splats,
            &cam,
            &opts,
            &d_rgb,
            Some(&d_alpha),
            None,
            &mut grads,
        );
        walls.push(start.elapsed().as_secs_f64() * 1e3);
        let p = r.phases();
        times.push([
            p.project,
            p.bin,
            p.composite,
            p.backward_tiles,
            p.backward_sum,
            p.backward_chain,
        ]);
    }
    let stats = r.stats();
    println!(
        "{} splats, {} visible, {} (tile, splat) pairs, {} evaluated (pixel, splat) pairs of \
         which {} contributed; {} thread(s), {} repeats; ms, minimum / median:",
        splats.len(),
        stats.visible,
        stats.pairs,
        stats.pixel_evaluations,
        stats.contributions,
        threads,
        times.len()
    );
    // Minimum and median of one figure's repeats.
    let row = |name: &str, mut ms: Vec<f64>| {
        ms.sort_by(f64::total_cmp);
        println!("  {name:<15} {:8.2} / {:8.2}", ms[0], ms[ms.len() / 2]);
    };
    for (k, name) in names.iter().enumerate() {
        row(
            name,
            times.iter().map(|t| t[k].as_secs_f64() * 1e3).collect(),
        );
    }
    let sums = times
        .iter()
        .map(|t| t.iter().map(Duration::as_secs_f64).sum::<f64>() * 1e3);
    row("all", sums.collect());
    // The whole forward + backward, start to end: what the phases leave out (buffers sized,
    // statistics gathered between them) is the difference.
    row("wall", walls);
    Ok(())
}

/// A camera looking down +z at the bounding box of `splats` from a distance that fits it in a
/// 20° field of view, 1024² pixels; `None` for an empty model.
fn framing_camera(splats: &Splats) -> Option<RenderCamera> {
    if splats.is_empty() {
        return None;
    }
    let (lo, hi) = splats.means.iter().fold(
        (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)),
        |(lo, hi), &m| (lo.min(m), hi.max(m)),
    );
    let size = 1024;
    let tan_half = 10.0_f32.to_radians().tan();
    let focal = 0.5 * size as f32 / tan_half;
    let distance = 1.15 * 0.5 * (hi - lo).max_element() / tan_half;
    let eye = 0.5 * (lo + hi) - Vec3::new(0.0, 0.0, distance);
    Some(RenderCamera {
        width: size,
        height: size,
        fx: focal,
        fy: focal,
        cx: 0.5 * size as f32,
        cy: 0.5 * size as f32,
        rotation: Mat3::IDENTITY,
        translation: -eye,
    })
}
