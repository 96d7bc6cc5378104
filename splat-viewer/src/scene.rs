//! What the viewer shows, as `scene.js` hands it to the page: the model file, the cameras to
//! jump to and the pictures to compare at each.

use serde::Serialize;

use crate::Error;

/// A pinhole camera in splat-core's conventions (COLMAP axes, world→camera pose, pixel (0, 0)'s
/// centre at (0.5, 0.5)); no skew.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewCamera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, in pixels.
    pub fx: f64,
    /// Focal length along y, in pixels.
    pub fy: f64,
    /// Principal point x, in pixels from the left edge.
    pub cx: f64,
    /// Principal point y, in pixels from the top edge.
    pub cy: f64,
    /// World→camera rotation, rows.
    pub rotation: [[f64; 3]; 3],
    /// World→camera translation.
    pub translation: [f64; 3],
}

/// Pictures of one camera, as paths relative to the viewer's folder.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct ViewImages {
    /// The reference view (what the model was trained to match).
    pub reference: Option<String>,
    /// The CPU rasteriser's render of the model.
    pub render: Option<String>,
    /// The error map between the two.
    pub error: Option<String>,
}

/// A camera the viewer can jump to.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneView {
    /// Its name (a button's label, and the `view=` URL parameter).
    pub name: String,
    /// Its camera.
    pub camera: ViewCamera,
    /// Pictures to compare with the live render there.
    pub images: Option<ViewImages>,
}

/// The model file of a scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SceneModel {
    /// The file (SPZ or 3DGS PLY), relative to the viewer's folder.
    pub file: String,
    /// A script beside it holding the same bytes in base64, for a page opened from disk
    /// (browsers refuse `fetch` there); `None` when the model is too large to embed.
    pub embedded: Option<String>,
}

/// Everything `scene.js` holds.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Scene {
    /// The page's title.
    pub title: String,
    /// The model, or `None` for a viewer that asks for a file.
    pub model: Option<SceneModel>,
    /// The cameras, in the order of their buttons.
    pub views: Vec<SceneView>,
}

impl Scene {
    /// Returns `scene.js`: the scene as `window.SPLAT_SCENE`.
    ///
    /// # Errors
    /// [`Error::Json`] when a number is not finite.
    pub fn to_script(&self) -> Result<String, Error> {
        Ok(format!(
            "window.SPLAT_SCENE = {};\n",
            serde_json::to_string(self)?
        ))
    }
}
