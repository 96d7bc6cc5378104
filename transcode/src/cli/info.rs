//! `transcode info FILE [--json]`: what a point cloud, plenoptic cloud, mesh or 3DGS splat model
//! file holds.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use plenoptic_io::summary::{Bounds, ColorStats, Summary};

/// Arguments of `transcode info`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The file to inspect (.ply, .obj, .gltf, .glb, .spz, .splat).
    pub file: PathBuf,
    /// Print one JSON object instead of the human-readable report.
    #[arg(long)]
    pub json: bool,
}

/// Loads the file and prints its summary.
pub fn run(args: Args) -> anyhow::Result<()> {
    if let Some(splats) = SplatSummary::of(&args.file)? {
        if args.json {
            println!("{}", serde_json::to_value(&splats)?);
        } else {
            print!("{}", splats.human());
        }
        return Ok(());
    }
    // Reading is fast (a 200 MB plenoptic frame loads in well under a second); a spinner covers slow disks.
    let spinner = ProgressBar::new_spinner().with_style(
        ProgressStyle::with_template("{spinner} reading {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    spinner.set_message(args.file.display().to_string());
    spinner.enable_steady_tick(Duration::from_millis(120));
    let model = plenoptic_io::load(&args.file);
    spinner.finish_and_clear();
    let model = match model {
        Err(plenoptic_io::Error::UnsupportedFormat { path, extension }) => anyhow::bail!(
            "{}: unsupported file type '{extension}': info reads clouds and meshes (.ply, .obj, \
             .gltf, .glb) and splat models (.ply, .spz, .splat, .glb)",
            path.display()
        ),
        other => other?,
    };
    let summary = Summary::of(&model);
    let format = format_of(&args.file);
    let drawn = drawn_as(&model);
    if args.json {
        let mut value = serde_json::to_value(&summary).context("serialising the summary")?;
        if let Some(object) = value.as_object_mut() {
            object.insert("file".into(), args.file.display().to_string().into());
            object.insert("format".into(), format.into());
            if let Some((kind, size, _)) = &drawn {
                let sizing = serde_json::json!({ "kind": kind, "size": size });
                object.insert("point_sizing".into(), sizing);
            }
        }
        println!("{value}");
    } else {
        let mut text = human(&args.file.display().to_string(), &format, &summary);
        if let Some((_, _, sentence)) = drawn {
            text.push_str(&format!("{:<18}{sentence}\n", "reference views"));
        }
        print!("{text}");
    }
    Ok(())
}

/// How the reference views draw a cloud's points with the default renderer settings
/// ([`plenoptic_render::point_sizing`]): its kind (`as_configured`, `grown`, `off_grid`, `voxelised`), the
/// cube side in the cloud's units and the sentence a run prints; `None` for a mesh.
fn drawn_as(model: &plenoptic_io::Model) -> Option<(&'static str, f32, String)> {
    use plenoptic_render::PointSizing;
    let plenoptic_io::Model::Cloud(_) = model else {
        return None;
    };
    let options = plenoptic_render::ViewOptions::default();
    let sizing = options.point_sizing(model);
    let kind = match sizing {
        PointSizing::AsConfigured => "as_configured",
        PointSizing::Grown(_) => "grown",
        PointSizing::OffGrid(_) => "off_grid",
        PointSizing::Voxelised(_) => "voxelised",
    };
    Some((kind, sizing.size(options.point_size), sizing.to_string()))
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

/// What a 3DGS splat model file holds.
#[derive(Debug, serde::Serialize)]
struct SplatSummary {
    file: String,
    format: String,
    kind: &'static str,
    splats: usize,
    sh_degree: u32,
    /// How the file says the model is drawn: `antialiased` (opacity compensated) or `plain`.
    drawn: &'static str,
    bounds: Option<Bounds>,
    /// Median activated opacity.
    opacity_median: f32,
    /// Medians of each splat's largest and smallest standard deviation.
    sigma_largest_median: f32,
    sigma_smallest_median: f32,
}

impl SplatSummary {
    /// The summary of `path` if it is a splat model: an SPZ or `.splat` file, a PLY whose vertices
    /// have 3DGS properties, or a `.glb` with a `KHR_gaussian_splatting` primitive; `None` for
    /// other files (clouds and meshes).
    fn of(path: &std::path::Path) -> anyhow::Result<Option<Self>> {
        use splat_core::model_file::{self, Format};
        let Ok(format) = Format::of(path) else {
            return Ok(None);
        };
        let splat_ply =
            |path| plenoptic_io::ply::read_header(path).is_ok_and(|h| h.holds_gaussian_splats());
        // A PLY without 3DGS properties is a cloud or a mesh, and so is a .glb whose reader
        // finds no splat primitive.
        let file = match format {
            Format::Ply if !splat_ply(path) => return Ok(None),
            Format::Glb => match model_file::read_model(path) {
                Ok(file) => file,
                Err(_) => return Ok(None),
            },
            _ => model_file::read_model(path)?,
        };
        let name = match (format, file.spz_version) {
            (Format::Ply, _) => "3DGS PLY".to_string(),
            (Format::Spz, Some(version)) => format!("SPZ version {version}"),
            (Format::Spz, None) => "SPZ".to_string(),
            (Format::Splat, _) => "antimatter15 .splat".to_string(),
            (Format::Glb, _) => "GLB with KHR_gaussian_splatting".to_string(),
        };
        let (splats, antialiased) = (file.splats, file.antialiased);
        let s = &splats;
        let median = |mut v: Vec<f32>| {
            v.sort_by(f32::total_cmp);
            v.get(v.len() / 2).copied().unwrap_or(f32::NAN)
        };
        let bounds = (!s.is_empty()).then(|| {
            let (lo, hi) = s.means.iter().fold(
                (
                    glam::Vec3::splat(f32::INFINITY),
                    glam::Vec3::splat(f32::NEG_INFINITY),
                ),
                |(lo, hi), &m| (lo.min(m), hi.max(m)),
            );
            Bounds {
                min: lo.as_dvec3().to_array(),
                max: hi.as_dvec3().to_array(),
            }
        });
        Ok(Some(Self {
            file: path.display().to_string(),
            format: name,
            kind: "3DGS splat model",
            splats: s.len(),
            sh_degree: s.sh_degree,
            drawn: if antialiased { "antialiased" } else { "plain" },
            bounds,
            opacity_median: median((0..s.len()).map(|i| s.opacity(i)).collect()),
            sigma_largest_median: median((0..s.len()).map(|i| s.scale(i).max_element()).collect()),
            sigma_smallest_median: median((0..s.len()).map(|i| s.scale(i).min_element()).collect()),
        }))
    }

    /// The human-readable report.
    fn human(&self) -> String {
        let mut out = String::new();
        let mut line = |k: &str, v: String| out.push_str(&format!("{k:<18}{v}\n"));
        line("file", self.file.clone());
        line("format", self.format.clone());
        line("kind", self.kind.to_string());
        line("splats", self.splats.to_string());
        line("SH degree", self.sh_degree.to_string());
        line(
            "drawn",
            match self.drawn {
                "antialiased" => "antialiased (the file says it was trained with the opacity \
                                  compensation)"
                    .to_string(),
                _ => "plain".to_string(),
            },
        );
        if let Some(b) = &self.bounds {
            line("bounds", bounds(b));
        }
        // (An empty model has no medians: its NaNs are not printed.)
        if self.splats > 0 {
            line("opacity", format!("median {:.3}", self.opacity_median));
            line(
                "sigma",
                format!(
                    "median of the largest axis {:.6}, of the smallest {:.6}",
                    self.sigma_largest_median, self.sigma_smallest_median
                ),
            );
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn testdata(rel: &str) -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../testdata")
            .join(rel)
    }

    #[test]
    fn splat_models_are_told_from_clouds_and_meshes_with_their_render_mode() {
        let gt = testdata("splat-scene/gt.ply");
        let plain = SplatSummary::of(&gt)
            .unwrap()
            .expect("gt.ply is a splat model");
        assert_eq!((plain.splats, plain.sh_degree), (4000, 3));
        assert_eq!((plain.format.as_str(), plain.drawn), ("3DGS PLY", "plain"));
        let splats = splat_core::ply::read_splats(&gt).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let tagged = dir.path().join("aa.ply");
        let options = splat_core::ply::PlyOptions { antialiased: true };
        splat_core::ply::write_model(&tagged, &splats, &options).unwrap();
        assert_eq!(
            SplatSummary::of(&tagged).unwrap().unwrap().drawn,
            "antialiased"
        );
        let spz = dir.path().join("m.spz");
        let v4 = splat_core::spz::SpzOptions {
            version: 4,
            antialiased: true,
            ..splat_core::spz::SpzOptions::default()
        };
        splat_core::spz::write_spz(&spz, &splats, &v4).unwrap();
        let s = SplatSummary::of(&spz).unwrap().unwrap();
        assert_eq!(
            (s.format.as_str(), s.drawn),
            ("SPZ version 4", "antialiased")
        );
        assert!(s.human().contains("antialiased (the file says"));
        // Clouds and meshes are not splat models, whatever their extension.
        for other in [
            "meshes/misc/cube_binary.ply",
            "meshes/misc/bun_zipper_res4.ply",
            "meshes/box-textured/BoxTextured.glb",
            "meshes/spider/spider.obj",
        ] {
            assert!(
                SplatSummary::of(&testdata(other)).unwrap().is_none(),
                "{other}"
            );
        }
    }

    /// `info` says how the reference views will draw a cloud: at the voxel for a voxelised
    /// cloud, a cell of its own grid for one voxelised at another pitch, at its own spacing for
    /// one on no grid; nothing for a mesh.
    #[test]
    fn clouds_say_how_their_points_are_drawn() {
        // A plane of 60 × 60 points one voxel apart, and the same scaled by 0.00137.
        let plane = |scale: f32| {
            let positions = (0..3600)
                .map(|i| scale * glam::Vec3::new((i % 60) as f32, (i / 60) as f32, 7.0))
                .collect();
            plenoptic_io::Model::Cloud(plenoptic_io::PlenopticCloud {
                colors: vec![[0.5; 3]; 3600],
                positions,
                ..Default::default()
            })
        };
        let (kind, size, sentence) = drawn_as(&plane(0.00137)).unwrap();
        assert_eq!(kind, "voxelised");
        assert!((size / 0.00137 - 1.0).abs() < 1e-3, "{size}");
        assert!(
            sentence.contains("on a grid of pitch 0.001370"),
            "{sentence}"
        );
        // Off every grid (each point nudged by a different share of a spacing).
        let plenoptic_io::Model::Cloud(mut off) = plane(0.00137) else {
            unreachable!()
        };
        for (i, p) in off.positions.iter_mut().enumerate() {
            let h = (i as f32 * 0.618_034).fract() - 0.5;
            *p += glam::Vec3::new(0.3 * h, 0.2 * h, 0.0) * 0.00137;
        }
        let (kind, size, sentence) = drawn_as(&plenoptic_io::Model::Cloud(off)).unwrap();
        assert_eq!(kind, "off_grid");
        assert!((size / 0.00137 - 1.5).abs() < 0.2, "{size}");
        assert!(sentence.contains("on no grid"), "{sentence}");
        let (kind, size, _) = drawn_as(&plane(1.0)).unwrap();
        assert_eq!((kind, size), ("as_configured", 1.0));
        let mesh = plenoptic_io::load(&testdata("meshes/spider/spider.obj")).unwrap();
        assert!(drawn_as(&mesh).is_none());
    }
}
