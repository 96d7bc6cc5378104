//! `transcode info FILE [--json]`: what a point cloud, plenoptic cloud or mesh file holds.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use plenoptic_io::summary::{Bounds, ColorStats, Summary};

/// Arguments of `transcode info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The file to inspect (.ply, .obj, .gltf, .glb).
    pub file: PathBuf,
    /// Print one JSON object instead of the human-readable report.
    #[arg(long)]
    pub json: bool,
}

/// Loads the file and prints its summary.
pub fn run(args: Args) -> anyhow::Result<()> {
    // Reading is fast (a 200 MB plenoptic frame loads in well under a second); a spinner covers slow disks.
    let spinner = ProgressBar::new_spinner().with_style(
        ProgressStyle::with_template("{spinner} reading {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    spinner.set_message(args.file.display().to_string());
    spinner.enable_steady_tick(Duration::from_millis(120));
    let model = plenoptic_io::load(&args.file);
    spinner.finish_and_clear();
    let model = model?;
    let summary = Summary::of(&model);
    let format = format_of(&args.file);
    if args.json {
        let mut value = serde_json::to_value(&summary).context("serialising the summary")?;
        if let Some(object) = value.as_object_mut() {
            object.insert("file".into(), args.file.display().to_string().into());
            object.insert("format".into(), format.into());
        }
        println!("{value}");
    } else {
        print!(
            "{}",
            human(&args.file.display().to_string(), &format, &summary)
        );
    }
    Ok(())
}

/// The container format: the PLY encoding from its header, else the extension.
fn format_of(path: &std::path::Path) -> String {
    let ext = path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "ply" => plenoptic_io::ply::read_header(path)
            .map(|h| format!("PLY {}", h.format.keyword()))
            .unwrap_or_else(|_| "PLY".into()),
        "obj" => "OBJ".into(),
        "gltf" => "glTF 2.0".into(),
        "glb" => "GLB (binary glTF 2.0)".into(),
        other => other.to_string(),
    }
}

fn vec3(v: [f64; 3]) -> String {
    format!("({:.6}, {:.6}, {:.6})", v[0], v[1], v[2])
}

fn bounds(b: &Bounds) -> String {
    let size = [
        b.max[0] - b.min[0],
        b.max[1] - b.min[1],
        b.max[2] - b.min[2],
    ];
    format!("{} .. {}  (size {})", vec3(b.min), vec3(b.max), vec3(size))
}

fn stats(s: &ColorStats) -> String {
    format!(
        "mean ({:.3}, {:.3}, {:.3})  min ({:.3}, {:.3}, {:.3})  max ({:.3}, {:.3}, {:.3})",
        s.mean[0], s.mean[1], s.mean[2], s.min[0], s.min[1], s.min[2], s.max[0], s.max[1], s.max[2]
    )
}

/// The human-readable report.
fn human(file: &str, format: &str, s: &Summary) -> String {
    let mut out = String::new();
    let mut line = |k: &str, v: String| out.push_str(&format!("{k:<18}{v}\n"));
    let yes = |b: bool| if b { "yes" } else { "no" }.to_string();
    line("file", file.to_string());
    line("format", format.to_string());
    line("kind", s.kind.to_string());
    if let Some(n) = s.points {
        line("points", n.to_string());
    }
    if let Some(n) = s.vertices {
        line("vertices", n.to_string());
    }
    if let Some(n) = s.triangles {
        line("triangles", n.to_string());
    }
    if let Some(n) = s.materials {
        line("materials", n.to_string());
    }
    if s.materials.is_some() {
        let sizes: Vec<String> = s
            .textures
            .iter()
            .map(|t| format!("{}x{}", t.width, t.height))
            .collect();
        line(
            "textures",
            if sizes.is_empty() {
                "0".into()
            } else {
                format!("{} ({})", sizes.len(), sizes.join(", "))
            },
        );
        line("uvs", yes(s.has_uvs));
        line("vertex colours", yes(s.has_colors));
    }
    line("normals", yes(s.has_normals));
    line("capture cameras", s.capture_cameras.to_string());
    if let Some(b) = &s.bounds {
        line("bounds", bounds(b));
    }
    if let Some(w) = s.voxel_width {
        line("voxel width", w.to_string());
    }
    if let Some(f) = &s.frame_to_world {
        line(
            "frame to world",
            format!("world = voxel * {} + {}", f.scale, vec3(f.translation)),
        );
    }
    if let Some(b) = &s.world_bounds {
        line("world bounds", bounds(b));
    }
    if let Some(c) = &s.main_colors {
        line("main colour", stats(c));
    }
    for cam in &s.cameras {
        let position = cam.position.map_or_else(
            || "position unknown (no rig comments)".to_string(),
            |p| format!("at {} voxels", vec3(p)),
        );
        let colours = cam.colors.as_ref().map(stats).unwrap_or_default();
        line(
            &format!("camera {}", cam.index),
            format!("{position}\n{:<18}{colours}", ""),
        );
    }
    out
}
