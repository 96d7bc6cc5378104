//! Draws the figure of `docs/cameras.md`: the world axes, a PccAppRenderer (OpenGL) viewport's
//! axes and the same camera's COLMAP axes. The axes are computed with this crate
//! ([`GlViewport::view_matrix`], [`GlViewport::to_colmap`]) and drawn through one of its own
//! pinhole cameras (SVG y points down, like COLMAP pixel rows).
//!
//! Run: `cargo run -p camera-model --example axes_figure -- docs/cameras-axes.svg`
#![allow(clippy::print_stdout)] // examples print their results

use std::fmt::Write as _;

use camera_model::{Camera, GlViewport, Intrinsics, Pose};
use glam::{DVec2, DVec3};

const PANEL_W: f64 = 330.0;
const W: u32 = 990;
const H: u32 = 430;
const RED: &str = "#d62728";
const GREEN: &str = "#2ca02c";
const BLUE: &str = "#1f77b4";
const GREY: &str = "#555555";
/// Where the figure is seen from (the same for every panel), and its zoom.
const DRAW_EYE: DVec3 = DVec3::new(11.0, 5.0, 5.0);
const DRAW_TARGET: DVec3 = DVec3::new(-0.6, -0.1, -0.7);
const DRAW_FOCAL: f64 = 1250.0;
const PANEL_CY: f64 = 205.0;

/// One panel of the figure, drawn through a pinhole camera centred on the panel.
struct Panel<'a> {
    out: &'a mut String,
    view: Camera,
}

impl Panel<'_> {
    fn new<'a>(out: &'a mut String, index: usize, title: &str, subtitle: &str) -> Panel<'a> {
        let cx = PANEL_W * (index as f64 + 0.5);
        let k = Intrinsics {
            cx,
            cy: PANEL_CY,
            ..Intrinsics::centered(W, H, DRAW_FOCAL, DRAW_FOCAL)
        };
        let view = Camera::new(k, Pose::look_at(DRAW_EYE, DRAW_TARGET, DVec3::Y));
        let _ = writeln!(
            out,
            r##"<text x="{cx}" y="30" font-size="17" font-weight="bold" font-family="sans-serif" text-anchor="middle" fill="#222">{title}</text>
<text x="{cx}" y="52" font-size="13" font-family="sans-serif" text-anchor="middle" fill="{GREY}">{subtitle}</text>"##
        );
        Panel { out, view }
    }

    fn px(&self, p: DVec3) -> DVec2 {
        // Everything drawn lies in front of the drawing camera by construction.
        self.view.project(p).unwrap_or(DVec2::ZERO)
    }

    fn arrow(
        &mut self,
        from: DVec3,
        to: DVec3,
        colour: &str,
        dashed: bool,
        label: &str,
        nudge: DVec2,
    ) {
        let (a, b) = (self.px(from), self.px(to));
        let dash = if dashed {
            r##" stroke-dasharray="7 4""##
        } else {
            ""
        };
        let _ = writeln!(
            self.out,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{colour}" stroke-width="2.5"{dash} marker-end="url(#head-{})"/>"##,
            a.x,
            a.y,
            b.x,
            b.y,
            &colour[1..]
        );
        self.text(
            b + (b - a).normalize_or_zero() * 16.0 + nudge,
            label,
            colour,
            14,
        );
    }

    fn line(&mut self, from: DVec3, to: DVec3, colour: &str) {
        let (a, b) = (self.px(from), self.px(to));
        let _ = writeln!(
            self.out,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{colour}" stroke-width="1.2"/>"##,
            a.x, a.y, b.x, b.y
        );
    }

    fn text(&mut self, at: DVec2, text: &str, colour: &str, size: u32) {
        let _ = writeln!(
            self.out,
            r##"<text x="{:.1}" y="{:.1}" fill="{colour}" font-size="{size}" font-family="sans-serif" text-anchor="middle" dominant-baseline="middle">{text}</text>"##,
            at.x, at.y
        );
    }

    /// The viewing frustum out to `depth`, with the image's top-left corner and principal point.
    fn frustum(&mut self, cam: &Camera, depth: f64, annotate: bool) {
        let k = cam.intrinsics;
        let at = |u: f64, v: f64| {
            let ray = cam.ray(DVec2::new(u, v));
            ray.at(depth / ray.direction.dot(cam.pose.forward()))
        };
        let (w, h) = (f64::from(k.width), f64::from(k.height));
        let corners = [at(0.0, 0.0), at(w, 0.0), at(w, h), at(0.0, h)];
        for i in 0..4 {
            self.line(corners[i], corners[(i + 1) % 4], GREY);
            self.line(cam.center(), corners[i], "#c8c8c8");
        }
        if annotate {
            let tl = self.px(corners[0]);
            self.text(tl + DVec2::new(0.0, -12.0), "pixel (0, 0) corner", GREY, 12);
            let pp = self.px(at(k.cx, k.cy));
            let _ = writeln!(
                self.out,
                r##"<circle cx="{:.1}" cy="{:.1}" r="3" fill="{GREY}"/>"##,
                pp.x, pp.y
            );
            self.text(
                pp + DVec2::new(0.0, 14.0),
                "(cx, cy) = (W/2, H/2)",
                GREY,
                12,
            );
        }
    }
}

fn main() -> std::io::Result<()> {
    let out_path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "docs/cameras-axes.svg".into());
    let mut body = String::new();
    let o = DVec3::ZERO;
    let len = 1.3;

    // Panel 1: the world (input) frame, +y up as in 8iVSLF and PccAppRenderer.
    let mut p = Panel::new(&mut body, 0, "world (input) frame", "voxel units, +Y up");
    p.arrow(o, DVec3::X * 0.9, RED, false, "X", DVec2::ZERO);
    p.arrow(o, DVec3::Y * 0.9, GREEN, false, "Y (up)", DVec2::ZERO);
    p.arrow(o, DVec3::Z * 0.9, BLUE, false, "Z", DVec2::ZERO);

    // The same viewer in panels 2 and 3: glm::lookAt(eye, center, up = +Y).
    let vp = GlViewport {
        fov_y_deg: 40.0, // wider than PccAppRenderer's 20° so the frustum reads at this size
        ..GlViewport::new(o, DVec3::new(-0.95, -0.2, 0.3) * 3.0, DVec3::Y, 800, 600)
    };
    let colmap = vp.to_colmap();
    let gl = vp.view_matrix();
    // Rows of the view rotation are the OpenGL eye axes in world coordinates.
    let gl_axis = |i: usize| DVec3::new(gl.x_axis[i], gl.y_axis[i], gl.z_axis[i]);

    let mut p = Panel::new(
        &mut body,
        1,
        "PccAppRenderer / OpenGL viewport",
        "x right, y up, looks down −z",
    );
    p.frustum(&colmap, 1.6, false);
    p.arrow(o, gl_axis(0) * len, RED, true, "x_gl", DVec2::ZERO);
    p.arrow(o, gl_axis(1) * len, GREEN, true, "y_gl (up)", DVec2::ZERO);
    p.arrow(
        o,
        gl_axis(2) * len,
        BLUE,
        true,
        "z_gl (backward)",
        DVec2::new(0.0, 6.0),
    );
    p.text(p.px(o) + DVec2::new(-8.0, 18.0), "eye", GREY, 13);

    let mut p = Panel::new(
        &mut body,
        2,
        "COLMAP / OpenCV camera",
        "x right, y down, z forward",
    );
    p.frustum(&colmap, 1.6, true);
    p.arrow(
        o,
        colmap.pose.right() * len,
        RED,
        false,
        "x (right)",
        DVec2::ZERO,
    );
    p.arrow(
        o,
        colmap.pose.down() * len,
        GREEN,
        false,
        "y (down)",
        DVec2::ZERO,
    );
    p.arrow(
        o,
        colmap.pose.forward() * len,
        BLUE,
        false,
        "z (forward)",
        DVec2::new(-6.0, -16.0),
    );
    p.text(p.px(o) + DVec2::new(22.0, 4.0), "centre", GREY, 13);

    let heads: String = [RED, GREEN, BLUE]
        .iter()
        .map(|c| {
            format!(
                r##"<marker id="head-{}" viewBox="0 0 10 10" refX="8" refY="5" markerWidth="6" markerHeight="6" orient="auto-start-reverse"><path d="M 0 0 L 10 5 L 0 10 z" fill="{c}"/></marker>"##,
                &c[1..]
            )
        })
        .collect();
    let doc = format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}">
<defs>{heads}</defs>
<rect width="100%" height="100%" fill="white"/>
{body}<text x="{x}" y="395" font-size="14" font-family="sans-serif" text-anchor="middle" fill="#222">R_colmap = diag(1, −1, −1)·R_gl,   t_colmap = diag(1, −1, −1)·t_gl,   centre = −Rᵀt,   fx = fy = H / (2·tan(fov_y / 2))</text>
<text x="{x}" y="417" font-size="13" font-family="sans-serif" text-anchor="middle" fill="{GREY}">pose = world→camera; pixel (0, 0)'s centre is at (0.5, 0.5); same viewer in the middle and right panels</text>
</svg>
"##,
        x = f64::from(W) / 2.0
    );
    std::fs::write(&out_path, doc)?;
    println!("wrote {out_path}");
    Ok(())
}
