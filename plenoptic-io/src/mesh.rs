//! The triangle mesh read from OBJ, glTF/GLB or PLY.

use glam::{Vec2, Vec3};

use crate::cloud::CaptureCamera;

/// A decoded texture image.
#[derive(Debug, Clone, PartialEq)]
pub struct Texture {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA in [0, 1], row-major, top row first.
    pub pixels: Vec<[f32; 4]>,
}

/// A material: base colour factor and optional base-colour texture.
#[derive(Debug, Clone, PartialEq)]
pub struct Material {
    /// Name from the file (may be empty).
    pub name: String,
    /// RGBA factor in [0, 1] (OBJ `Kd` with alpha `d`, glTF `baseColorFactor`).
    pub base_color: [f32; 4],
    /// Index into [`Mesh::textures`] (OBJ `map_Kd`, glTF `baseColorTexture`).
    pub texture: Option<usize>,
}

/// A triangle mesh with optional per-vertex attributes and materials.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mesh {
    /// Vertex positions (node transforms applied for glTF).
    pub positions: Vec<Vec3>,
    /// Vertex normals.
    pub normals: Option<Vec<Vec3>>,
    /// Texture coordinates, image convention: (0, 0) = top-left of the texture.
    pub uvs: Option<Vec<Vec2>>,
    /// Vertex colours in [0, 1].
    pub colors: Option<Vec<[f32; 3]>>,
    /// Per-vertex plenoptic colours (PLY `red{k}`…), else 0.
    pub num_cameras: usize,
    /// Per-camera vertex colours, vertex-major: `[v * num_cameras + k]`.
    pub camera_colors: Vec<[f32; 3]>,
    /// Capture rig of the per-vertex plenoptic colours (PLY rig comments).
    pub cameras: Vec<CaptureCamera>,
    /// Triangles as vertex indices (polygons are fan-triangulated).
    pub triangles: Vec<[u32; 3]>,
    /// Material index of each triangle (empty when there are no materials).
    pub triangle_materials: Vec<u32>,
    /// Materials.
    pub materials: Vec<Material>,
    /// Texture images referred to by materials.
    pub textures: Vec<Texture>,
}

impl Mesh {
    /// Number of vertices.
    #[must_use]
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// The `num_cameras` colours of vertex `v` (empty when not plenoptic). Panics if out of range.
    #[must_use]
    pub fn camera_colors_of(&self, v: usize) -> &[[f32; 3]] {
        &self.camera_colors[v * self.num_cameras..(v + 1) * self.num_cameras]
    }
}

/// Resolves a texture name from a model file: Windows separators (`.\SpiderTex.jpg`, as written by
/// some exporters) become `/`, relative names are taken from the model's folder, and when that
/// file does not exist the bare file name next to the model is tried.
#[must_use]
pub(crate) fn resolve_relative(model: &std::path::Path, name: &str) -> std::path::PathBuf {
    let cleaned = name.trim().replace('\\', "/");
    let dir = model.parent().unwrap_or_else(|| std::path::Path::new(""));
    let candidate = dir.join(cleaned.trim_start_matches("./"));
    if candidate.exists() {
        return candidate;
    }
    match std::path::Path::new(&cleaned).file_name() {
        Some(file) => dir.join(file),
        None => candidate,
    }
}

/// Decodes a texture file into RGBA floats in [0, 1].
pub(crate) fn load_texture(
    model: &std::path::Path,
    texture: &std::path::Path,
) -> Result<Texture, crate::Error> {
    let err = |message: String| crate::Error::Texture {
        path: model.to_path_buf(),
        texture: texture.to_path_buf(),
        message,
    };
    let image = image::ImageReader::open(texture)
        .map_err(|e| err(e.to_string()))?
        .with_guessed_format()
        .map_err(|e| err(e.to_string()))?
        .decode()
        .map_err(|e| err(e.to_string()))?;
    Ok(texture_from_image(image))
}

/// Converts a decoded image to a [`Texture`].
pub(crate) fn texture_from_image(image: image::DynamicImage) -> Texture {
    let rgba = image.into_rgba32f();
    let (width, height) = rgba.dimensions();
    Texture {
        width,
        height,
        pixels: rgba.pixels().map(|p| p.0).collect(),
    }
}
