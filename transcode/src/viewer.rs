//! The interactive viewer beside the report: the model as SPZ, the held-out cameras, and at each
//! the reference, the CPU render and the error map the report's pictures also show; and the
//! held-out cameras as a COLMAP text model (`viewer/heldout/`), so that any renderer
//! (`transcode render` among them) can draw the same views.

use std::path::{Path, PathBuf};

use camera_model::Camera;
use splat_core::Splats;
use splat_core::spz::{SpzOptions, encode_spz};
use splat_train::View;
use splat_train::eval::RenderedView;
use splat_viewer::{Scene, SceneModel, SceneView, ViewCamera, ViewImages};

use crate::report::{VIEWER_DIR, heat_map, png_bytes};

/// Why the viewer could not be written.
#[derive(Debug, thiserror::Error)]
pub enum ViewerError {
    /// The model could not be packed as SPZ.
    #[error("cannot pack the model as SPZ: {0}")]
    Model(Box<splat_core::Error>),
    /// The held-out cameras could not be written as a COLMAP model.
    #[error("cannot write the held-out cameras in {}: {source}", path.display())]
    Cameras {
        /// The folder.
        path: PathBuf,
        /// The cause.
        source: Box<colmap_io::Error>,
    },
    /// A picture could not be encoded, or a folder created or removed.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The viewer's files could not be written.
    #[error(transparent)]
    Files(#[from] splat_viewer::Error),
}
/// The held-out cameras' COLMAP model inside the viewer's folder.
pub const HELDOUT_DIR: &str = "heldout";
/// The model's file in the viewer's folder.
pub const MODEL_FILE: &str = "model.spz";

/// Returns the viewer's description of a camera.
#[must_use]
pub fn view_camera(camera: &Camera) -> ViewCamera {
    let k = &camera.intrinsics;
    let r = camera.pose.rotation_matrix();
    ViewCamera {
        width: k.width,
        height: k.height,
        fx: k.fx,
        fy: k.fy,
        cx: k.cx,
        cy: k.cy,
        rotation: [0, 1, 2].map(|row| r.row(row).to_array()),
        translation: camera.pose.translation.to_array(),
    }
}

/// Writes `report_dir/viewer/` for `splats` (flagged antialiased when they were trained so)
/// with the held-out `views` and the model's CPU `renders` of them (in the same order),
/// replacing an earlier one.
///
/// # Errors
/// A [`ViewerError`] naming what could not be packed or written.
pub fn write_report_viewer(
    report_dir: &Path,
    title: &str,
    splats: &Splats,
    antialiased: bool,
    views: &[View],
    renders: &[RenderedView],
) -> Result<PathBuf, ViewerError> {
    let dir = report_dir.join(VIEWER_DIR);
    let io = |path: &Path| {
        let path = path.to_path_buf();
        move |source: std::io::Error| ViewerError::Io { path, source }
    };
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(io(&dir))?;
    }
    let spz = SpzOptions {
        antialiased,
        ..SpzOptions::default()
    };
    let model = encode_spz(splats, &spz).map_err(|e| ViewerError::Model(Box::new(e)))?;
    let mut pictures = Vec::new();
    let mut scene_views = Vec::new();
    for (v, render) in views.iter().zip(renders) {
        let (w, h) = (v.camera.intrinsics.width, v.camera.intrinsics.height);
        let reference: Vec<f32> = v
            .on_background([0.0; 3])
            .iter()
            .map(|x| x.clamp(0.0, 1.0))
            .collect();
        let name = |kind: &str| format!("views/{}-{kind}.png", v.name);
        for (kind, rgb) in [
            ("reference", reference.clone()),
            ("render", render.rgb.clone()),
            ("error", heat_map(&reference, &render.rgb)),
        ] {
            let png = png_bytes(&rgb, w, h).map_err(io(&dir.join(name(kind))))?;
            pictures.push((name(kind), png));
        }
        scene_views.push(SceneView {
            name: v.name.clone(),
            camera: view_camera(&v.camera),
            images: Some(ViewImages {
                reference: Some(name("reference")),
                render: Some(name("render")),
                error: Some(name("error")),
            }),
        });
    }
    let scene = Scene {
        title: title.to_string(),
        model: Some(SceneModel {
            file: MODEL_FILE.to_string(),
            embedded: None,
        }),
        views: scene_views,
    };
    splat_viewer::write_folder(&dir, &scene, &model, pictures)?;
    let heldout = dir.join(HELDOUT_DIR);
    let names: Vec<String> = views.iter().map(|v| format!("{}.png", v.name)).collect();
    let dataset_err = |source: colmap_io::Error| ViewerError::Cameras {
        path: heldout.clone(),
        source: Box::new(source),
    };
    let rec = colmap_io::dataset::reconstruction_from_cameras(
        names
            .iter()
            .map(String::as_str)
            .zip(views.iter().map(|v| &v.camera)),
    )
    .map_err(dataset_err)?;
    std::fs::create_dir_all(&heldout).map_err(io(&heldout))?;
    colmap_io::write_model(&heldout, &rec, colmap_io::Format::Text).map_err(dataset_err)?;
    Ok(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::{Intrinsics, Pose};
    use glam::{DVec3, Vec3};

    #[test]
    fn writes_the_viewer_its_pictures_and_the_cameras_as_colmap() {
        let dir = tempfile::tempdir().unwrap();
        let splats = Splats::from_points(
            &[Vec3::ZERO, Vec3::X],
            &[[1.0, 0.5, 0.0], [0.0, 0.5, 1.0]],
            &[Vec3::splat(0.3); 2],
            None,
            0.8,
            1,
        )
        .unwrap();
        let camera = Camera::new(
            Intrinsics::from_fov_y(8, 6, 40.0),
            Pose::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y),
        );
        let view = View {
            name: "heldout_000".into(),
            camera,
            image: vec![32768; 8 * 6 * 3],
            mask: None,
        };
        let render = RenderedView {
            rgb: vec![0.25; 8 * 6 * 3],
            alpha: vec![1.0; 8 * 6],
        };
        let out = write_report_viewer(dir.path(), "t", &splats, false, &[view], &[render]).unwrap();
        for f in [
            "index.html",
            "viewer.js",
            "viewer.css",
            "scene.js",
            "model.spz",
            "model.js",
            "views/heldout_000-reference.png",
            "views/heldout_000-render.png",
            "views/heldout_000-error.png",
        ] {
            assert!(out.join(f).is_file(), "{f}");
        }
        let scene = std::fs::read_to_string(out.join("scene.js")).unwrap();
        assert!(scene.contains("\"name\":\"heldout_000\""), "{scene}");
        assert!(scene.contains("\"embedded\":\"model.js\""), "{scene}");
        // The SPZ decodes to the same number of splats, and the cameras read back as COLMAP.
        let spz = splat_core::spz::read_spz(&out.join(MODEL_FILE)).unwrap();
        assert_eq!(spz.splats.len(), 2);
        let rec = colmap_io::read_model(&out.join(HELDOUT_DIR)).unwrap();
        let back = rec.camera_of(1).unwrap();
        assert!((back.center() - DVec3::new(0.0, 0.0, 5.0)).length() < 1e-6);
        assert_eq!(rec.images[&1].name, "heldout_000.png");
    }
}
