//! `synth`: a plenoptic cloud made from a real mesh, with the demo's shading model.

use std::collections::HashMap;

use camera_model::rig::{WORLD_UP, framing_focal};
use camera_model::{Camera, Intrinsics, Pose};
use glam::{DVec3, Vec3};
use plenoptic_io::{Mesh, PlenopticCloud};
use rand::{RngExt, SeedableRng};
use rayon::prelude::*;

use super::{Error, Gloss, Shading, capture_cameras, capture_directions, to_u8_grid};
use plenoptic_render::{self as views, ViewImage, ViewOptions};

/// Parameters of [`synth_from_mesh`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SynthConfig {
    /// Number of surface samples (before merging samples that fall in the same voxel).
    pub points: usize,
    /// Number of capture cameras (on two rings).
    pub cameras: usize,
    /// Voxel grid width: the mesh's longest side spans `grid − 1` voxels; [`AUTO_GRID`] (0, the
    /// default) chooses it from the mesh's area and `points` ([`auto_grid`]) so the surface is
    /// watertight.
    pub grid: u32,
    /// Capture-camera distance from the mesh centre, in bounding-sphere radii.
    pub camera_distance: f64,
    /// Specular weight added to every surface.
    pub specular: f32,
    /// Blinn–Phong exponent.
    pub shininess: f32,
    /// The shading model.
    pub shading: Shading,
    /// Side of the capture cameras' depth maps used for visibility, in pixels.
    pub visibility_resolution: u32,
    /// Seed of the surface sampler.
    pub seed: u64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        Self {
            points: 300_000,
            cameras: 13,
            grid: AUTO_GRID,
            camera_distance: 3.0,
            specular: 0.5,
            shininess: 40.0,
            shading: Shading::default(),
            visibility_resolution: 1024,
            seed: 0,
        }
    }
}

impl SynthConfig {
    fn validate(&self) -> Result<(), Error> {
        let bad = |m: String| Err(Error::InvalidConfig(m));
        if !(1..=50_000_000).contains(&self.points) {
            return bad(format!(
                "points must be in 1..=50000000, got {}",
                self.points
            ));
        }
        if !(1..=64).contains(&self.cameras) {
            return bad(format!("cameras must be in 1..=64, got {}", self.cameras));
        }
        if self.grid != AUTO_GRID && !(2..=65_536).contains(&self.grid) {
            return bad(format!(
                "grid must be 0 (auto) or in 2..=65536, got {}",
                self.grid
            ));
        }
        if !(self.camera_distance > 1.0 && self.camera_distance.is_finite()) {
            return bad(format!(
                "camera_distance must exceed 1 radius, got {}",
                self.camera_distance
            ));
        }
        if !(self.specular >= 0.0 && self.shininess > 0.0 && self.shininess.is_finite()) {
            return bad(format!(
                "bad gloss: specular {}, shininess {}",
                self.specular, self.shininess
            ));
        }
        if !(16..=8192).contains(&self.visibility_resolution) {
            return bad(format!(
                "visibility_resolution must be in 16..=8192, got {}",
                self.visibility_resolution
            ));
        }
        self.shading.validate()
    }
}

/// Sums over the samples that fell into one voxel.
struct Voxel {
    position: Vec3,
    normal: Vec3,
    main: [f32; 3],
    colors: Vec<[f32; 3]>,
    count: f32,
}

/// One surface sample in mesh units.
struct Sample {
    position: Vec3,
    normal: Vec3,
    albedo: [f32; 3],
}

/// Where a synthesised frame sits, in mesh units: the voxel grid's corner and the length its
/// `grid − 1` voxels span, and the centre and radius the capture rig is placed around. A sequence
/// has one for all its frames, so they share the grid and the rig, as 8iVSLF frames do.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaptureVolume {
    /// The grid's corner (voxel 0, 0, 0).
    pub lo: Vec3,
    /// The length the grid's longest side spans.
    pub extent: f32,
    /// The rig's centre.
    pub center: Vec3,
    /// The radius the rig frames (half the bounding box's diagonal).
    pub radius: f32,
}

impl CaptureVolume {
    /// The bounding box of `positions` (all frames' vertices, for a sequence).
    ///
    /// # Errors
    /// [`Error::EmptyMesh`] when the box has no extent or is not finite.
    pub fn of_points(positions: impl IntoIterator<Item = Vec3>) -> Result<Self, Error> {
        let (lo, hi) = positions
            .into_iter()
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p), hi.max(p))
            });
        let extent = (hi - lo).max_element();
        if !(extent > 0.0 && extent.is_finite()) {
            return Err(Error::EmptyMesh(format!(
                "the mesh's bounding box has extent {extent}"
            )));
        }
        Ok(Self {
            lo,
            extent,
            center: 0.5 * (lo + hi),
            radius: 0.5 * (hi - lo).length(),
        })
    }
}

/// The grid width `config` asks for on `mesh` within `volume`: its own, or [`auto_grid`]'s.
pub(crate) fn grid_for(mesh: &Mesh, config: &SynthConfig, volume: &CaptureVolume) -> u32 {
    if config.grid == AUTO_GRID {
        let area: f64 = triangle_areas(mesh).iter().sum();
        auto_grid(area, f64::from(volume.extent), config.points)
    } else {
        config.grid
    }
}

/// Samples `config.points` points on the mesh (area-weighted), shades them towards 13 (or
/// `config.cameras`) capture cameras on two rings, and voxelises them into an 8iVSLF-layout cloud.
///
/// Albedo is [`Mesh::albedo_at`] (base colour × texture × vertex colour). A capture camera sees a
/// sample when the sample is not farther than the camera's depth map of the mesh (rendered with
/// [`views::render_mesh`]) by more than the map's resolution allows; hidden samples get the main
/// colour. Samples in the same voxel are merged by averaging (as PccAppRenderer's
/// `--dropdups=2`); frame_to_world maps voxels back to mesh units.
pub fn synth_from_mesh(mesh: &Mesh, config: &SynthConfig) -> Result<PlenopticCloud, Error> {
    config.validate()?;
    views::check_mesh(mesh)?;
    let volume = CaptureVolume::of_points(mesh.positions.iter().copied())?;
    synth_in_volume(mesh, config, &volume)
}

/// [`synth_from_mesh`] on the grid and rig of `volume` instead of the mesh's own bounding box
/// (the mesh should lie inside it): what every frame of a sequence uses.
pub fn synth_in_volume(
    mesh: &Mesh,
    config: &SynthConfig,
    volume: &CaptureVolume,
) -> Result<PlenopticCloud, Error> {
    config.validate()?;
    views::check_mesh(mesh)?;
    let samples = sample_surface(mesh, config.points, config.seed)?;

    // The voxel frame: voxel = (p − lo) · scale.
    let grid = grid_for(mesh, config, volume);
    let lo = volume.lo;
    let scale = f64::from(grid - 1) / f64::from(volume.extent);
    let (center, radius) = (volume.center, volume.radius);

    let rig = CaptureRig::new(mesh, config, center, radius)?;
    let shaded = rig.shade(&samples, config);
    let voxels = merge_into_voxels(&samples, shaded, lo, scale, config.cameras);
    let mut cloud = PlenopticCloud {
        num_cameras: config.cameras,
        cameras: capture_cameras(
            &rig.eyes
                .iter()
                .map(|e| (*e - lo.as_dvec3()) * scale)
                .collect::<Vec<_>>(),
            (center - lo).as_dvec3() * scale,
            1.0 / scale,
            lo.as_dvec3(),
        ),
        frame_to_world_scale: Some(1.0 / scale),
        frame_to_world_translation: Some(lo.as_dvec3()),
        width: Some(grid - 1),
        ..Default::default()
    };
    let mut normals = Vec::with_capacity(voxels.len());
    for Voxel {
        position: p,
        normal: n,
        main,
        colors,
        count,
    } in voxels
    {
        cloud.positions.push(p);
        normals.push(n.normalize_or(Vec3::Y));
        cloud.colors.push(to_u8_grid(main.map(|c| c / count)));
        cloud
            .camera_colors
            .extend(colors.into_iter().map(|c| to_u8_grid(c.map(|v| v / count))));
    }
    cloud.normals = Some(normals);
    Ok(cloud)
}

/// The capture cameras in mesh units, with a depth map each for visibility.
struct CaptureRig {
    eyes: Vec<DVec3>,
    cameras: Vec<Camera>,
    depth_maps: Vec<ViewImage>,
}

/// A sample's view-independent colour, its colour seen from each capture camera, and its
/// normal turned towards the cameras that see it.
type Shaded = ([f32; 3], Vec<[f32; 3]>, Vec3);

impl CaptureRig {
    /// `config.cameras` cameras at `config.camera_distance` radii around (`center`, `radius`),
    /// framing the sphere, and `mesh`'s depth from each.
    fn new(mesh: &Mesh, config: &SynthConfig, center: Vec3, radius: f32) -> Result<Self, Error> {
        let res = config.visibility_resolution;
        let distance = config.camera_distance * f64::from(radius);
        let focal = framing_focal(f64::from(radius), distance, res, res, 0.02)?;
        let intrinsics = Intrinsics::centered(res, res, focal, focal);
        let eyes: Vec<DVec3> = capture_directions(config.cameras)
            .iter()
            .map(|d| center.as_dvec3() + distance * *d)
            .collect();
        let cameras: Vec<Camera> = eyes
            .iter()
            .map(|&e| Camera::new(intrinsics, Pose::look_at(e, center.as_dvec3(), WORLD_UP)))
            .collect();
        let depth_maps: Vec<ViewImage> = cameras
            .iter()
            .map(|c| views::render_mesh(mesh, c, &ViewOptions::single_sample()))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            eyes,
            cameras,
            depth_maps,
        })
    }

    /// Every sample shaded for every camera (its view-independent colour where the camera does
    /// not see it), in parallel.
    fn shade(&self, samples: &[Sample], config: &SynthConfig) -> Vec<Shaded> {
        let gloss = Gloss {
            specular: config.specular,
            shininess: config.shininess,
        };
        samples
            .par_iter()
            .map(|s| {
                let main = config.shading.diffuse_color(s.normal, s.albedo);
                let mut facing = 0i32;
                let colors = self
                    .cameras
                    .iter()
                    .zip(&self.depth_maps)
                    .map(|(cam, map)| {
                        let to_cam = (cam.center().as_vec3() - s.position).normalize_or_zero();
                        if !sees(cam, map, s.position, s.normal) {
                            return main;
                        }
                        facing += if s.normal.dot(to_cam) >= 0.0 { 1 } else { -1 };
                        config.shading.color(s.normal, to_cam, s.albedo, gloss)
                    })
                    .collect();
                // Orient the stored normal towards the cameras that see the sample (meshes may
                // wind either way).
                let normal = if facing < 0 { -s.normal } else { s.normal };
                (main, colors, normal)
            })
            .collect()
    }
}

/// The samples voxelised (voxel = (p − lo) · scale, rounded) and those sharing a voxel summed,
/// in the order their voxels are first met.
fn merge_into_voxels(
    samples: &[Sample],
    shaded: Vec<Shaded>,
    lo: Vec3,
    scale: f64,
    n_cam: usize,
) -> Vec<Voxel> {
    let mut index: HashMap<[i32; 3], usize> = HashMap::new();
    let mut acc: Vec<Voxel> = Vec::new();
    for (s, (main, colors, normal)) in samples.iter().zip(shaded) {
        let v = ((s.position - lo).as_dvec3() * scale).round();
        let key = [v.x as i32, v.y as i32, v.z as i32];
        let slot = *index.entry(key).or_insert_with(|| {
            acc.push(Voxel {
                position: v.as_vec3(),
                normal: Vec3::ZERO,
                main: [0.0; 3],
                colors: vec![[0.0; 3]; n_cam],
                count: 0.0,
            });
            acc.len() - 1
        });
        let a = &mut acc[slot];
        a.normal += normal;
        for k in 0..3 {
            a.main[k] += main[k];
            for (sum, c) in a.colors.iter_mut().zip(&colors) {
                sum[k] += c[k];
            }
        }
        a.count += 1.0;
    }
    acc
}

/// Whether capture camera `cam` sees the surface point `p` (normal `n`), by its depth map.
fn sees(cam: &Camera, map: &ViewImage, p: Vec3, n: Vec3) -> bool {
    let pd = p.as_dvec3();
    let Some(uv) = cam.project(pd) else {
        return false;
    };
    if !cam.intrinsics.contains(uv) {
        return false;
    }
    let (x, y) = (uv.x as u32, uv.y as u32);
    let surface = f64::from(map.depth_at(x, y));
    if surface <= 0.0 {
        return false;
    }
    let depth = cam.depth(pd);
    // The map holds the surface at the pixel centre, up to half a pixel away from p: on a slope of
    // angle θ to the view that changes depth by footprint·tanθ. Allow two pixels' worth, capped.
    let footprint = depth / cam.intrinsics.fx;
    let view = (cam.center() - pd).normalize();
    let cos = n.as_dvec3().dot(view).abs().max(0.2);
    let slack = 2.0 * footprint * (1.0 - cos * cos).sqrt() / cos + 1e-4 * depth;
    depth <= surface + slack
}

/// [`SynthConfig::grid`] value that asks for [`auto_grid`].
pub const AUTO_GRID: u32 = 0;

/// Mean number of surface samples per voxel face's worth of area (`voxel²`) chosen by
/// [`auto_grid`]. Samples are area-uniform, so the count in a voxel the surface crosses with area
/// a is Poisson with mean N·a/A: a voxel crossed by a full face stays empty with probability
/// e^−12 ≈ 6·10⁻⁶, about one in a 100,000-voxel cloud, and a voxel crossed by less is covered in
/// the views by its neighbours. (On a sphere, 5 samples a voxel² still rendered without holes and
/// 3 did not; 12 leaves room for flat faces seen head-on, where an empty voxel is a hole.)
pub const SAMPLES_PER_VOXEL: f64 = 12.0;

/// The grid width for which `points` area-uniform samples of a surface of area `area` put about
/// `SAMPLES_PER_VOXEL` (12) samples on each voxel² of surface: voxel side v = √(k·area/points), the
/// longest side `extent` spanning `extent / v` voxels. Rendered with the reference renderer's
/// default one-voxel cubes, such a cloud has no holes inside its silhouette.
#[must_use]
pub fn auto_grid(area: f64, extent: f64, points: usize) -> u32 {
    let voxel = (SAMPLES_PER_VOXEL * area / points.max(1) as f64).sqrt();
    let cells = (extent / voxel).floor();
    if cells.is_finite() {
        (cells as u32).saturating_add(1).clamp(2, 65_536)
    } else {
        2
    }
}

/// Area of every triangle (0 for degenerate or non-finite ones).
fn triangle_areas(mesh: &Mesh) -> Vec<f64> {
    mesh.triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize].as_dvec3());
            let area = 0.5 * (b - a).cross(c - a).length();
            if area.is_finite() { area } else { 0.0 }
        })
        .collect()
}

/// `count` points on the mesh, area-weighted, with interpolated normals and albedo.
fn sample_surface(mesh: &Mesh, count: usize, seed: u64) -> Result<Vec<Sample>, Error> {
    let areas = triangle_areas(mesh);
    let mut cdf = Vec::with_capacity(areas.len());
    let mut total = 0.0;
    for a in &areas {
        total += *a;
        cdf.push(total);
    }
    if !(total > 0.0 && total.is_finite()) {
        return Err(Error::EmptyMesh(format!(
            "{} triangles with total area {total}",
            mesh.triangles.len()
        )));
    }
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let draws: Vec<(f64, f32, f32)> = (0..count)
        .map(|_| {
            (
                rng.random::<f64>() * total,
                rng.random::<f32>(),
                rng.random::<f32>(),
            )
        })
        .collect();
    Ok(draws
        .into_par_iter()
        .map(|(r, r1, r2)| {
            let t = cdf.partition_point(|&c| c <= r).min(cdf.len() - 1);
            // Uniform point in a triangle (Osada et al. 2002): (1 − √r1, √r1(1 − r2), √r1·r2).
            let s = r1.sqrt();
            let bary = [1.0 - s, s * (1.0 - r2), s * r2];
            let tri = mesh.triangles[t];
            let [a, b, c] = tri.map(|v| mesh.positions[v as usize]);
            let position = bary[0] * a + bary[1] * b + bary[2] * c;
            let face = (b - a).cross(c - a).normalize_or(Vec3::Y);
            let normal = match &mesh.normals {
                Some(n) => {
                    let v = bary[0] * n[tri[0] as usize]
                        + bary[1] * n[tri[1] as usize]
                        + bary[2] * n[tri[2] as usize];
                    v.try_normalize().unwrap_or(face)
                }
                None => face,
            };
            Sample {
                position,
                normal,
                albedo: mesh.albedo_at(t, bary),
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(z: f32) -> Mesh {
        Mesh {
            positions: vec![
                Vec3::new(-1.0, -1.0, z),
                Vec3::new(1.0, -1.0, z),
                Vec3::new(1.0, 1.0, z),
                Vec3::new(-1.0, 1.0, z),
            ],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
            ..Default::default()
        }
    }

    #[test]
    fn depth_map_visibility_sees_the_surface_not_what_is_behind() {
        let mesh = square(0.0);
        let cam = Camera::new(
            Intrinsics::from_fov_y(128, 128, 40.0),
            Pose::look_at(DVec3::new(0.3, 0.2, 5.0), DVec3::ZERO, WORLD_UP),
        );
        let map = views::render_mesh(&mesh, &cam, &ViewOptions::single_sample()).unwrap();
        for p in [
            Vec3::new(0.1, 0.2, 0.0),
            Vec3::new(-0.7, 0.5, 0.0),
            Vec3::new(0.9, -0.9, 0.0),
        ] {
            assert!(sees(&cam, &map, p, Vec3::Z), "{p} on the square");
            assert!(
                !sees(&cam, &map, p - 0.2 * Vec3::Z, Vec3::Z),
                "{p} behind the square"
            );
        }
        // Off the square (background in the map) nothing is seen.
        assert!(!sees(&cam, &map, Vec3::new(1.5, 0.0, 0.0), Vec3::Z));
    }

    #[test]
    fn samples_are_uniform_over_area() {
        // Two triangles of areas 1 and 3: about a quarter of the samples on the first.
        let mesh = Mesh {
            positions: vec![
                Vec3::ZERO,
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(0.0, 1.0, 0.0),
                Vec3::new(10.0, 0.0, 0.0),
                Vec3::new(13.0, 0.0, 0.0),
                Vec3::new(10.0, 2.0, 0.0),
            ],
            triangles: vec![[0, 1, 2], [3, 4, 5]],
            ..Default::default()
        };
        let s = sample_surface(&mesh, 20_000, 7).unwrap();
        let first = s.iter().filter(|p| p.position.x < 5.0).count() as f64 / 20_000.0;
        assert!((first - 0.25).abs() < 0.02, "{first}");
        // Inside the triangle: x/2 + y ≤ 1 on the first.
        assert!(
            s.iter()
                .filter(|p| p.position.x < 5.0)
                .all(|p| p.position.x / 2.0 + p.position.y <= 1.0 + 1e-5)
        );
    }

    /// A UV sphere of radius 1 with `rings` × 2·`rings` quads.
    fn sphere(rings: u32) -> Mesh {
        let segs = 2 * rings;
        let mut positions = Vec::new();
        for i in 0..=rings {
            let theta = std::f32::consts::PI * i as f32 / rings as f32;
            for j in 0..segs {
                let phi = std::f32::consts::TAU * j as f32 / segs as f32;
                positions.push(Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.cos(),
                    theta.sin() * phi.sin(),
                ));
            }
        }
        let at = |i: u32, j: u32| i * segs + j % segs;
        let mut triangles = Vec::new();
        for i in 0..rings {
            for j in 0..segs {
                triangles.push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
                triangles.push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
            }
        }
        Mesh {
            positions,
            triangles,
            ..Default::default()
        }
    }

    /// Pixels inside the mesh's silhouette, at least `margin` pixels from its edge, that the
    /// cloud leaves uncovered at the renderer's default one-voxel cubes, over three views; and
    /// the number of pixels checked.
    fn count_holes(mesh: &Mesh, cloud: &PlenopticCloud, margin: i32) -> (usize, usize) {
        let opts = ViewOptions::single_sample();
        assert_eq!(opts.point_size, 1.0);
        let (mut holes, mut checked) = (0, 0);
        for eye in [
            DVec3::new(0.0, 0.3, 3.2),
            DVec3::new(2.5, 1.5, -1.0),
            DVec3::new(-1.0, -2.8, 1.0),
        ] {
            let cam = Camera::new(
                Intrinsics::from_fov_y(160, 160, 45.0),
                Pose::look_at(eye, DVec3::ZERO, WORLD_UP),
            );
            // The cloud is in voxel units: the same view from the eye in that frame.
            let (s, t) = (
                cloud.frame_to_world_scale.unwrap(),
                cloud.frame_to_world_translation.unwrap(),
            );
            let voxel_cam = Camera::new(
                cam.intrinsics,
                Pose::look_at((eye - t) / s, -t / s, WORLD_UP),
            );
            let reference = views::render_mesh(mesh, &cam, &opts).unwrap();
            let rendered = views::render_cloud(cloud, &voxel_cam, &opts).unwrap();
            let inside = |x: i32, y: i32| {
                (0..160).contains(&x)
                    && (0..160).contains(&y)
                    && reference.alpha_at(x as u32, y as u32) > 0.5
            };
            for y in 0..160 {
                for x in 0..160 {
                    let deep = (-margin..=margin)
                        .all(|dy| (-margin..=margin).all(|dx| inside(x + dx, y + dy)));
                    if deep {
                        checked += 1;
                        if rendered.alpha_at(x as u32, y as u32) < 0.5 {
                            holes += 1;
                        }
                    }
                }
            }
        }
        (holes, checked)
    }

    #[test]
    fn default_grid_is_watertight_at_one_voxel_cubes() {
        // A radius-1 sphere (area 4π) with 60,000 samples: auto grid √(12·4π/60,000) ≈ 0.050
        // voxel, 40 voxels across, ≈ 2.5 pixels a voxel in the views.
        let mesh = sphere(24);
        let config = SynthConfig {
            points: 60_000,
            visibility_resolution: 128,
            ..SynthConfig::default()
        };
        let area: f64 = triangle_areas(&mesh).iter().sum();
        let grid = auto_grid(area, 2.0, config.points);
        assert!((38..=42).contains(&grid), "auto grid {grid}");
        let cloud = synth_from_mesh(&mesh, &config).unwrap();
        assert_eq!(cloud.width, Some(grid - 1));
        // Voxel centres are up to half a voxel off the surface: skip a voxel's width of edge.
        let (holes, checked) = count_holes(&mesh, &cloud, 3);
        assert!(checked > 20_000, "{checked} pixels checked");
        assert_eq!(holes, 0, "{holes} holes in {checked} pixels");
        // The same samples on a grid four times finer leave most voxels empty: the check sees it.
        let fine = synth_from_mesh(
            &mesh,
            &SynthConfig {
                grid: 4 * grid,
                ..config
            },
        )
        .unwrap();
        let (fine_holes, _) = count_holes(&mesh, &fine, 3);
        assert!(
            fine_holes > checked / 20,
            "{fine_holes} holes on the fine grid"
        );
    }

    #[test]
    fn empty_or_degenerate_meshes_are_refused() {
        let mut mesh = square(0.0);
        mesh.triangles.clear();
        assert!(matches!(
            synth_from_mesh(&mesh, &SynthConfig::default()),
            Err(Error::EmptyMesh(_))
        ));
        let mut flat = square(0.0);
        flat.positions = vec![Vec3::ONE; 4];
        assert!(matches!(
            synth_from_mesh(&flat, &SynthConfig::default()),
            Err(Error::EmptyMesh(_))
        ));
        let bad = SynthConfig {
            points: 0,
            ..SynthConfig::default()
        };
        assert!(matches!(
            synth_from_mesh(&square(0.0), &bad),
            Err(Error::InvalidConfig(_))
        ));
    }
}
