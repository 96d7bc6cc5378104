//! The views at each resolution a run trains on: the full views, and the coarse warm-up's
//! reduced copies.

use std::sync::Arc;

use splat_core::RenderCamera;

use crate::error::Error;
use crate::view::View;

/// Views at one resolution with their rasteriser cameras.
#[derive(Debug)]
pub(super) struct Level {
    pub(super) views: Arc<Vec<View>>,
    pub(super) cameras: Vec<RenderCamera>,
}

impl Level {
    /// The level of `views` (checked already, so the conversion only fails on a bug).
    pub(super) fn new(views: Arc<Vec<View>>) -> Result<Self, Error> {
        let cameras = views
            .iter()
            .enumerate()
            .map(|(index, v)| {
                v.render_camera().map_err(|problem| Error::View {
                    index,
                    name: v.name.clone(),
                    problem,
                })
            })
            .collect::<Result<_, _>>()?;
        Ok(Self { views, cameras })
    }
}

/// `view` reduced by an integer `factor`: each output pixel is the mean of a factor × factor
/// block (a remainder at the right and bottom is dropped), and the intrinsics are divided by the
/// factor, which keeps pixel centres aligned (centre of block = factor · (i + ½)).
///
/// With a mask, the block's colour is its coverage-weighted mean, Σ c·a / Σ a, and its coverage
/// the mean of a: the reduced view over any background is then the mean of the full view over
/// it (Σ (c·a + bg·(1 − a)) / n), as a dataset's reduction averages colour on black with its
/// coverage. A plain mean of straight colour would let a block's uncovered pixels (black) darken
/// its silhouette. The sums are integers of the 16-bit fractions, rounded once at the end.
pub(super) fn downsample_view(view: &View, factor: u32) -> View {
    let k = view.camera.intrinsics;
    let f = factor.max(1) as usize;
    let (w, h) = (k.width as usize, k.height as usize);
    let (cw, ch) = ((w / f).max(1), (h / f).max(1));
    let div_round = |num: u64, den: u64| ((num + den / 2) / den.max(1)) as u16;
    let mut image = vec![0u16; cw * ch * 3];
    let mut mask = view.mask.as_ref().map(|_| vec![0u16; cw * ch]);
    for y in 0..ch {
        for x in 0..cw {
            // Σ c·a per channel, Σ a, pixel count (a = 65535 without a mask).
            let (mut sums, mut cover, mut n) = ([0u64; 3], 0u64, 0u64);
            for yy in y * f..((y + 1) * f).min(h) {
                for xx in x * f..((x + 1) * f).min(w) {
                    let i = yy * w + xx;
                    let a = view.mask.as_ref().map_or(u16::MAX, |m| m[i]);
                    for (c, s) in sums.iter_mut().enumerate() {
                        *s += u64::from(view.image[3 * i + c]) * u64::from(a);
                    }
                    cover += u64::from(a);
                    n += 1;
                }
            }
            let o = y * cw + x;
            for c in 0..3 {
                image[3 * o + c] = if cover == 0 {
                    0
                } else {
                    div_round(sums[c], cover)
                };
            }
            if let Some(m) = mask.as_mut() {
                m[o] = div_round(cover, n);
            }
        }
    }
    let inv = 1.0 / f as f64;
    let intrinsics = camera_model::Intrinsics {
        width: cw as u32,
        height: ch as u32,
        fx: k.fx * inv,
        fy: k.fy * inv,
        cx: k.cx * inv,
        cy: k.cy * inv,
        skew: k.skew * inv,
    };
    View {
        name: view.name.clone(),
        camera: camera_model::Camera::new(intrinsics, view.camera.pose),
        image,
        mask,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use camera_model::{Camera, Intrinsics, Pose};
    use glam::DVec3;

    #[test]
    fn downsampling_averages_blocks() {
        let k = Intrinsics::centered(5, 4, 10.0, 12.0);
        let pose = Pose::look_at(DVec3::new(0.0, 0.0, -5.0), DVec3::ZERO, DVec3::Y);
        // Values in 16-bit steps (1000 a pixel index, 10 a channel), so block means are exact.
        let image: Vec<u16> = (0..3 * 20).map(|i| 1000 * (i / 3) + 10 * (i % 3)).collect();
        let v = View {
            name: "v".into(),
            camera: Camera::new(k, pose),
            image,
            mask: None,
        };
        let d = downsample_view(&v, 2);
        assert_eq!(
            (d.camera.intrinsics.width, d.camera.intrinsics.height),
            (2, 2)
        );
        // Block (0,0) holds pixels 0, 1, 5, 6; block (1,1) pixels 12, 13, 17, 18.
        assert_eq!(&d.image[..3], &[3000, 3010, 3020]);
        assert_eq!(&d.image[9..], &[15000, 15010, 15020]);
        assert!(d.mask.is_none());
        // Block means round to the nearest step: (1 + 2 + 2 + 2) / 4 = 1.75 → 2.
        let odd = View {
            image: vec![1, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2, 2],
            mask: None,
            camera: Camera::new(Intrinsics::centered(2, 2, 10.0, 12.0), pose),
            ..v.clone()
        };
        assert_eq!(downsample_view(&odd, 2).image, vec![2, 2, 2]);
    }

    /// A reduced masked view over any background is the mean of the full view over it (against
    /// an f64 reference, to a step of rounding), a block with no coverage is black and
    /// uncovered, and its colour is coverage-weighted (a half-covered block keeps its colour).
    #[test]
    fn downsampling_a_masked_view_commutes_with_compositing() {
        let (w, h) = (12u32, 8u32);
        let pose = Pose::look_at(DVec3::new(0.0, 0.0, -5.0), DVec3::ZERO, DVec3::Y);
        let n = (w * h) as usize;
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut r = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 48) as u16
        };
        let image: Vec<u16> = (0..3 * n).map(|_| r()).collect();
        // Coverage: random, but the top-left 3×3 block uncovered and the next one half covered
        // by full-coverage pixels.
        let mut mask: Vec<u16> = (0..n).map(|_| r()).collect();
        for y in 0..3 {
            for x in 0..6 {
                mask[y * w as usize + x] = if x < 3 || (x + y) % 2 == 0 {
                    0
                } else {
                    u16::MAX
                };
            }
        }
        let v = View {
            name: "v".into(),
            camera: Camera::new(Intrinsics::centered(w, h, 10.0, 10.0), pose),
            image,
            mask: Some(mask),
        };
        let d = downsample_view(&v, 3);
        let (cw, ch) = (4usize, 2usize);
        assert_eq!(d.image.len(), 3 * cw * ch);
        for bg in [[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [0.2, 0.7, 0.4]] {
            let fine = v.on_background(bg);
            let coarse = d.on_background(bg);
            for by in 0..ch {
                for bx in 0..cw {
                    for c in 0..3 {
                        let mut mean = 0.0f64;
                        for y in 3 * by..3 * by + 3 {
                            for x in 3 * bx..3 * bx + 3 {
                                mean += f64::from(fine[3 * (y * w as usize + x) + c]) / 9.0;
                            }
                        }
                        let got = f64::from(coarse[3 * (by * cw + bx) + c]);
                        assert!(
                            (got - mean).abs() < 2.0 / 65535.0,
                            "{bg:?} {bx},{by}: {got} {mean}"
                        );
                    }
                }
            }
        }
        let mask = d.mask.as_ref().unwrap();
        assert_eq!((mask[0], &d.image[..3]), (0, &[0u16; 3][..]));
        // The half-covered block: its covered pixels' colour mean, not darkened by the others.
        let covered: Vec<usize> = (0..3)
            .flat_map(|y| (3..6).map(move |x| (x, y)))
            .filter(|&(x, y)| (x + y) % 2 == 1)
            .map(|(x, y)| y * w as usize + x)
            .collect();
        let mean = covered
            .iter()
            .map(|&i| u64::from(v.image[3 * i]))
            .sum::<u64>() as f64
            / covered.len() as f64;
        assert!(
            (f64::from(d.image[3]) - mean).abs() <= 0.5,
            "{} {mean}",
            d.image[3]
        );
    }

    #[test]
    fn downsampling_keeps_projection() {
        let k = Intrinsics::centered(5, 4, 10.0, 12.0);
        let pose = Pose::look_at(DVec3::new(0.0, 0.0, -5.0), DVec3::ZERO, DVec3::Y);
        let v = View {
            name: "v".into(),
            camera: Camera::new(k, pose),
            image: vec![0; 60],
            mask: None,
        };
        let d = downsample_view(&v, 2);
        let p = DVec3::new(0.3, -0.2, 0.4);
        let fine = v.camera.project(p).unwrap();
        let coarse = d.camera.project(p).unwrap();
        assert!((fine / 2.0 - coarse).length() < 1e-12);
    }
}
