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
    let text = String::from_utf8_lossy(&bytes);
    let scan = scan_lines(path, &text)?;
    check_faces(path, &text, &scan)?;
    // tobj's index arithmetic overflows on some malformed faces (`f 1//2 7//2 5/-2` multiplies
    // a wrapped relative index), a panic where overflow checks are on; turn any into an error.
    let (models, materials) =
        std::panic::catch_unwind(|| tobj::load_obj(path, &tobj::GPU_LOAD_OPTIONS))
            .map_err(|_| err("the OBJ parser failed on malformed input".into()))?
            .map_err(|e| err(e.to_string()))?;
    let obj_materials = match materials {
        Ok(m) => m,
        // tobj reports a missing `mtllib` as an error too; only a face that names a material
        // makes it fatal (tobj then leaves the faces without one, and they would be drawn white).
        Err(e) => match &scan.first_usemtl {
            Some((line, name)) => {
                return Err(err(format!(
                    "line {line}: usemtl '{name}', but the material library cannot be read: {e}"
                )));
            }
            None => Vec::new(),
        },
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
    // An attribute is kept only where every vertex has it: tobj leaves out the UV (normal) of
    // a face vertex written without one, so a file that mixes `v/vt` and `v` faces has fewer
    // UVs than vertices, and they would pair with the wrong vertices.
    let all = |f: fn(&tobj::Mesh) -> usize| {
        models
            .iter()
            .all(|m| m.mesh.positions.len() / 3 == f(&m.mesh))
    };
    let has_normals = all(|m| m.normals.len() / 3);
    let has_uvs = all(|m| m.texcoords.len() / 2);
    let has_colors = all(|m| m.vertex_color.len() / 3);
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

/// What the scan of an OBJ's lines learns that tobj's result cannot say.
struct LineScan {
    /// Lines of each kind: `v`, `vn`, `vt`.
    counts: [u64; 3],
    /// The first `usemtl` line (1-based) and the material it names.
    first_usemtl: Option<(usize, String)>,
}

/// The kinds of line a face refers to, in the order of a face vertex's `v/vt/vn` and with the
/// index of each in [`LineScan::counts`].
const FACE_KINDS: [(&str, usize); 3] = [("v", 0), ("vt", 2), ("vn", 1)];

/// Counts the `v`, `vn` and `vt` lines and refuses the first holding a NaN or an infinity (or
/// a number beyond the f32 range), naming the line, the 0-based index among lines of its kind
/// and the component. tobj parses `nan` and `inf` as numbers, and its re-indexed vertices could
/// not say which line they came from, so the text is scanned before tobj sees it.
fn scan_lines(path: &Path, text: &str) -> Result<LineScan, Error> {
    const V: [&str; 6] = ["x", "y", "z", "red", "green", "blue"];
    const VN: [&str; 3] = ["x", "y", "z"];
    const VT: [&str; 3] = ["u", "v", "w"];
    let mut scan = LineScan {
        counts: [0; 3],
        first_usemtl: None,
    };
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let (key, kind, names): (&str, usize, &[&str]) = match words.next() {
            Some("v") => ("v", 0, &V),
            Some("vn") => ("vn", 1, &VN),
            Some("vt") => ("vt", 2, &VT),
            Some("usemtl") => {
                if scan.first_usemtl.is_none() {
                    scan.first_usemtl = Some((n + 1, words.collect::<Vec<_>>().join(" ")));
                }
                continue;
            }
            _ => continue,
        };
        // (Up to a trailing comment.)
        let words: Vec<&str> = words.take_while(|w| !w.starts_with('#')).collect();
        // tobj refuses these as "position parse error" (or normal, texture) without a line.
        let needed = [3, 3, 1][kind];
        let malformed = |problem: String| Error::Obj {
            path: path.to_path_buf(),
            message: format!("line {}: {key}: {problem}", n + 1),
        };
        if let Some(word) = words.iter().find(|w| w.parse::<f32>().is_err()) {
            return Err(malformed(format!("'{word}' is not a number")));
        }
        if words.len() < needed {
            return Err(malformed(format!(
                "{} number(s); it needs at least {needed} ({})",
                words.len(),
                names[..needed].join(", ")
            )));
        }
        for (c, word) in words.iter().enumerate() {
            if let Ok(x) = word.parse::<f32>()
                && !x.is_finite()
            {
                return Err(Error::NonFinite {
                    path: path.to_path_buf(),
                    what: format!("line {}: {key}", n + 1),
                    index: scan.counts[kind],
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
        scan.counts[kind] += 1;
    }
    Ok(scan)
}

/// Refuses the first `f` line that tobj would refuse without saying where, or read wrongly:
/// fewer than three vertices, a vertex with more than `v/vt/vn`, a word that is not an index,
/// index 0 (tobj took it for "absent"), a relative index before the first line of its kind, or
/// an index past the file's lines of its kind (tobj ignored `vt` and `vn` references when the
/// file had none). Positive indices may refer forward (tobj resolves them after reading), so
/// they are checked against the whole file's counts and negative ones against the lines so far.
fn check_faces(path: &Path, text: &str, scan: &LineScan) -> Result<(), Error> {
    let mut so_far = [0u64; 3];
    for (n, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => so_far[0] += 1,
            Some("vn") => so_far[1] += 1,
            Some("vt") => so_far[2] += 1,
            Some("f") => {
                let bad = |problem: String| Error::Obj {
                    path: path.to_path_buf(),
                    message: format!("line {}: f: {problem}", n + 1),
                };
                let vertices: Vec<&str> = words.collect();
                if vertices.len() < 3 {
                    return Err(bad(format!(
                        "{} vertices; a face needs at least 3",
                        vertices.len()
                    )));
                }
                for vertex in vertices {
                    let parts: Vec<&str> = vertex.split('/').collect();
                    if parts.len() > 3 || parts[0].is_empty() {
                        return Err(bad(format!(
                            "'{vertex}' is not a vertex (v, v/vt, v//vn or v/vt/vn)"
                        )));
                    }
                    for (part, &(kind, k)) in parts.iter().zip(&FACE_KINDS) {
                        if part.is_empty() {
                            continue;
                        }
                        let index: i64 = part.parse().map_err(|_| {
                            bad(format!("'{part}' in '{vertex}' is not a {kind} index"))
                        })?;
                        let problem = if index == 0 {
                            Some("0 (OBJ indices count from 1)".to_string())
                        } else if index < 0 && index.unsigned_abs() > so_far[k] {
                            Some(format!(
                                "{index}, before the first (only {} {kind} lines precede it)",
                                so_far[k]
                            ))
                        } else if index > 0 && index.unsigned_abs() > scan.counts[k] {
                            Some(format!(
                                "{index}, but the file has {} {kind} lines",
                                scan.counts[k]
                            ))
                        } else {
                            None
                        };
                        if let Some(problem) = problem {
                            return Err(bad(format!("'{vertex}': {kind} index {problem}")));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}
