//! A rendered reference view: colour, coverage and depth.

/// One rendered view: colour, coverage and depth for the same camera.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewImage {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Interleaved RGB in [0, 1], row-major, top row first (3·W·H), composited on the background.
    pub rgb: Vec<f32>,
    /// Coverage in [0, 1] (W·H): 1 where the object is, fractional at edges when supersampled.
    pub alpha: Vec<f32>,
    /// Camera-space z of the visible surface (W·H); 0 where nothing is seen. Empty when the
    /// view was rendered without depth ([`crate::ViewOptions::depth`]).
    pub depth: Vec<f32>,
}

impl ViewImage {
    /// RGB of pixel (x, y).
    #[must_use]
    pub fn rgb_at(&self, x: u32, y: u32) -> [f32; 3] {
        let i = 3 * (y as usize * self.width as usize + x as usize);
        [self.rgb[i], self.rgb[i + 1], self.rgb[i + 2]]
    }

    /// Alpha of pixel (x, y).
    #[must_use]
    pub fn alpha_at(&self, x: u32, y: u32) -> f32 {
        self.alpha[y as usize * self.width as usize + x as usize]
    }

    /// Depth of pixel (x, y) (0 where nothing is seen).
    ///
    /// # Panics
    /// When the view was rendered without depth ([`crate::ViewOptions::depth`]).
    #[must_use]
    pub fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.depth[y as usize * self.width as usize + x as usize]
    }
}
