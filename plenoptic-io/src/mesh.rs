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

/// Barycentric mix of three colours: `bary[0]·c[0] + bary[1]·c[1] + bary[2]·c[2]` per channel.
#[inline]
#[must_use]
pub fn barycentric_mix(c: [[f32; 3]; 3], bary: [f32; 3]) -> [f32; 3] {
    std::array::from_fn(|k| bary[0] * c[0][k] + bary[1] * c[1][k] + bary[2] * c[2][k])
}

impl Mesh {
    /// The view-independent colour of triangle `t` at barycentrics `bary`: material base colour ×
    /// bilinear texture (when the material has one and the mesh has texture coordinates) × vertex
    /// colour (when present); white when none is given (glTF's default base colour).
    #[must_use]
    pub fn albedo_at(&self, t: usize, bary: [f32; 3]) -> [f32; 3] {
        let tri = self.triangles[t];
        let mut color = [1.0f32; 3];
        if let Some(material) = self
            .triangle_materials
            .get(t)
            .and_then(|&m| self.materials.get(m as usize))
        {
            for (k, c) in color.iter_mut().enumerate() {
                *c *= material.base_color[k];
            }
            if let (Some(tex), Some(uvs)) = (
                material.texture.and_then(|i| self.textures.get(i)),
                &self.uvs,
            ) {
                let uv = bary[0] * uvs[tri[0] as usize]
                    + bary[1] * uvs[tri[1] as usize]
                    + bary[2] * uvs[tri[2] as usize];
                let s = tex.sample_bilinear(uv);
                for (k, c) in color.iter_mut().enumerate() {
                    *c *= s[k];
                }
            }
        }
        if let Some(colors) = &self.colors {
            let v = barycentric_mix(tri.map(|v| colors[v as usize]), bary);
            for (k, c) in color.iter_mut().enumerate() {
                *c *= v[k];
            }
        }
        color
    }
}

impl Texture {
    /// Bilinear sample at `uv` (image convention: (0, 0) is the top-left corner of the texture,
    /// texel (i, j)'s centre at ((i + 0.5)/W, (j + 0.5)/H)), wrapping around (glTF's default
    /// REPEAT sampler).
    #[must_use]
    pub fn sample_bilinear(&self, uv: Vec2) -> [f32; 4] {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = uv.x * w as f32 - 0.5;
        let y = uv.y * h as f32 - 0.5;
        if !(x.is_finite() && y.is_finite()) {
            return self.pixels[0];
        }
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let texel = |i: i64, j: i64| self.pixels[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize];
        let (i, j) = (x0 as i64, y0 as i64);
        let (c00, c10, c01, c11) = (
            texel(i, j),
            texel(i + 1, j),
            texel(i, j + 1),
            texel(i + 1, j + 1),
        );
        std::array::from_fn(|k| {
            let top = c00[k] + fx * (c10[k] - c00[k]);
            let bottom = c01[k] + fx * (c11[k] - c01[k]);
            top + fy * (bottom - top)
        })
    }
}

#[cfg(test)]
mod colour_tests {
    use super::*;

    /// One triangle in the z = 0 plane with the given vertex colours.
    fn triangle(colors: Option<Vec<[f32; 3]>>) -> Mesh {
        Mesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            colors,
            triangles: vec![[0, 1, 2]],
            ..Default::default()
        }
    }

    #[test]
    fn bilinear_sampling_matches_hand_values() {
        let tex = Texture {
            width: 2,
            height: 2,
            pixels: vec![
                [0.0, 0.0, 0.0, 1.0],
                [1.0, 0.0, 0.0, 1.0],
                [0.0, 1.0, 0.0, 1.0],
                [1.0, 1.0, 1.0, 1.0],
            ],
        };
        // Texel centres give the texels.
        assert_eq!(
            tex.sample_bilinear(Vec2::new(0.25, 0.25)),
            [0.0, 0.0, 0.0, 1.0]
        );
        assert_eq!(
            tex.sample_bilinear(Vec2::new(0.75, 0.75)),
            [1.0, 1.0, 1.0, 1.0]
        );
        // The middle is the mean of the four.
        assert_eq!(
            tex.sample_bilinear(Vec2::new(0.5, 0.5)),
            [0.5, 0.5, 0.25, 1.0]
        );
        // Wrapping: u = 1.25 is u = 0.25.
        assert_eq!(
            tex.sample_bilinear(Vec2::new(1.25, 0.75)),
            tex.sample_bilinear(Vec2::new(0.25, 0.75))
        );
        // A quarter of the way from texel (0,0) to (1,0).
        let s = tex.sample_bilinear(Vec2::new(0.375, 0.25));
        assert!((s[0] - 0.25).abs() < 1e-6);
    }

    #[test]
    fn material_texture_and_vertex_colours_multiply() {
        let mut mesh = triangle(Some(vec![[0.5, 1.0, 1.0]; 3]));
        mesh.uvs = Some(vec![
            Vec2::new(0.0, 1.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(1.0, 0.0),
        ]);
        mesh.textures = vec![Texture {
            width: 1,
            height: 1,
            pixels: vec![[1.0, 0.5, 1.0, 1.0]],
        }];
        mesh.materials = vec![Material {
            name: "m".into(),
            base_color: [1.0, 1.0, 0.5, 1.0],
            texture: Some(0),
        }];
        mesh.triangle_materials = vec![0];
        let c = mesh.albedo_at(0, [0.2, 0.3, 0.5]);
        assert_eq!(c, [0.5, 0.5, 0.5]);
    }
}
