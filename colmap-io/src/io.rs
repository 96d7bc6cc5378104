//! Reading and writing whole models in a folder, in either encoding.

use std::collections::BTreeMap;
use std::collections::btree_map::Range;
use std::io::Write;
use std::path::Path;

use rayon::prelude::*;

use crate::binary::POINT2D_SIZE;
use crate::error::{Location, Problem};

use crate::{Error, Point3D, Reconstruction, binary, text};

/// Encoding of a model's files.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Format {
    /// `cameras.txt`, `images.txt`, `points3D.txt`.
    Text,
    /// `cameras.bin`, `images.bin`, `points3D.bin`.
    Binary,
}

impl Format {
    /// File extension of the encoding, without the dot.
    #[must_use]
    pub fn extension(self) -> &'static str {
        match self {
            Format::Text => "txt",
            Format::Binary => "bin",
        }
    }
}

/// The encoding of the model in `dir`, if a complete one is there; binary first, as COLMAP.
#[must_use]
pub fn detect_format(dir: &Path) -> Option<Format> {
    [Format::Binary, Format::Text].into_iter().find(|f| {
        ["cameras", "images", "points3D"]
            .iter()
            .all(|name| dir.join(format!("{name}.{}", f.extension())).is_file())
    })
}

/// Reads the model in `dir` (binary if all three `.bin` files are there, else text), and checks
/// that every image's camera, every observation's 3D point and every track element exist.
/// Files written by newer COLMAP beside the model (`rigs.bin`, `frames.bin`) are ignored.
pub fn read_model(dir: &Path) -> Result<Reconstruction, Error> {
    let format = detect_format(dir).ok_or_else(|| Error::NoModel {
        dir: dir.to_path_buf(),
    })?;
    read_model_as(dir, format)
}

/// Reads the model in `dir` in the given encoding (see [`read_model`]).
pub fn read_model_as(dir: &Path, format: Format) -> Result<Reconstruction, Error> {
    let path = |name: &str| dir.join(format!("{name}.{}", format.extension()));
    let (cameras_path, images_path, points_path) =
        (path("cameras"), path("images"), path("points3D"));
    let (cameras, images, points) = match format {
        Format::Text => (
            text::read_cameras(&cameras_path)?,
            text::read_images(&images_path)?,
            text::read_points3d(&points_path)?,
        ),
        Format::Binary => (
            binary::read_cameras(&cameras_path)?,
            binary::read_images(&images_path)?,
            binary::read_points3d(&points_path)?,
        ),
    };
    let rec = Reconstruction {
        cameras,
        images: images.images,
        points3d: points.points,
    };
    if let Err(problem) = rec.validate_images() {
        let location = match &problem {
            Problem::MissingPoint3D {
                image_id,
                point2d_idx,
                ..
            } => match images.points2d_location.get(image_id) {
                Some(Location::Offset(o)) => {
                    Location::Offset(o + POINT2D_SIZE * *point2d_idx as u64)
                }
                Some(other) => *other,
                None => Location::File,
            },
            Problem::MissingCamera { image_id, .. } => images
                .record_location
                .get(image_id)
                .copied()
                .unwrap_or(Location::File),
            _ => Location::File,
        };
        return Err(Error::Format {
            path: images_path,
            location,
            problem,
        });
    }
    if let Err((pid, problem)) = rec.validate_points() {
        let location = points.location.get(&pid).copied().unwrap_or(Location::File);
        return Err(Error::Format {
            path: points_path,
            location,
            problem,
        });
    }
    Ok(rec)
}

/// Writes the model into `dir` (created if needed) in the given encoding, each file atomically.
/// The reconstruction is validated first; image names must be non-empty and, for text,
/// free of whitespace (COLMAP reads them with `>>`).
pub fn write_model(dir: &Path, rec: &Reconstruction, format: Format) -> Result<(), Error> {
    rec.validate()?;
    for im in rec.images.values() {
        let bad = match format {
            Format::Text => im.name.is_empty() || im.name.chars().any(char::is_whitespace),
            Format::Binary => im.name.is_empty() || im.name.contains('\0'),
        };
        if bad {
            return Err(Error::Invalid(Problem::BadName(im.name.clone())));
        }
    }
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let path = |name: &str| dir.join(format!("{name}.{}", format.extension()));
    let (cameras, images, head, records): (_, _, _, EncodeRun) = match format {
        Format::Text => (
            text::cameras_text(&rec.cameras).into_bytes(),
            text::images_text(&rec.images)
                .map_err(Error::Invalid)?
                .into_bytes(),
            text::points3d_head(&rec.points3d),
            text::points3d_lines,
        ),
        Format::Binary => (
            binary::cameras_bytes(&rec.cameras),
            binary::images_bytes(&rec.images),
            binary::points3d_head(&rec.points3d),
            binary::points3d_records,
        ),
    };
    write_file(&path("cameras"), &cameras)?;
    write_file(&path("images"), &images)?;
    write_points(&path("points3D"), &head, &rec.points3d, records)
}

/// Points of `points3D` that one parallel task encodes: a paper-scale frame's 3M points make a
/// 100 MB text file whose number formatting takes over a second on one core.
pub(crate) const POINTS_PER_TASK: usize = 1 << 15;

/// Encodes a run of points (consecutive ids) as their records in a `points3D` file.
pub(crate) type EncodeRun = fn(Range<'_, u64, Point3D>) -> Vec<u8>;

/// Tasks encoded before their pieces are written: what is held at once is this many pieces
/// (about 20 MB of text), not the whole file.
const TASKS_PER_BATCH: usize = 8;

/// Writes `head` and then the records of `points` in id order to `path` atomically (like
/// [`write_file`]): runs of [`POINTS_PER_TASK`] points, each taken as a key range of the map,
/// are encoded by `encode` in parallel a batch at a time and written in order.
pub(crate) fn write_points(
    path: &Path,
    head: &[u8],
    points: &BTreeMap<u64, Point3D>,
    encode: EncodeRun,
) -> Result<(), Error> {
    let firsts: Vec<u64> = points.keys().step_by(POINTS_PER_TASK).copied().collect();
    let run = |k: usize| match firsts.get(k + 1) {
        Some(&end) => points.range(firsts[k]..end),
        None => points.range(firsts[k]..),
    };
    atomic_output::write_atomic_with(path, |w| {
        w.write_all(head)?;
        for batch in (0..firsts.len()).step_by(TASKS_PER_BATCH) {
            let tasks = batch..(batch + TASKS_PER_BATCH).min(firsts.len());
            let pieces: Vec<Vec<u8>> = tasks.into_par_iter().map(|k| encode(run(k))).collect();
            for piece in &pieces {
                w.write_all(piece)?;
            }
        }
        Ok(())
    })
    .map_err(|e| Error::io(path, e))
}

/// Writes `bytes` to `path` atomically (see [`atomic_output::write_atomic`]), so readers never
/// see a half-written file; the error names the file.
pub(crate) fn write_file(path: &Path, bytes: &[u8]) -> Result<(), Error> {
    atomic_output::write_atomic(path, bytes).map_err(|e| Error::io(path, e))
}
