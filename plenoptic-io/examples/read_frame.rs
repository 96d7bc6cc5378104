//! Reads a PLY cloud or any supported model and prints what it holds and how long reading took.
//!
//! `cargo run --release -p plenoptic-io --example read_frame -- FILE`
#![allow(clippy::print_stdout)] // examples print their results

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Some(path) = std::env::args_os().nth(1) else {
        return Err("usage: read_frame FILE".into());
    };
    let start = Instant::now();
    let model = plenoptic_io::load(std::path::Path::new(&path))?;
    let elapsed = start.elapsed();
    let summary = plenoptic_io::summary::Summary::of(&model);
    println!(
        "{}: {} points, {} vertices, {} triangles, {} capture cameras, read in {:.3} s",
        summary.kind,
        summary.points.unwrap_or(0),
        summary.vertices.unwrap_or(0),
        summary.triangles.unwrap_or(0),
        summary.capture_cameras,
        elapsed.as_secs_f64()
    );
    Ok(())
}
