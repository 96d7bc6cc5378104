//! glTF 2.0 / GLB meshes through gltf: every TRIANGLES primitive of the default scene, node
//! transforms applied, base-colour factor and texture, COLOR_0.

use std::collections::HashMap;
use std::path::Path;

use glam::{Mat3, Mat4, Vec2, Vec3};

use crate::Error;
use crate::mesh::{Material, Mesh, Texture};

/// Reads a glTF or GLB mesh. Colours and factors are taken as stored (no linearisation, see the crate docs).
pub(crate) fn read_gltf(path: &Path) -> Result<Mesh, Error> {
    let err = |message: String| Error::Gltf {
        path: path.to_path_buf(),
        message,
    };
    Error::require_file(path)?;
    if let Some(problem) = container_problem(path) {
        return Err(err(problem));
    }
    if let Some(version) = asset_version(path).filter(|v| !v.starts_with("2.")) {
        return Err(err(format!(
            "glTF version {version} is not supported (glTF 2.0 only)"
        )));
    }
    // gltf has had panics on malformed input (gltf-rs/gltf#359); turn any into an error.
    let imported = std::panic::catch_unwind(|| gltf::import(path))
        .map_err(|_| err("the glTF importer failed on malformed input".into()))?;
    let (document, buffers, images) = imported.map_err(|e| match e {
        gltf::Error::Io(io) => err(missing_resource(path).unwrap_or_else(|| io.to_string())),
        other => err(other.to_string()),
    })?;
    let scene = document
        .default_scene()
        .or_else(|| document.scenes().next())
        .ok_or_else(|| err("the file has no scene".into()))?;
    let mut builder = Builder {
        path,
        buffers: &buffers,
        images: &images,
        mesh: Mesh::default(),
        material_index: HashMap::new(),
        texture_index: HashMap::new(),
        normals: Some(Vec::new()),
        uvs: Some(Vec::new()),
        colors: Some(Vec::new()),
    };
    let mut stack: Vec<(gltf::Node<'_>, Mat4)> =
        scene.nodes().map(|n| (n, Mat4::IDENTITY)).collect();
    // The node hierarchy must be a set of disjoint trees (glTF 2.0, "Nodes and Hierarchy"); a node reached a
    // second time means a cycle (or a shared child), which would otherwise loop forever.
    let mut reached = vec![false; document.nodes().len()];
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut reached[node.index()], true) {
            return Err(err(format!(
                "node {} is reached twice from scene {}: the node hierarchy has a cycle or a \
                 node with two parents",
                node.index(),
                scene.index()
            )));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            for primitive in mesh.primitives() {
                builder.primitive(&mesh, &primitive, world)?;
            }
        }
        stack.extend(node.children().map(|c| (c, world)));
    }
    let mut mesh = builder.mesh;
    if mesh.triangles.is_empty() {
        return Err(err(format!(
            "the default scene ({}) has no triangles",
            scene.index()
        )));
    }
    mesh.normals = builder.normals;
    mesh.uvs = builder.uvs;
    mesh.colors = builder.colors;
    Ok(mesh)
}

/// The `asset.version` of a .gltf or .glb file, or `None` when it cannot be read (the importer
/// then reports the problem). A GLB container of version 1 is glTF 1.0.
/// What is wrong with the file as a container, said before the importer says it less clearly
/// ("failed to fill whole buffer", "expected value at line 1 column 1"): a GLB shorter than its
/// header's length, a `.glb` without the magic, a `.gltf` that is not JSON text.
fn container_problem(path: &Path) -> Option<String> {
    use std::io::Read as _;
    let mut head = [0u8; 12];
    let file = std::fs::File::open(path).ok()?;
    let size = file.metadata().ok()?.len();
    let read = file.take(12).read(&mut head).ok()?;
    let glb_extension = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if head.starts_with(b"glTF") {
        if read < 12 {
            return Some(format!("a GLB header is 12 bytes; the file has {size}"));
        }
        let declared = u64::from(u32::from_le_bytes([head[8], head[9], head[10], head[11]]));
        return (declared > size).then(|| {
            format!(
                "the GLB header declares {declared} bytes but the file has {size}: it is cut short"
            )
        });
    }
    if glb_extension {
        return Some("not a GLB file: it does not start with the magic `glTF`".into());
    }
    // (A byte-order mark, which the spec forbids writing but readers meet, is not the problem.)
    let text = head[..read]
        .strip_prefix(b"\xEF\xBB\xBF")
        .unwrap_or(&head[..read]);
    let first = text.iter().find(|b| !b.is_ascii_whitespace());
    (read > 0 && first.is_some_and(|&b| b != b'{'))
        .then(|| "not a glTF JSON file (it does not start with `{`) nor a GLB (`glTF`)".into())
}

fn asset_version(path: &Path) -> Option<String> {
    let bytes = std::fs::read(path).ok()?;
    let json = if bytes.starts_with(b"glTF") {
        let word =
            |at: usize| Some(u32::from_le_bytes(bytes.get(at..at + 4)?.try_into().ok()?) as usize);
        if word(4)? != 2 {
            return Some(format!(
                "{} (binary container version {})",
                if word(4)? == 1 { "1.0" } else { "?" },
                word(4)?
            ));
        }
        bytes.get(20..20 + word(12)?)?
    } else {
        &bytes[..]
    };
    let value: serde_json::Value = serde_json::from_slice(json).ok()?;
    value
        .get("asset")?
        .get("version")?
        .as_str()
        .map(str::to_string)
}

/// Names the first external buffer or image that does not exist next to the glTF file (the
/// importer's I/O error does not say which one it was).
fn missing_resource(path: &Path) -> Option<String> {
    let document = gltf::Gltf::open(path).ok()?;
    let dir = resource_folder(path);
    let buffers = document.buffers().filter_map(|b| match b.source() {
        gltf::buffer::Source::Uri(uri) => {
            Some(format!("buffer {} refers to '{uri}'", b.index())).zip(Some(uri))
        }
        gltf::buffer::Source::Bin => None,
    });
    let images = document.images().filter_map(|i| match i.source() {
        gltf::image::Source::Uri { uri, .. } => {
            Some(format!("image {} refers to '{uri}'", i.index())).zip(Some(uri))
        }
        gltf::image::Source::View { .. } => None,
    });
    buffers
        .chain(images)
        .find(|(_, uri)| !uri.starts_with("data:") && !dir.join(uri).exists())
        .map(|(what, _)| format!("{what}, which does not exist in {}", dir.display()))
}

/// The folder a glTF file's relative URIs start from, as it is named to a person: a bare file
/// name's parent is the empty path, which names the current folder.
fn resource_folder(path: &Path) -> &Path {
    path.parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or_else(|| Path::new("."))
}

/// An accessor's component type and dimensions.
type Layout = (gltf::accessor::DataType, gltf::accessor::Dimensions);

/// The layouts glTF allows for the attributes we read (`None`: the indices); empty for others.
fn layouts(semantic: Option<&gltf::Semantic>) -> &'static [Layout] {
    use gltf::Semantic;
    use gltf::accessor::DataType::{F32, U8, U16, U32};
    use gltf::accessor::Dimensions::{Scalar, Vec2, Vec3, Vec4};
    match semantic {
        None => &[(U8, Scalar), (U16, Scalar), (U32, Scalar)],
        Some(Semantic::Positions | Semantic::Normals) => &[(F32, Vec3)],
        Some(Semantic::TexCoords(0)) => &[(U8, Vec2), (U16, Vec2), (F32, Vec2)],
        Some(Semantic::Colors(0)) => &[
            (U8, Vec3),
            (U16, Vec3),
            (F32, Vec3),
            (U8, Vec4),
            (U16, Vec4),
            (F32, Vec4),
        ],
        Some(_) => &[],
    }
}

/// Most items a sparse accessor without a buffer view may declare (16.7 M; 200 MB of positions).
const MAX_VIEWLESS_ITEMS: usize = 1 << 24;

/// Accumulates primitives into one mesh.
struct Builder<'a> {
    path: &'a Path,
    buffers: &'a [gltf::buffer::Data],
    images: &'a [gltf::image::Data],
    mesh: Mesh,
    /// glTF material index (None = default material) → our index.
    material_index: HashMap<Option<usize>, u32>,
    /// glTF image index → our texture index.
    texture_index: HashMap<usize, usize>,
    /// Kept only while every primitive so far has the attribute.
    normals: Option<Vec<Vec3>>,
    uvs: Option<Vec<Vec2>>,
    colors: Option<Vec<[f32; 3]>>,
}

impl Builder<'_> {
    fn err(&self, message: String) -> Error {
        Error::Gltf {
            path: self.path.to_path_buf(),
            message,
        }
    }

    /// Refuses accessor counts that gltf's readers would trust: a count of 0 underflows their
    /// bounds arithmetic, and a sparse accessor without a buffer view yields `count` items (zeros
    /// plus the sparse values) from no data at all, so a tiny file could claim billions.
    /// A layout outside `layouts` (when not empty) is refused too: gltf's readers assert or hit
    /// `unreachable!` on component types and dimensions glTF does not allow for the attribute.
    fn check_accessor(
        &self,
        what: &str,
        role: &str,
        layouts: &[Layout],
        accessor: &gltf::Accessor<'_>,
    ) -> Result<(), Error> {
        let bad = |problem: String| {
            self.err(format!(
                "{what} {role} (accessor {}): {problem}",
                accessor.index()
            ))
        };
        let layout = (accessor.data_type(), accessor.dimensions());
        if !layouts.is_empty() && !layouts.contains(&layout) {
            return Err(bad(format!(
                "{:?} {:?} is not a layout glTF allows here",
                layout.0, layout.1
            )));
        }
        if accessor.count() == 0 {
            return Err(bad("count is 0 (glTF requires at least 1)".into()));
        }
        // gltf asserts the stride holds an item; without debug assertions items would overlap.
        if let Some(stride) = accessor.view().and_then(|v| v.stride())
            && stride < accessor.size()
        {
            return Err(bad(format!(
                "byte stride {stride} is smaller than one item ({} bytes)",
                accessor.size()
            )));
        }
        if let Some(sparse) = accessor.sparse() {
            if sparse.count() == 0 {
                return Err(bad("sparse count is 0 (glTF requires at least 1)".into()));
            }
            if accessor.view().is_none() && accessor.count() > MAX_VIEWLESS_ITEMS {
                return Err(bad(format!(
                    "{} items with no buffer view behind them (at most {MAX_VIEWLESS_ITEMS} are accepted)",
                    accessor.count()
                )));
            }
            let indices = sparse.indices();
            let (index_size, count) = (indices.index_type().size(), sparse.count());
            self.check_span(&indices.view(), indices.offset(), count, index_size)
                .map_err(|p| bad(format!("its sparse indices: {p}")))?;
            let values = sparse.values();
            self.check_span(&values.view(), values.offset(), count, accessor.size())
                .map_err(|p| bad(format!("its sparse values: {p}")))?;
        }
        if let Some(view) = accessor.view() {
            self.check_span(&view, accessor.offset(), accessor.count(), accessor.size())
                .map_err(bad)?;
        }
        Ok(())
    }

    /// Refuses `count` items of `size` bytes from `offset` into `view` (`count` ≥ 1) that reach
    /// past the view, and a view that reaches past its buffer's data. gltf's readers return
    /// nothing for either (an attribute then looked absent, indices were read from beyond their
    /// view) and compute the ends with sums that can wrap.
    fn check_span(
        &self,
        view: &gltf::buffer::View<'_>,
        offset: usize,
        count: usize,
        size: usize,
    ) -> Result<(), String> {
        let buffer = view.buffer().index();
        let data = self.buffers.get(buffer).map_or(0, |d| d.0.len());
        if view
            .offset()
            .checked_add(view.length())
            .is_none_or(|end| end > data)
        {
            return Err(format!(
                "buffer view {} ({} bytes from byte {}) reaches past the {data} bytes of buffer \
                 {buffer}",
                view.index(),
                view.length(),
                view.offset()
            ));
        }
        let stride = view.stride().unwrap_or(size);
        let end = stride
            .checked_mul(count - 1)
            .and_then(|b| b.checked_add(size))
            .and_then(|b| b.checked_add(offset));
        if end.is_none_or(|end| end > view.length()) {
            return Err(format!(
                "{count} items of {size} bytes, {stride} apart from byte {offset}, reach past the \
                 {} bytes of buffer view {}",
                view.length(),
                view.index()
            ));
        }
        Ok(())
    }

    fn primitive(
        &mut self,
        mesh: &gltf::Mesh<'_>,
        primitive: &gltf::Primitive<'_>,
        world: Mat4,
    ) -> Result<(), Error> {
        let what = format!("mesh {} primitive {}", mesh.index(), primitive.index());
        if primitive.mode() != gltf::mesh::Mode::Triangles {
            return Err(self.err(format!(
                "{what} has mode {:?}; only TRIANGLES is supported",
                primitive.mode()
            )));
        }
        let accessors = primitive
            .attributes()
            .map(|(semantic, a)| (format!("{semantic:?}"), layouts(Some(&semantic)), a))
            .chain(
                primitive
                    .indices()
                    .map(|a| ("indices".to_string(), layouts(None), a)),
            );
        for (role, layouts, accessor) in accessors {
            self.check_accessor(&what, &role, layouts, &accessor)?;
        }
        let reader = primitive.reader(|b| self.buffers.get(b.index()).map(|d| &d.0[..]));
        let positions: Vec<[f32; 3]> = match reader.read_positions() {
            Some(positions) => positions.collect(),
            None => {
                return Err(self.err(match primitive.get(&gltf::Semantic::Positions) {
                    None => format!("{what} has no POSITION attribute"),
                    // Spans are checked above and the importer refuses an accessor with
                    // neither a view nor sparse values, so this is a reader's own limit.
                    Some(a) => format!(
                        "{what} POSITION (accessor {}) could not be read from its buffer",
                        a.index()
                    ),
                }));
            }
        };
        let vertex = format!("glTF {what} vertex");
        let position = ["POSITION.x", "POSITION.y", "POSITION.z"];
        crate::error::check_finite(self.path, &vertex, position, &positions)?;
        let count = positions.len();
        let base = self.mesh.positions.len();
        self.mesh.positions.extend(
            positions
                .iter()
                .map(|&p| world.transform_point3(Vec3::from(p))),
        );
        let normal_matrix = Mat3::from_mat4(world).inverse().transpose();
        let normals = reader
            .read_normals()
            .map(Iterator::collect::<Vec<[f32; 3]>>);
        if let Some(n) = &normals {
            let normal = ["NORMAL.x", "NORMAL.y", "NORMAL.z"];
            crate::error::check_finite(self.path, &vertex, normal, n)?;
        }
        let normals = normals.map(|n| {
            n.into_iter()
                .map(|n| (normal_matrix * Vec3::from(n)).normalize_or_zero())
                .collect::<Vec<_>>()
        });
        let uvs = reader
            .read_tex_coords(0)
            .map(|t| t.into_f32().collect::<Vec<[f32; 2]>>());
        if let Some(t) = &uvs {
            crate::error::check_finite(self.path, &vertex, ["TEXCOORD_0.u", "TEXCOORD_0.v"], t)?;
        }
        let uvs = uvs.map(|t| t.into_iter().map(Vec2::from).collect::<Vec<_>>());
        let colors = reader
            .read_colors(0)
            .map(|c| c.into_rgb_f32().collect::<Vec<_>>());
        if let Some(c) = &colors {
            crate::error::check_finite(
                self.path,
                &vertex,
                ["COLOR_0.r", "COLOR_0.g", "COLOR_0.b"],
                c,
            )?;
        }
        append(&mut self.normals, normals, count);
        append(&mut self.uvs, uvs, count);
        append(&mut self.colors, colors, count);
        let indices: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..count as u32).collect(),
        };
        if !indices.len().is_multiple_of(3) {
            return Err(self.err(format!(
                "{what} has {} indices, not a multiple of 3",
                indices.len()
            )));
        }
        let material = self.material(primitive.material())?;
        for (t, tri) in indices.chunks_exact(3).enumerate() {
            if let Some(&bad) = tri.iter().find(|&&v| v as usize >= count) {
                return Err(Error::IndexOutOfRange {
                    path: self.path.to_path_buf(),
                    what: format!("glTF {what} triangle"),
                    index: t as u64,
                    vertex: i64::from(bad),
                    count: count as u64,
                });
            }
            self.mesh
                .triangles
                .push([0, 1, 2].map(|c| (base + tri[c] as usize) as u32));
            self.mesh.triangle_materials.push(material);
        }
        Ok(())
    }

    /// Our index of a glTF material, added on first use with its base-colour texture.
    fn material(&mut self, material: gltf::Material<'_>) -> Result<u32, Error> {
        if let Some(&i) = self.material_index.get(&material.index()) {
            return Ok(i);
        }
        let pbr = material.pbr_metallic_roughness();
        let texture = match pbr.base_color_texture() {
            Some(info) => {
                if info.tex_coord() != 0 {
                    return Err(self.err(format!(
                        "material {:?} samples its base-colour texture with TEXCOORD_{}; only TEXCOORD_0 is read",
                        material.name(),
                        info.tex_coord()
                    )));
                }
                let image = info.texture().source().index();
                Some(match self.texture_index.get(&image) {
                    Some(&t) => t,
                    None => {
                        let data = self
                            .images
                            .get(image)
                            .ok_or_else(|| self.err(format!("image {image} was not loaded")))?;
                        self.mesh.textures.push(texture_from_gltf(data));
                        self.texture_index
                            .insert(image, self.mesh.textures.len() - 1);
                        self.mesh.textures.len() - 1
                    }
                })
            }
            None => None,
        };
        self.mesh.materials.push(Material {
            name: material.name().unwrap_or_default().to_string(),
            base_color: pbr.base_color_factor(),
            texture,
        });
        let index = (self.mesh.materials.len() - 1) as u32;
        self.material_index.insert(material.index(), index);
        Ok(index)
    }
}

/// Appends a primitive's attribute, or drops the attribute for the whole mesh when a primitive lacks it.
fn append<T>(all: &mut Option<Vec<T>>, part: Option<Vec<T>>, count: usize) {
    match (all.as_mut(), part) {
        (Some(v), Some(p)) if p.len() == count => v.extend(p),
        _ => *all = None,
    }
}

/// Converts gltf's decoded image to RGBA floats (grey formats replicate, missing alpha is 1).
fn texture_from_gltf(data: &gltf::image::Data) -> Texture {
    use gltf::image::Format;
    let u8s = |b: &[u8]| {
        b.iter()
            .map(|&v| f32::from(v) / 255.0)
            .collect::<Vec<f32>>()
    };
    let u16s = |b: &[u8]| {
        b.chunks_exact(2)
            .map(|c| f32::from(u16::from_ne_bytes([c[0], c[1]])) / 65535.0)
            .collect::<Vec<f32>>()
    };
    let f32s = |b: &[u8]| {
        b.chunks_exact(4)
            .map(|c| f32::from_ne_bytes([c[0], c[1], c[2], c[3]]))
            .collect::<Vec<f32>>()
    };
    let (values, channels) = match data.format {
        Format::R8 => (u8s(&data.pixels), 1),
        Format::R8G8 => (u8s(&data.pixels), 2),
        Format::R8G8B8 => (u8s(&data.pixels), 3),
        Format::R8G8B8A8 => (u8s(&data.pixels), 4),
        Format::R16 => (u16s(&data.pixels), 1),
        Format::R16G16 => (u16s(&data.pixels), 2),
        Format::R16G16B16 => (u16s(&data.pixels), 3),
        Format::R16G16B16A16 => (u16s(&data.pixels), 4),
        Format::R32G32B32FLOAT => (f32s(&data.pixels), 3),
        Format::R32G32B32A32FLOAT => (f32s(&data.pixels), 4),
    };
    let pixels = values
        .chunks_exact(channels)
        .map(|p| match channels {
            1 => [p[0], p[0], p[0], 1.0],
            2 => [p[0], p[0], p[0], p[1]],
            3 => [p[0], p[1], p[2], 1.0],
            _ => [p[0], p[1], p[2], p[3]],
        })
        .collect();
    Texture {
        width: data.width,
        height: data.height,
        pixels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bare_file_name_resolves_in_the_current_folder() {
        assert_eq!(resource_folder(Path::new("m.gltf")), Path::new("."));
        assert_eq!(resource_folder(Path::new("a/b/m.gltf")), Path::new("a/b"));
        assert_eq!(resource_folder(Path::new("/m.gltf")), Path::new("/"));
    }
}
