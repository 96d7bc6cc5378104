//! PLY point clouds and meshes: header, fast binary path, general path, writer.

mod read;
mod rig;
mod schema;
mod write;

pub use ply_core::{Element, Header, HeaderError, PlyFormat, Property, PropertyKind, ScalarType};

use std::path::Path;

use read::{Body, Want, read_body};
use rig::parse_rig_comments;

use crate::cloud::ExtraProperty;
use crate::mesh::{Material, Mesh, Texture};
use crate::{Error, Model, PlenopticCloud, PlyLayout};

/// Maps the file and hands its bytes to `f` (empty files get an empty slice: mapping 0 bytes fails).
fn with_bytes<R>(path: &Path, f: impl FnOnce(&[u8]) -> Result<R, Error>) -> Result<R, Error> {
    Error::require_file(path)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    if len == 0 {
        return f(&[]);
    }
    // SAFETY: the map is read-only and lives only during `f`; like every mmap reader we rely on
    // the file not being truncated by another process meanwhile (documented in docs/formats-input.md).
    // Every byte is read anyway, so pre-fault the whole map (MAP_POPULATE) instead of page by page.
    #[allow(unsafe_code)]
    let map = unsafe { memmap2::MmapOptions::new().populate().map(&file) }
        .map_err(|e| Error::io(path, e))?;
    f(&map)
}

/// The colour in [0, 1] that a uchar colour property storing `level` reads as (`level / 255`,
/// as every colour a reader here returns from an 8-bit property).
#[must_use]
#[inline]
pub fn uchar_color(level: u8) -> f32 {
    schema::color_from_stored(f64::from(level), ScalarType::U8)
}

/// Parses the header at the start of `bytes` (see [`ply_core::parse_header`]); `path` names the
/// file in errors.
pub fn parse_header(path: &Path, bytes: &[u8]) -> Result<Header, Error> {
    ply_core::parse_header(bytes).map_err(|e| Error::header(path, e))
}

/// Reads the header of a PLY file (cheap: the body is not touched).
pub fn read_header(path: &Path) -> Result<Header, Error> {
    with_bytes(path, |bytes| parse_header(path, bytes))
}

/// Reads a PLY point cloud (the vertex element; faces, if any, are ignored).
pub(crate) fn read_cloud(path: &Path) -> Result<PlenopticCloud, Error> {
    with_bytes(path, |bytes| cloud_from_bytes(path, bytes))
}

/// Parses a whole PLY file held in memory as a point cloud; `name` is used in error messages.
pub fn cloud_from_bytes(name: &Path, bytes: &[u8]) -> Result<PlenopticCloud, Error> {
    let header = parse_header(name, bytes)?;
    cloud_from(name, bytes, &header)
}

/// Parses a whole PLY file held in memory as a mesh (if it has faces) or a cloud, like [`crate::load`].
pub fn model_from_bytes(name: &Path, bytes: &[u8]) -> Result<Model, Error> {
    let header = parse_header(name, bytes)?;
    if has_faces(&header) {
        mesh_from(name, bytes, &header).map(Model::Mesh)
    } else {
        cloud_from(name, bytes, &header).map(Model::Cloud)
    }
}

/// Reads a PLY mesh; a PLY without faces is an error that says it is a point cloud.
pub(crate) fn read_mesh(path: &Path) -> Result<Mesh, Error> {
    with_bytes(path, |bytes| {
        let header = parse_header(path, bytes)?;
        if !has_faces(&header) {
            return Err(Error::Content {
                path: path.to_path_buf(),
                message: "the file has no faces (it is a point cloud; read it as a cloud)".into(),
            });
        }
        mesh_from(path, bytes, &header)
    })
}

/// Reads a PLY as a mesh when it has a face element with at least one face, else as a cloud.
pub(crate) fn load(path: &Path) -> Result<Model, Error> {
    with_bytes(path, |bytes| model_from_bytes(path, bytes))
}

/// True when the header declares a face element with at least one face.
fn has_faces(header: &Header) -> bool {
    header.element("face").is_some_and(|(_, e)| e.count > 0)
}

/// Builds the cloud from a parsed header and the file bytes.
fn cloud_from(path: &Path, bytes: &[u8], header: &Header) -> Result<PlenopticCloud, Error> {
    let rig = parse_rig_comments(path, &header.comments)?;
    let Body { plan, vertices, .. } = read_body(path, bytes, header, false, Want::Points)?;
    let cameras = rig.cameras(path, plan.cameras.len())?;
    let num_cameras = plan.cameras.len();
    let colors = main_colors(
        vertices.colors,
        &vertices.camera_colors,
        vertices.positions.len(),
        num_cameras,
    );
    let (_, element) = header.element("vertex").ok_or_else(|| Error::Content {
        path: path.to_path_buf(),
        message: "the file has no 'vertex' element".into(),
    })?;
    let properties = element
        .properties
        .iter()
        .filter_map(|p| match p.kind {
            PropertyKind::Scalar(t) => Some((p.name.clone(), t)),
            PropertyKind::List { .. } => None,
        })
        .collect();
    Ok(PlenopticCloud {
        positions: vertices.positions,
        normals: vertices.normals,
        colors,
        num_cameras,
        camera_colors: vertices.camera_colors,
        cameras,
        frame_to_world_scale: rig.scale,
        frame_to_world_translation: rig.translation,
        width: rig.width,
        extra: plan
            .extras
            .iter()
            .zip(vertices.extras)
            .map(|((name, _), values)| ExtraProperty {
                name: name.clone(),
                values,
            })
            .collect(),
        layout: Some(PlyLayout {
            format: header.format,
            properties,
            comments: rig.other,
        }),
    })
}

/// Mid grey: the main colour of points whose file has no colour at all.
const NO_COLOR: [f32; 3] = [0.5, 0.5, 0.5];

/// The main colour: the file's, else the mean of the camera colours, else mid grey.
fn main_colors(
    colors: Option<Vec<[f32; 3]>>,
    camera_colors: &[[f32; 3]],
    n: usize,
    num_cameras: usize,
) -> Vec<[f32; 3]> {
    if let Some(c) = colors {
        return c;
    }
    if num_cameras == 0 {
        return vec![NO_COLOR; n];
    }
    camera_colors
        .chunks_exact(num_cameras)
        .map(|cams| {
            let mut sum = [0.0f32; 3];
            for c in cams {
                for i in 0..3 {
                    sum[i] += c[i];
                }
            }
            sum.map(|s| s / num_cameras as f32)
        })
        .collect()
}

/// Builds a mesh from a parsed header and the file bytes (MeshLab's `comment TextureFile` is honoured).
fn mesh_from(path: &Path, bytes: &[u8], header: &Header) -> Result<Mesh, Error> {
    let rig = parse_rig_comments(path, &header.comments)?;
    let Body {
        plan,
        vertices,
        triangles,
    } = read_body(path, bytes, header, true, Want::Triangles)?;
    let cameras = rig.cameras(path, plan.cameras.len())?;
    let texture_file = rig
        .other
        .iter()
        .find_map(|c| c.strip_prefix("TextureFile "))
        .map(str::trim);
    let (materials, textures, triangle_materials) = match texture_file {
        Some(name) => {
            let texture =
                crate::mesh::load_texture(path, &crate::mesh::resolve_relative(path, name))?;
            let material = Material {
                name: name.to_string(),
                base_color: [1.0; 4],
                texture: Some(0),
            };
            (vec![material], vec![texture], vec![0; triangles.len()])
        }
        None => (Vec::<Material>::new(), Vec::<Texture>::new(), Vec::new()),
    };
    Ok(Mesh {
        positions: vertices.positions,
        normals: vertices.normals,
        uvs: vertices.uvs,
        colors: vertices.colors,
        num_cameras: plan.cameras.len(),
        camera_colors: vertices.camera_colors,
        cameras,
        triangles,
        triangle_materials,
        materials,
        textures,
    })
}

/// Writes a PLY point cloud atomically.
pub(crate) fn write_cloud(path: &Path, cloud: &PlenopticCloud) -> Result<(), Error> {
    write::write_cloud(path, cloud)
}
