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
    /// Camera-space z of the visible surface (W·H); 0 where nothing is seen.
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
    #[must_use]
    pub fn depth_at(&self, x: u32, y: u32) -> f32 {
        self.depth[y as usize * self.width as usize + x as usize]
    }

    /// Straight (un-premultiplied) colour: `rgb` is composited on a black background, so a pixel
    /// with coverage `a` holds `a·colour`; dividing by `a` (clamped to [0, 1]) recovers the
    /// colour, and uncovered pixels are black. This is what a trainer compositing its own
    /// backgrounds under the coverage mask wants.
    #[must_use]
    pub fn straight_rgb(&self) -> Vec<f32> {
        self.rgb
            .chunks_exact(3)
            .zip(&self.alpha)
            .flat_map(|(px, &a)| {
                if a > 1e-6 {
                    [0, 1, 2].map(|c| (px[c] / a).clamp(0.0, 1.0))
                } else {
                    [0.0; 3]
                }
            })
            .collect()
    }
}
