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
            eprintln!("error: {}", message(&err));
            std::process::ExitCode::FAILURE
        }
    }
}

/// One line a person can act on: the chain of causes, outermost first, each said once (a typed
/// error whose message already ends with its source's, as `"{path}: {source}"` does, is not
/// followed by that source again).
fn message(err: &anyhow::Error) -> String {
    let mut out = String::new();
    for cause in err.chain() {
        let text = cause.to_string();
        if out.ends_with(&text) {
            continue;
        }
        if !out.is_empty() {
            out.push_str(": ");
        }
        out.push_str(&text);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::message;

    #[test]
    fn each_cause_is_said_once() {
        let missing = std::fs::read("/nonexistent/one.ply").unwrap_err();
        let typed = splat_core::Error::Io {
            path: "one.ply".into(),
            source: missing,
        };
        let err = anyhow::Error::from(typed).context("reading the model");
        let text = message(&err);
        assert!(
            text.starts_with("reading the model: one.ply: No such file or directory"),
            "{text}"
        );
        assert_eq!(text.matches("No such file").count(), 1, "{text}");
    }
}
