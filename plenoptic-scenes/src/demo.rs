//! The built-in demo scenes, voxelised, with a highlight that moves from capture camera to
//! capture camera: a checker-textured matte slab with a glossy red sphere sunk into it (the
//! demo), or a wide plain floor with a small glossy checkered ball on it (a large flat region
//! and a small detailed object: what an automatic splat budget should tell apart).

use glam::{DVec3, Vec3};
use plenoptic_io::PlenopticCloud;
use rayon::prelude::*;

use super::{Error, Gloss, Shading, capture_cameras, capture_directions, to_u8_grid};

/// Parameters of the demo scene.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DemoConfig {
    /// Voxel grid width: the scene fills most of a grid of this many voxels per side
    /// (128 gives about 35,000 points; the count grows with its square).
    pub grid: u32,
    /// Number of capture cameras (on two rings).
    pub cameras: usize,
    /// Capture-camera distance from the scene centre, in scene radii.
    pub camera_distance: f64,
    /// Specular weight of the sphere.
    pub specular: f32,
    /// Blinn–Phong exponent of the sphere.
    pub shininess: f32,
    /// The shading model.
    pub shading: Shading,
    /// Which solids and textures.
    pub layout: DemoLayout,
}

/// The demo scene's solids and textures.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DemoLayout {
    /// A 0.7 × 0.2 × 0.7 checker-textured matte slab with a glossy red sphere of radius 0.22
    /// sunk into it (fractions of the grid): texture everywhere.
    #[default]
    Slab,
    /// A 0.9 × 0.06 × 0.9 plain matte floor with a glossy checkered ball of radius 0.12 resting
    /// on it: about seven in eight points on the flat, uniform floor, the detail on the ball.
    Floor,
}

impl DemoConfig {
    /// Checks the ranges: a grid of 16 to 2048 voxels, 1 to 64 cameras at more than one scene
    /// radius, a usable gloss and shading.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] naming the value.
    pub fn validate(&self) -> Result<(), Error> {
        if !(16..=2048).contains(&self.grid) {
            return Err(Error::InvalidConfig(format!(
                "grid must be in 16..=2048, got {}",
                self.grid
            )));
        }
        if !(1..=64).contains(&self.cameras) {
            return Err(Error::InvalidConfig(format!(
                "cameras must be in 1..=64, got {}",
                self.cameras
            )));
        }
        if !(self.camera_distance > 1.0 && self.camera_distance.is_finite()) {
            return Err(Error::InvalidConfig(format!(
                "camera_distance must exceed 1 scene radius, got {}",
                self.camera_distance
            )));
        }
        if !(self.specular >= 0.0 && self.shininess > 0.0 && self.shininess.is_finite()) {
            return Err(Error::InvalidConfig(format!(
                "bad gloss: specular {}, shininess {}",
                self.specular, self.shininess
            )));
        }
        self.shading.validate()
    }
}

impl Default for DemoConfig {
    fn default() -> Self {
        Self {
            grid: 128,
            cameras: 13,
            camera_distance: 3.0,
            specular: 0.8,
            shininess: 60.0,
            shading: Shading::default(),
            layout: DemoLayout::Slab,
        }
    }
}

/// The scene's two solids in voxel units.
struct Solids {
    box_lo: Vec3,
    box_hi: Vec3,
    sphere_center: Vec3,
    sphere_radius: f32,
    /// Checker cell size (on the slab, or on the ball).
    cell: f32,
    layout: DemoLayout,
}

/// The slab's checker colours.
const CHECKER: [[f32; 3]; 2] = [[0.92, 0.86, 0.70], [0.12, 0.30, 0.55]];

impl Solids {
    fn new(grid: f32, layout: DemoLayout) -> Self {
        match layout {
            // Fractions of the grid: a 0.7 × 0.2 × 0.7 slab with a sphere of radius 0.22 sunk
            // 0.02 into it.
            DemoLayout::Slab => Self {
                box_lo: Vec3::new(0.15, 0.10, 0.15) * grid,
                box_hi: Vec3::new(0.85, 0.30, 0.85) * grid,
                sphere_center: Vec3::new(0.5, 0.50, 0.5) * grid,
                sphere_radius: 0.22 * grid,
                cell: grid / 14.0,
                layout,
            },
            // A 0.9 × 0.06 × 0.9 floor with a ball of radius 0.12 sunk 0.01 into it, checkered
            // in cells a quarter of its radius wide.
            DemoLayout::Floor => Self {
                box_lo: Vec3::new(0.05, 0.30, 0.05) * grid,
                box_hi: Vec3::new(0.95, 0.36, 0.95) * grid,
                sphere_center: Vec3::new(0.5, 0.47, 0.5) * grid,
                sphere_radius: 0.12 * grid,
                cell: 0.03 * grid,
                layout,
            },
        }
    }

    /// Whether `p` (a surface voxel) belongs to the sphere rather than the box.
    fn on_sphere(&self, p: Vec3) -> bool {
        self.sphere_sdf(p).abs() < self.box_sdf(p).abs()
    }

    /// The albedo at surface voxel `p` and whether it is glossy: the checker is on the slab in
    /// the demo and on the ball over the floor; the other solid is uniform.
    fn material(&self, p: Vec3) -> ([f32; 3], bool) {
        let checker = || {
            let q = (p / self.cell).floor();
            CHECKER[usize::from((q.x + q.y + q.z).rem_euclid(2.0) >= 1.0)]
        };
        match (self.layout, self.on_sphere(p)) {
            (DemoLayout::Slab, true) => ([0.80, 0.12, 0.10], true),
            (DemoLayout::Slab, false) => (checker(), false),
            (DemoLayout::Floor, true) => (checker(), true),
            (DemoLayout::Floor, false) => ([0.55, 0.55, 0.52], false),
        }
    }

    fn box_sdf(&self, p: Vec3) -> f32 {
        let c = 0.5 * (self.box_lo + self.box_hi);
        let h = 0.5 * (self.box_hi - self.box_lo);
        let q = (p - c).abs() - h;
        q.max(Vec3::ZERO).length() + q.max_element().min(0.0)
    }

    fn sphere_sdf(&self, p: Vec3) -> f32 {
        (p - self.sphere_center).length() - self.sphere_radius
    }

    fn sdf(&self, p: Vec3) -> f32 {
        self.box_sdf(p).min(self.sphere_sdf(p))
    }

    fn inside(&self, p: Vec3) -> bool {
        self.sdf(p) <= 0.0
    }

    /// Outward normal: the normalised central-difference gradient of the union's distance.
    fn normal(&self, p: Vec3) -> Vec3 {
        let e = 0.5;
        let d = |v: Vec3| self.sdf(p + v) - self.sdf(p - v);
        Vec3::new(d(Vec3::X * e), d(Vec3::Y * e), d(Vec3::Z * e)).normalize_or(Vec3::Y)
    }

    /// The voxels of a `grid`³ grid whose centre lies in the union and that have a 6-neighbour
    /// outside it (a closed surface), slice by slice in parallel.
    fn surface_voxels(&self, grid: u32) -> Vec<Vec3> {
        (0..grid)
            .into_par_iter()
            .flat_map_iter(|x| {
                (0..grid).flat_map(move |y| {
                    (0..grid).filter_map(move |z| {
                        let p = Vec3::new(x as f32, y as f32, z as f32);
                        let surface = self.inside(p)
                            && [
                                Vec3::X,
                                Vec3::NEG_X,
                                Vec3::Y,
                                Vec3::NEG_Y,
                                Vec3::Z,
                                Vec3::NEG_Z,
                            ]
                            .iter()
                            .any(|&o| !self.inside(p + o));
                        surface.then_some(p)
                    })
                })
            })
            .collect()
    }

    /// Whether the segment from `from` to `to` passes through either solid (analytic slab and
    /// sphere tests).
    fn blocked(&self, from: Vec3, to: Vec3) -> bool {
        let d = to - from;
        // Sphere: |from + t·d − c|² = r² for some t in [0, 1].
        let oc = from - self.sphere_center;
        let (a, b, c) = (
            d.dot(d),
            oc.dot(d),
            oc.dot(oc) - self.sphere_radius * self.sphere_radius,
        );
        let disc = b * b - a * c;
        if disc >= 0.0 {
            let s = disc.sqrt();
            let (t0, t1) = ((-b - s) / a, (-b + s) / a);
            if t1 >= 0.0 && t0 <= 1.0 {
                return true;
            }
        }
        let inv = d.recip();
        let t0 = (self.box_lo - from) * inv;
        let t1 = (self.box_hi - from) * inv;
        let near = t0.min(t1).max_element().max(0.0);
        let far = t0.max(t1).min_element().min(1.0);
        near <= far
    }
}

/// Builds the demo scene as an 8iVSLF-layout plenoptic cloud (voxel units, frame_to_world scale 1).
///
/// Voxels whose centre lies in the union of the slab and the sphere and that have a 6-neighbour
/// outside form a closed surface; each gets the normal of the nearer solid, a checker albedo
/// (slab, matte) or a red albedo (sphere, glossy), and one Blinn–Phong colour per capture camera.
pub fn demo_scene(config: &DemoConfig) -> Result<PlenopticCloud, Error> {
    config.validate()?;
    let grid = config.grid as f32;
    let solids = Solids::new(grid, config.layout);
    let positions = solids.surface_voxels(config.grid);
    let center = match config.layout {
        DemoLayout::Slab => Vec3::new(0.5, 0.42, 0.5),
        DemoLayout::Floor => Vec3::new(0.5, 0.4, 0.5),
    } * grid;
    let radius = positions
        .iter()
        .map(|p| p.distance(center))
        .fold(0.0f32, f32::max);
    let voxel_cams: Vec<DVec3> = capture_directions(config.cameras)
        .iter()
        .map(|d| center.as_dvec3() + config.camera_distance * f64::from(radius) * *d)
        .collect();
    let cam_f32: Vec<Vec3> = voxel_cams.iter().map(|c| c.as_vec3()).collect();
    let sphere_gloss = Gloss {
        specular: config.specular,
        shininess: config.shininess,
    };
    let matte = Gloss {
        specular: 0.0,
        shininess: 1.0,
    };

    let per_point: Vec<(Vec3, [f32; 3], Vec<[f32; 3]>)> = positions
        .par_iter()
        .map(|&p| {
            let normal = solids.normal(p);
            let (albedo, glossy) = solids.material(p);
            let gloss = if glossy { sphere_gloss } else { matte };
            let main = config.shading.diffuse_color(normal, albedo);
            // Leave the point's own voxel before testing the line of sight.
            let start = p + 1.5 * normal;
            let colors = cam_f32
                .iter()
                .map(|&c| {
                    let to_cam = (c - p).normalize_or_zero();
                    let sees = normal.dot(to_cam) > 0.0 && !solids.blocked(start, c);
                    to_u8_grid(if sees {
                        config.shading.color(normal, to_cam, albedo, gloss)
                    } else {
                        main
                    })
                })
                .collect();
            (normal, to_u8_grid(main), colors)
        })
        .collect();

    let num_cameras = config.cameras;
    let mut normals = Vec::with_capacity(positions.len());
    let mut colors = Vec::with_capacity(positions.len());
    let mut camera_colors = Vec::with_capacity(positions.len() * num_cameras);
    for (n, c, cc) in per_point {
        normals.push(n);
        colors.push(c);
        camera_colors.extend(cc);
    }
    Ok(PlenopticCloud {
        positions,
        normals: Some(normals),
        colors,
        num_cameras,
        camera_colors,
        cameras: capture_cameras(&voxel_cams, center.as_dvec3(), 1.0, DVec3::ZERO),
        frame_to_world_scale: Some(1.0),
        frame_to_world_translation: Some(DVec3::ZERO),
        width: Some(config.grid - 1),
        ..Default::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small() -> PlenopticCloud {
        demo_scene(&DemoConfig {
            grid: 64,
            ..Default::default()
        })
        .unwrap()
    }

    #[test]
    fn demo_is_a_consistent_plenoptic_cloud() {
        let c = small();
        let n = c.len();
        assert!(n > 5_000 && n < 20_000, "{n} points");
        assert_eq!(c.num_cameras, 13);
        assert_eq!(c.cameras.len(), 13);
        assert_eq!(c.camera_colors.len(), 13 * n);
        assert!(
            c.positions
                .iter()
                .all(|p| p.min_element() >= 0.0 && p.max_element() <= 63.0 && *p == p.round())
        );
        let default_count = demo_scene(&DemoConfig::default()).unwrap().len();
        assert!(
            (20_000..60_000).contains(&default_count),
            "default demo has {default_count} points"
        );
    }

    #[test]
    fn highlight_moves_between_cameras_on_the_sphere_only() {
        let c = small();
        let solids = Solids::new(64.0, DemoLayout::Slab);
        let (mut sphere_varies, mut slab_varies) = (0, 0);
        for i in 0..c.len() {
            let cc = c.camera_colors_of(i);
            let spread = cc.iter().map(|v| v[1]).fold(0.0f32, f32::max)
                - cc.iter().map(|v| v[1]).fold(1.0f32, f32::min);
            let on_sphere = solids.on_sphere(c.positions[i]);
            if spread > 0.3 {
                if on_sphere {
                    sphere_varies += 1
                } else {
                    slab_varies += 1
                }
            }
        }
        assert!(
            sphere_varies > 50,
            "{sphere_varies} sphere points with a highlight in some camera"
        );
        assert_eq!(slab_varies, 0, "the matte slab must be view-independent");
        // Different cameras see their highlight at different points.
        let brightest: std::collections::HashSet<usize> = (0..13)
            .map(|k| {
                (0..c.len())
                    .max_by(|&a, &b| {
                        c.camera_colors_of(a)[k][1].total_cmp(&c.camera_colors_of(b)[k][1])
                    })
                    .unwrap()
            })
            .collect();
        assert!(
            brightest.len() >= 10,
            "highlights at {} distinct points",
            brightest.len()
        );
    }

    #[test]
    fn hidden_points_get_the_main_colour() {
        let c = small();
        let normals = c.normals.as_ref().unwrap();
        // Bottom face of the slab points down, away from every camera (all above the floor).
        let bottom: Vec<usize> = (0..c.len()).filter(|&i| normals[i].y < -0.9).collect();
        assert!(!bottom.is_empty());
        for &i in &bottom {
            assert!(c.camera_colors_of(i).iter().all(|&cc| cc == c.colors[i]));
        }
    }

    #[test]
    fn the_floor_layout_is_a_plain_floor_under_a_small_checkered_ball() {
        let c = demo_scene(&DemoConfig {
            grid: 64,
            layout: DemoLayout::Floor,
            ..Default::default()
        })
        .unwrap();
        let solids = Solids::new(64.0, DemoLayout::Floor);
        let ball: Vec<usize> = (0..c.len())
            .filter(|&i| solids.on_sphere(c.positions[i]))
            .collect();
        // Areas: the ball 4π·7.68² ≈ 740 voxels, the floor's faces 2·57.6² + sides ≈ 7,560.
        let share = ball.len() as f64 / c.len() as f64;
        assert!((0.05..0.15).contains(&share), "ball share {share}");
        // The floor is one view-independent colour wherever a camera sees it.
        let floor_colours: std::collections::HashSet<[u8; 3]> = (0..c.len())
            .filter(|i| !ball.contains(i))
            .flat_map(|i| c.camera_colors_of(i).to_vec())
            .map(|v| v.map(|x| (x * 255.0).round() as u8))
            .collect();
        let ball_colours: std::collections::HashSet<[u8; 3]> = ball
            .iter()
            .map(|&i| c.colors[i].map(|x| (x * 255.0).round() as u8))
            .collect();
        // Flat faces of one albedo shade to one colour each (top, sides, bottom, under the ball).
        assert!(
            floor_colours.len() <= 12,
            "{} floor colours",
            floor_colours.len()
        );
        // Both checker colours under smooth shading: many distinct colours on the ball.
        assert!(
            ball_colours.len() > 100,
            "{} ball colours",
            ball_colours.len()
        );
    }

    #[test]
    fn bad_config_is_refused() {
        assert!(
            demo_scene(&DemoConfig {
                grid: 4,
                ..Default::default()
            })
            .is_err()
        );
        assert!(
            demo_scene(&DemoConfig {
                cameras: 0,
                ..Default::default()
            })
            .is_err()
        );
    }
}
