//! `transcode synth`: a synthetic plenoptic cloud (8iVSLF layout) from a real mesh.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use plenoptic_scenes::{AUTO_GRID, SynthConfig, synth_from_mesh};

/// Arguments of `transcode synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The mesh to sample (OBJ, glTF/GLB or PLY with faces).
    #[arg(long)]
    pub mesh: PathBuf,
    /// Output plenoptic PLY.
    #[arg(long)]
    pub out: PathBuf,
    /// Number of capture cameras (on two rings around the mesh).
    #[arg(long, default_value_t = SynthConfig::default().cameras)]
    pub cameras: usize,
    /// Number of surface samples (samples sharing a voxel are merged).
    #[arg(long, default_value_t = SynthConfig::default().points)]
    pub points: usize,
    /// Voxel grid width spanned by the mesh's longest side, or `auto`: chosen from the mesh's
    /// area and `--points` so the voxelised surface is watertight at one-voxel cubes.
    #[arg(long, default_value = "auto")]
    pub grid: Grid,
    /// Specular weight of the shading model.
    #[arg(long, default_value_t = SynthConfig::default().specular)]
    pub specular: f32,
    /// Blinn–Phong exponent of the shading model.
    #[arg(long, default_value_t = SynthConfig::default().shininess)]
    pub shininess: f32,
    /// Seed of the surface sampler.
    #[arg(long, default_value_t = SynthConfig::default().seed)]
    pub seed: u64,
}

/// Loads the mesh, synthesises the plenoptic cloud and writes it.
pub fn run(args: Args) -> anyhow::Result<()> {
    let spinner = ProgressBar::new_spinner().with_style(
        ProgressStyle::with_template("{spinner} {msg} [{elapsed}]")
            .unwrap_or_else(|_| ProgressStyle::default_spinner()),
    );
    spinner.enable_steady_tick(Duration::from_millis(120));
    spinner.set_message(format!("reading {}", args.mesh.display()));
    let mesh = plenoptic_io::read_mesh(&args.mesh)
        .with_context(|| format!("cannot read the mesh {}", args.mesh.display()))?;
    let config = SynthConfig {
        points: args.points,
        cameras: args.cameras,
        grid: args.grid.0.unwrap_or(AUTO_GRID),
        specular: args.specular,
        shininess: args.shininess,
        seed: args.seed,
        ..SynthConfig::default()
    };
    spinner.set_message(format!(
        "sampling {} points and shading them for {} cameras",
        args.points, args.cameras
    ));
    let cloud = synth_from_mesh(&mesh, &config)
        .with_context(|| format!("cannot synthesise from {}", args.mesh.display()))?;
    spinner.set_message(format!("writing {}", args.out.display()));
    plenoptic_io::write_cloud(&args.out, &cloud)
        .with_context(|| format!("cannot write {}", args.out.display()))?;
    spinner.finish_and_clear();
    println!(
        "wrote {} ({} points, {} capture cameras, grid {})",
        args.out.display(),
        cloud.len(),
        cloud.num_cameras,
        cloud.width.map_or(0, |w| w + 1)
    );
    Ok(())
}

/// `--grid`: `auto` or a grid width.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Grid(pub Option<u32>);

impl std::str::FromStr for Grid {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.eq_ignore_ascii_case("auto") {
            return Ok(Self(None));
        }
        s.parse::<u32>()
            .map(|g| Self(Some(g)))
            .map_err(|e| format!("expected `auto` or a grid width, got {s:?}: {e}"))
    }
}

#[cfg(test)]
mod tests {
    use clap::Parser;

    use super::*;

    #[derive(Debug, Parser)]
    struct Cli {
        #[command(flatten)]
        args: Args,
    }

    #[test]
    fn grid_flag_is_auto_by_default_or_a_width() {
        let parse = |extra: &[&str]| {
            let mut argv = vec!["synth", "--mesh", "m.obj", "--out", "o.ply"];
            argv.extend_from_slice(extra);
            Cli::try_parse_from(argv).map(|c| c.args.grid)
        };
        assert_eq!(parse(&[]).unwrap(), Grid(None));
        assert_eq!(parse(&["--grid", "AUTO"]).unwrap(), Grid(None));
        assert_eq!(parse(&["--grid", "256"]).unwrap(), Grid(Some(256)));
        let e = parse(&["--grid", "fine"]).unwrap_err().to_string();
        assert!(e.contains("fine"), "{e}");
    }
}
