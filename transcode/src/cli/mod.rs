//! Command-line interface: one module per subcommand, each with its own `Args` and `run`.

use clap::{Parser, Subcommand};

#[cfg(feature = "scenes")]
mod bench;
mod colmap;
mod config;
mod convert;
#[cfg(feature = "scenes")]
mod demo;
mod eval;
mod info;
mod outputs;
mod progress;
mod render;
mod run;
mod sequence;
#[cfg(feature = "scenes")]
mod synth;
mod train;
mod view;
mod views;

/// Turn plenoptic point clouds and meshes into 3D Gaussian Splatting models.
#[derive(Debug, Parser)]
#[command(name = "transcode", version, about)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Print what a point cloud, plenoptic cloud or mesh file holds.
    Info(info::Args),
    /// Inspect and convert COLMAP sparse models.
    #[command(subcommand)]
    Colmap(colmap::Command),
    /// Render a 3DGS PLY from the cameras of a COLMAP model.
    Render(render::Args),
    /// Train splats on a COLMAP dataset folder (images/ + sparse/0/).
    Train(train::Args),
    /// Run the whole pipeline: input model to 3DGS model with a report.
    Run(run::Args),
    /// Run the pipeline on every frame of a sequence (a folder or glob), warm-started and
    /// resumable, optionally as one shard of a cluster job.
    Sequence(sequence::Args),
    /// Render the reference views of an input and write the COLMAP dataset only.
    Views(views::Args),
    /// Evaluate a 3DGS model against reference views with their COLMAP cameras.
    Eval(eval::Args),
    /// Generate the built-in plenoptic demo scene and run the pipeline on it.
    #[cfg(feature = "scenes")]
    Demo(demo::Args),
    /// Generate a synthetic plenoptic cloud from a real mesh.
    #[cfg(feature = "scenes")]
    Synth(synth::Args),
    /// Generate a frame of a given size and measure the pipeline's speed on it (reading,
    /// reference views, rasteriser at several thread counts, a training step's phases).
    #[cfg(feature = "scenes")]
    Bench(bench::Args),
    /// Print or check the configuration shared by all subcommands.
    Config(config::Args),
    /// Serve the splat viewer on this machine: an output folder's report, or any PLY/SPZ model.
    View(view::Args),
    /// Convert a splat model between 3DGS PLY, SPZ, .splat and .glb (by extension).
    Convert(convert::Args),
}

/// Runs the chosen subcommand.
pub fn dispatch(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Info(a) => info::run(a),
        Command::Colmap(c) => colmap::run(c),
        Command::Render(a) => render::run(a),
        Command::Train(a) => train::run(a),
        Command::Run(a) => run::run(a),
        Command::Sequence(a) => sequence::run(a),
        Command::Views(a) => views::run(a),
        Command::Eval(a) => eval::run(a),
        #[cfg(feature = "scenes")]
        Command::Demo(a) => demo::run(a),
        #[cfg(feature = "scenes")]
        Command::Synth(a) => synth::run(a),
        #[cfg(feature = "scenes")]
        Command::Bench(a) => bench::run(a),
        Command::Config(a) => config::run(a),
        Command::View(a) => view::run(a),
        Command::Convert(a) => convert::run(a),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether `transcode ARGS` parses; the error's text when it does not.
    fn parses(args: &[&str]) -> Result<(), String> {
        let argv = std::iter::once("transcode").chain(args.iter().copied());
        Cli::try_parse_from(argv)
            .map(drop)
            .map_err(|e| e.to_string())
    }

    /// A command offers only the flags it acts on: `eval` took (and ignored) every pipeline
    /// flag, `views` every training one.
    #[test]
    fn commands_refuse_the_flags_they_would_ignore() {
        let eval = ["eval", "m.ply", "--reference", "d"];
        assert!(parses(&[&eval[..], &["--config", "c.toml", "--plain"]].concat()).is_ok());
        for flag in [
            ["--resolution", "64"],
            ["--cameras", "8"],
            ["--splats", "10"],
        ] {
            let e = parses(&[&eval[..], &flag[..]].concat()).unwrap_err();
            assert!(
                e.contains(&format!("unexpected argument '{}'", flag[0])),
                "{e}"
            );
        }
        let views = ["views", "in.ply", "--out", "d"];
        let rig = [
            "--config",
            "c.toml",
            "--resolution",
            "64",
            "--cameras",
            "8",
            "--fov",
            "40",
        ];
        assert!(parses(&[&views[..], &rig[..]].concat()).is_ok());
        for flag in [
            ["--heldout", "2"],
            ["--iterations", "9"],
            ["--splats", "10"],
        ] {
            let e = parses(&[&views[..], &flag[..]].concat()).unwrap_err();
            assert!(
                e.contains(&format!("unexpected argument '{}'", flag[0])),
                "{e}"
            );
        }
        let run = [
            "run",
            "in.ply",
            "--out",
            "o",
            "--heldout",
            "2",
            "--splats",
            "10",
        ];
        assert!(parses(&[&run[..], &rig[..], &["--antialiased"]].concat()).is_ok());
    }
}
