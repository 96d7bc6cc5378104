//! `transcode synth`: a synthetic plenoptic cloud (8iVSLF layout) from a real mesh.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::Context;
use indicatif::{ProgressBar, ProgressStyle};
use plenoptic_scenes::{
    AUTO_GRID, Motion, SequenceSynth, SynthConfig, frame_file_name, synth_from_mesh,
};

/// Arguments of `transcode synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The mesh to sample (OBJ, glTF/GLB or PLY with faces).
    #[arg(long)]
    pub mesh: PathBuf,
    /// Output plenoptic PLY; with `--frames` above 1, the folder the frames are written to
    /// (`MESH_voxB_0001.ply`, …, 8iVSLF-style names that sort in frame order).
    #[arg(long)]
    pub out: PathBuf,
    /// Number of frames: above 1, a sequence of the mesh turning, shifting and bending on one
    /// voxel grid with one capture rig (see `--turn`, `--shift`, `--bend`).
    #[arg(long, default_value_t = 1, value_parser = parse_frames)]
    pub frames: usize,
    /// Turn about the vertical axis over the sequence, in degrees.
    #[arg(long, default_value_t = Motion::default().turn_deg)]
    pub turn: f64,
    /// Shift along x over the sequence, in bounding radii of the mesh.
    #[arg(long, default_value_t = Motion::default().shift)]
    pub shift: f64,
    /// Amplitude of the back-and-forth bend (top and bottom swaying along x), in radii.
    #[arg(long, default_value_t = Motion::default().bend)]
    pub bend: f64,
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
    // The frame replaced the mesh it was made from (a plenoptic cloud, no longer a mesh).
    super::outputs::refuse_overwriting_inputs(&args.out, "--out", &[&args.mesh], &[])?;
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
    if args.frames > 1 {
        spinner.finish_and_clear();
        return sequence(&args, &mesh, &config);
    }
    // The folder the frame goes into is made now, so that a path that cannot be written fails
    // before the sampling and shading rather than after them.
    if let Some(parent) = args.out.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)
            .with_context(|| format!("cannot create the folder {}", parent.display()))?;
    }
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

/// `synth --frames N`: the sequence, frame by frame, into the folder `args.out`.
fn sequence(args: &Args, mesh: &plenoptic_io::Mesh, config: &SynthConfig) -> anyhow::Result<()> {
    let motion = Motion {
        turn_deg: args.turn,
        shift: args.shift,
        bend: args.bend,
    };
    let plan = SequenceSynth::new(mesh, config, motion, args.frames)
        .with_context(|| format!("cannot plan a sequence from {}", args.mesh.display()))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create the folder {}", args.out.display()))?;
    let name = args
        .mesh
        .file_stem()
        .map_or_else(|| "frame".into(), |s| s.to_string_lossy().into_owned());
    let bar = ProgressBar::new(args.frames as u64).with_style(
        ProgressStyle::with_template("{bar:30} {pos}/{len} frames {msg} [{elapsed}, ETA {eta}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut points = Vec::with_capacity(args.frames);
    for k in 0..args.frames {
        let path = args.out.join(frame_file_name(&name, plan.grid(), k));
        bar.set_message(path.display().to_string());
        let cloud = plan
            .frame(k)
            .with_context(|| format!("cannot synthesise frame {}", k + 1))?;
        plenoptic_io::write_cloud(&path, &cloud)
            .with_context(|| format!("cannot write {}", path.display()))?;
        points.push(cloud.len());
        bar.inc(1);
    }
    bar.finish_and_clear();
    println!(
        "wrote {} frames to {} ({}–{} points, {} capture cameras, grid {})",
        args.frames,
        args.out.display(),
        points.iter().min().unwrap_or(&0),
        points.iter().max().unwrap_or(&0),
        config.cameras,
        plan.grid()
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

/// `--frames`: at least one.
fn parse_frames(s: &str) -> Result<usize, String> {
    match s.parse::<usize>() {
        Ok(0) => Err("a sequence has at least 1 frame".into()),
        Ok(n) => Ok(n),
        Err(e) => Err(e.to_string()),
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
