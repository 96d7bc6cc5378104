//! The frames of a sequence: a folder's model files or a glob's matches, in natural order.

use std::cmp::Ordering;
use std::path::{Path, PathBuf};

use super::SequenceError;

/// File extensions (lower case) of the inputs `transcode run` reads.
pub const FRAME_EXTENSIONS: [&str; 4] = ["ply", "obj", "gltf", "glb"];

/// One frame of a sequence.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    /// The input file.
    pub path: PathBuf,
    /// Its file stem: the name of its output folder and its entry in the manifest.
    pub name: String,
}

/// The frames named by `input`: every model file of a folder, or the files a glob pattern
/// (`*`, `?`, `[…]`) matches, in natural order (`frame_9` before `frame_10`), with the holes of
/// a numbered sequence as frames whose files do not exist. Refuses an empty
/// folder, a glob matching nothing, a path that is neither, and two frames with one stem.
pub fn list_frames(input: &str) -> Result<Vec<Frame>, SequenceError> {
    let as_path = Path::new(input);
    let paths: Vec<PathBuf> = if as_path.is_dir() {
        let entries = std::fs::read_dir(as_path).map_err(|source| SequenceError::Io {
            path: as_path.to_path_buf(),
            source,
        })?;
        let mut paths = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|source| SequenceError::Io {
                path: as_path.to_path_buf(),
                source,
            })?;
            let path = entry.path();
            // Hidden files are no frames: macOS's `._f_1.ply` beside `f_1.ply`, editors'
            // backups, and `..ply`, whose stem `.` would name the frames folder itself.
            let hidden = entry.file_name().to_string_lossy().starts_with('.');
            if !hidden && path.is_file() && has_frame_extension(&path) {
                paths.push(path);
            }
        }
        if paths.is_empty() {
            return Err(SequenceError::NoFrames(format!(
                "the folder {input} holds no frames (files ending in .{})",
                FRAME_EXTENSIONS.join(", .")
            )));
        }
        paths
    } else if input.contains(['*', '?', '[']) {
        let matches = glob::glob(input)
            .map_err(|e| SequenceError::NoFrames(format!("bad glob pattern {input}: {e}")))?;
        let mut paths = Vec::new();
        for m in matches {
            let path = m.map_err(|e| SequenceError::Io {
                path: e.path().to_path_buf(),
                source: std::io::Error::new(e.error().kind(), e.error().to_string()),
            })?;
            if path.is_file() {
                paths.push(path);
            }
        }
        if paths.is_empty() {
            return Err(SequenceError::NoFrames(format!(
                "the glob {input} matches no file"
            )));
        }
        paths
    } else if as_path.exists() {
        return Err(SequenceError::NoFrames(format!(
            "{input} is a file: a sequence is a folder of frames or a glob (e.g. 'frames/*.ply'); \
             `transcode run` takes one frame"
        )));
    } else {
        return Err(SequenceError::NoFrames(format!(
            "{input} does not exist (a sequence is a folder of frames or a glob)"
        )));
    };
    let mut frames: Vec<Frame> = paths
        .into_iter()
        .map(|path| Frame {
            name: path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default(),
            path,
        })
        .collect();
    if let Some(f) = frames
        .iter()
        .find(|f| f.name.is_empty() || f.name.starts_with('.'))
    {
        // Each frame's outputs go to `OUT/frames/NAME`: `.` and `..` are the frames folder and
        // the output folder themselves, which a frame's run would clear.
        return Err(SequenceError::NoFrames(format!(
            "{}: a frame's output folder is named by its file stem, and {:?} is hidden or names \
             a folder above it; rename the file",
            f.path.display(),
            f.name
        )));
    }
    frames.sort_by(|a, b| natural_cmp(&a.name, &b.name).then_with(|| a.path.cmp(&b.path)));
    for pair in frames.windows(2) {
        if pair[0].name == pair[1].name {
            return Err(SequenceError::NoFrames(format!(
                "frames {} and {} share the name {}: each frame's output folder is named by its \
                 file stem",
                pair[0].path.display(),
                pair[1].path.display(),
                pair[0].name
            )));
        }
    }
    Ok(with_gaps(frames))
}

/// Adds the frames missing from a numbered sequence. When every frame is one folder, one prefix,
/// one number and one extension (`longdress_vox10_1051.ply`, …) and the numbers step by a common
/// stride with holes, each hole becomes a frame whose file does not exist, so that the sequence
/// reports it (as a failed frame) instead of silently joining the frames on either side. Left
/// as they are: names that do not fit that pattern, and numbers with more holes than frames
/// (timestamps, a deliberate selection).
fn with_gaps(frames: Vec<Frame>) -> Vec<Frame> {
    struct Numbered<'a> {
        prefix: &'a str,
        digits: &'a str,
        number: u64,
    }
    let numbered: Option<Vec<Numbered<'_>>> = frames
        .iter()
        .map(|f| {
            let start = f.name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
            let (prefix, digits) = f.name.split_at(start);
            let number = (!digits.is_empty() && digits.len() <= 18)
                .then(|| digits.parse().ok())
                .flatten()?;
            Some(Numbered {
                prefix,
                digits,
                number,
            })
        })
        .collect();
    let Some(numbered) = numbered else {
        return frames;
    };
    let first = &frames[0];
    let same = |f: &Frame, n: &Numbered<'_>| {
        n.prefix == numbered[0].prefix
            && f.path.parent() == first.path.parent()
            && f.path.extension() == first.path.extension()
    };
    if frames.len() < 2 || !frames.iter().zip(&numbered).all(|(f, n)| same(f, n)) {
        return frames;
    }
    // Zero-padded numbers must all have one width, which the holes then get too.
    let padded = numbered.iter().any(|n| n.digits.starts_with('0'));
    let width = numbered[0].digits.len();
    if padded && numbered.iter().any(|n| n.digits.len() != width) {
        return frames;
    }
    let steps: Vec<u64> = numbered
        .windows(2)
        .map(|w| w[1].number.saturating_sub(w[0].number))
        .collect();
    let Some(stride) = steps.iter().copied().min().filter(|&d| d > 0) else {
        return frames;
    };
    let holes: u64 = steps.iter().map(|d| d / stride - 1).sum();
    if steps.iter().any(|d| d % stride != 0) || holes == 0 || holes > frames.len() as u64 {
        return frames;
    }
    let extension = first
        .path
        .extension()
        .map(|e| format!(".{}", e.to_string_lossy()))
        .unwrap_or_default();
    let folder = first.path.parent().unwrap_or(Path::new(""));
    let mut out = Vec::with_capacity(frames.len() + holes as usize);
    for (k, frame) in frames.iter().enumerate() {
        if k > 0 {
            let mut n = numbered[k - 1].number + stride;
            while n < numbered[k].number {
                let name = if padded {
                    format!("{}{n:0width$}", numbered[0].prefix)
                } else {
                    format!("{}{n}", numbered[0].prefix)
                };
                out.push(Frame {
                    path: folder.join(format!("{name}{extension}")),
                    name,
                });
                n += stride;
            }
        }
        out.push(frame.clone());
    }
    out
}

fn has_frame_extension(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| FRAME_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// Natural order: runs of digits compare by value (`frame_9` < `frame_10`), the rest by
/// character; between equal values, fewer leading zeros first.
#[must_use]
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a, b);
    loop {
        match (a.chars().next(), b.chars().next()) {
            (None, None) => return Ordering::Equal,
            (None, Some(_)) => return Ordering::Less,
            (Some(_), None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let (da, ra) = split_digits(a);
                let (db, rb) = split_digits(b);
                let (va, vb) = (da.trim_start_matches('0'), db.trim_start_matches('0'));
                let by_value = va.len().cmp(&vb.len()).then_with(|| va.cmp(vb));
                let order = by_value.then_with(|| da.len().cmp(&db.len()));
                if order != Ordering::Equal {
                    return order;
                }
                (a, b) = (ra, rb);
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(&y);
                }
                (a, b) = (&a[x.len_utf8()..], &b[y.len_utf8()..]);
            }
        }
    }
}

fn split_digits(s: &str) -> (&str, &str) {
    let end = s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len());
    s.split_at(end)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order_compares_numbers_by_value() {
        let mut names = vec![
            "frame_10",
            "frame_9",
            "frame_100",
            "frame_09",
            "frame_1",
            "frame",
            "frame_2b",
            "frame_2a",
            "other_1",
        ];
        names.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(
            names,
            [
                "frame",
                "frame_1",
                "frame_2a",
                "frame_2b",
                "frame_9",
                "frame_09",
                "frame_10",
                "frame_100",
                "other_1"
            ]
        );
        // Longer than any integer type: compared as digit strings.
        assert_eq!(
            natural_cmp("f99999999999999999999999", "f100000000000000000000000"),
            Ordering::Less
        );
    }

    #[test]
    fn folders_globs_and_their_refusals() {
        let dir = tempfile::tempdir().unwrap();
        for name in ["s_10.ply", "s_9.ply", "s_1.PLY", "notes.txt", "s_2.obj"] {
            std::fs::write(dir.path().join(name), b"x").unwrap();
        }
        std::fs::create_dir(dir.path().join("sub.ply")).unwrap();
        let names = |frames: Vec<Frame>| frames.into_iter().map(|f| f.name).collect::<Vec<_>>();
        let folder = dir.path().to_str().unwrap();
        assert_eq!(
            names(list_frames(folder).unwrap()),
            ["s_1", "s_2", "s_9", "s_10"]
        );
        let pattern = format!("{folder}/s_*.ply");
        assert_eq!(names(list_frames(&pattern).unwrap()), ["s_9", "s_10"]);
        // Hidden files in a folder are no frames (`._s_1.ply`, and `..ply` whose stem `.` named
        // the frames folder itself); a glob that names them is refused.
        let hidden = dir.path().join("hidden");
        std::fs::create_dir(&hidden).unwrap();
        for name in ["a.ply", "._a.ply", "..ply", "...ply"] {
            std::fs::write(hidden.join(name), b"x").unwrap();
        }
        assert_eq!(names(list_frames(hidden.to_str().unwrap()).unwrap()), ["a"]);
        let dots = list_frames(&format!("{}/.*ply", hidden.display())).unwrap_err();
        assert!(
            dots.to_string()
                .contains("is hidden or names a folder above it"),
            "{dots}"
        );

        // Holes in a numbered sequence become frames whose files do not exist.
        let numbered = dir.path().join("numbered");
        std::fs::create_dir(&numbered).unwrap();
        for n in [1051, 1052, 1054, 1057] {
            std::fs::write(numbered.join(format!("longdress_vox10_{n}.ply")), b"x").unwrap();
        }
        let listed = list_frames(numbered.to_str().unwrap()).unwrap();
        let missing: Vec<&str> = listed
            .iter()
            .filter(|f| !f.path.exists())
            .map(|f| f.name.as_str())
            .collect();
        assert_eq!(listed.len(), 7);
        assert_eq!(
            missing,
            [
                "longdress_vox10_1053",
                "longdress_vox10_1055",
                "longdress_vox10_1056"
            ]
        );
        assert_eq!(listed[2].path, numbered.join("longdress_vox10_1053.ply"));
        // Zero padding is kept; a stride of 2 is a stride, not holes.
        let holes = |names: &[&str]| -> Vec<String> {
            let frames: Vec<Frame> = names
                .iter()
                .map(|n| Frame {
                    path: PathBuf::from(format!("d/{n}.ply")),
                    name: (*n).into(),
                })
                .collect();
            let known: Vec<&str> = names.to_vec();
            with_gaps(frames)
                .into_iter()
                .map(|f| f.name)
                .filter(|n| !known.contains(&n.as_str()))
                .collect()
        };
        assert_eq!(holes(&["f_0008", "f_0010", "f_0014"]), ["f_0012"]);
        assert!(holes(&["f_0", "f_2", "f_4"]).is_empty());
        // More holes than frames (a selection, timestamps), mixed prefixes: left alone.
        assert!(holes(&["t_100", "t_101", "t_200"]).is_empty());
        assert!(holes(&["a_1", "b_3"]).is_empty());
        assert!(holes(&["f_1", "f_3", "g"]).is_empty());

        let error = |input: &str| list_frames(input).unwrap_err().to_string();
        assert!(error(&format!("{folder}/none_*.ply")).contains("matches no file"));
        let empty = tempfile::tempdir().unwrap();
        assert!(error(empty.path().to_str().unwrap()).contains("holds no frames"));
        assert!(error(&format!("{folder}/s_9.ply")).contains("is a file"));
        assert!(error(&format!("{folder}/missing")).contains("does not exist"));
        std::fs::write(dir.path().join("s_9.obj"), b"x").unwrap();
        let clash = error(folder);
        assert!(clash.contains("share the name s_9"), "{clash}");
    }
}
