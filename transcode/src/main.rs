//! The `transcode` command: turn plenoptic point clouds and meshes into 3DGS models.
// The binary is the one place in the workspace that prints (`print_*` lints warn everywhere
// else): its commands, here and in `cli/`, talk to the person at the terminal.
#![allow(clippy::print_stdout, clippy::print_stderr)]

mod cli;

use clap::Parser;

fn main() -> std::process::ExitCode {
    let args = cli::Cli::parse();
    match cli::dispatch(args) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(err) => {
            // One line a person can act on: the chain of causes, outermost first.
            eprintln!("error: {err:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
