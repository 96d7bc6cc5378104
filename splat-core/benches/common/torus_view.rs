//! The rasteriser bench's scene and camera (the torus of `torus.rs` with small view-dependent SH
//! terms, framed from above its plane), shared by the criterion bench and the `phases` example so
//! the two time the same work.

use glam::{Mat3, Vec3};
use splat_core::{RenderCamera, Splats};

use super::torus;

/// The shared torus scene with small view-dependent SH terms added.
pub fn torus_scene(n: usize) -> Splats {
    let mut s = torus::torus_scene(n);
    for (j, c) in s.sh.iter_mut().enumerate() {
        if j % 16 != 0 {
            let t = j as f32 * 0.618;
            *c = [0.05 * t.sin(), 0.05 * t.cos(), 0.03 * (2.0 * t).sin()];
        }
    }
    s
}

/// A camera 3.2 units from the origin looking at it from above the torus plane, 50° field of
/// view, `size`² pixels.
pub fn camera(size: u32) -> RenderCamera {
    let eye = Vec3::new(0.0, -2.2, 2.3);
    let z = (-eye).normalize();
    let x = Vec3::Z.cross(z).normalize();
    let y = z.cross(x);
    let rotation = Mat3::from_cols(x, y, z).transpose();
    let f = 0.5 * size as f32 / (25.0_f32.to_radians()).tan();
    RenderCamera {
        width: size,
        height: size,
        fx: f,
        fy: f,
        cx: 0.5 * size as f32,
        cy: 0.5 * size as f32,
        rotation,
        translation: -(rotation * eye),
    }
}
