//! Meshes rasterised with perspective-correct attributes: bilinear textures, vertex colours,
//! material base colours, and per-vertex plenoptic colours.

use camera_model::Camera;
use glam::{Vec2, Vec3};
use plenoptic_io::view_color::interpolate;
use plenoptic_io::{Mesh, barycentric_mix};
use rayon::prelude::*;

use crate::camera::ViewCamera;
use crate::pixels::{render_supersampled, resolve};
use crate::zbuffer::ZBuffer;
use crate::{Error, ViewImage, ViewOptions};

/// Triangles per parallel work item of the visibility pass.
const CHUNK: usize = 4_096;

/// Barycentric slack: pixel centres exactly on a shared edge are claimed by both triangles
/// (the z-buffer keeps one) instead of by neither through rounding.
const EDGE_EPS: f32 = 1e-5;

/// Nearest depth (camera z) a surface may have, in units of the camera's [`SceneScale`];
/// geometry at or behind the camera is clipped.
const NEAR: f32 = 1e-4;

/// A power of two near the distance from the camera to the farthest vertex: the triangle
/// tests run on camera-space positions divided by it, so that their products neither overflow
/// nor underflow f32 at any scale the degeneracy checks accept (a tetrahedron of side 3e-5
/// drew 6 pixels under an absolute near plane, one of side 1e19 overflowed the determinant),
/// and the near plane is a fixed share of the scene's depth. Dividing by a power of two is
/// exact, so a scene of unit size renders the same bits as it did unscaled.
#[derive(Debug, Clone, Copy)]
struct SceneScale {
    /// The power of two.
    factor: f32,
}

impl SceneScale {
    /// The scale of camera-space positions `cam_space` (1 when there are none to measure).
    fn of(cam_space: &[Vec3]) -> Self {
        let farthest = cam_space
            .iter()
            .map(|p| p.abs().max_element())
            .fold(0.0_f32, f32::max);
        let factor = if farthest.is_finite() && farthest > 0.0 {
            2.0_f32.powi(farthest.log2().ceil() as i32)
        } else {
            1.0
        };
        Self {
            factor: if factor.is_finite() && factor > 0.0 {
                factor
            } else {
                1.0
            },
        }
    }
}

/// Renders a triangle mesh from `camera`.
///
/// Depth and barycentric coordinates come from intersecting each pixel-centre ray with the
/// triangle, which is exactly perspective-correct. Colour: for a mesh with per-vertex plenoptic
/// colours, each vertex's colour is [`interpolate`]d towards the viewer and the result is
/// interpolated across the triangle (the PccAppRenderer's surface shader); otherwise
/// [`Mesh::albedo_at`]: material base colour × bilinear texture × vertex colour.
pub fn render_mesh(mesh: &Mesh, camera: &Camera, opts: &ViewOptions) -> Result<ViewImage, Error> {
    check_mesh(mesh)?;
    render_checked_mesh(mesh, camera, opts)
}

/// [`render_mesh`] of a mesh [`check_mesh`] has accepted.
pub(crate) fn render_checked_mesh(
    mesh: &Mesh,
    camera: &Camera,
    opts: &ViewOptions,
) -> Result<ViewImage, Error> {
    render_supersampled(camera, opts, |cam| render_once(mesh, cam, opts))
}

/// Checks every index and array length the renderer relies on.
pub fn check_mesh(mesh: &Mesh) -> Result<(), Error> {
    let nv = mesh.positions.len();
    let nt = mesh.triangles.len();
    if nt >= u32::MAX as usize {
        return Err(Error::InvalidModel(format!(
            "{nt} triangles exceed the renderer's limit of {}",
            u32::MAX - 1
        )));
    }
    if let Some((t, tri)) = mesh
        .triangles
        .iter()
        .enumerate()
        .find(|(_, tri)| tri.iter().any(|&v| v as usize >= nv))
    {
        return Err(Error::InvalidModel(format!(
            "triangle {t} {tri:?} refers to a vertex beyond the {nv} vertices"
        )));
    }
    let per_vertex = [
        ("normals", mesh.normals.as_ref().map(Vec::len)),
        ("texture coordinates", mesh.uvs.as_ref().map(Vec::len)),
        ("vertex colours", mesh.colors.as_ref().map(Vec::len)),
    ];
    for (what, len) in per_vertex {
        if let Some(len) = len.filter(|&l| l != nv) {
            return Err(Error::InvalidModel(format!(
                "{nv} vertices but {len} {what}"
            )));
        }
    }
    if mesh.camera_colors.len() != nv * mesh.num_cameras {
        return Err(Error::InvalidModel(format!(
            "{nv} vertices × {} cameras but {} per-camera colours",
            mesh.num_cameras,
            mesh.camera_colors.len()
        )));
    }
    if !mesh.triangle_materials.is_empty() && mesh.triangle_materials.len() != nt {
        return Err(Error::InvalidModel(format!(
            "{nt} triangles but {} triangle materials",
            mesh.triangle_materials.len()
        )));
    }
    if let Some((t, m)) = mesh
        .triangle_materials
        .iter()
        .enumerate()
        .find(|(_, m)| **m as usize >= mesh.materials.len())
    {
        return Err(Error::InvalidModel(format!(
            "triangle {t} uses material {m} of {}",
            mesh.materials.len()
        )));
    }
    for (i, m) in mesh.materials.iter().enumerate() {
        if let Some(t) = m.texture.filter(|&t| t >= mesh.textures.len()) {
            return Err(Error::InvalidModel(format!(
                "material {i} ({}) uses texture {t} of {}",
                m.name,
                mesh.textures.len()
            )));
        }
    }
    for (i, t) in mesh.textures.iter().enumerate() {
        if t.width == 0 || t.height == 0 || t.pixels.len() != t.width as usize * t.height as usize {
            return Err(Error::InvalidModel(format!(
                "texture {i} is {}×{} with {} pixels",
                t.width,
                t.height,
                t.pixels.len()
            )));
        }
    }
    Ok(())
}

/// One render at the camera's own resolution, filtered down to the output's.
fn render_once(mesh: &Mesh, camera: &Camera, opts: &ViewOptions) -> Result<ViewImage, Error> {
    let view = ViewCamera::new(camera)?;
    let mut cam_space: Vec<Vec3> = mesh
        .positions
        .par_iter()
        .map(|&p| view.rotation * p + view.translation)
        .collect();
    let scale = SceneScale::of(&cam_space);
    cam_space.par_iter_mut().for_each(|p| *p /= scale.factor);
    let zbuf = ZBuffer::new(view.width as usize, view.height as usize);
    draw_triangles(&mesh.triangles, &cam_space, scale, &view, &zbuf);
    let plenoptic = vertex_view_colors(mesh, view.center, opts.exponent);
    Ok(resolve(&view, &zbuf, opts, |id, x, y| {
        let t = id as usize;
        let tri = mesh.triangles[t];
        let [a, b, c] = tri.map(|v| cam_space[v as usize]);
        // The winning ray hit this triangle in the visibility pass; recompute its barycentrics.
        let bary =
            intersect(view.camera_ray(x, y), a, b, c).map_or([1.0 / 3.0; 3], |(_, bary)| bary);
        match &plenoptic {
            Some(colors) => barycentric_mix(tri.map(|v| colors[v as usize]), bary),
            None => mesh.albedo_at(t, bary),
        }
    }))
}

/// The view colour of every vertex of a mesh with per-vertex plenoptic colours, or `None`.
fn vertex_view_colors(mesh: &Mesh, viewer: Vec3, exponent: i32) -> Option<Vec<[f32; 3]>> {
    if mesh.num_cameras == 0 {
        return None;
    }
    let capture: Vec<Vec3> = mesh.cameras.iter().map(|c| c.position.as_vec3()).collect();
    Some(
        (0..mesh.positions.len())
            .into_par_iter()
            .map(|v| {
                let main = mesh.colors.as_ref().map_or([1.0; 3], |c| c[v]);
                interpolate(
                    mesh.positions[v],
                    viewer,
                    &capture,
                    mesh.camera_colors_of(v),
                    main,
                    exponent,
                )
            })
            .collect(),
    )
}

/// Visibility pass: the nearest triangle under each pixel centre; `cam_space` is divided by
/// `scale`, the depths kept in the camera's own units.
fn draw_triangles(
    triangles: &[[u32; 3]],
    cam_space: &[Vec3],
    scale: SceneScale,
    view: &ViewCamera,
    zbuf: &ZBuffer,
) {
    triangles
        .par_chunks(CHUNK)
        .enumerate()
        .for_each(|(chunk, tris)| {
            for (j, tri) in tris.iter().enumerate() {
                let [a, b, c] = tri.map(|v| cam_space[v as usize]);
                let Some((x0, x1, y0, y1)) = screen_bounds(a, b, c, view) else {
                    continue;
                };
                let id = (chunk * CHUNK + j) as u32;
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        if let Some((t, _)) = intersect(view.camera_ray(x, y), a, b, c) {
                            zbuf.insert(x, y, t * scale.factor, id);
                        }
                    }
                }
            }
        });
}

/// Pixel range covered by the part of a camera-space triangle in front of the near plane.
fn screen_bounds(a: Vec3, b: Vec3, c: Vec3, view: &ViewCamera) -> Option<(u32, u32, u32, u32)> {
    // Clip against z = NEAR: keep the vertices in front and the edge crossings.
    let mut pts = [Vec3::ZERO; 6];
    let mut n = 0;
    for (p, q) in [(a, b), (b, c), (c, a)] {
        if p.z >= NEAR {
            pts[n] = p;
            n += 1;
        }
        if (p.z >= NEAR) != (q.z >= NEAR) {
            let s = (NEAR - p.z) / (q.z - p.z);
            pts[n] = p + s * (q - p);
            pts[n].z = NEAR;
            n += 1;
        }
    }
    if n == 0 {
        return None;
    }
    // Bound the projections: a zero-thickness box per point keeps ViewCamera::pixel_range's maths.
    let mut lo = Vec2::splat(f32::INFINITY);
    let mut hi = Vec2::splat(f32::NEG_INFINITY);
    for p in &pts[..n] {
        let q = Vec2::new(p.x / p.z, p.y / p.z);
        lo = lo.min(q);
        hi = hi.max(q);
    }
    view.pixel_range(lo.extend(1.0), hi.extend(1.0))
}

/// Ray (origin 0, direction `d` with z = 1) against triangle (a, b, c), both sides
/// (Möller & Trumbore 1997): the hit's camera z and barycentrics, when in front of the near plane.
#[inline]
fn intersect(d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<(f32, [f32; 3])> {
    let e1 = b - a;
    let e2 = c - a;
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let inv = 1.0 / det;
    let s = -a;
    let u = s.dot(p) * inv;
    if !(-EDGE_EPS..=1.0 + EDGE_EPS).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = d.dot(q) * inv;
    if v < -EDGE_EPS || u + v > 1.0 + EDGE_EPS {
        return None;
    }
    // d has z = 1, so the ray parameter is the camera z of the hit.
    let t = e2.dot(q) * inv;
    if t < NEAR {
        return None;
    }
    Some((t, [1.0 - u - v, u, v]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::{Intrinsics, Pose};
    use glam::DVec3;
    use plenoptic_io::CaptureCamera;

    fn quad(colors: Option<Vec<[f32; 3]>>) -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            colors,
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        }
    }

    #[test]
    fn perspective_correct_interpolation_matches_closed_form() {
        // A plane receding in depth with the colour red = its world x mapped to [0, 1]: screen-space
        // (affine) interpolation would bend this; the closed form is the x of the ray's hit.
        let mesh = Mesh {
            positions: vec![
                Vec3::new(-4.0, -1.0, -10.0),
                Vec3::new(4.0, -1.0, 0.0),
                Vec3::new(4.0, 1.0, 0.0),
                Vec3::new(-4.0, 1.0, -10.0),
            ],
            colors: Some(vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 0.0, 0.0],
            ]),
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        };
        let cam = Camera::new(
            Intrinsics::from_fov_y(200, 100, 30.0),
            Pose::look_at(
                DVec3::new(0.0, 0.0, 8.0),
                DVec3::new(0.0, 0.0, -3.0),
                DVec3::Y,
            ),
        );
        let img = render_mesh(&mesh, &cam, &ViewOptions::single_sample()).unwrap();
        let mut checked = 0;
        for y in 0..100 {
            for x in 0..200 {
                if img.alpha_at(x, y) == 0.0 {
                    continue;
                }
                let ray = cam.ray(glam::DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5));
                // Plane through the quad: z = −10 + 10·(x + 4)/8, i.e. 10x − 8z = 40... solve along the ray.
                let (o, d) = (ray.origin, ray.direction);
                let s = (40.0 - 10.0 * o.x + 8.0 * o.z) / (10.0 * d.x - 8.0 * d.z);
                let hit = ray.at(s);
                let expected = ((hit.x + 4.0) / 8.0) as f32;
                assert!(
                    (img.rgb_at(x, y)[0] - expected).abs() < 2e-3,
                    "({x}, {y}): {} vs {expected}",
                    img.rgb_at(x, y)[0]
                );
                let depth = cam.depth(hit) as f32;
                assert!((img.depth_at(x, y) - depth).abs() < 1e-3 * depth);
                checked += 1;
            }
        }
        assert!(checked > 2000, "only {checked} pixels covered");
    }

    #[test]
    fn shared_edges_leave_no_cracks() {
        // A fan of thin triangles around a centre: every pixel inside the polygon must be covered.
        let n = 97;
        let mut positions = vec![Vec3::ZERO];
        for k in 0..n {
            let a = std::f32::consts::TAU * k as f32 / n as f32;
            positions.push(Vec3::new(a.cos(), a.sin(), 0.0));
        }
        let triangles = (0..n as u32)
            .map(|k| [0, 1 + k, 1 + (k + 1) % n as u32])
            .collect();
        let mesh = Mesh {
            positions,
            triangles,
            ..Default::default()
        };
        let cam = Camera::new(
            Intrinsics::from_fov_y(300, 300, 30.0),
            Pose::look_at(DVec3::new(0.3, 0.2, 4.5), DVec3::ZERO, DVec3::Y),
        );
        let img = render_mesh(&mesh, &cam, &ViewOptions::single_sample()).unwrap();
        let inner = (std::f64::consts::PI / n as f64).cos() - 1e-3;
        let mut inside = 0;
        for y in 0..300 {
            for x in 0..300 {
                let ray = cam.ray(glam::DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5));
                let hit = ray.at(-ray.origin.z / ray.direction.z);
                if hit.truncate().length() < inner {
                    inside += 1;
                    assert_eq!(img.alpha_at(x, y), 1.0, "crack at ({x}, {y})");
                }
            }
        }
        assert!(inside > 5000);
    }

    #[test]
    fn plenoptic_vertices_are_interpolated_then_mixed() {
        let mut mesh = quad(Some(vec![[0.5; 3]; 4]));
        mesh.num_cameras = 2;
        mesh.cameras = vec![
            CaptureCamera {
                position: DVec3::new(0.0, 0.0, 100.0),
                matrix: None,
            },
            CaptureCamera {
                position: DVec3::new(0.0, 0.0, -100.0),
                matrix: None,
            },
        ];
        // Camera 0 sees red on the left vertices and green on the right ones; camera 1 blue.
        mesh.camera_colors = [
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
        ]
        .iter()
        .flat_map(|&c| [c, [0.0, 0.0, 1.0]])
        .collect();
        let cam = Camera::new(
            Intrinsics::from_fov_y(64, 64, 40.0),
            Pose::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y),
        );
        let img = render_mesh(&mesh, &cam, &ViewOptions::single_sample()).unwrap();
        // Each vertex's view colour, by the one interpolation, then mixed by perspective-correct barycentrics.
        let viewer = Vec3::new(0.0, 0.0, 5.0);
        let caps = [Vec3::new(0.0, 0.0, 100.0), Vec3::new(0.0, 0.0, -100.0)];
        let vc: Vec<[f32; 3]> = (0..4)
            .map(|v| {
                interpolate(
                    mesh.positions[v],
                    viewer,
                    &caps,
                    mesh.camera_colors_of(v),
                    [0.5; 3],
                    10,
                )
            })
            .collect();
        for (x, y) in [(20u32, 32u32), (32, 20), (44, 40), (31, 33)] {
            let ray = cam.ray(glam::DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5));
            let hit = ray.at(-ray.origin.z / ray.direction.z).as_vec3();
            // Bilinear on the square is not barycentric; use the triangle that holds the hit.
            let (tri, bary) = if hit.y <= hit.x {
                (
                    [0usize, 1, 2],
                    [
                        (1.0 - hit.x) / 2.0,
                        (hit.x - hit.y) / 2.0,
                        (1.0 + hit.y) / 2.0,
                    ],
                )
            } else {
                (
                    [0usize, 2, 3],
                    [
                        (1.0 - hit.y) / 2.0,
                        (1.0 + hit.x) / 2.0,
                        (hit.y - hit.x) / 2.0,
                    ],
                )
            };
            let expected = barycentric_mix(tri.map(|v| vc[v]), bary);
            let got = img.rgb_at(x, y);
            for k in 0..3 {
                assert!(
                    (got[k] - expected[k]).abs() < 1e-3,
                    "({x}, {y}): {got:?} vs {expected:?}"
                );
            }
        }
    }

    /// Found by an adversarial sweep: a tetrahedron of side 3e-5 drew 6 pixels a view, one of
    /// 1e-5 none (an absolute near plane, and a floor of 10⁻³ on the framing radius), and one
    /// of 1e19 left views empty (the determinant overflowed f32). Framed by its own bounding
    /// sphere, the same shape must cover the same pixels at every scale the checks accept,
    /// with depths in proportion.
    #[test]
    fn a_shape_renders_the_same_at_every_scale() {
        let tetrahedron = |side: f32| Mesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::new(side, 0.0, 0.0),
                Vec3::new(0.0, side, 0.0),
                Vec3::new(0.0, 0.0, side),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3], [0, 1, 3], [1, 2, 3]],
            ..Default::default()
        };
        let rig = crate::RigConfig {
            cameras: 6,
            width: 48,
            height: 48,
            ..crate::RigConfig::default()
        };
        let views = |side: f32| {
            let mesh = tetrahedron(side);
            let (center, radius) =
                crate::bounding_sphere(&plenoptic_io::Model::Mesh(mesh.clone())).unwrap();
            crate::fibonacci_rig(center, radius, &rig)
                .unwrap()
                .iter()
                .map(|cam| render_mesh(&mesh, cam, &ViewOptions::default()).unwrap())
                .collect::<Vec<_>>()
        };
        let unit = views(1.0);
        assert!(unit.iter().all(|v| v.alpha.iter().any(|&a| a > 0.0)));
        for side in [1e-18_f32, 1e-9, 3e-5, 1e-5, 1e19, 1e30] {
            for (k, (got, want)) in views(side).iter().zip(&unit).enumerate() {
                let covered = |v: &ViewImage| v.alpha.iter().filter(|&&a| a > 0.5).count();
                let (g, w) = (covered(got), covered(want));
                // The rig's poses round differently at each scale: a pixel or two of the
                // outline may change.
                assert!(
                    g.abs_diff(w) <= 3,
                    "side {side}, view {k}: {g} against {w} pixels"
                );
                let depth = |v: &ViewImage| v.depth.iter().copied().fold(0.0_f32, f32::max);
                let ratio = depth(got) / (depth(want) * side);
                assert!(
                    (ratio - 1.0).abs() < 1e-3,
                    "side {side}, view {k}: depth × {ratio}"
                );
            }
        }
    }

    #[test]
    fn bad_indices_are_refused() {
        let mut mesh = quad(None);
        mesh.triangles.push([0, 1, 9]);
        let cam = Camera::new(
            Intrinsics::from_fov_y(8, 8, 40.0),
            Pose::look_at(DVec3::new(0.0, 0.0, 5.0), DVec3::ZERO, DVec3::Y),
        );
        let err = render_mesh(&mesh, &cam, &ViewOptions::single_sample()).unwrap_err();
        assert!(err.to_string().contains("triangle 2"), "{err}");
    }

    #[test]
    fn geometry_behind_the_camera_is_clipped() {
        // A huge floor passing under and behind the camera still renders in front of it.
        let mesh = Mesh {
            positions: vec![
                Vec3::new(-100.0, -1.0, -100.0),
                Vec3::new(100.0, -1.0, -100.0),
                Vec3::new(0.0, -1.0, 100.0),
            ],
            triangles: vec![[0, 1, 2]],
            ..Default::default()
        };
        let cam = Camera::new(
            Intrinsics::from_fov_y(40, 40, 60.0),
            Pose::look_at(DVec3::ZERO, DVec3::new(0.0, -0.3, -1.0), DVec3::Y),
        );
        let img = render_mesh(&mesh, &cam, &ViewOptions::single_sample()).unwrap();
        assert_eq!(img.alpha_at(20, 39), 1.0);
        assert_eq!(img.alpha_at(20, 0), 0.0);
        let ray = cam.ray(glam::DVec2::new(20.5, 39.5));
        let hit = ray.at((-1.0 - ray.origin.y) / ray.direction.y);
        assert!((f64::from(img.depth_at(20, 39)) - cam.depth(hit)).abs() < 1e-3);
    }

    #[test]
    fn views_without_depth_have_the_same_colour_and_coverage() {
        let mesh = quad(Some(vec![
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 0.0, 1.0],
            [1.0, 1.0, 0.0],
        ]));
        let cam = Camera::new(
            Intrinsics::from_fov_y(24, 20, 40.0),
            Pose::look_at(DVec3::new(1.0, 0.5, 4.0), DVec3::ZERO, DVec3::Y),
        );
        for supersample in [1, 3] {
            let opts = ViewOptions {
                supersample,
                ..ViewOptions::default()
            };
            let with = render_mesh(&mesh, &cam, &opts).unwrap();
            let without = render_mesh(
                &mesh,
                &cam,
                &ViewOptions {
                    depth: false,
                    ..opts
                },
            )
            .unwrap();
            assert!(with.depth.iter().any(|&z| z > 0.0));
            assert!(without.depth.is_empty());
            assert_eq!((without.rgb, without.alpha), (with.rgb, with.alpha));
        }
    }
}
