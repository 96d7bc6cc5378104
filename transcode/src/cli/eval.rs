//! PLACEHOLDER: owned by the helper implementing this subcommand; replace this whole file.

/// Arguments (to be defined by the subcommand's owner).
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Runs the subcommand.
pub fn run(_args: Args) -> anyhow::Result<()> {
    anyhow::bail!("this subcommand is not built yet")
}
