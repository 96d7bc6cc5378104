//! Writes the kind of model the transcoder exports: a Fibonacci rig of PINHOLE cameras around
//! a voxel-sized object (one camera straight above it, where look-at needs its pole rule),
//! points on the object's bounding sphere, and next to it `projections.txt` with where
//! `camera-model` projects every point in every image (`IMAGE_ID POINT3D_ID U V`, only points
//! in front of the camera and inside the image). The pycolmap interop test projects the same
//! points with COLMAP's own code and compares.
//!
//! Run: `cargo run -p colmap-io --example rig_model -- OUT_DIR [txt|bin]`
#![allow(clippy::print_stdout)] // examples print their results

use std::fmt::Write as _;
use std::path::PathBuf;

use camera_model::{GlViewport, rig};
use colmap_io::dataset::{points_without_tracks, reconstruction_from_cameras};
use colmap_io::{Format, write_model};
use glam::DVec3;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().ok_or("usage: rig_model OUT_DIR [txt|bin]")?);
    let format = match args.next().as_deref() {
        None | Some("bin") => Format::Binary,
        Some("txt") => Format::Text,
        Some(other) => return Err(format!("unknown encoding `{other}` (txt or bin)").into()),
    };

    // An 8iVSLF-like object: centre of a 1024³ voxel grid, bounding sphere of radius 600.
    let (target, radius) = (DVec3::new(512.0, 480.0, 530.0), 600.0);
    let intrinsics = GlViewport::new(DVec3::ZERO, DVec3::Z, DVec3::Y, 800, 600).intrinsics();
    let distance = rig::framing_distance(radius, &intrinsics, 0.05)?;
    let mut directions = rig::fibonacci_sphere(11);
    directions.push(rig::WORLD_UP); // straight above: up is parallel to the view
    let mut cameras = rig::look_at_rig(&directions, target, distance, intrinsics, rig::WORLD_UP);
    // One camera given as a PccAppRenderer viewport, converted with the OpenGL → COLMAP rule.
    let eye = target + DVec3::new(-0.3, 0.2, 1.0).normalize() * distance;
    cameras.push(GlViewport::new(eye, target, DVec3::new(0.1, 1.0, 0.0), 800, 600).to_colmap());
    let names: Vec<String> = (0..cameras.len())
        .map(|i| format!("cam_{i:03}.png"))
        .collect();
    let mut rec = reconstruction_from_cameras(names.iter().map(String::as_str).zip(&cameras))?;
    rec.points3d = points_without_tracks(rig::fibonacci_sphere(200).into_iter().enumerate().map(
        |(i, d)| {
            (
                target + d * radius * 0.9,
                [(i % 256) as u8, 128, 255 - (i % 256) as u8],
            )
        },
    ));
    write_model(&out, &rec, format)?;

    let mut projections = String::from("# IMAGE_ID POINT3D_ID U V (camera-model)\n");
    for &image_id in rec.images.keys() {
        let camera = rec.camera_of(image_id)?;
        for (&point_id, point) in &rec.points3d {
            if let Some(px) = camera
                .project(point.xyz)
                .filter(|px| camera.intrinsics.contains(*px))
            {
                writeln!(projections, "{image_id} {point_id} {:?} {:?}", px.x, px.y)?;
            }
        }
    }
    atomic_output::write_atomic(&out.join("projections.txt"), projections.as_bytes())?;
    println!(
        "wrote {} cameras and {} points to {}",
        cameras.len(),
        rec.points3d.len(),
        out.display()
    );
    Ok(())
}
