//! The COLMAP training dataset of an input: rendered images, cameras and the input's points.

use std::path::{Path, PathBuf};

use camera_model::Camera;
use colmap_io::Format;
use colmap_io::dataset::{DatasetWriter, points_without_tracks, reconstruction_from_cameras};
use glam::Vec3;
use plenoptic_io::{Model, PlenopticCloud};
use rayon::prelude::*;

use crate::output::{encode_png_rgb, write_alpha_png, write_depth_exr};
use crate::{BitDepth, Error, ModelRenderer, ViewImage, ViewOptions};

/// What [`write_dataset`] writes besides `images/` and `sparse/0/`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DatasetOptions {
    /// Bits per channel of the RGB images.
    pub bit_depth: BitDepth,
    /// Alpha masks as `masks/<name>.png` (8-bit grey), same names as the images.
    pub masks: bool,
    /// Depth as `depth/<stem>.exr` (channel `Z`, camera z, 0 where nothing is seen).
    pub depth: bool,
}

impl Default for DatasetOptions {
    fn default() -> Self {
        Self {
            bit_depth: BitDepth::Eight,
            masks: true,
            depth: false,
        }
    }
}

/// The image file name of view `i` in a dataset (`view_000.png`): one dot and no folders, as
/// COLMAP's text format and Inria's loader need.
#[must_use]
pub fn dataset_image_name(i: usize) -> String {
    format!("{VIEW_PREFIX}{i:03}.png")
}

/// What every view file of a dataset is named from: `view_NNN.png` (images, masks) and
/// `view_NNN.exr` (depth).
const VIEW_PREFIX: &str = "view_";

/// Whether `name` is a view file as a dataset names them ([`dataset_image_name`], and the
/// depth map's `.exr` of the same stem).
fn is_view_file(name: &str) -> bool {
    let digits = name
        .strip_prefix(VIEW_PREFIX)
        .and_then(|r| r.strip_suffix(".png").or_else(|| r.strip_suffix(".exr")));
    digits.is_some_and(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit()))
}

/// Renders `model` from every camera (in parallel over views) and writes the dataset folder:
/// `dir/images/view_NNN.png`, `dir/masks/` and `dir/depth/` when asked, `dir/sparse/0/` in both
/// text and binary (PINHOLE cameras, world→camera poses, points3D = the input's points with their
/// colours and empty tracks) and `dir/sparse/0/points3D.ply` (Inria's loader reads it first).
/// `on_view` is called once per finished view. Returns `keep(i, image)` of each view i in camera
/// order (`|_, image| image` keeps the images; see [`crate::render_views_with`] for why a caller
/// keeps less). When more than half of the views see nothing
/// ([`crate::degenerate::check_coverage`]) the error comes before `sparse/0/` is written, and a
/// model left there by an earlier run is removed first, so a failed dataset never looks complete;
/// so are an earlier dataset's views (`view_NNN.png` / `.exr` in `images/`, `masks/`, `depth/`),
/// which would otherwise sit beside this one's. Other files in the folder are left alone.
pub fn write_dataset<T, F>(
    dir: &Path,
    model: &Model,
    cameras: &[Camera],
    view: &ViewOptions,
    opts: &DatasetOptions,
    on_view: &(dyn Fn() + Sync),
    keep: F,
) -> Result<Vec<T>, Error>
where
    T: Send,
    F: Fn(usize, ViewImage) -> T + Sync,
{
    view.validate()?;
    if cameras.is_empty() {
        return Err(Error::InvalidOption(
            "a dataset needs at least one camera".into(),
        ));
    }
    let writer = DatasetWriter::create(dir)?;
    // A model left by an earlier run would make a failed one look complete: it goes first, and
    // is written again only once every view is rendered and something is visible in them. So
    // do an earlier run's views: where it had more cameras, or masks or depth this one does not
    // write, they would sit beside this run's as if they belonged to it (a reader pairs every
    // image with the mask of its name).
    remove_stale_model(&writer)?;
    for folder in ["images", "masks", "depth"] {
        remove_view_files(&dir.join(folder))?;
    }
    let masks_dir = opts.masks.then(|| create_dir(dir, "masks")).transpose()?;
    let depth_dir = opts.depth.then(|| create_dir(dir, "depth")).transpose()?;

    // A sparse cloud's point size and a cloud's drawing order are worked out once, not once a view.
    // The depth maps need the views' depth whatever the caller keeps of them.
    let view = ViewOptions {
        depth: view.depth || opts.depth,
        ..view.clone()
    };
    let renderer = ModelRenderer::new(model, &view)?;
    renderer.expect_views(cameras.len());
    let names: Vec<String> = (0..cameras.len()).map(dataset_image_name).collect();
    // Per view: whether anything covers it, and what the caller keeps of it.
    let kept: Vec<(bool, T)> = cameras
        .par_iter()
        .enumerate()
        .map(|(i, camera)| -> Result<(bool, T), Error> {
            let image = renderer.render(camera)?;
            let name = &names[i];
            let png = encode_png_rgb(&writer.images_dir().join(name), &image, opts.bit_depth)?;
            writer.write_image(name, &png)?;
            if let Some(masks) = &masks_dir {
                write_alpha_png(&masks.join(name), &image)?;
            }
            if let Some(depth) = &depth_dir {
                let stem = name.trim_end_matches(".png");
                write_depth_exr(&depth.join(format!("{stem}.exr")), &image)?;
            }
            let covered = image.alpha.iter().any(|&a| a > 0.0);
            let kept = keep(i, image);
            on_view();
            Ok((covered, kept))
        })
        .collect::<Result<_, _>>()?;
    // The drawing order and its copy of the positions are not needed for the model files.
    drop(renderer);
    let covered: Vec<bool> = kept.iter().map(|k| k.0).collect();
    crate::degenerate::check_coverage(dir, "training", &covered, |i| names[i].clone())?;

    write_model_files(&writer, model, &names, cameras)?;
    Ok(kept.into_iter().map(|k| k.1).collect())
}

/// `sparse/0/` of the dataset: the COLMAP model (text and binary) of the cameras named `names`
/// with the input's points as points3D without tracks, and `points3D.ply`.
fn write_model_files(
    writer: &DatasetWriter,
    model: &Model,
    names: &[String],
    cameras: &[Camera],
) -> Result<(), Error> {
    let points = input_points(model);
    let rec = reconstruction_from_cameras(names.iter().map(String::as_str).zip(cameras))?;
    // Three independent files, written at once: at a paper-scale frame's 3M points they are
    // 100, 160 and 85 MB, each encoded in parallel and then written and synced. The PLY starts
    // first, while one thread builds the COLMAP model's point map (a third of a second there).
    let ply = writer.sparse_dir().join("points3D.ply");
    let (cloud, (text, binary)) = rayon::join(
        || {
            plenoptic_io::write_cloud(&ply, &points).map_err(|e| Error::Encode {
                path: ply.clone(),
                message: e.to_string(),
            })
        },
        || {
            let mut rec = rec;
            rec.points3d =
                points_without_tracks(points.positions.iter().zip(&points.colors).map(|(p, c)| {
                    (
                        p.as_dvec3(),
                        c.map(|v| crate::output::quantise(v, 255.0) as u8),
                    )
                }));
            rayon::join(
                || writer.finish(&rec, Format::Text),
                || writer.finish(&rec, Format::Binary),
            )
        },
    );
    text?;
    binary?;
    cloud?;
    Ok(())
}

/// Removes the files of `sparse/0/` that would make the dataset look usable.
fn remove_stale_model(writer: &DatasetWriter) -> Result<(), Error> {
    remove_model_files(writer.sparse_dir())
}

/// Removes the COLMAP model of the dataset in `dir` (the files of `dir/sparse/0/` that make it
/// usable), where there is one: a run that is about to write the dataset again, or that fails
/// before it does, must not leave an earlier input's dataset looking complete.
///
/// # Errors
/// [`Error::Io`] naming a file that is there and could not be removed.
pub fn remove_dataset_model(dir: &Path) -> Result<(), Error> {
    remove_model_files(&dir.join("sparse").join("0"))
}

/// Removes the files of [`STALE_MODEL_FILES`] from `sparse_dir` that are there, and the
/// temporaries a killed writer of them left.
fn remove_model_files(sparse_dir: &Path) -> Result<(), Error> {
    for name in STALE_MODEL_FILES {
        let path = sparse_dir.join(name);
        match std::fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(source) => return Err(Error::Io { path, source }),
        }
    }
    remove_files_where(sparse_dir, |name| STALE_MODEL_FILES.contains(&name))
}

/// Removes the files in `folder` named as a dataset names its views (`view_NNN.png`, and
/// `view_NNN.exr` for depth), and the temporaries a killed writer of them left (see
/// [`remove_files_where`]); other files, and a missing folder, are left alone.
fn remove_view_files(folder: &Path) -> Result<(), Error> {
    remove_files_where(folder, is_view_file)
}

/// Removes the regular files in `folder` whose name passes `named`, and the atomic writes'
/// temporaries of such names whose writer is gone (`.view_017.png.PID.N.tmp`: a run killed
/// while writing its dataset left them there through every later run); a missing folder is
/// left alone.
fn remove_files_where(folder: &Path, named: impl Fn(&str) -> bool) -> Result<(), Error> {
    let Ok(entries) = std::fs::read_dir(folder) else {
        return Ok(());
    };
    for entry in entries.flatten() {
        let is_view = entry.file_name().to_str().is_some_and(|name| {
            named(name) || atomic_output::stale_temporary_target(name).is_some_and(&named)
        });
        if is_view && entry.file_type().is_ok_and(|t| t.is_file()) {
            let path = entry.path();
            std::fs::remove_file(&path).map_err(|source| Error::Io { path, source })?;
        }
    }
    Ok(())
}

/// `dir/name`, created if missing.
fn create_dir(dir: &Path, name: &str) -> Result<PathBuf, Error> {
    let path = dir.join(name);
    std::fs::create_dir_all(&path).map_err(|source| Error::Io {
        path: path.clone(),
        source,
    })?;
    Ok(path)
}

/// The files of `sparse/0/` that make a dataset usable, removed before a dataset is written.
const STALE_MODEL_FILES: [&str; 7] = [
    "cameras.txt",
    "images.txt",
    "points3D.txt",
    "cameras.bin",
    "images.bin",
    "points3D.bin",
    "points3D.ply",
];

/// The input's points with one colour each and normals (zero when unknown: Inria's loader
/// requires the nx/ny/nz columns): a cloud's points and main colours, or a mesh's referenced
/// vertices with their albedo.
fn input_points(model: &Model) -> PlenopticCloud {
    match model {
        Model::Cloud(c) => PlenopticCloud {
            positions: c.positions.clone(),
            normals: Some(
                c.normals
                    .clone()
                    .unwrap_or_else(|| vec![Vec3::ZERO; c.len()]),
            ),
            colors: c.colors.clone(),
            ..Default::default()
        },
        Model::Mesh(m) => {
            let mut color: Vec<Option<[f32; 3]>> = vec![None; m.positions.len()];
            for (t, tri) in m.triangles.iter().enumerate() {
                for (corner, &v) in tri.iter().enumerate() {
                    let slot = &mut color[v as usize];
                    if slot.is_none() {
                        let mut bary = [0.0; 3];
                        bary[corner] = 1.0;
                        *slot = Some(m.albedo_at(t, bary));
                    }
                }
            }
            let mut out = PlenopticCloud {
                normals: Some(Vec::new()),
                ..Default::default()
            };
            for (v, c) in color.iter().enumerate() {
                if let Some(c) = c {
                    out.positions.push(m.positions[v]);
                    out.colors.push(*c);
                    if let Some(n) = out.normals.as_mut() {
                        n.push(m.normals.as_ref().map_or(Vec3::ZERO, |ns| ns[v]));
                    }
                }
            }
            out
        }
    }
}
