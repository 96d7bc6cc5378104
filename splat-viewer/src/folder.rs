//! The viewer's files for one scene, written into a folder (beside a report) or held in memory
//! (for a model served as it is), and the HTML that embeds the viewer in another page.

use std::path::Path;

use base64::Engine as _;

use crate::scene::SceneModel;
use crate::{Error, Scene, Site, assets};

/// The largest model embedded as base64 in `model.js` for pages opened from disk: beyond it the
/// page offers a file button instead (a script this size already takes a second or two to parse).
pub const EMBED_LIMIT: usize = 64 << 20;

/// The name of the script holding the embedded model.
const EMBEDDED: &str = "model.js";

/// Returns every file of the viewer for `scene`: the assets, `scene.js`, the model's bytes
/// under `scene.model.file` (when given) with `model.js` when they are small enough, and
/// `extra` (pictures), as (relative path, content).
fn viewer_files(
    scene: &Scene,
    model: Option<&[u8]>,
    extra: Vec<(String, Vec<u8>)>,
) -> Result<Vec<(String, Vec<u8>)>, Error> {
    let mut files: Vec<(String, Vec<u8>)> = assets::files()
        .into_iter()
        .map(|(n, s)| (n.to_string(), s.into_bytes()))
        .collect();
    let mut scene = scene.clone();
    if let (Some(m), Some(bytes)) = (&mut scene.model, model) {
        m.embedded = None;
        if bytes.len() <= EMBED_LIMIT {
            let b64 = base64::engine::general_purpose::STANDARD.encode(bytes);
            files.push((
                EMBEDDED.to_string(),
                format!("window.SPLAT_MODEL_BASE64 = \"{b64}\";\n").into_bytes(),
            ));
            m.embedded = Some(EMBEDDED.to_string());
        }
        files.push((m.file.clone(), bytes.to_vec()));
    }
    files.push(("scene.js".to_string(), scene.to_script()?.into_bytes()));
    files.extend(extra);
    Ok(files)
}

/// Writes the viewer of `scene` into `dir` (created if needed): `index.html`, `viewer.js`,
/// `viewer.css`, `scene.js`, the model (and `model.js`, the model in base64 for pages opened
/// from disk, up to [`EMBED_LIMIT`]) and the `extra` files (pictures named by the scene's
/// views), each atomically.
///
/// # Errors
/// [`Error::Io`] naming the file that could not be written; [`Error::Json`] for a non-finite
/// camera number.
pub fn write_folder(
    dir: &Path,
    scene: &Scene,
    model: &[u8],
    extra: Vec<(String, Vec<u8>)>,
) -> Result<(), Error> {
    for (name, bytes) in viewer_files(scene, Some(model), extra)? {
        let path = dir.join(&name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        atomic_output::write_atomic(&path, &bytes).map_err(|e| Error::io(&path, e))?;
    }
    Ok(())
}

/// Returns a site holding the viewer of one model file in memory: the page at `index.html`, the
/// model at `model_name` (a bare file name; its extension tells SPZ from PLY), no other file.
///
/// # Errors
/// [`Error::Json`] for a non-finite camera number.
pub fn model_site(
    title: &str,
    model_name: &str,
    model: Vec<u8>,
    views: Vec<crate::SceneView>,
) -> Result<Site, Error> {
    let scene = Scene {
        title: title.to_string(),
        model: Some(SceneModel {
            file: model_name.to_string(),
            embedded: None,
        }),
        views,
    };
    let mut site = Site::new("index.html");
    // Served over HTTP, the page fetches the model: no base64 copy.
    for (name, bytes) in viewer_files(&scene, None, Vec::new())? {
        site.add(&name, bytes);
    }
    site.add(model_name, model);
    Ok(site)
}

/// Returns the HTML that embeds the viewer written into the folder `dir` (relative to the page,
/// e.g. `viewer`) in another page: a heading, the viewer's element and its scripts.
#[must_use]
pub fn report_section(dir: &str) -> String {
    let d = dir
        .replace('&', "&amp;")
        .replace('"', "&quot;")
        .replace('<', "&lt;");
    format!(
        "<h2>Explore the model</h2>\n<p>The trained splats, drawn by WebGL2 with the CPU \
         rasteriser's projection and colours. Buttons jump to the held-out cameras; there the \
         live render can be compared with the reference, the CPU render and the error map. \
         <a href=\"{d}/index.html\">Open the viewer on a page of its own</a>.</p>\n\
         <link rel=\"stylesheet\" href=\"{d}/viewer.css\">\n\
         <div class=\"splat-viewer\" data-base=\"{d}/\"></div>\n\
         <script src=\"{d}/scene.js\"></script>\n<script src=\"{d}/viewer.js\"></script>\n"
    )
}
