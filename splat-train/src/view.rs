//! A training or evaluation view: a posed camera and its image, and colour over a background.
//!
//! A view's colour is straight (not multiplied by its mask); [`View::target_into`] (and
//! [`View::on_background`], [`composite_into`] below them) put it over a background colour.
//! They are the one place where `colour·a + background·(1 − a)` is written, so the trainer's
//! targets and the evaluator's references cannot drift apart.
//!
//! Colour and coverage are held as 16-bit fractions of one ([`to_unorm16`]), not as f32: a
//! paper-scale frame's 44 views at 1024² then take 0.37 GB instead of 0.74 GB (and their warm-up
//! copies 92 MB instead of 185 MB), which is most of what stood between its run and 2 GB of
//! memory. A step of 1/65535 is far below what any score here resolves (its rounding error,
//! 1/65535/√12 RMS, moves a score of 48 dB by a few millionths of a dB), 8- and 16-bit images are
//! held exactly, and the trainer expands each step's target to f32 as it composites it over the
//! step's background.

use camera_model::{Camera, Intrinsics};
use rayon::prelude::*;

/// Pixels per parallel task when a view is expanded over a background.
const TARGET_CHUNK: usize = 16 * 1024;

/// A value in [0, 1] as a 16-bit fraction of one: `round(x · 65535)` after clamping to [0, 1].
/// The caller has refused non-finite values (a NaN would become 0).
#[inline]
#[must_use]
pub fn to_unorm16(x: f32) -> u16 {
    // x·65535 + ½ truncated is round-half-up, which for x ≥ 0 is `round` without its libm call.
    (x.clamp(0.0, 1.0) * 65535.0 + 0.5) as u16
}

/// The value a 16-bit fraction of one stands for: `u / 65535` (an 8-bit `v` stored as
/// `257·v` comes back as `v / 255`, correctly rounded).
#[inline]
#[must_use]
pub fn from_unorm16(u: u16) -> f32 {
    f32::from(u) / 65535.0
}

/// An image with its camera.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Name (usually the image file name).
    pub name: String,
    /// Intrinsics and world→camera pose.
    pub camera: Camera,
    /// Straight colour, interleaved RGB, row-major, top row first (3·W·H), each value in [0, 1]
    /// held as a 16-bit fraction of one ([`to_unorm16`]).
    pub image: Vec<u16>,
    /// Optional coverage (W·H) as 16-bit fractions of one; pixels with 0 show the background.
    pub mask: Option<Vec<u16>>,
}

impl View {
    /// A view from straight colour `rgb` (interleaved RGB) and an optional coverage `mask`,
    /// each value clamped to [0, 1] and stored as a 16-bit fraction ([`to_unorm16`]).
    ///
    /// # Errors
    /// A message naming the first value that is not finite.
    pub fn from_straight(
        name: String,
        camera: Camera,
        rgb: &[f32],
        mask: Option<&[f32]>,
    ) -> Result<Self, String> {
        refuse_non_finite("image", rgb)?;
        if let Some(m) = mask {
            refuse_non_finite("mask", m)?;
        }
        Ok(Self {
            name,
            camera,
            image: rgb.iter().map(|&v| to_unorm16(v)).collect(),
            mask: mask.map(|m| m.iter().map(|&v| to_unorm16(v)).collect()),
        })
    }

    /// A view from colour composited on black (premultiplied by `alpha`, as rendered reference
    /// views and the images of `transcode views` datasets hold it): the colour is divided by
    /// the coverage back to straight colour, clamped to [0, 1], and black where the coverage is
    /// at most 1e-6 (nothing there to divide, and nothing of it shows over any background).
    /// `alpha` becomes the view's mask.
    ///
    /// Pixels `rgb` holds beyond `alpha`'s length are dropped, as `zip` drops them.
    ///
    /// # Errors
    /// A message naming the first value that is not finite.
    pub fn from_premultiplied(
        name: String,
        camera: Camera,
        rgb: &[f32],
        alpha: &[f32],
    ) -> Result<Self, String> {
        refuse_non_finite("image", rgb)?;
        refuse_non_finite("mask", alpha)?;
        let image = rgb
            .chunks_exact(3)
            .zip(alpha)
            .flat_map(|(px, &a)| {
                if a > 1e-6 {
                    [0, 1, 2].map(|c| to_unorm16(px[c] / a))
                } else {
                    [0; 3]
                }
            })
            .collect();
        Ok(Self {
            name,
            camera,
            image,
            mask: Some(alpha.iter().map(|&v| to_unorm16(v)).collect()),
        })
    }

    /// The rasteriser's camera for this view ([`splat_core::RenderCamera`]'s one conversion, which refuses
    /// skew).
    ///
    /// # Errors
    /// The conversion's message when the camera is skewed.
    pub fn render_camera(&self) -> Result<splat_core::RenderCamera, String> {
        splat_core::RenderCamera::try_from(&self.camera).map_err(|e| e.to_string())
    }

    /// Checks that the camera's size fits the rasteriser's buffers and that the image and mask
    /// sizes match the camera (their values are in range by their type).
    ///
    /// # Errors
    /// A message naming the mismatch or the limit.
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
        if let Some(m) = self.mask.as_ref().filter(|m| m.len() != px) {
            return Err(format!(
                "mask holds {} values, the camera needs {px}",
                m.len()
            ));
        }
        if !(k.fx > 0.0 && k.fy > 0.0 && k.fx.is_finite() && k.fy.is_finite()) {
            return Err(format!(
                "focal lengths fx = {}, fy = {} are not positive",
                k.fx, k.fy
            ));
        }
        Ok(())
    }

    /// The straight colour as f32 (3·W·H).
    #[must_use]
    pub fn colour(&self) -> Vec<f32> {
        self.image.iter().map(|&u| from_unorm16(u)).collect()
    }

    /// The coverage as f32 (W·H), if the view has a mask.
    #[must_use]
    pub fn coverage(&self) -> Option<Vec<f32>> {
        self.mask
            .as_ref()
            .map(|m| m.iter().map(|&u| from_unorm16(u)).collect())
    }

    /// The view's colour as it looks over `background`, as f32 ([`View::target_into`]).
    #[must_use]
    pub fn on_background(&self, background: [f32; 3]) -> Vec<f32> {
        let mut out = Vec::new();
        self.target_into(&mut out, background);
        out
    }

    /// The view's colour over `background` written into `out` (resized to 3·W·H; the trainer
    /// reuses it from step to step): the image composited with its mask ([`composite_into`]),
    /// or the image itself when it has no mask (it covers every pixel). Runs in parallel;
    /// every pixel is computed alone, so the result does not depend on the thread count.
    pub fn target_into(&self, out: &mut Vec<f32>, background: [f32; 3]) {
        out.resize(self.image.len(), 0.0);
        out.par_chunks_mut(3 * TARGET_CHUNK)
            .enumerate()
            .for_each(|(c, o)| self.target_part_into(c * TARGET_CHUNK, o, background));
    }

    /// The view's colour over `background` for as many pixels as `out` holds (3 values each),
    /// from pixel `first` on: what [`View::target_into`] writes there, for callers that work
    /// through a view a part at a time without its whole target in memory.
    ///
    /// # Panics
    /// If those pixels run past the view's image.
    pub fn target_part_into(&self, first: usize, out: &mut [f32], background: [f32; 3]) {
        let n = out.len() / 3;
        let image = &self.image[3 * first..3 * (first + n)];
        match &self.mask {
            Some(mask) => composite_into(out, image, &mask[first..first + n], background),
            None => {
                for (o, &u) in out.iter_mut().zip(image) {
                    *o = from_unorm16(u);
                }
            }
        }
    }
}

/// Refuses `values` if one is not finite, naming `what` and the first such value's index.
fn refuse_non_finite(what: &str, values: &[f32]) -> Result<(), String> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(format!("{what} value {i} is not finite")),
        None => Ok(()),
    }
}

/// One channel of a straight colour `c` with coverage `a` over background channel `bg`:
/// `c·a + bg·(1 − a)`. Every compositing in the trainer and the evaluator goes through here.
#[inline(always)]
#[must_use]
pub fn over(c: f32, a: f32, bg: f32) -> f32 {
    c * a + bg * (1.0 - a)
}

/// Interleaved RGB `image` (3 values a pixel) with per-pixel coverage `alpha`, both as 16-bit
/// fractions of one, over the colour `background`, written into `out` ([`over`] for each
/// channel); pixels beyond the shortest of `out`, `image` and `alpha` are left alone.
#[inline]
pub fn composite_into(out: &mut [f32], image: &[u16], alpha: &[u16], background: [f32; 3]) {
    for ((o, px), &a) in out
        .chunks_exact_mut(3)
        .zip(image.chunks_exact(3))
        .zip(alpha)
    {
        let a = from_unorm16(a);
        for c in 0..3 {
            o[c] = over(from_unorm16(px[c]), a, background[c]);
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
        let view = |w: u32, h: u32, image: Vec<u16>| View {
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
        view(4, 3, vec![32768; 36]).check().unwrap();
    }

    /// 16-bit fractions: 8-bit values come back exactly as v/255, every 16-bit value makes
    /// the round trip, values are rounded to the nearest step and clamped to [0, 1].
    #[test]
    fn unorm16_holds_8_and_16_bit_values_exactly() {
        for v in 0..=255u16 {
            let x = f32::from(v) / 255.0;
            assert_eq!(to_unorm16(x), 257 * v);
            assert_eq!(from_unorm16(257 * v), x);
        }
        for u in 0..=u16::MAX {
            assert_eq!(to_unorm16(from_unorm16(u)), u);
        }
        // f64 reference for the rounding: within half a step everywhere.
        for i in 0..=10_000 {
            let x = i as f32 / 10_000.0;
            let err = (f64::from(from_unorm16(to_unorm16(x))) - f64::from(x)).abs();
            assert!(err <= 0.5 / 65535.0 + 1e-9, "{x}: {err}");
        }
        assert_eq!((to_unorm16(-0.5), to_unorm16(1.5)), (0, u16::MAX));
    }

    /// Compositing against hand-computed values (fractions chosen exact in 16 bits: 0, ½ of
    /// 65535 is not, so the half-covered pixel uses 32768/65535 and the f64 form of `over`).
    #[test]
    fn composite_puts_colour_over_the_background() {
        let image: Vec<u16> = [0.2, 0.4, 0.6, 1.0, 0.0, 0.5, 0.75, 0.75, 0.75]
            .map(to_unorm16)
            .to_vec();
        let alpha = [u16::MAX, 0, 32768];
        let bg = [0.0, 1.0, 0.25];
        let mut out = vec![9.0; 9];
        composite_into(&mut out, &image, &alpha, bg);
        let a = 32768.0 / 65535.0;
        let expect = [
            0.2,
            0.4,
            0.6,
            0.0,
            1.0,
            0.25,
            0.75 * a,
            0.75 * a + (1.0 - a),
            0.75 * a + 0.25 * (1.0 - a),
        ];
        for (o, e) in out.iter().zip(expect) {
            assert!((f64::from(*o) - e).abs() < 1e-5, "{out:?}");
        }
        // A short mask composites only the pixels it covers.
        let mut short = vec![9.0; 9];
        composite_into(&mut short, &image, &alpha[..1], bg);
        assert_eq!(&short[..3], &out[..3]);
        assert_eq!(&short[3..], &[9.0; 6]);
    }

    /// The parallel target of a large view is the per-pixel composite, bit for bit, with and
    /// without a mask.
    #[test]
    fn target_into_is_the_composite_of_every_pixel() {
        let (w, h) = (300u32, 200u32);
        let n = (w * h) as usize;
        let cam = Camera::new(Intrinsics::centered(w, h, 100.0, 100.0), Pose::IDENTITY);
        let rgb: Vec<f32> = (0..3 * n).map(|i| (i % 97) as f32 / 96.0).collect();
        let mask: Vec<f32> = (0..n).map(|i| (i % 13) as f32 / 12.0).collect();
        let v = View::from_straight("v".into(), cam, &rgb, Some(&mask)).unwrap();
        let bg = [0.1, 0.6, 0.9];
        let mut serial = vec![0.0; 3 * n];
        composite_into(&mut serial, &v.image, v.mask.as_ref().unwrap(), bg);
        assert_eq!(v.on_background(bg), serial);
        let plain = View { mask: None, ..v };
        assert_eq!(plain.on_background(bg), plain.colour());
    }

    /// Non-finite values are refused with their place, before anything is stored.
    #[test]
    fn non_finite_values_are_refused() {
        let cam = Camera::new(Intrinsics::centered(2, 1, 1.0, 1.0), Pose::IDENTITY);
        let rgb = [0.0, 0.0, 0.0, 0.5, f32::NAN, 0.0];
        let err = View::from_straight("v".into(), cam, &rgb, None).unwrap_err();
        assert_eq!(err, "image value 4 is not finite");
        let err = View::from_premultiplied("v".into(), cam, &[0.0; 6], &[1.0, f32::INFINITY])
            .unwrap_err();
        assert_eq!(err, "mask value 1 is not finite");
    }

    /// Straight colour from premultiplied colour: divided by the coverage, clamped, black where
    /// nothing is covered; composited on black it gives the premultiplied colour back.
    #[test]
    fn premultiplied_colour_becomes_straight() {
        let cam = Camera::new(Intrinsics::centered(4, 1, 1.0, 1.0), Pose::IDENTITY);
        let rgb = [
            0.1, 0.2, 0.3, 0.25, 0.5, 0.125, 0.9, 0.9, 0.9, 0.7, 0.0, 0.0,
        ];
        let alpha = [1.0, 0.5, 0.0, 0.5];
        let v = View::from_premultiplied("v".into(), cam, &rgb, &alpha).unwrap();
        let close = |got: &[f32], want: &[f32]| {
            assert_eq!(got.len(), want.len());
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() <= 0.5 / 65535.0 + 1e-7, "{got:?} vs {want:?}");
            }
        };
        close(
            &v.colour(),
            &[0.1, 0.2, 0.3, 0.5, 1.0, 0.25, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0],
        );
        close(&v.coverage().unwrap(), &alpha);
        close(
            &v.on_background([0.0; 3]),
            &[
                0.1, 0.2, 0.3, 0.25, 0.5, 0.125, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0,
            ],
        );
        close(&v.on_background([1.0; 3])[6..9], &[1.0, 1.0, 1.0]);
        let unmasked = View { mask: None, ..v };
        assert_eq!(unmasked.on_background([1.0; 3]), unmasked.colour());
    }
}
