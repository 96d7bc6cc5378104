//! PLACEHOLDER: owned by the helper implementing `transcode colmap`; replace this whole file.

/// `transcode colmap` subcommands (to be defined by the owner).
#[derive(Debug, clap::Subcommand)]
pub enum Command {
    /// Placeholder.
    Info,
}

/// Runs the subcommand.
pub fn run(_cmd: Command) -> anyhow::Result<()> {
    anyhow::bail!("this subcommand is not built yet")
}
