//! The reference renderer and the synthetic scenes on real data: textured glTF, the spider and the
//! bunny through `synth`, projection agreement with camera-model, and the demo scene's highlight.

use std::path::PathBuf;

use camera_model::{Camera, Intrinsics, Pose};
use glam::{DVec2, DVec3, Vec2, Vec3};
use plenoptic_io::{Model, PlenopticCloud};
use plenoptic_render::RigConfig;
use plenoptic_render::{self as views, ViewOptions};
use plenoptic_scenes::{DemoConfig, SynthConfig, demo_scene, synth_from_mesh};

fn data(rel: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../testdata")).join(rel)
}

#[test]
fn textured_box_shows_its_texture_where_camera_model_projects_it() {
    let mesh = plenoptic_io::read_mesh(&data("meshes/box-textured/BoxTextured.gltf")).unwrap();
    let material = mesh
        .materials
        .iter()
        .find(|m| m.texture.is_some())
        .expect("a textured material");
    let tex = &mesh.textures[material.texture.unwrap()];
    let uvs = mesh.uvs.as_ref().unwrap();
    let model = Model::Mesh(mesh.clone());
    let (c, r) = views::bounding_sphere(&model).unwrap();
    let cams = views::fibonacci_rig(
        c,
        r,
        &RigConfig {
            cameras: 6,
            width: 256,
            height: 256,
            ..RigConfig::default()
        },
    )
    .unwrap();
    let mut checked = 0;
    for cam in &cams {
        let img = views::render_mesh(&mesh, cam, &ViewOptions::single_sample()).unwrap();
        // For each visible triangle, its centroid projects (camera_model) to a pixel whose colour is
        // base × texture at the centroid's uv, when no nearer triangle covers that pixel.
        for (t, tri) in mesh.triangles.iter().enumerate() {
            let centroid = tri
                .iter()
                .map(|&v| mesh.positions[v as usize])
                .sum::<Vec3>()
                / 3.0;
            let Some(px) = cam.project(centroid.as_dvec3()) else {
                continue;
            };
            let (x, y) = (px.x.floor() as u32, px.y.floor() as u32);
            if !cam.intrinsics.contains(px) || img.alpha_at(x, y) < 1.0 {
                continue;
            }
            let depth = cam.depth(centroid.as_dvec3()) as f32;
            if (img.depth_at(x, y) - depth).abs() > 1e-2 * depth {
                continue; // hidden or at a grazing angle
            }
            // The exact pixel centre lands a fraction of a pixel from the centroid; sample there.
            let ray = cam.ray(DVec2::new(f64::from(x) + 0.5, f64::from(y) + 0.5));
            let [a, b, cc] = tri.map(|v| mesh.positions[v as usize].as_dvec3());
            let n = (b - a).cross(cc - a);
            let hit = ray.at((a - ray.origin).dot(n) / ray.direction.dot(n));
            let area = |p: DVec3, q: DVec3, s: DVec3| (q - p).cross(s - p).dot(n);
            let total = area(a, b, cc);
            let bary = [
                area(hit, b, cc) / total,
                area(a, hit, cc) / total,
                area(a, b, hit) / total,
            ];
            let uv: Vec2 = tri
                .iter()
                .zip(bary)
                .map(|(&v, w)| uvs[v as usize] * w as f32)
                .sum();
            let mat = &mesh.materials[mesh.triangle_materials[t] as usize];
            let s = tex.sample_bilinear(uv);
            let expected: [f32; 3] = std::array::from_fn(|k| mat.base_color[k] * s[k]);
            let got = img.rgb_at(x, y);
            for k in 0..3 {
                assert!(
                    (got[k] - expected[k]).abs() < 0.02,
                    "triangle {t} at ({x}, {y}): {got:?} vs {expected:?}"
                );
            }
            checked += 1;
        }
    }
    assert!(checked >= 12, "only {checked} triangle centres checked");
}

#[test]
fn single_point_lands_where_camera_model_projects_it() {
    let cam = Camera::new(
        Intrinsics::from_fov_y(320, 240, 20.0),
        Pose::look_at(
            DVec3::new(900.0, 700.0, 3000.0),
            DVec3::splat(500.0),
            DVec3::Y,
        ),
    );
    for p in [
        Vec3::new(500.0, 500.0, 500.0),
        Vec3::new(430.0, 610.0, 520.0),
        Vec3::new(610.0, 380.0, 470.0),
    ] {
        let cloud = PlenopticCloud {
            positions: vec![p],
            colors: vec![[1.0, 0.5, 0.25]],
            ..Default::default()
        };
        // A point the size of a third of a pixel at this distance.
        let opts = ViewOptions {
            point_size: 0.3,
            supersample: 1,
            ..ViewOptions::single_sample()
        };
        let img = views::render_cloud(&cloud, &cam, &opts).unwrap();
        let uv = cam.project(p.as_dvec3()).unwrap();
        let covered: Vec<(u32, u32)> = (0..240)
            .flat_map(|y| (0..320).map(move |x| (x, y)))
            .filter(|&(x, y)| img.alpha_at(x, y) > 0.0)
            .collect();
        // The cube covers the pixel centres within ~0.1 px of the projection: at most the
        // nearest one, and it is covered when the projection is that close to it.
        let nearest = (uv.x.floor() as u32, uv.y.floor() as u32);
        for &(x, y) in &covered {
            assert_eq!((x, y), nearest, "pixel ({x}, {y}) lit for projection {uv}");
        }
        let off = (uv - DVec2::new(f64::from(nearest.0) + 0.5, f64::from(nearest.1) + 0.5)).abs();
        if off.max_element() < 0.05 {
            assert_eq!(covered, vec![nearest]);
        }
    }
}

#[test]
fn synth_on_the_spider_keeps_its_texture_and_rig() {
    let mesh = plenoptic_io::read_mesh(&data("meshes/spider/spider.obj")).unwrap();
    let config = SynthConfig {
        points: 20_000,
        grid: 512,
        visibility_resolution: 512,
        ..SynthConfig::default()
    };
    let cloud = synth_from_mesh(&mesh, &config).unwrap();
    assert!(
        cloud.len() > 15_000 && cloud.len() <= 20_000,
        "{} points",
        cloud.len()
    );
    assert_eq!(cloud.num_cameras, 13);
    assert_eq!(cloud.camera_colors.len(), 13 * cloud.len());
    assert!(
        cloud
            .positions
            .iter()
            .all(|p| *p == p.round() && p.min_element() >= 0.0 && p.max_element() <= 511.0)
    );
    // Frame to world brings voxels back onto the mesh: every point is near the mesh's bounding box.
    let (lo, hi) = mesh
        .positions
        .iter()
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(l, h), &p| {
            (l.min(p), h.max(p))
        });
    let tol = f64::from((hi - lo).max_element()) / 511.0;
    for p in cloud.positions.iter().step_by(97) {
        let w = cloud.voxel_to_world(p.as_dvec3());
        assert!(
            w.cmpge(lo.as_dvec3() - tol).all() && w.cmple(hi.as_dvec3() + tol).all(),
            "{w}"
        );
    }
    // The spider's textures are brown and dark: its mean main colour is far from the white default.
    let mean: Vec3 = cloud.colors.iter().map(|c| Vec3::from(*c)).sum::<Vec3>() / cloud.len() as f32;
    assert!(
        mean.max_element() < 0.6 && mean.x >= mean.z,
        "mean colour {mean}"
    );
    // Some points are hidden from some cameras (legs occlude the body) but most cameras see most points.
    let hidden = (0..cloud.len())
        .filter(|&i| {
            cloud
                .camera_colors_of(i)
                .iter()
                .all(|c| *c == cloud.colors[i])
        })
        .count();
    assert!(
        hidden < cloud.len() / 2,
        "{hidden} points seen by no camera"
    );
    // Rendering the synthetic cloud from a capture camera's direction gives an image of the spider.
    let model = Model::Cloud(cloud);
    let (c, r) = views::bounding_sphere(&model).unwrap();
    let cams = views::fibonacci_rig(
        c,
        r,
        &RigConfig {
            cameras: 2,
            width: 128,
            height: 128,
            ..RigConfig::default()
        },
    )
    .unwrap();
    for img in views::render_views(&model, &cams, &ViewOptions::single_sample()).unwrap() {
        assert!(img.alpha.iter().filter(|&&a| a > 0.0).count() > 500);
    }
}

#[test]
fn synth_on_the_bunny_has_a_moving_highlight() {
    let mesh = plenoptic_io::read_mesh(&data("meshes/misc/bun_zipper_res4.ply")).unwrap();
    let config = SynthConfig {
        points: 30_000,
        grid: 256,
        visibility_resolution: 512,
        specular: 0.6,
        ..SynthConfig::default()
    };
    let cloud = synth_from_mesh(&mesh, &config).unwrap();
    assert!(cloud.len() > 10_000, "{} points", cloud.len());
    // White albedo (no colours in the file) with a highlight: per-camera colours vary for many points.
    let varying = (0..cloud.len())
        .filter(|&i| {
            let cc = cloud.camera_colors_of(i);
            let g: Vec<f32> = cc.iter().map(|c| c[1]).collect();
            g.iter().cloned().fold(0.0, f32::max) - g.iter().cloned().fold(1.0, f32::min) > 0.2
        })
        .count();
    assert!(
        varying > cloud.len() / 20,
        "{varying} of {} points show a highlight",
        cloud.len()
    );
    // Stored normals point out of the body: away from the centroid for most points (the bunny is
    // a blob), whatever the mesh's winding.
    let normals = cloud.normals.as_ref().unwrap();
    let centroid = cloud.positions.iter().sum::<Vec3>() / cloud.len() as f32;
    let outward = (0..cloud.len())
        .filter(|&i| normals[i].dot(cloud.positions[i] - centroid) > 0.0)
        .count();
    assert!(
        outward as f64 > 0.8 * cloud.len() as f64,
        "{outward} of {} normals point outwards",
        cloud.len()
    );
}

#[test]
fn demo_scene_renders_watertight_with_the_highlight_moving() {
    let cloud = demo_scene(&DemoConfig {
        grid: 96,
        ..DemoConfig::default()
    })
    .unwrap();
    let caps = cloud.camera_positions();
    let model = Model::Cloud(cloud.clone());
    let (c, _) = views::bounding_sphere(&model).unwrap();
    // Render from two capture cameras' own positions at a resolution where a voxel is ~1 px.
    let mut brightest = Vec::new();
    for k in [0usize, 3] {
        let cam = Camera::new(
            Intrinsics::from_fov_y(200, 200, 30.0),
            Pose::look_at(caps[k].as_dvec3(), c, DVec3::Y),
        );
        let img = views::render_cloud(&cloud, &cam, &ViewOptions::single_sample()).unwrap();
        // Watertight: no background pixel with covered pixels on both sides in a row and a column
        // (a hole), apart from the silhouette's concavities which the closed scene does not have.
        let w = 200;
        for y in 1..w - 1 {
            for x in 1..w - 1 {
                if img.alpha_at(x, y) == 0.0 {
                    let row = (0..x).any(|i| img.alpha_at(i, y) > 0.0)
                        && (x + 1..w).any(|i| img.alpha_at(i, y) > 0.0);
                    let col = (0..y).any(|j| img.alpha_at(x, j) > 0.0)
                        && (y + 1..w).any(|j| img.alpha_at(x, j) > 0.0);
                    assert!(!(row && col), "hole at ({x}, {y}) from capture camera {k}");
                }
            }
        }
        // The brightest pixel (the highlight) is where camera k's own colour peaks.
        let (i, _) = img
            .rgb
            .chunks(3)
            .enumerate()
            .max_by(|a, b| a.1[1].total_cmp(&b.1[1]))
            .unwrap();
        brightest.push(i);
    }
    assert_ne!(brightest[0], brightest[1]);
}

/// The reference renderer's Gaussian pixel filter is the rasteriser's 0.3 px² dilation: the two
/// constants live in crates that do not depend on each other, so this is where they meet.
#[test]
fn reference_pixel_filter_is_the_rasterisers_dilation() {
    assert_eq!(
        plenoptic_render::PIXEL_FILTER_VARIANCE,
        splat_core::constants::DILATION
    );
}

/// What `render_views_with` hands to `keep` is each view with its own index, the same image
/// `render_model` makes alone from that camera, for a cloud (drawn in its prepared order) and
/// for a mesh; and a cloud listed in another order renders the same masks.
#[test]
fn views_kept_one_at_a_time_are_the_views_rendered_alone() {
    let cloud = demo_scene(&DemoConfig {
        grid: 48,
        ..Default::default()
    })
    .unwrap();
    let mesh = plenoptic_io::read_mesh(&data("meshes/box-textured/BoxTextured.gltf")).unwrap();
    for model in [Model::Cloud(cloud.clone()), Model::Mesh(mesh)] {
        let (c, r) = views::bounding_sphere(&model).unwrap();
        let cams = views::fibonacci_rig(
            c,
            r,
            &RigConfig {
                cameras: 5,
                width: 40,
                height: 32,
                ..RigConfig::default()
            },
        )
        .unwrap();
        let opts = ViewOptions::default();
        let kept = views::render_views_with(&model, &cams, &opts, |i, img| (i, img)).unwrap();
        assert_eq!(kept.len(), cams.len());
        for (i, (index, img)) in kept.into_iter().enumerate() {
            assert_eq!(index, i);
            assert_eq!(img, views::render_model(&model, &cams[i], &opts).unwrap());
            assert!(img.alpha.iter().any(|&a| a > 0.0), "view {i} sees nothing");
        }
    }
    // The same points listed backwards: the same coverage from every camera.
    let n = cloud.len();
    let reversed = PlenopticCloud {
        positions: cloud.positions.iter().rev().copied().collect(),
        colors: cloud.colors.iter().rev().copied().collect(),
        camera_colors: (0..n)
            .rev()
            .flat_map(|i| cloud.camera_colors_of(i).to_vec())
            .collect(),
        normals: None,
        ..cloud.clone()
    };
    let (c, r) = views::bounding_sphere(&Model::Cloud(cloud.clone())).unwrap();
    let cams = views::fibonacci_rig(
        c,
        r,
        &RigConfig {
            cameras: 3,
            width: 40,
            height: 32,
            ..RigConfig::default()
        },
    )
    .unwrap();
    let forward =
        views::render_views(&Model::Cloud(cloud), &cams, &ViewOptions::default()).unwrap();
    let backward =
        views::render_views(&Model::Cloud(reversed), &cams, &ViewOptions::default()).unwrap();
    for (a, b) in forward.iter().zip(&backward) {
        assert_eq!(a.alpha, b.alpha);
    }
}

/// A cloud that lies on no voxel grid is drawn at its own spacing: the same sphere of 20,000
/// points (arbitrary floats) at radius 0.01, 1 and 1000 gives the same views. Cubes one unit
/// wide, as a voxelised capture's are drawn, left the small sphere's views empty (the cameras
/// inside the cubes) and spilled the unit one past its frame.
#[test]
fn an_off_grid_cloud_looks_the_same_at_every_scale() {
    let unit: Vec<Vec3> = camera_model::rig::fibonacci_sphere(20_000)
        .into_iter()
        .map(|d| d.as_vec3())
        .collect();
    let coverage = |scale: f32| -> Vec<f32> {
        let cloud = PlenopticCloud {
            colors: unit.iter().map(|p| (0.5 + 0.4 * *p).to_array()).collect(),
            positions: unit.iter().map(|&p| p * scale).collect(),
            ..Default::default()
        };
        let model = Model::Cloud(cloud);
        let opts = ViewOptions::default();
        let sizing = opts.point_sizing(&model);
        assert!(
            matches!(sizing, views::PointSizing::OffGrid(s) if s > 0.005 * scale && s < 0.05 * scale),
            "scale {scale}: {sizing:?}"
        );
        let (c, r) = views::bounding_sphere(&model).unwrap();
        let cams = views::fibonacci_rig(
            c,
            r,
            &RigConfig {
                cameras: 3,
                width: 48,
                height: 48,
                ..RigConfig::default()
            },
        )
        .unwrap();
        views::render_views(&model, &cams, &opts.sized(sizing))
            .unwrap()
            .iter()
            .flat_map(|v| (0..48 * 48).map(|i| v.alpha_at(i % 48, i / 48)))
            .collect()
    };
    let unit_views = coverage(1.0);
    // Each view is the sphere's disc, which the rig frames 0.95 × 24 = 22.8 px in radius:
    // covered inside (no hole) and its area that of the disc, grown by the cubes reaching
    // past the sphere (under 0.8 px).
    for view in unit_views.chunks(48 * 48) {
        for (i, &a) in view.iter().enumerate() {
            let d = ((i % 48) as f32 + 0.5 - 24.0).hypot((i / 48) as f32 + 0.5 - 24.0);
            if d < 22.0 {
                assert!(
                    a > 0.99,
                    "hole at pixel {i}, {d} px from the centre: alpha {a}"
                );
            }
        }
        let area: f32 = view.iter().sum();
        let disc = |r: f32| std::f32::consts::PI * r * r;
        assert!(
            area > disc(22.8) && area < disc(23.6),
            "covered area {area} px² for a disc of {} px²",
            disc(22.8)
        );
    }
    for scale in [0.01, 1000.0] {
        let scaled = coverage(scale);
        let differ = unit_views
            .iter()
            .zip(&scaled)
            .filter(|(a, b)| (*a - *b).abs() > 0.02)
            .count();
        assert!(
            differ <= 8,
            "scale {scale}: {differ} pixels differ from scale 1"
        );
    }
}
