//! A training dataset folder: `images/` + `sparse/0/`, in the layout that COLMAP, gsplat,
//! Inria's gaussian-splatting, nerfstudio (`--colmap-path sparse/0`) and Brush all load
//! (`reference/formats.md` §3.5).
//!
//! The caller supplies the images already encoded (PNG bytes through [`DatasetWriter::write_image`])
//! or writes them itself into [`DatasetWriter::images_dir`]; [`DatasetWriter::finish`] then checks
//! that every image of the model is there and writes the model.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

use camera_model::Camera;
use glam::DVec3;

use crate::{CameraRecord, Error, Format, ImageRecord, Point3D, Reconstruction, write_model};

/// Writes a dataset folder.
#[derive(Debug, Clone)]
pub struct DatasetWriter {
    root: PathBuf,
    images_dir: PathBuf,
    sparse_dir: PathBuf,
}

fn dataset_error(path: &Path, message: impl Into<String>) -> Error {
    Error::Dataset {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Checks an image file name: a plain file name (no folders), no whitespace (COLMAP's text
/// format), exactly one dot (Inria's loader takes the stem up to the first dot).
fn check_image_name(root: &Path, name: &str) -> Result<(), Error> {
    let plain = !name.is_empty()
        && !name.contains(['/', '\\', '\0'])
        && !name.chars().any(char::is_whitespace)
        && name.matches('.').count() == 1
        && !name.starts_with('.');
    if plain {
        Ok(())
    } else {
        Err(dataset_error(
            root,
            format!(
                "image name `{name}` must be a plain file name with one dot and no whitespace (e.g. cam_000.png)"
            ),
        ))
    }
}

impl DatasetWriter {
    /// Creates `root/images/` and `root/sparse/0/` (and `root` itself) if needed.
    pub fn create(root: &Path) -> Result<Self, Error> {
        let images_dir = root.join("images");
        let sparse_dir = root.join("sparse").join("0");
        for dir in [&images_dir, &sparse_dir] {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir.as_path(), e))?;
        }
        Ok(Self {
            root: root.to_path_buf(),
            images_dir,
            sparse_dir,
        })
    }

    /// The dataset folder.
    #[must_use]
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The folder images go into (`root/images`).
    #[must_use]
    pub fn images_dir(&self) -> &Path {
        &self.images_dir
    }

    /// The folder the model goes into (`root/sparse/0`).
    #[must_use]
    pub fn sparse_dir(&self) -> &Path {
        &self.sparse_dir
    }

    /// Writes one already-encoded image file (e.g. PNG bytes) atomically; returns its path.
    pub fn write_image(&self, name: &str, encoded: &[u8]) -> Result<PathBuf, Error> {
        check_image_name(&self.root, name)?;
        let path = self.images_dir.join(name);
        crate::io::write_file(&path, encoded)?;
        Ok(path)
    }

    /// Writes the model into `sparse/0/` after checking that it has 3D points (Inria's trainer
    /// and nerfstudio need them), that image names are plain with unique stems, and that every
    /// image file is present in `images/`.
    pub fn finish(&self, rec: &Reconstruction, format: Format) -> Result<(), Error> {
        if rec.points3d.is_empty() {
            return Err(dataset_error(
                &self.sparse_dir,
                "points3D is empty; trainers need initial points (use points_without_tracks)",
            ));
        }
        let mut stems = BTreeSet::new();
        for im in rec.images.values() {
            check_image_name(&self.root, &im.name)?;
            let stem = im.name.split('.').next().unwrap_or_default();
            if !stems.insert(stem.to_string()) {
                return Err(dataset_error(
                    &self.root,
                    format!("two images share the stem `{stem}`"),
                ));
            }
            let file = self.images_dir.join(&im.name);
            if !file.is_file() {
                return Err(dataset_error(
                    &file,
                    format!("image {} (`{}`) has no file", im.id, im.name),
                ));
            }
        }
        write_model(&self.sparse_dir, rec, format)
    }
}

/// A reconstruction of named pinhole cameras with no points yet: one PINHOLE camera record per
/// distinct intrinsics (ids from 1 in order of first use), one image per camera (ids from 1).
pub fn reconstruction_from_cameras<'a>(
    views: impl IntoIterator<Item = (&'a str, &'a Camera)>,
) -> Result<Reconstruction, Error> {
    let mut rec = Reconstruction::default();
    let mut camera_ids: Vec<(camera_model::Intrinsics, u32)> = Vec::new();
    for (index, (name, camera)) in views.into_iter().enumerate() {
        let camera_id = match camera_ids.iter().find(|(k, _)| *k == camera.intrinsics) {
            Some(&(_, id)) => id,
            None => {
                let id = u32::try_from(camera_ids.len() + 1)
                    .map_err(|_| Error::Unrepresentable("more than u32::MAX cameras".into()))?;
                rec.cameras
                    .insert(id, CameraRecord::from_intrinsics(id, &camera.intrinsics)?);
                camera_ids.push((camera.intrinsics, id));
                id
            }
        };
        let image_id = u32::try_from(index + 1)
            .map_err(|_| Error::Unrepresentable("more than u32::MAX images".into()))?;
        rec.images.insert(
            image_id,
            ImageRecord::new(image_id, camera_id, name, &camera.pose),
        );
    }
    Ok(rec)
}

/// 3D points with empty tracks (accepted by COLMAP and every trainer), ids from 1, error 0.
#[must_use]
pub fn points_without_tracks(
    points: impl IntoIterator<Item = (DVec3, [u8; 3])>,
) -> BTreeMap<u64, Point3D> {
    (1..)
        .zip(points)
        .map(|(id, (xyz, rgb))| {
            (
                id,
                Point3D {
                    xyz,
                    rgb,
                    error: 0.0,
                    track: Vec::new(),
                },
            )
        })
        .collect()
}
