//! The PLY cloud writer: the cloud's own layout (bit-exact round trip) or the default layout.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use rayon::prelude::*;

use super::schema::{Role, color_to_stored, role_of_name};
use crate::{Error, PlenopticCloud, PlyLayout};
use ply_core::{PlyFormat, ScalarType, write_ascii, write_binary};

/// Points encoded per parallel task.
const CHUNK_POINTS: usize = 16 * 1024;

/// The layout used when a cloud has none: binary little endian, float positions and normals,
/// uchar colours (the 8iVSLF layout), extra columns as double.
#[must_use]
pub fn default_layout(cloud: &PlenopticCloud) -> PlyLayout {
    let mut properties: Vec<(String, ScalarType)> = ["x", "y", "z"]
        .iter()
        .map(|n| (n.to_string(), ScalarType::F32))
        .collect();
    if cloud.normals.is_some() {
        properties.extend(
            ["nx", "ny", "nz"]
                .iter()
                .map(|n| (n.to_string(), ScalarType::F32)),
        );
    }
    properties.extend(
        ["red", "green", "blue"]
            .iter()
            .map(|n| (n.to_string(), ScalarType::U8)),
    );
    for k in 0..cloud.num_cameras {
        properties.extend(
            ["red", "green", "blue"]
                .iter()
                .map(|n| (format!("{n}{k}"), ScalarType::U8)),
        );
    }
    properties.extend(
        cloud
            .extra
            .iter()
            .map(|e| (e.name.clone(), ScalarType::F64)),
    );
    PlyLayout {
        format: PlyFormat::BinaryLittleEndian,
        properties,
        comments: Vec::new(),
    }
}

/// Where each written property takes its value from.
#[derive(Clone, Copy)]
enum Source {
    Position(usize),
    Normal(usize),
    Main(usize),
    Camera(usize, usize),
    Extra(usize),
}

/// Writes `cloud` to `path` atomically in its layout (or [`default_layout`]).
pub(crate) fn write_cloud(path: &Path, cloud: &PlenopticCloud) -> Result<(), Error> {
    let err = |message: String| Error::Write {
        path: path.to_path_buf(),
        message,
    };
    check_columns(cloud).map_err(err)?;
    let layout = cloud
        .layout
        .clone()
        .unwrap_or_else(|| default_layout(cloud));
    let sources = plan_sources(cloud, &layout).map_err(err)?;
    let header = header_text(cloud, &layout, cloud.len());
    let body = match layout.format {
        PlyFormat::Ascii => ascii_body(cloud, &sources),
        format => binary_body(cloud, &sources, format == PlyFormat::BinaryBigEndian),
    };
    atomic_output::write_atomic_with(path, |w| {
        w.write_all(header.as_bytes())?;
        w.write_all(&body)
    })
    .map_err(|e| Error::io(path, e))
}

/// The cloud's columns agree with its point and camera counts.
fn check_columns(cloud: &PlenopticCloud) -> Result<(), String> {
    let n = cloud.len();
    let k = cloud.num_cameras;
    if cloud.colors.len() != n
        || cloud.camera_colors.len() != n * k
        || cloud.normals.as_ref().is_some_and(|v| v.len() != n)
        || cloud.extra.iter().any(|e| e.values.len() != n)
    {
        return Err(format!(
            "column lengths disagree with {n} points and {k} cameras (colours {}, camera colours {}, normals {:?})",
            cloud.colors.len(),
            cloud.camera_colors.len(),
            cloud.normals.as_ref().map(Vec::len)
        ));
    }
    if !cloud.cameras.is_empty() && cloud.cameras.len() != k {
        return Err(format!(
            "the rig has {} cameras but the points have colours for {k}",
            cloud.cameras.len()
        ));
    }
    Ok(())
}

/// Where each of the layout's properties takes its value from, refusing a property the cloud
/// has no data for, a colour in a type colours cannot take, and a layout that leaves out a
/// coordinate or a camera's colour channel.
fn plan_sources(
    cloud: &PlenopticCloud,
    layout: &PlyLayout,
) -> Result<Vec<(Source, ScalarType)>, String> {
    let k = cloud.num_cameras;
    let mut sources = Vec::with_capacity(layout.properties.len());
    let mut seen_position = [false; 3];
    let mut seen_cameras = vec![[false; 3]; k];
    for (name, ty) in &layout.properties {
        let source = match role_of_name(name, false) {
            Some(Role::Position(c)) => {
                seen_position[c] = true;
                Source::Position(c)
            }
            Some(Role::Normal(c)) if cloud.normals.is_some() => Source::Normal(c),
            Some(Role::Main(c)) => Source::Main(c),
            Some(Role::Camera(cam, c)) if cam < k => {
                seen_cameras[cam][c] = true;
                Source::Camera(cam, c)
            }
            _ => match cloud.extra.iter().position(|e| &e.name == name) {
                Some(e) => Source::Extra(e),
                None => {
                    return Err(format!(
                        "the layout has property '{name}' but the cloud has no data for it"
                    ));
                }
            },
        };
        if matches!(source, Source::Main(_) | Source::Camera(..))
            && !super::schema::is_color_type(*ty)
        {
            return Err(format!(
                "colour property '{name}' cannot be written as {}",
                ty.name()
            ));
        }
        sources.push((source, *ty));
    }
    if seen_position.contains(&false) {
        return Err("the layout lacks x, y or z".into());
    }
    if let Some(cam) = seen_cameras.iter().position(|s| s.contains(&false)) {
        return Err(format!(
            "the layout lacks a colour property of camera {cam}"
        ));
    }
    Ok(sources)
}

/// The value point `i` stores for `source`, as a property of type `ty` holds it.
fn value(cloud: &PlenopticCloud, i: usize, source: Source, ty: ScalarType) -> f64 {
    match source {
        Source::Position(c) => f64::from(cloud.positions[i][c]),
        Source::Normal(c) => cloud.normals.as_ref().map_or(0.0, |v| f64::from(v[i][c])),
        Source::Main(c) => color_to_stored(cloud.colors[i][c], ty),
        Source::Camera(cam, c) => {
            color_to_stored(cloud.camera_colors[i * cloud.num_cameras + cam][c], ty)
        }
        Source::Extra(e) => cloud.extra[e].values[i],
    }
}

/// An ASCII body: one line a point, chunks of points in parallel.
fn ascii_body(cloud: &PlenopticCloud, sources: &[(Source, ScalarType)]) -> Vec<u8> {
    (0..cloud.len())
        .into_par_iter()
        .chunks(CHUNK_POINTS)
        .map(|rows| {
            let mut text = String::new();
            for i in rows {
                for (p, &(source, ty)) in sources.iter().enumerate() {
                    if p > 0 {
                        text.push(' ');
                    }
                    write_ascii(&mut text, value(cloud, i, source, ty), ty);
                }
                text.push('\n');
            }
            text.into_bytes()
        })
        .collect::<Vec<_>>()
        .concat()
}

/// A binary body: fixed-size records, chunks of points in parallel.
fn binary_body(cloud: &PlenopticCloud, sources: &[(Source, ScalarType)], big: bool) -> Vec<u8> {
    let (n, k) = (cloud.len(), cloud.num_cameras);
    let stride: usize = sources.iter().map(|(_, t)| t.size()).sum();
    let mut fields = Vec::with_capacity(sources.len());
    let mut at = 0;
    for &(source, ty) in sources {
        fields.push((source, ty, at));
        at += ty.size();
    }
    // uchar camera colours packed as r0 g0 b0 r1 … (the 8iVSLF layout) are written as one run.
    let camera_block = fields
        .iter()
        .find(|(s, _, _)| matches!(s, Source::Camera(0, 0)))
        .map(|&(_, _, base)| base)
        .filter(|&base| {
            fields.iter().all(|&(s, ty, off)| match s {
                Source::Camera(cam, c) => ty == ScalarType::U8 && off == base + 3 * cam + c,
                _ => true,
            })
        });
    if camera_block.is_some() {
        fields.retain(|(s, _, _)| !matches!(s, Source::Camera(..)));
    }
    let mut body = vec![0u8; n * stride];
    body.par_chunks_mut((CHUNK_POINTS * stride).max(1))
        .enumerate()
        .for_each(|(c, chunk)| {
            for (j, rec) in chunk.chunks_exact_mut(stride).enumerate() {
                let i = c * CHUNK_POINTS + j;
                for &(source, ty, off) in &fields {
                    write_binary(
                        &mut rec[off..off + ty.size()],
                        value(cloud, i, source, ty),
                        ty,
                        big,
                    );
                }
                if let Some(base) = camera_block {
                    let colors = &cloud.camera_colors[i * k..(i + 1) * k];
                    for (dst, color) in rec[base..base + 3 * k].chunks_exact_mut(3).zip(colors) {
                        for (d, &v) in dst.iter_mut().zip(color) {
                            *d = color_to_stored(v, ScalarType::U8) as u8;
                        }
                    }
                }
            }
        });
    body
}

/// The header: format, comments, rig comments, the vertex element.
fn header_text(cloud: &PlenopticCloud, layout: &PlyLayout, n: usize) -> String {
    let mut h = format!("ply\nformat {} 1.0\n", layout.format.keyword());
    for c in &layout.comments {
        let _ = writeln!(h, "comment {c}");
    }
    if let Some(s) = cloud.frame_to_world_scale {
        let _ = writeln!(h, "comment frame_to_world_scale {s}");
    }
    if let Some(t) = cloud.frame_to_world_translation {
        let _ = writeln!(
            h,
            "comment frame_to_world_translation {} {} {}",
            t.x, t.y, t.z
        );
    }
    if let Some(w) = cloud.width {
        let _ = writeln!(h, "comment width {w}");
    }
    if !cloud.cameras.is_empty() {
        let _ = writeln!(h, "comment rig_count {}", cloud.cameras.len());
        for (k, cam) in cloud.cameras.iter().enumerate() {
            // Without a matrix: identity rotation, centre (in world units) at values 12..14 (formats.md §2.2).
            let m = cam.matrix.unwrap_or_else(|| {
                let w = cloud.voxel_to_world(cam.position);
                [
                    1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, w.x, w.y, w.z, 1.0,
                ]
            });
            let numbers: Vec<String> = m.iter().map(f64::to_string).collect();
            let _ = writeln!(h, "comment rig_matrix_{k} {}", numbers.join(" "));
        }
    }
    let _ = writeln!(h, "element vertex {n}");
    for (name, ty) in &layout.properties {
        let _ = writeln!(h, "property {} {name}", ty.name());
    }
    h.push_str("end_header\n");
    h
}
