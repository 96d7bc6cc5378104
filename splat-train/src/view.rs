//! A training or evaluation view: a posed camera and its image, and colour over a background.
//!
//! A view's colour is straight (not multiplied by its mask); [`composite`] and its in-place and
//! buffer variants put it over a background colour. They are the one place where
//! `colour·a + background·(1 − a)` is written, so the trainer's targets and the evaluator's
//! references cannot drift apart.

use camera_model::{Camera, Intrinsics};

/// An image with its camera.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Name (usually the image file name).
    pub name: String,
    /// Intrinsics and world→camera pose.
    pub camera: Camera,
    /// Colours, interleaved RGB in [0, 1], row-major, top row first (3·W·H).
    pub image: Vec<f32>,
    /// Optional coverage mask in [0, 1] (W·H); pixels with 0 show the background.
    pub mask: Option<Vec<f32>>,
}

impl View {
    /// The rasteriser's camera for this view ([`splat_core::RenderCamera`]'s one conversion, which refuses
    /// skew).
    ///
    /// # Errors
    /// The conversion's message when the camera is skewed.
    pub fn render_camera(&self) -> Result<splat_core::RenderCamera, String> {
        splat_core::RenderCamera::try_from(&self.camera).map_err(|e| e.to_string())
    }

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
        self.render_camera()?;
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

    /// A view from colour composited on black (premultiplied by `alpha`, as rendered reference
    /// views and the images of `transcode views` datasets hold it): the colour is divided by
    /// the coverage back to straight colour, clamped to [0, 1], and black where the coverage is
    /// at most 1e-6 (nothing there to divide, and nothing of it shows over any background).
    /// `alpha` becomes the view's mask.
    ///
    /// Pixels `rgb` holds beyond `alpha`'s length are dropped, as `zip` drops them.
    #[must_use]
    pub fn from_premultiplied(name: String, camera: Camera, rgb: &[f32], alpha: Vec<f32>) -> Self {
        let image = rgb
            .chunks_exact(3)
            .zip(&alpha)
            .flat_map(|(px, &a)| {
                if a > 1e-6 {
                    [0, 1, 2].map(|c| (px[c] / a).clamp(0.0, 1.0))
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        Self {
            name,
            camera,
            image,
            mask: Some(alpha),
        }
    }

    /// The view's colour as it looks over `background`: the image composited with its mask
    /// ([`composite`]), or the image itself when it has no mask (it covers every pixel).
    #[must_use]
    pub fn on_background(&self, background: [f32; 3]) -> Vec<f32> {
        match &self.mask {
            Some(mask) => composite(&self.image, mask, background),
            None => self.image.clone(),
        }
    }
}

/// One channel of a straight colour `c` with coverage `a` over background channel `bg`:
/// `c·a + bg·(1 − a)`. Every compositing in the trainer and the evaluator goes through here.
#[inline(always)]
#[must_use]
pub fn over(c: f32, a: f32, bg: f32) -> f32 {
    c * a + bg * (1.0 - a)
}

/// Interleaved RGB `image` (3 values a pixel) with per-pixel coverage `alpha` over the colour
/// `background`, as a new image ([`over`] for each channel). Pixels beyond the shorter of the
/// two are dropped.
#[must_use]
pub fn composite(image: &[f32], alpha: &[f32], background: [f32; 3]) -> Vec<f32> {
    let mut out = vec![0.0; 3 * (image.len() / 3).min(alpha.len())];
    composite_into(&mut out, image, alpha, background);
    out
}

/// [`composite`] written into `out` (which the trainer reuses from step to step); pixels beyond
/// the shortest of `out`, `image` and `alpha` are left alone.
#[inline]
pub fn composite_into(out: &mut [f32], image: &[f32], alpha: &[f32], background: [f32; 3]) {
    for ((o, px), &a) in out
        .chunks_exact_mut(3)
        .zip(image.chunks_exact(3))
        .zip(alpha)
    {
        for c in 0..3 {
            o[c] = over(px[c], a, background[c]);
        }
    }
}

/// [`composite`] in place: `image` is replaced by itself over `background`.
#[inline]
pub fn composite_in_place(image: &mut [f32], alpha: &[f32], background: [f32; 3]) {
    for (px, &a) in image.chunks_exact_mut(3).zip(alpha) {
        for c in 0..3 {
            px[c] = over(px[c], a, background[c]);
        }
    }
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

    /// Compositing against hand-computed values; the three variants agree bit for bit.
    #[test]
    fn composite_puts_colour_over_the_background() {
        let image = [0.2, 0.4, 0.6, 1.0, 0.0, 0.5, 0.75, 0.75, 0.75];
        let alpha = [1.0, 0.0, 0.5];
        let bg = [0.0, 1.0, 0.25];
        let out = composite(&image, &alpha, bg);
        // Full coverage keeps the colour, none gives the background, half averages the two.
        assert_eq!(out, vec![0.2, 0.4, 0.6, 0.0, 1.0, 0.25, 0.375, 0.875, 0.5]);
        let mut buf = vec![9.0; 9];
        composite_into(&mut buf, &image, &alpha, bg);
        assert_eq!(buf, out);
        let mut inplace = image.to_vec();
        composite_in_place(&mut inplace, &alpha, bg);
        assert_eq!(inplace, out);
        // A short mask composites only the pixels it covers.
        assert_eq!(composite(&image, &alpha[..1], bg), vec![0.2, 0.4, 0.6]);
    }

    /// Straight colour from premultiplied colour: divided by the coverage, clamped, black where
    /// nothing is covered; composited on black it gives the premultiplied colour back.
    #[test]
    fn premultiplied_colour_becomes_straight() {
        let cam = Camera::new(Intrinsics::centered(4, 1, 1.0, 1.0), Pose::IDENTITY);
        let rgb = [
            0.1, 0.2, 0.3, 0.25, 0.5, 0.125, 0.9, 0.9, 0.9, 0.7, 0.0, 0.0,
        ];
        let alpha = vec![1.0, 0.5, 0.0, 0.5];
        let v = View::from_premultiplied("v".into(), cam, &rgb, alpha.clone());
        assert_eq!(
            v.image,
            vec![0.1, 0.2, 0.3, 0.5, 1.0, 0.25, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0]
        );
        assert_eq!(v.mask.as_deref(), Some(&alpha[..]));
        assert_eq!(
            v.on_background([0.0; 3]),
            vec![
                0.1, 0.2, 0.3, 0.25, 0.5, 0.125, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0
            ]
        );
        assert_eq!(
            v.on_background([1.0; 3])[6..9].to_vec(),
            vec![1.0, 1.0, 1.0]
        );
        let unmasked = View { mask: None, ..v };
        assert_eq!(unmasked.on_background([1.0; 3]), unmasked.image);
    }
}
