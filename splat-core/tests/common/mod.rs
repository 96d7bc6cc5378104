//! Test support: a brute-force f64 reference renderer written independently of the crate
//! (per pixel, every splat whose 3σ tile rectangle covers the pixel's tile, sorted by depth),
//! scene generators and a small deterministic PRNG.
#![allow(dead_code)]
// The reference renderer indexes pixels and channels as its maths is written.
#![allow(clippy::needless_range_loop)]

use glam::{Mat3, Quat, Vec3};
use splat_core::{RenderCamera, Splats};

pub mod gradcheck;

/// The real 3DGS model of `testdata/splat-scene` (4,000 splats, SH degree 3, Inria's layout).
pub fn gt_path() -> std::path::PathBuf {
    std::path::PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene/gt.ply"
    ))
}

/// SplitMix64: a tiny deterministic generator so the tests need no RNG API.
pub struct Rng(u64);
impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [lo, hi).
    pub fn uniform(&mut self, lo: f32, hi: f32) -> f32 {
        let u = (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * u
    }
    pub fn normal(&mut self) -> f32 {
        let u1 = self.uniform(1e-7, 1.0);
        let u2 = self.uniform(0.0, 1.0);
        (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
    }
}

/// A camera at `eye` looking at `target` (COLMAP axes), with the given intrinsics.
pub fn look_at(eye: Vec3, target: Vec3, w: u32, h: u32, f: f32, cx: f32, cy: f32) -> RenderCamera {
    let z = (target - eye).normalize();
    let up = if z.y.abs() > 0.9 {
        Vec3::X
    } else {
        Vec3::NEG_Y
    };
    let x = up.cross(z).normalize();
    let x = -x;
    let y = z.cross(x);
    // Rows of R are the camera axes in world coordinates.
    let rot = Mat3::from_cols(x, y, z).transpose();
    RenderCamera {
        width: w,
        height: h,
        fx: f,
        fy: f * 1.05,
        cx,
        cy,
        rotation: rot,
        translation: -(rot * eye),
    }
}

/// Random splats in a ball of radius `r` around `center`, random anisotropic scales
/// exp(U[ls_lo, ls_hi]), random rotations, opacities, SH of degree `degree`.
pub fn random_splats(
    rng: &mut Rng,
    n: usize,
    center: Vec3,
    r: f32,
    ls: (f32, f32),
    op: (f32, f32),
    degree: u32,
) -> Splats {
    let mut s = Splats::new(degree);
    let k = splat_core::num_sh_coeffs(degree);
    for _ in 0..n {
        let m = center + Vec3::new(rng.uniform(-r, r), rng.uniform(-r, r), rng.uniform(-r, r));
        let l = Vec3::new(
            rng.uniform(ls.0, ls.1),
            rng.uniform(ls.0, ls.1),
            rng.uniform(ls.0, ls.1),
        );
        let q = [rng.normal(), rng.normal(), rng.normal(), rng.normal()];
        let o = splat_core::logit(rng.uniform(op.0, op.1));
        let sh: Vec<[f32; 3]> = (0..k)
            .map(|j| {
                let amp = if j == 0 { 1.2 } else { 0.25 };
                [
                    rng.uniform(-amp, amp),
                    rng.uniform(-amp, amp),
                    rng.uniform(-amp, amp),
                ]
            })
            .collect();
        s.push(m, l, q, o, &sh);
    }
    s
}

/// Splats on a surface: a sphere of radius `r` with flat discs along the normals.
pub fn surface_splats(rng: &mut Rng, n: usize, r: f32, degree: u32) -> Splats {
    let mut pts = Vec::with_capacity(n);
    let mut normals = Vec::with_capacity(n);
    let mut colors = Vec::with_capacity(n);
    let mut scales = Vec::with_capacity(n);
    let spacing = r * (4.0 * std::f32::consts::PI / n as f32).sqrt();
    let golden = std::f32::consts::PI * (3.0 - 5.0_f32.sqrt());
    for i in 0..n {
        let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
        let rr = (1.0 - y * y).sqrt();
        let t = golden * i as f32;
        let nrm = Vec3::new(rr * t.cos(), y, rr * t.sin());
        pts.push(nrm * r * (1.0 + 0.02 * rng.normal()));
        normals.push(nrm);
        colors.push([0.5 + 0.4 * nrm.x, 0.5 + 0.4 * nrm.y, rng.uniform(0.2, 0.8)]);
        scales.push(Vec3::new(spacing * 0.7, spacing * 0.7, spacing * 0.05));
    }
    let mut s = Splats::from_points(&pts, &colors, &scales, Some(&normals), 0.8, degree).unwrap();
    let k = s.coeffs_per_splat();
    for i in 0..n {
        for j in 1..k {
            s.sh[i * k + j] = [0.1 * rng.normal(), 0.1 * rng.normal(), 0.1 * rng.normal()];
        }
    }
    s
}

/// The splats in f64 for the reference.
#[derive(Clone, Debug)]
pub struct RefSplats {
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub rots: Vec<[f64; 4]>,
    pub logits: Vec<f64>,
    pub degree: u32,
    pub sh: Vec<[f64; 3]>,
}

impl RefSplats {
    pub fn from(s: &Splats) -> Self {
        Self {
            means: s.means.iter().map(|m| m.as_dvec3().to_array()).collect(),
            log_scales: s
                .log_scales
                .iter()
                .map(|m| m.as_dvec3().to_array())
                .collect(),
            rots: s.rotations.iter().map(|q| q.map(f64::from)).collect(),
            logits: s.opacity_logits.iter().map(|&o| f64::from(o)).collect(),
            degree: s.sh_degree,
            sh: s.sh.iter().map(|c| c.map(f64::from)).collect(),
        }
    }
    pub fn len(&self) -> usize {
        self.means.len()
    }
}

/// Reference output.
pub struct RefImage {
    pub rgb: Vec<f64>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
}

fn sh_basis(deg: u32, d: [f64; 3]) -> Vec<f64> {
    // Inria's sh_utils.py constants and order.
    let (x, y, z) = (d[0], d[1], d[2]);
    let c0 = 0.28209479177387814;
    let c1 = 0.4886025119029199;
    let c2 = [
        1.0925484305920792,
        -1.0925484305920792,
        0.31539156525252005,
        -1.0925484305920792,
        0.5462742152960396,
    ];
    let c3 = [
        -0.5900435899266435,
        2.890611442640554,
        -0.4570457994644658,
        0.3731763325901154,
        -0.4570457994644658,
        1.445305721320277,
        -0.5900435899266435,
    ];
    let mut b = vec![c0];
    if deg >= 1 {
        b.extend([-c1 * y, c1 * z, -c1 * x]);
    }
    if deg >= 2 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        b.extend([
            c2[0] * x * y,
            c2[1] * y * z,
            c2[2] * (2.0 * zz - xx - yy),
            c2[3] * x * z,
            c2[4] * (xx - yy),
        ]);
    }
    if deg >= 3 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        b.extend([
            c3[0] * y * (3.0 * xx - yy),
            c3[1] * x * y * z,
            c3[2] * y * (4.0 * zz - xx - yy),
            c3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
            c3[4] * x * (4.0 * zz - xx - yy),
            c3[5] * z * (xx - yy),
            c3[6] * x * (xx - 3.0 * yy),
        ]);
    }
    b
}

type M3 = [[f64; 3]; 3];
fn mm(a: &M3, b: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}
fn tr(a: &M3) -> M3 {
    let mut r = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
    }
    r
}

struct RefSplat2d {
    xy: [f64; 2],
    conic: [f64; 3],
    opacity: f64,
    color: [f64; 3],
    depth: f64,
    rect: [i64; 4],
    index: usize,
}

/// Renders with the Inria rules in f64 without tiles: per pixel, all splats whose tile
/// rectangle covers the pixel's tile, sorted by (depth, index), composited front to back.
pub fn render_ref(
    s: &RefSplats,
    cam: &RenderCamera,
    bg: [f64; 3],
    degree: u32,
    antialiased: bool,
) -> RefImage {
    let w = cam.width as usize;
    let h = cam.height as usize;
    let (fx, fy, cx, cy) = (
        f64::from(cam.fx),
        f64::from(cam.fy),
        f64::from(cam.cx),
        f64::from(cam.cy),
    );
    let rc = cam.rotation;
    let wr: M3 = std::array::from_fn(|i| std::array::from_fn(|j| f64::from(rc.col(j)[i])));
    let tw = cam.translation.as_dvec3().to_array();
    let center: [f64; 3] = std::array::from_fn(|i| -(0..3).map(|k| wr[k][i] * tw[k]).sum::<f64>());
    let deg = degree.min(s.degree);
    let kk = ((s.degree + 1) * (s.degree + 1)) as usize;
    let tiles_x = (w as i64 + 15) / 16;
    let tiles_y = (h as i64 + 15) / 16;
    let mut list = Vec::new();
    for i in 0..s.len() {
        let m = s.means[i];
        let p: [f64; 3] =
            std::array::from_fn(|r| (0..3).map(|k| wr[r][k] * m[k]).sum::<f64>() + tw[r]);
        if p[2].is_nan() || p[2] <= 0.01 {
            continue;
        }
        let o = 1.0 / (1.0 + (-s.logits[i]).exp());
        let q = s.rots[i];
        let n = (q.iter().map(|v| v * v).sum::<f64>()).sqrt();
        let (qw, qx, qy, qz) = if n > 1e-30 {
            (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
        } else {
            (1.0, 0.0, 0.0, 0.0)
        };
        let r: M3 = [
            [
                1.0 - 2.0 * (qy * qy + qz * qz),
                2.0 * (qx * qy - qw * qz),
                2.0 * (qx * qz + qw * qy),
            ],
            [
                2.0 * (qx * qy + qw * qz),
                1.0 - 2.0 * (qx * qx + qz * qz),
                2.0 * (qy * qz - qw * qx),
            ],
            [
                2.0 * (qx * qz - qw * qy),
                2.0 * (qy * qz + qw * qx),
                1.0 - 2.0 * (qx * qx + qy * qy),
            ],
        ];
        let sc = s.log_scales[i].map(f64::exp);
        let s2: M3 = [
            [sc[0] * sc[0], 0.0, 0.0],
            [0.0, sc[1] * sc[1], 0.0],
            [0.0, 0.0, sc[2] * sc[2]],
        ];
        let sigma = mm(&mm(&r, &s2), &tr(&r));
        let sc_cam = mm(&mm(&wr, &sigma), &tr(&wr));
        let tanx = 0.5 * w as f64 / fx;
        let tany = 0.5 * h as f64 / fy;
        let ux = (p[0] / p[2]).clamp(-(cx / fx + 0.3 * tanx), (w as f64 - cx) / fx + 0.3 * tanx);
        let uy = (p[1] / p[2]).clamp(-(cy / fy + 0.3 * tany), (h as f64 - cy) / fy + 0.3 * tany);
        let j = [
            [fx / p[2], 0.0, -fx * ux / p[2]],
            [0.0, fy / p[2], -fy * uy / p[2]],
        ];
        let mut c2 = [[0.0; 2]; 2];
        for a in 0..2 {
            for b in 0..2 {
                c2[a][b] = (0..3)
                    .map(|k| {
                        (0..3)
                            .map(|l| j[a][k] * sc_cam[k][l] * j[b][l])
                            .sum::<f64>()
                    })
                    .sum();
            }
        }
        // det(J·Σ_cam·Jᵀ) by Cauchy–Binet on its factor F = J·W·R·S (2×3): the sum of squares of
        // F's 2×2 minors. a·c − b² cancels even in f64 for needles 10⁴ px long (a·c ≈ 10¹⁶), which
        // made finite differences of this reference noisy.
        let wrs = mm(
            &mm(&wr, &r),
            &[[sc[0], 0.0, 0.0], [0.0, sc[1], 0.0], [0.0, 0.0, sc[2]]],
        );
        let f: [[f64; 3]; 2] = std::array::from_fn(|a| {
            std::array::from_fn(|k| (0..3).map(|l| j[a][l] * wrs[l][k]).sum())
        });
        let minor = |k: usize, l: usize| f[0][k] * f[1][l] - f[0][l] * f[1][k];
        let det0 = minor(0, 1).powi(2) + minor(0, 2).powi(2) + minor(1, 2).powi(2);
        let (a, b, c) = (c2[0][0] + 0.3, c2[0][1], c2[1][1] + 0.3);
        let det = det0 + 0.3 * (c2[0][0] + c2[1][1]) + 0.09;
        if det <= 0.0 {
            continue;
        }
        let comp = if antialiased {
            (det0.max(0.0) / det).sqrt()
        } else {
            1.0
        };
        let op = o * comp;
        if op < 1.0 / 255.0 {
            continue;
        }
        let mid = 0.5 * (a + c);
        let lam = mid + (mid * mid - det).max(0.1).sqrt();
        let radius = (3.0 * lam.sqrt()).ceil();
        let xy = [fx * p[0] / p[2] + cx - 0.5, fy * p[1] / p[2] + cy - 0.5];
        let rect = [
            ((xy[0] - radius) / 16.0).floor().clamp(0.0, tiles_x as f64) as i64,
            ((xy[0] + radius + 15.0) / 16.0)
                .floor()
                .clamp(0.0, tiles_x as f64) as i64,
            ((xy[1] - radius) / 16.0).floor().clamp(0.0, tiles_y as f64) as i64,
            ((xy[1] + radius + 15.0) / 16.0)
                .floor()
                .clamp(0.0, tiles_y as f64) as i64,
        ];
        if rect[0] >= rect[1] || rect[2] >= rect[3] {
            continue;
        }
        let d = [m[0] - center[0], m[1] - center[1], m[2] - center[2]];
        let dl = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let basis = sh_basis(deg, [d[0] / dl, d[1] / dl, d[2] / dl]);
        let mut color = [0.0; 3];
        for (k, bk) in basis.iter().enumerate() {
            for ch in 0..3 {
                color[ch] += bk * s.sh[i * kk + k][ch];
            }
        }
        let color = color.map(|v| (v + 0.5).max(0.0));
        list.push(RefSplat2d {
            xy,
            conic: [c / det, -b / det, a / det],
            opacity: op,
            color,
            depth: p[2],
            rect,
            index: i,
        });
    }
    list.sort_by(|a, b| a.depth.total_cmp(&b.depth).then(a.index.cmp(&b.index)));
    let mut out = RefImage {
        rgb: vec![0.0; 3 * w * h],
        alpha: vec![0.0; w * h],
        depth: vec![0.0; w * h],
    };
    for py in 0..h {
        for px in 0..w {
            let (tx, ty) = ((px / 16) as i64, (py / 16) as i64);
            let mut t = 1.0;
            let mut col = [0.0; 3];
            let mut dsum = 0.0;
            for g in &list {
                if tx < g.rect[0] || tx >= g.rect[1] || ty < g.rect[2] || ty >= g.rect[3] {
                    continue;
                }
                let dx = g.xy[0] - px as f64;
                let dy = g.xy[1] - py as f64;
                let power =
                    -0.5 * (g.conic[0] * dx * dx + g.conic[2] * dy * dy) - g.conic[1] * dx * dy;
                if power > 0.0 {
                    continue;
                }
                let alpha = (g.opacity * power.exp()).min(0.99);
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                let nt = t * (1.0 - alpha);
                if nt < 1e-4 {
                    break;
                }
                for ch in 0..3 {
                    col[ch] += g.color[ch] * alpha * t;
                }
                dsum += g.depth * alpha * t;
                t = nt;
            }
            let p = py * w + px;
            for ch in 0..3 {
                out.rgb[3 * p + ch] = col[ch] + t * bg[ch];
            }
            out.alpha[p] = 1.0 - t;
            out.depth[p] = if 1.0 - t > 1e-6 {
                dsum / (1.0 - t)
            } else {
                0.0
            };
        }
    }
    out
}

/// A camera whose rotation is a unit quaternion (to build test cameras from COLMAP text).
pub fn camera_from_colmap(
    q_wxyz: [f64; 4],
    t: [f64; 3],
    w: u32,
    h: u32,
    k: [f64; 4],
) -> RenderCamera {
    let q = Quat::from_xyzw(
        q_wxyz[1] as f32,
        q_wxyz[2] as f32,
        q_wxyz[3] as f32,
        q_wxyz[0] as f32,
    )
    .normalize();
    RenderCamera {
        width: w,
        height: h,
        fx: k[0] as f32,
        fy: k[1] as f32,
        cx: k[2] as f32,
        cy: k[3] as f32,
        rotation: Mat3::from_quat(q),
        translation: Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32),
    }
}

/// PSNR in dB of an f32 image against the f64 reference (peak 1).
pub fn psnr(image: &[f32], reference: &[f64]) -> f64 {
    assert_eq!(image.len(), reference.len());
    let mse = image
        .iter()
        .zip(reference)
        .map(|(a, b)| (f64::from(*a) - b).powi(2))
        .sum::<f64>()
        / image.len() as f64;
    -10.0 * mse.log10()
}
