//! Synthetic sequences: a real mesh moved and bent over time, each frame synthesised like
//! [`crate::synth_from_mesh`] but on one voxel grid and one capture rig for the whole sequence,
//! as in 8iVSLF, so that tests and benchmarks of sequences see real motion.

use glam::{DMat3, DVec3, Vec3};
use plenoptic_io::{Mesh, PlenopticCloud};

use crate::synth::{CaptureVolume, grid_for, synth_in_volume};
use crate::{Error, SynthConfig};

/// How the mesh moves over a sequence, as a function of time t ∈ [0, 1] (first to last frame),
/// about the rest mesh's bounding-box centre c and radius r (half its diagonal), y up.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Motion {
    /// Turn about the vertical axis through c at t = 1, in degrees (linear in t).
    pub turn_deg: f64,
    /// Shift along x at t = 1, in radii (linear in t).
    pub shift: f64,
    /// Amplitude of the bend, in radii: a point at height h = (y − c.y)/r moves along x by
    /// bend · r · h² · sin(2πt) before the turn, so top and bottom sway back and forth.
    pub bend: f64,
}

impl Default for Motion {
    fn default() -> Self {
        Self {
            turn_deg: 30.0,
            shift: 0.25,
            bend: 0.15,
        }
    }
}

impl Motion {
    /// Each value finite, the shift and bend at most [`Self::MAX_RADII`] radii (the frames share
    /// one grid that holds them all: a bend of 10³⁰ radii left each frame a speck of 1–28
    /// points).
    fn validate(&self) -> Result<(), Error> {
        for (name, value, bound) in [
            ("turn_deg", self.turn_deg, f64::INFINITY),
            ("shift", self.shift, Self::MAX_RADII),
            ("bend", self.bend, Self::MAX_RADII),
        ] {
            if !(value.is_finite() && value.abs() <= bound) {
                return Err(Error::InvalidConfig(format!(
                    "motion `{name}` must be finite{}, got {value:?}",
                    if bound.is_finite() {
                        format!(" and at most {bound} radii either way")
                    } else {
                        String::new()
                    }
                )));
            }
        }
        Ok(())
    }

    /// The largest shift or bend, in radii of the rest mesh.
    pub const MAX_RADII: f64 = 10.0;

    /// Where the rest-mesh point `p` is at time `t`, and the transformed normal `n` (unit), for
    /// a rest mesh of centre `c` and radius `r`.
    ///
    /// The normal goes through the inverse transpose of the map's Jacobian: the bend
    /// x ↦ x + a(y) has Jacobian J = I + e_x ⊗ ∇a, so J⁻ᵀ n = (n_x, n_y − a′(y)·n_x, n_z);
    /// the turn is a rotation and the shift a translation.
    #[must_use]
    pub fn apply(&self, p: Vec3, n: Vec3, c: Vec3, r: f32, t: f64) -> (Vec3, Vec3) {
        let (c, r) = (c.as_dvec3(), f64::from(r));
        let rel = p.as_dvec3() - c;
        let h = rel.y / r;
        let sway = (std::f64::consts::TAU * t).sin();
        let bent = rel + DVec3::X * (self.bend * r * h * h * sway);
        // d/dy of bend · r · (y/r)² · sway.
        let slope = 2.0 * self.bend * h * sway;
        let turn = DMat3::from_rotation_y(self.turn_deg.to_radians() * t);
        let moved = c + turn * bent + DVec3::X * (self.shift * r * t);
        let n = n.as_dvec3();
        let normal = turn * DVec3::new(n.x, n.y - slope * n.x, n.z);
        (moved.as_vec3(), normal.normalize_or(DVec3::Y).as_vec3())
    }
}

/// A sequence of plenoptic frames from one mesh: `frames` frames of [`Motion`] on one voxel grid
/// and capture rig (the bounding box of every frame), synthesised one at a time.
#[derive(Debug)]
pub struct SequenceSynth<'a> {
    mesh: &'a Mesh,
    config: SynthConfig,
    motion: Motion,
    frames: usize,
    centre: Vec3,
    radius: f32,
    volume: CaptureVolume,
}

impl<'a> SequenceSynth<'a> {
    /// Plans `frames` frames of `mesh` moving by `motion`. With [`crate::AUTO_GRID`], the grid
    /// width is chosen once, from the rest mesh's area, and kept for every frame.
    ///
    /// # Errors
    /// [`Error::InvalidConfig`] for no frames or a non-finite motion, and what
    /// [`crate::synth_from_mesh`] refuses.
    pub fn new(
        mesh: &'a Mesh,
        config: &SynthConfig,
        motion: Motion,
        frames: usize,
    ) -> Result<Self, Error> {
        if !(1..=100_000).contains(&frames) {
            return Err(Error::InvalidConfig(format!(
                "frames must be in 1..=100000, got {frames}"
            )));
        }
        motion.validate()?;
        plenoptic_render::check_mesh(mesh)?;
        let rest = CaptureVolume::of_points(mesh.positions.iter().copied())?;
        let (centre, radius) = (rest.center, rest.radius);
        let mut plan = Self {
            mesh,
            config: config.clone(),
            motion,
            frames,
            centre,
            radius,
            volume: rest,
        };
        plan.volume = CaptureVolume::of_points((0..frames).flat_map(|k| {
            let t = plan.time(k);
            mesh.positions
                .iter()
                .map(move |&p| motion.apply(p, Vec3::Y, centre, radius, t).0)
        }))?;
        plan.config.grid = grid_for(mesh, config, &plan.volume);
        Ok(plan)
    }

    /// Number of frames.
    #[must_use]
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The grid width every frame uses.
    #[must_use]
    pub fn grid(&self) -> u32 {
        self.config.grid
    }

    /// The volume (grid and rig) every frame shares.
    #[must_use]
    pub fn volume(&self) -> CaptureVolume {
        self.volume
    }

    /// Time of frame `k`: 0 for the first, 1 for the last.
    #[must_use]
    pub fn time(&self, k: usize) -> f64 {
        if self.frames > 1 {
            k as f64 / (self.frames - 1) as f64
        } else {
            0.0
        }
    }

    /// The mesh as it is in frame `k`.
    #[must_use]
    pub fn mesh_at(&self, k: usize) -> Mesh {
        let t = self.time(k);
        let m = self.mesh;
        let normals = m.normals.as_ref();
        let (positions, moved_normals): (Vec<Vec3>, Vec<Vec3>) = m
            .positions
            .iter()
            .enumerate()
            .map(|(i, &p)| {
                let n = normals.map_or(Vec3::Y, |n| n[i]);
                self.motion.apply(p, n, self.centre, self.radius, t)
            })
            .unzip();
        Mesh {
            positions,
            normals: normals.map(|_| moved_normals),
            ..m.clone()
        }
    }

    /// Synthesises frame `k` (0-based).
    ///
    /// # Errors
    /// What [`crate::synth_from_mesh`] returns.
    pub fn frame(&self, k: usize) -> Result<PlenopticCloud, Error> {
        synth_in_volume(&self.mesh_at(k), &self.config, &self.volume)
    }
}

/// The 8iVSLF-style file name of frame `k` (0-based) of a sequence called `name` on a grid of
/// width `grid`: `NAME_voxB_NNNN.ply`, B the bits of a voxel coordinate, frames counted from 1,
/// so that names sort in frame order.
#[must_use]
pub fn frame_file_name(name: &str, grid: u32, k: usize) -> String {
    let bits = u32::BITS - (grid.max(2) - 1).leading_zeros();
    format!("{name}_vox{bits}_{:04}.ply", k + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tilted strip of triangles across z whose normal leans along x, so the bend (along x)
    /// turns it.
    fn strip() -> Mesh {
        let mut positions = Vec::new();
        for i in 0..=10 {
            let y = -1.0 + 0.2 * i as f32;
            positions.push(Vec3::new(0.3 * y, y, -0.5));
            positions.push(Vec3::new(0.3 * y, y, 0.5));
        }
        let triangles = (0..10)
            .flat_map(|i| {
                let a = 2 * i;
                [[a, a + 1, a + 3], [a, a + 3, a + 2]]
            })
            .collect();
        Mesh {
            positions,
            triangles,
            ..Default::default()
        }
    }

    #[test]
    fn motion_is_the_identity_at_time_zero_and_rigid_without_bend() {
        let m = Motion::default();
        let (c, r) = (Vec3::new(1.0, 2.0, 3.0), 2.0);
        let p = Vec3::new(1.5, 3.0, 2.0);
        let n = Vec3::new(0.0, 0.6, 0.8);
        let (q, nq) = m.apply(p, n, c, r, 0.0);
        assert!((q - p).length() < 1e-6 && (nq - n).length() < 1e-6);
        // Turn 90° about y and shift by one radius: closed form.
        let rigid = Motion {
            turn_deg: 90.0,
            shift: 1.0,
            bend: 0.0,
        };
        let (q, nq) = rigid.apply(p, n, c, r, 1.0);
        let rel = p - c; // (0.5, 1, −1); R_y(90°)(x, y, z) = (z, y, −x)
        let expected = c + Vec3::new(rel.z, rel.y, -rel.x) + Vec3::new(r, 0.0, 0.0);
        assert!((q - expected).length() < 1e-5, "{q} {expected}");
        assert!((nq - Vec3::new(n.z, n.y, -n.x)).length() < 1e-6);
    }

    #[test]
    fn moved_normals_are_the_moved_surface_normals() {
        // Independent truth: the face normal of the moved triangle, against the moved vertex
        // normals (exact per-vertex normals of the flat rest strip).
        let rest = strip();
        let normal = (rest.positions[1] - rest.positions[0])
            .cross(rest.positions[2] - rest.positions[0])
            .normalize();
        let rest = Mesh {
            normals: Some(vec![normal; rest.positions.len()]),
            ..rest
        };
        let motion = Motion {
            turn_deg: 40.0,
            shift: 0.3,
            bend: 0.4,
        };
        let plan = SequenceSynth::new(&rest, &SynthConfig::default(), motion, 5).unwrap();
        let moved = plan.mesh_at(1); // t = 1/4: the bend at its largest
        let normals = moved.normals.as_ref().unwrap();
        for t in &moved.triangles {
            let [a, b, c] = t.map(|v| moved.positions[v as usize]);
            let face = (b - a).cross(c - a).normalize();
            let vertex = normals[t[0] as usize];
            // The triangles are small against the bend's curvature: a face normal differs from
            // its vertices' by at most the bend's turn across one triangle.
            assert!(face.dot(vertex) > 0.995, "{face} {vertex}");
        }
        // Without the normal transform (rotation only), the bent strip's normals are off.
        let off = moved
            .triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| moved.positions[v as usize]);
                let face = (b - a).cross(c - a).normalize();
                let rotated = DMat3::from_rotation_y(40f64.to_radians() * 0.25) * normal.as_dvec3();
                face.dot(rotated.as_vec3())
            })
            .fold(1.0_f32, f32::min);
        assert!(off < 0.99, "{off}");
    }

    #[test]
    fn frames_share_grid_and_rig_and_follow_the_motion() {
        let mesh = strip();
        let config = SynthConfig {
            points: 20_000,
            grid: 64,
            cameras: 5,
            visibility_resolution: 64,
            ..SynthConfig::default()
        };
        let motion = Motion {
            turn_deg: 60.0,
            shift: 0.5,
            bend: 0.0,
        };
        let plan = SequenceSynth::new(&mesh, &config, motion, 3).unwrap();
        let frames: Vec<PlenopticCloud> = (0..3).map(|k| plan.frame(k).unwrap()).collect();
        for f in &frames[1..] {
            assert_eq!(f.cameras, frames[0].cameras);
            assert_eq!(f.frame_to_world_scale, frames[0].frame_to_world_scale);
            assert_eq!(
                f.frame_to_world_translation,
                frames[0].frame_to_world_translation
            );
            assert_eq!(f.width, Some(63));
        }
        // Rigid motion keeps areas, so the same seed samples the same surface points: each
        // frame's centroid (in mesh units) is frame 0's moved by the motion, to a voxel.
        let world = |f: &PlenopticCloud| -> Vec3 {
            let s = f.frame_to_world_scale.unwrap() as f32;
            let t = f.frame_to_world_translation.unwrap().as_vec3();
            f.positions.iter().map(|p| *p * s + t).sum::<Vec3>() / f.len() as f32
        };
        let voxel = plan.volume().extent / 63.0;
        let rest = CaptureVolume::of_points(mesh.positions.iter().copied()).unwrap();
        let c0 = world(&frames[0]);
        for (k, f) in frames.iter().enumerate() {
            let (expected, _) = motion.apply(c0, Vec3::Y, rest.center, rest.radius, plan.time(k));
            let got = world(f);
            assert!(
                (got - expected).length() < voxel,
                "frame {k}: {got} {expected}"
            );
        }
        assert!((world(&frames[2]) - c0).length() > 10.0 * voxel, "it moves");
    }

    #[test]
    fn names_sort_in_frame_order_and_bad_plans_are_refused() {
        assert_eq!(frame_file_name("spider", 1024, 0), "spider_vox10_0001.ply");
        assert_eq!(frame_file_name("spider", 1025, 9), "spider_vox11_0010.ply");
        let mut names: Vec<String> = (0..12).map(|k| frame_file_name("s", 600, k)).collect();
        let sorted = names.clone();
        names.sort();
        assert_eq!(names, sorted);
        let mesh = strip();
        let config = SynthConfig::default();
        let e = SequenceSynth::new(&mesh, &config, Motion::default(), 0).unwrap_err();
        assert!(e.to_string().contains("frames"), "{e}");
        let bad = Motion {
            bend: f64::NAN,
            ..Motion::default()
        };
        let e = SequenceSynth::new(&mesh, &config, bad, 3).unwrap_err();
        assert!(
            e.to_string().contains("motion `bend` must be finite"),
            "{e}"
        );
        let far = Motion {
            shift: 1e30,
            ..Motion::default()
        };
        let e = SequenceSynth::new(&mesh, &config, far, 3).unwrap_err();
        assert!(
            e.to_string()
                .contains("at most 10 radii either way, got 1e30"),
            "{e}"
        );
    }
}
