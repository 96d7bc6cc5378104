//! A training or evaluation view: a posed camera and its image.

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
    /// Checks that the image and mask sizes match the camera and that values are finite.
    ///
    /// # Errors
    /// A message naming the mismatch or the first bad value.
    pub fn check(&self) -> Result<(), String> {
        let k = &self.camera.intrinsics;
        let px = k.width as usize * k.height as usize;
        if px == 0 {
            return Err(format!(
                "camera has an empty image size {}×{}",
                k.width, k.height
            ));
        }
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
