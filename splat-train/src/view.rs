//! A training or evaluation view: a posed camera and its image.

use std::path::Path;

use camera_model::{Camera, Intrinsics};

use crate::error::Error;

/// An image with its camera.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Name (usually the image file name).
    pub name: String,
    /// Intrinsics and world→camera pose.
    pub camera: camera_model::Camera,
    /// Colours, interleaved RGB in [0, 1], row-major, top row first (3·W·H).
    pub image: Vec<f32>,
    /// Optional coverage mask in [0, 1] (W·H); pixels with 0 show the background.
    pub mask: Option<Vec<f32>>,
}

impl View {
    /// Checks that the camera's size fits the rasteriser's buffers, that the image and mask
    /// sizes match the camera and that values are finite.
    ///
    /// # Errors
    /// A message naming the mismatch, the limit or the first bad value.
    pub fn check(&self) -> Result<(), String> {
        let k = &self.camera.intrinsics;
        let px = k.width as usize * k.height as usize;
        if px == 0 {
            return Err(format!(
                "camera has an empty image size {}×{}",
                k.width, k.height
            ));
        }
        // The trainer's per-pixel buffers (loss, SSIM) are sized by the view like the
        // rasteriser's: the rasteriser's limit refuses them all before any is allocated.
        splat_core::Rasterizer::check_view_size(k.width, k.height).map_err(|e| e.to_string())?;
        if self.image.len() != 3 * px {
            return Err(format!(
                "image holds {} values, the {}×{} camera needs {}",
                self.image.len(),
                k.width,
                k.height,
                3 * px
            ));
        }
        if let Some(i) = self.image.iter().position(|v| !v.is_finite()) {
            return Err(format!("image value {i} is not finite"));
        }
        if let Some(m) = &self.mask {
            if m.len() != px {
                return Err(format!(
                    "mask holds {} values, the camera needs {px}",
                    m.len()
                ));
            }
            if let Some(i) = m.iter().position(|v| !v.is_finite()) {
                return Err(format!("mask value {i} is not finite"));
            }
        }
        if !(k.fx > 0.0 && k.fy > 0.0 && k.fx.is_finite() && k.fy.is_finite()) {
            return Err(format!(
                "focal lengths fx = {}, fy = {} are not positive",
                k.fx, k.fy
            ));
        }
        Ok(())
    }
}

/// Loads a view from a PNG or JPEG file (an alpha channel becomes the mask), reduced by
/// `downscale` ≥ 1 with the camera's intrinsics scaled to match.
///
/// # Errors
/// [`Error::Image`] when the file cannot be read or decoded, or its size is not the camera's.
pub fn load_view(path: &Path, name: &str, camera: Camera, downscale: f64) -> Result<View, Error> {
    let fail = |problem: String| Error::Image {
        path: path.to_path_buf(),
        problem,
    };
    if !(downscale.is_finite() && downscale >= 1.0) {
        return Err(fail(format!(
            "downscale factor {downscale} must be at least 1"
        )));
    }
    let img = image::ImageReader::open(path)
        .map_err(|e| fail(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| fail(e.to_string()))?
        .decode()
        .map_err(|e| fail(e.to_string()))?;
    let k = camera.intrinsics;
    if img.width() != k.width || img.height() != k.height {
        return Err(fail(format!(
            "image is {}×{} but its camera is {}×{}",
            img.width(),
            img.height(),
            k.width,
            k.height
        )));
    }
    let has_alpha = img.color().has_alpha();
    let mut rgba = img.into_rgba32f();
    let mut intrinsics = k;
    if downscale > 1.0 {
        let w = ((f64::from(k.width) / downscale).round() as u32).max(1);
        let h = ((f64::from(k.height) / downscale).round() as u32).max(1);
        // The triangle filter widens its kernel by the reduction factor, so it averages.
        rgba = image::imageops::resize(&rgba, w, h, image::imageops::FilterType::Triangle);
        intrinsics = scale_intrinsics(&k, w, h);
    }
    let px = rgba.as_raw();
    let image: Vec<f32> = px
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let mask = has_alpha.then(|| px.chunks_exact(4).map(|p| p[3]).collect());
    Ok(View {
        name: name.to_string(),
        camera: Camera::new(intrinsics, camera.pose),
        image,
        mask,
    })
}

/// Intrinsics of the same camera at a `w × h` image size (pixel-centre convention kept: the
/// principal point scales with the image edges).
#[must_use]
pub fn scale_intrinsics(k: &Intrinsics, w: u32, h: u32) -> Intrinsics {
    let sx = f64::from(w) / f64::from(k.width);
    let sy = f64::from(h) / f64::from(k.height);
    Intrinsics {
        width: w,
        height: h,
        fx: k.fx * sx,
        fy: k.fy * sy,
        cx: k.cx * sx,
        cy: k.cy * sy,
        skew: k.skew * sx,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::Pose;

    /// A view over the rasteriser's pixel limit is refused by its size alone, before its image
    /// (which here is not even there) is looked at; the message names the limit.
    #[test]
    fn views_over_the_pixel_limit_are_refused() {
        let view = |w: u32, h: u32, image: Vec<f32>| View {
            name: "big".into(),
            camera: Camera::new(Intrinsics::centered(w, h, 1000.0, 1000.0), Pose::IDENTITY),
            image,
            mask: None,
        };
        let err = view(100_000, 100_000, Vec::new()).check().unwrap_err();
        assert!(
            err.contains("100000×100000") && err.contains(&splat_core::MAX_PIXELS.to_string()),
            "{err}"
        );
        view(4, 3, vec![0.5; 36]).check().unwrap();
    }
}
