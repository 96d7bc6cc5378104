//! Where a command may write: never over the files it reads.

use std::path::{Path, PathBuf};

use anyhow::bail;

/// A path resolved as far as it exists (links followed), for comparing with other paths: a file
/// not written yet resolves through its folder.
fn resolved(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    match (path.parent(), path.file_name()) {
        (Some(folder), Some(name)) if !folder.as_os_str().is_empty() => folder
            .canonicalize()
            .map_or_else(|_| path.to_path_buf(), |f| f.join(name)),
        _ => std::env::current_dir().map_or_else(|_| path.to_path_buf(), |d| d.join(path)),
    }
}

/// Refuses `output` when writing it would replace what the command reads: one of the `files`,
/// or a file that already lies in one of the `folders` (a dataset's images, its COLMAP model).
/// `what` names the output's flag in the message.
pub fn refuse_overwriting_inputs(
    output: &Path,
    what: &str,
    files: &[&Path],
    folders: &[&Path],
) -> anyhow::Result<()> {
    let out = resolved(output);
    for file in files {
        if resolved(file) == out {
            bail!(
                "{what} {} is {}, which this command reads: give another output",
                output.display(),
                file.display()
            );
        }
    }
    if out.is_file() {
        for folder in folders {
            if folder.canonicalize().is_ok_and(|f| out.starts_with(f)) {
                bail!(
                    "{what} {} would replace a file in {}, which this command reads: give \
                     another output",
                    output.display(),
                    folder.display()
                );
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inputs_are_refused_as_outputs_and_other_paths_are_not() {
        let dir = tempfile::tempdir().unwrap();
        let model = dir.path().join("m.ply");
        let images = dir.path().join("images");
        std::fs::create_dir(&images).unwrap();
        std::fs::write(&model, b"x").unwrap();
        std::fs::write(images.join("a.png"), b"x").unwrap();
        let check = |out: &Path| {
            refuse_overwriting_inputs(out, "--json", &[&model], &[&images])
                .map_err(|e| e.to_string())
        };
        // The model itself, also by another spelling of its path.
        let other_spelling = dir.path().join("images/../m.ply");
        for out in [&model, &other_spelling] {
            let msg = check(out).unwrap_err();
            assert!(msg.contains("which this command reads"), "{msg}");
        }
        // An existing file in a read folder; a new file there, and files elsewhere, are fine.
        assert!(
            check(&images.join("a.png"))
                .unwrap_err()
                .contains("would replace a file")
        );
        assert!(check(&images.join("new.json")).is_ok());
        assert!(check(&dir.path().join("metrics.json")).is_ok());
        assert!(check(&dir.path().join("no/such/folder/x.json")).is_ok());
    }
}
