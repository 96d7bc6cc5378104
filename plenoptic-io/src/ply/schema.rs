//! Which vertex property plays which role (position, normal, colours, UV, extra).

use std::path::Path;

use crate::Error;
use ply_core::{Element, PropertyKind, ScalarType};

/// The role of one vertex property, as decided from its name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Role {
    /// x, y, z (channel 0..3).
    Position(usize),
    /// nx, ny, nz.
    Normal(usize),
    /// red, green, blue or diffuse_*.
    Main(usize),
    /// red{k}, green{k}, blue{k}.
    Camera(usize, usize),
    /// Texture coordinate u (0) or v (1): s/t, u/v, texture_u/texture_v, texture_s/texture_t.
    Uv(usize),
    /// A scalar with no role, kept as the given extra column.
    Extra(usize),
}

/// The role of a property name; `with_uv` makes s/t/u/v texture coordinates (meshes).
pub(crate) fn role_of_name(name: &str, with_uv: bool) -> Option<Role> {
    let channel = |c: &str| match c {
        "red" => Some(0),
        "green" => Some(1),
        "blue" => Some(2),
        _ => None,
    };
    Some(match name {
        "x" => Role::Position(0),
        "y" => Role::Position(1),
        "z" => Role::Position(2),
        "nx" => Role::Normal(0),
        "ny" => Role::Normal(1),
        "nz" => Role::Normal(2),
        "red" | "diffuse_red" => Role::Main(0),
        "green" | "diffuse_green" => Role::Main(1),
        "blue" | "diffuse_blue" => Role::Main(2),
        "s" | "u" | "texture_u" | "texture_s" if with_uv => Role::Uv(0),
        "t" | "v" | "texture_v" | "texture_t" if with_uv => Role::Uv(1),
        _ => {
            let split = name.find(|ch: char| ch.is_ascii_digit())?;
            let (colour, digits) = name.split_at(split);
            let c = channel(colour)?;
            // "red01" is not camera 1: only canonical decimal indices, as the renderer writes them.
            if digits.len() > 1 && digits.starts_with('0') {
                return None;
            }
            Role::Camera(digits.parse().ok()?, c)
        }
    })
}

/// How to turn the vertex properties into points: property index per role, and types.
#[derive(Debug, Clone)]
pub(crate) struct VertexPlan {
    /// Scalar type of every property (the item type for lists).
    pub types: Vec<ScalarType>,
    /// Property indices of x, y, z.
    pub position: [usize; 3],
    /// Property indices of nx, ny, nz.
    pub normal: Option<[usize; 3]>,
    /// Property indices of the main red, green, blue.
    pub main: Option<[usize; 3]>,
    /// Property indices of red{k}, green{k}, blue{k} for k = 0..N.
    pub cameras: Vec<[usize; 3]>,
    /// Property indices of u, v.
    pub uv: Option<[usize; 2]>,
    /// (name, property index) of each extra column.
    pub extras: Vec<(String, usize)>,
}

/// The largest camera index accepted in a property name; avoids allocating for `red99999999`.
const MAX_CAMERA_INDEX: usize = 4096;

impl VertexPlan {
    /// Builds the plan for a vertex element, checking that every role is complete.
    pub(crate) fn new(path: &Path, element: &Element, with_uv: bool) -> Result<Self, Error> {
        let err = |message: String| Error::Content {
            path: path.to_path_buf(),
            message,
        };
        let n = element.properties.len();
        let mut types = Vec::with_capacity(n);
        let mut position = [None; 3];
        let mut normal = [None; 3];
        let mut main = [None; 3];
        let mut uv = [None; 2];
        let mut cameras: Vec<[Option<usize>; 3]> = Vec::new();
        let mut extras = Vec::new();
        for (i, p) in element.properties.iter().enumerate() {
            let ty = match p.kind {
                PropertyKind::Scalar(t) => t,
                PropertyKind::List { item, .. } => {
                    types.push(item);
                    continue;
                }
            };
            let mut role = role_of_name(&p.name, with_uv).unwrap_or(Role::Extra(0));
            let slot = match role {
                Role::Position(c) => Some(&mut position[c]),
                Role::Normal(c) => Some(&mut normal[c]),
                Role::Main(c) => Some(&mut main[c]),
                Role::Uv(c) => Some(&mut uv[c]),
                Role::Camera(k, c) => {
                    if k >= MAX_CAMERA_INDEX {
                        return Err(err(format!(
                            "property '{}': camera index {k} exceeds the limit {MAX_CAMERA_INDEX}",
                            p.name
                        )));
                    }
                    if cameras.len() <= k {
                        cameras.resize(k + 1, [None; 3]);
                    }
                    Some(&mut cameras[k][c])
                }
                Role::Extra(_) => None,
            };
            match slot {
                // A second spelling of a role already taken (e.g. both red and diffuse_red) is kept as extra.
                Some(s) if s.is_none() => *s = Some(i),
                _ => role = Role::Extra(0),
            }
            if matches!(role, Role::Main(_) | Role::Camera(..)) && !is_color_type(ty) {
                return Err(err(format!(
                    "colour property '{}' has type {}; supported colour types are uchar, ushort, float and double",
                    p.name,
                    ty.name()
                )));
            }
            if let Role::Extra(_) = role {
                role = Role::Extra(extras.len());
                extras.push((p.name.clone(), i));
            }
            types.push(ty);
        }
        let complete = |what: &str,
                        names: &[&str],
                        slots: &[Option<usize>]|
         -> Result<Option<Vec<usize>>, Error> {
            if slots.iter().all(Option::is_none) {
                return Ok(None);
            }
            if let Some(missing) = slots.iter().position(Option::is_none) {
                return Err(err(format!(
                    "the vertex element has part of the {what} but no '{}' property",
                    names[missing]
                )));
            }
            Ok(Some(slots.iter().flatten().copied().collect()))
        };
        let position = complete("position", &["x", "y", "z"], &position)?
            .ok_or_else(|| err("the vertex element has no x, y, z properties".into()))?;
        let normal = complete("normal", &["nx", "ny", "nz"], &normal)?;
        let main = complete("main colour", &["red", "green", "blue"], &main)?;
        let uv = complete("texture coordinates", &["u", "v"], &uv)?;
        let mut camera_indices = Vec::with_capacity(cameras.len());
        for (k, c) in cameras.iter().enumerate() {
            let names = [format!("red{k}"), format!("green{k}"), format!("blue{k}")];
            let names: Vec<&str> = names.iter().map(String::as_str).collect();
            let found = complete(&format!("colour of camera {k}"), &names, c)?.ok_or_else(|| {
                err(format!(
                    "per-camera colours go up to camera {} but camera {k} has no red{k}/green{k}/blue{k}",
                    cameras.len() - 1
                ))
            })?;
            camera_indices.push([found[0], found[1], found[2]]);
        }
        let arr3 = |v: Vec<usize>| [v[0], v[1], v[2]];
        Ok(VertexPlan {
            types,
            position: arr3(position),
            normal: normal.map(arr3),
            main: main.map(arr3),
            cameras: camera_indices,
            uv: uv.map(|v| [v[0], v[1]]),
            extras,
        })
    }
}

/// Colour types we normalise to [0, 1]: integers by their maximum, floats as they are.
pub(crate) fn is_color_type(ty: ScalarType) -> bool {
    matches!(
        ty,
        ScalarType::U8 | ScalarType::U16 | ScalarType::F32 | ScalarType::F64
    )
}

/// A stored colour value as a [0, 1] float: uchar / 255, ushort / 65535, floats unchanged.
#[inline]
pub(crate) fn color_from_stored(value: f64, ty: ScalarType) -> f32 {
    match ty {
        ScalarType::U8 => value as f32 / 255.0,
        ScalarType::U16 => value as f32 / 65535.0,
        _ => value as f32,
    }
}

/// The inverse of [`color_from_stored`]: rounds to the nearest integer level for integer types.
#[inline]
pub(crate) fn color_to_stored(color: f32, ty: ScalarType) -> f64 {
    match ty {
        ScalarType::U8 => f64::from((color * 255.0).round().clamp(0.0, 255.0)),
        ScalarType::U16 => f64::from((color * 65535.0).round().clamp(0.0, 65535.0)),
        _ => f64::from(color),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_map_to_roles() {
        assert_eq!(role_of_name("red12", false), Some(Role::Camera(12, 0)));
        assert_eq!(role_of_name("blue0", false), Some(Role::Camera(0, 2)));
        assert_eq!(role_of_name("red01", false), None);
        assert_eq!(role_of_name("diffuse_green", false), Some(Role::Main(1)));
        assert_eq!(role_of_name("s", false), None);
        assert_eq!(role_of_name("s", true), Some(Role::Uv(0)));
        assert_eq!(role_of_name("alpha", true), None);
    }

    #[test]
    fn every_integer_colour_level_round_trips() {
        for v in 0..=255u32 {
            let c = color_from_stored(f64::from(v), ScalarType::U8);
            assert_eq!(color_to_stored(c, ScalarType::U8), f64::from(v));
        }
        for v in 0..=65535u32 {
            let c = color_from_stored(f64::from(v), ScalarType::U16);
            assert_eq!(color_to_stored(c, ScalarType::U16), f64::from(v));
        }
    }
}
