//! OBJ meshes through tobj: every object merged into one mesh, materials from the MTL file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};

use crate::mesh::{Material, Mesh, load_texture, resolve_relative};
use crate::{Error, Texture};

/// Reads an OBJ mesh (triangulated; positions, normals, UVs with v flipped, vertex colours, materials).
pub(crate) fn read_obj(path: &Path) -> Result<Mesh, Error> {
    let err = |message: String| Error::Obj {
        path: path.to_path_buf(),
        message,
    };
    Error::require_file(path)?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    check_finite_lines(path, &String::from_utf8_lossy(&bytes))?;
    // tobj's index arithmetic overflows on some malformed faces (`f 1//2 7//2 5/-2` multiplies
    // a wrapped relative index), a panic where overflow checks are on; turn any into an error.
    let (models, materials) =
        std::panic::catch_unwind(|| tobj::load_obj(path, &tobj::GPU_LOAD_OPTIONS))
            .map_err(|_| err("the OBJ parser failed on malformed input".into()))?
            .map_err(|e| err(e.to_string()))?;
    let obj_materials = match materials {
        Ok(m) => m,
        Err(e) => {
            // tobj reports a missing `mtllib` as an error too; only a referenced material makes it fatal.
            if models.iter().any(|m| m.mesh.material_id.is_some()) {
                return Err(err(format!("material library: {e}")));
            }
            Vec::new()
        }
    };
    let (materials, textures) = materials_of(path, &obj_materials)?;
    let mut mesh = Mesh {
        materials,
        textures,
        ..Mesh::default()
    };
    merge_objects(path, &models, obj_materials.len(), &mut mesh)?;
    if mesh.triangles.is_empty() {
        return Err(err("the file has no faces".into()));
    }
    Ok(mesh)
}

/// The MTL materials as the mesh's, each diffuse texture loaded once however many materials
/// name it.
fn materials_of(
    path: &Path,
    obj_materials: &[tobj::Material],
) -> Result<(Vec<Material>, Vec<Texture>), Error> {
    let mut materials = Vec::with_capacity(obj_materials.len());
    let (mut textures, mut texture_index) =
        (Vec::<Texture>::new(), HashMap::<PathBuf, usize>::new());
    for m in obj_materials {
        let texture = match &m.diffuse_texture {
            Some(name) if !name.trim().is_empty() => {
                let file = resolve_relative(path, name);
                Some(match texture_index.get(&file) {
                    Some(&i) => i,
                    None => {
                        textures.push(load_texture(path, &file)?);
                        texture_index.insert(file, textures.len() - 1);
                        textures.len() - 1
                    }
                })
            }
            _ => None,
        };
        let kd = m.diffuse.unwrap_or([1.0; 3]);
        materials.push(Material {
            name: m.name.clone(),
            base_color: [kd[0], kd[1], kd[2], m.dissolve.unwrap_or(1.0)],
            texture,
        });
    }
    Ok((materials, textures))
}

/// Every object's vertices and triangles appended to `mesh` (which holds the MTL's
/// `obj_materials` materials): normals, UVs (v flipped) and colours kept only where every
/// object has them, triangles given their material (a plain white one for faces with none
/// when the file has materials), and a triangle naming a vertex its object lacks refused.
fn merge_objects(
    path: &Path,
    models: &[tobj::Model],
    obj_materials: usize,
    mesh: &mut Mesh,
) -> Result<(), Error> {
    let all = |f: fn(&tobj::Mesh) -> bool| models.iter().all(|m| f(&m.mesh));
    let has_normals = all(|m| !m.normals.is_empty());
    let has_uvs = all(|m| !m.texcoords.is_empty());
    let has_colors = all(|m| !m.vertex_color.is_empty());
    let mut default_material = None;
    let (mut normals, mut uvs, mut colors) = (Vec::new(), Vec::new(), Vec::new());
    for (object, model) in models.iter().enumerate() {
        let m = &model.mesh;
        let base = mesh.positions.len();
        let count = m.positions.len() / 3;
        mesh.positions.extend(
            m.positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], p[1], p[2])),
        );
        if has_normals {
            normals.extend(
                m.normals
                    .chunks_exact(3)
                    .map(|n| Vec3::new(n[0], n[1], n[2])),
            );
        }
        if has_uvs {
            // OBJ's v grows upwards; the Mesh convention has (0, 0) at the top-left of the image.
            uvs.extend(
                m.texcoords
                    .chunks_exact(2)
                    .map(|t| Vec2::new(t[0], 1.0 - t[1])),
            );
        }
        if has_colors {
            colors.extend(m.vertex_color.chunks_exact(3).map(|c| [c[0], c[1], c[2]]));
        }
        for (t, tri) in m.indices.chunks_exact(3).enumerate() {
            if let Some(&bad) = tri.iter().find(|&&v| v as usize >= count) {
                return Err(Error::IndexOutOfRange {
                    path: path.to_path_buf(),
                    what: format!("OBJ object {object} ('{}') triangle", model.name),
                    index: t as u64,
                    vertex: i64::from(bad),
                    count: count as u64,
                });
            }
            mesh.triangles
                .push([0, 1, 2].map(|c| (base + tri[c] as usize) as u32));
        }
        if !mesh.materials.is_empty() {
            let id = match m.material_id.filter(|&id| id < obj_materials) {
                Some(id) => id,
                None => *default_material.get_or_insert_with(|| {
                    mesh.materials.push(Material {
                        name: String::new(),
                        base_color: [1.0; 4],
                        texture: None,
                    });
                    mesh.materials.len() - 1
                }),
            };
            mesh.triangle_materials
                .extend(std::iter::repeat_n(id as u32, m.indices.len() / 3));
        }
    }
    mesh.normals = has_normals.then_some(normals);
    mesh.uvs = has_uvs.then_some(uvs);
    mesh.colors = has_colors.then_some(colors);
    Ok(())
}

/// Refuses the first `v`, `vn` or `vt` line holding a NaN or an infinity (or a number beyond the
/// f32 range), naming the line, the 0-based index among lines of its kind and the component.
/// tobj parses `nan` and `inf` as numbers, and its re-indexed vertices could not say which line
/// they came from, so the text is scanned before tobj sees it.
fn check_finite_lines(path: &Path, text: &str) -> Result<(), Error> {
    const V: [&str; 6] = ["x", "y", "z", "red", "green", "blue"];
    const VN: [&str; 3] = ["x", "y", "z"];
    const VT: [&str; 3] = ["u", "v", "w"];
    let mut counts = [0u64; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let (key, kind, names): (&str, usize, &[&str]) = match words.next() {
            Some("v") => ("v", 0, &V),
            Some("vn") => ("vn", 1, &VN),
            Some("vt") => ("vt", 2, &VT),
            _ => continue,
        };
        for (c, word) in words.enumerate() {
            if let Ok(x) = word.parse::<f32>()
                && !x.is_finite()
            {
                return Err(Error::NonFinite {
                    path: path.to_path_buf(),
                    what: format!("line {}: {key}", n + 1),
                    index: counts[kind],
                    property: names
                        .get(c)
                        .map_or_else(|| format!("value {}", c + 1), |s| (*s).to_string()),
                    value: if word.parse::<f64>().is_ok_and(f64::is_finite) {
                        format!("{word} (beyond the 32-bit float range)")
                    } else {
                        x.to_string()
                    },
                });
            }
        }
        counts[kind] += 1;
    }
    Ok(())
}
