//! `transcode demo [--out DIR]`: the built-in plenoptic scene through the whole pipeline.

use std::path::PathBuf;

use anyhow::Context as _;
use plenoptic_scenes::{DemoConfig, DemoLayout, demo_scene};
use transcode::config::Config;

use super::config::{Overrides, flat};
use super::progress::Reporter;

/// Arguments of `transcode demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output folder (input/demo.ply, dataset/, model/, report/).
    #[arg(long, value_name = "DIR", default_value = "out/demo")]
    out: PathBuf,
    /// Voxel grid width of the demo scene (128 gives about 35,000 points).
    #[arg(long, default_value_t = DemoConfig::default().grid)]
    grid: u32,
    /// The scene: `slab` (a checkered slab under a glossy red sphere: texture everywhere) or
    /// `floor` (a wide plain floor under a small glossy checkered ball: a large flat region and
    /// a small detailed object).
    #[arg(long, default_value = "slab", value_parser = parse_layout)]
    layout: DemoLayout,
    #[command(flatten)]
    overrides: Overrides,
    /// Print nothing but errors and the result.
    #[arg(long)]
    quiet: bool,
}

/// The demo's settings: the defaults, scaled so the whole demo runs in about a minute on two
/// cores: 256² views and a 3,000-step schedule under a 60 s training budget. Recent 2-core
/// hosts finish the schedule inside it (the whole demo took 27–53 s in sessions 62–66,
/// docs/BENCHMARKS.md); a slower machine fits the schedule to the budget.
#[must_use]
pub fn demo_config() -> Config {
    let mut c = Config::default();
    c.rig.width = 256;
    c.rig.height = 256;
    c.training.iterations = 3_000;
    c.training.time_budget_s = Some(60.0);
    c
}

/// Runs `transcode demo`.
pub fn run(args: Args) -> anyhow::Result<()> {
    let config = args.overrides.resolve(demo_config())?;
    let scene = DemoConfig {
        grid: args.grid,
        layout: args.layout,
        ..DemoConfig::default()
    };
    if !args.quiet {
        eprintln!(
            "generating the demo scene ({:?} layout, grid {})",
            scene.layout, scene.grid
        );
    }
    let cloud = demo_scene(&scene).context("generating the demo scene")?;
    let input_dir = args.out.join("input");
    std::fs::create_dir_all(&input_dir)
        .with_context(|| format!("cannot create {}", input_dir.display()))?;
    let input = input_dir.join("demo.ply");
    plenoptic_io::write_cloud(&input, &cloud)
        .with_context(|| format!("cannot write the demo scene to {}", input.display()))?;
    let reporter = Reporter::new(args.quiet);
    let outcome = transcode::pipeline::run(&input, &args.out, &config, &|e| reporter.show(e))
        .map_err(flat)?;
    super::run::print_outcome(&outcome);
    Ok(())
}

/// `--layout`: `slab` or `floor`.
fn parse_layout(s: &str) -> Result<DemoLayout, String> {
    match s {
        "slab" => Ok(DemoLayout::Slab),
        "floor" => Ok(DemoLayout::Floor),
        _ => Err(format!("expected `slab` or `floor`, got {s:?}")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_flag_names_the_two_scenes() {
        assert_eq!(parse_layout("slab"), Ok(DemoLayout::Slab));
        assert_eq!(parse_layout("floor"), Ok(DemoLayout::Floor));
        assert!(
            parse_layout("Floor")
                .unwrap_err()
                .contains("`slab` or `floor`")
        );
    }
}
