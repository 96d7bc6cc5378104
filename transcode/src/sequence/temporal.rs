//! Temporal stability: how much the rendered models change from one frame to the next, beside
//! how much the references change. Flicker is change the references do not have: a model figure
//! well below the reference figure.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::SequenceError;

/// Consecutive-frame PSNR of one pair of frames, over the held-out views both have.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TemporalPoint {
    /// The later frame.
    pub frame: String,
    /// The frame before it.
    pub previous: String,
    /// PSNR between the two models' renders of the same held-out cameras, dB.
    pub model_psnr: f64,
    /// PSNR between the two frames' reference views of the same cameras, dB.
    pub reference_psnr: f64,
    /// Held-out views compared.
    pub views: usize,
}

/// The held-out pictures the report's viewer keeps: `report/viewer/views/NAME-{render,reference}.png`.
fn pictures(frame_dir: &Path, kind: &str) -> Vec<(String, PathBuf)> {
    let dir = frame_dir.join("report").join("viewer").join("views");
    let suffix = format!("-{kind}.png");
    let mut found: Vec<(String, PathBuf)> = std::fs::read_dir(&dir)
        .into_iter()
        .flatten()
        .filter_map(Result::ok)
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            name.strip_suffix(&suffix)
                .map(|view| (view.to_string(), e.path()))
        })
        .collect();
    found.sort();
    found
}

/// PSNR (dB, 8-bit range) between the same views of two frames: one mean squared error over
/// every pixel of every view both frames have. `None` when they share no view.
pub fn consecutive_psnr(
    previous: &Path,
    frame: &Path,
    kind: &str,
) -> Result<Option<(f64, usize)>, SequenceError> {
    let later = pictures(frame, kind);
    let mut sum = 0.0f64;
    let mut count = 0u64;
    let mut views = 0;
    for (view, path) in pictures(previous, kind) {
        let Some((_, other)) = later.iter().find(|(v, _)| *v == view) else {
            continue;
        };
        let (a, b) = (read_rgb(&path)?, read_rgb(other)?);
        if a.dimensions() != b.dimensions() {
            return Err(SequenceError::Manifest {
                path: other.clone(),
                problem: format!(
                    "is {:?} pixels, the previous frame's {} is {:?}: the frames' rigs differ",
                    b.dimensions(),
                    path.display(),
                    a.dimensions()
                ),
            });
        }
        for (x, y) in a.as_raw().iter().zip(b.as_raw()) {
            let d = f64::from(*x) - f64::from(*y);
            sum += d * d;
        }
        count += a.as_raw().len() as u64;
        views += 1;
    }
    if views == 0 {
        return Ok(None);
    }
    // On colours in [0, 1], as every PSNR here; identical pictures are capped at 100 dB, far
    // above any difference of one 8-bit level.
    let mse = sum / count as f64 / (255.0 * 255.0);
    let psnr = if mse <= 0.0 {
        100.0
    } else {
        splat_train::metrics::psnr_from_mse(mse)
    };
    Ok(Some((psnr, views)))
}

fn read_rgb(path: &Path) -> Result<image::RgbImage, SequenceError> {
    image::open(path)
        .map(|i| i.to_rgb8())
        .map_err(|e| SequenceError::Manifest {
            path: path.to_path_buf(),
            problem: format!("cannot read the picture: {e}"),
        })
}

/// The temporal-stability point of `frame` after `previous` (their output folders), when both
/// have held-out pictures.
pub fn temporal_point(
    previous: (&str, &Path),
    frame: (&str, &Path),
) -> Result<Option<TemporalPoint>, SequenceError> {
    let model = consecutive_psnr(previous.1, frame.1, "render")?;
    let reference = consecutive_psnr(previous.1, frame.1, "reference")?;
    Ok(match (model, reference) {
        (Some((model_psnr, views)), Some((reference_psnr, _))) => Some(TemporalPoint {
            frame: frame.0.to_string(),
            previous: previous.0.to_string(),
            model_psnr,
            reference_psnr,
            views,
        }),
        _ => None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, name: &str, value: u8) {
        let views = dir.join("report").join("viewer").join("views");
        std::fs::create_dir_all(&views).unwrap();
        image::RgbImage::from_pixel(4, 2, image::Rgb([value; 3]))
            .save(views.join(name))
            .unwrap();
    }

    #[test]
    fn psnr_of_a_known_difference() {
        let (a, b) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
        // Renders differ by 16 levels everywhere, references by nothing; view 1 only in `a`.
        write(a.path(), "heldout_000-render.png", 100);
        write(b.path(), "heldout_000-render.png", 116);
        write(a.path(), "heldout_000-reference.png", 50);
        write(b.path(), "heldout_000-reference.png", 50);
        write(a.path(), "heldout_001-render.png", 0);
        let p = temporal_point(("a", a.path()), ("b", b.path()))
            .unwrap()
            .unwrap();
        let expected = 10.0 * (255.0f64 * 255.0 / 256.0).log10();
        assert!((p.model_psnr - expected).abs() < 1e-9, "{}", p.model_psnr);
        assert_eq!((p.reference_psnr, p.views), (100.0, 1));
        let empty = tempfile::tempdir().unwrap();
        assert!(
            temporal_point(("a", a.path()), ("e", empty.path()))
                .unwrap()
                .is_none()
        );
    }
}
