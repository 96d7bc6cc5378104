//! From primitives to pixels, shared by the cloud and mesh renderers: shading a resolved z-buffer
//! into a [`ViewImage`], and supersampling with a box or Gaussian pixel filter.

use camera_model::Camera;
use rayon::prelude::*;

use crate::camera::{ViewCamera, scaled_camera};
use crate::zbuffer::ZBuffer;
use crate::{Error, PIXEL_FILTER_VARIANCE, PixelFilter, ViewImage, ViewOptions};

/// Renders at `opts.supersample`× and filters down with `opts.pixel_filter`: colour (composited
/// on the background) and alpha alike; depth is the mean over the pixel's own covered
/// sub-pixels.
pub(crate) fn render_supersampled<F>(
    camera: &Camera,
    opts: &ViewOptions,
    render: F,
) -> Result<ViewImage, Error>
where
    F: Fn(&Camera) -> Result<ViewImage, Error>,
{
    opts.validate()?;
    let k = opts.supersample;
    if k == 1 {
        return render(camera);
    }
    let big = render(&scaled_camera(camera, k))?;
    let mut out = downsample(&big, k);
    if opts.pixel_filter == PixelFilter::Gaussian {
        let taps = gaussian_taps(k);
        out.rgb = filter_separable(&big.rgb, big.width, big.height, 3, k, &taps);
        out.alpha = filter_separable(&big.alpha, big.width, big.height, 1, k, &taps);
    }
    Ok(out)
}

/// Weights of the Gaussian pixel filter along one axis, for the sub-pixels of a k×-supersampled
/// row relative to the first sub-pixel of an output pixel: `(offset, weight)` with `offset` in
/// sub-pixels (negative before the pixel), normalised to sum to 1, truncated at 3σ.
fn gaussian_taps(k: u32) -> Vec<(i64, f32)> {
    let sigma = PIXEL_FILTER_VARIANCE.sqrt();
    let k = i64::from(k);
    let reach = (3.0 * sigma * k as f32).ceil() as i64;
    let mut taps: Vec<(i64, f32)> = (-reach..k + reach)
        .filter_map(|j| {
            // Distance in output pixels from the sub-pixel's centre to the pixel's centre.
            let d = (j as f32 + 0.5) / k as f32 - 0.5;
            (d.abs() <= 3.0 * sigma).then(|| (j, (-d * d / (2.0 * PIXEL_FILTER_VARIANCE)).exp()))
        })
        .collect();
    let sum: f32 = taps.iter().map(|t| t.1).sum();
    for t in &mut taps {
        t.1 /= sum;
    }
    taps
}

/// Separable filtering of a `width`×`height` image of `channels` interleaved channels from k×
/// sub-pixels to pixels with 1-D `taps`; at the image's border the taps that fall outside are
/// dropped and the rest renormalised, so a constant image stays constant.
fn filter_separable(
    big: &[f32],
    width: u32,
    height: u32,
    channels: usize,
    k: u32,
    taps: &[(i64, f32)],
) -> Vec<f32> {
    let (bw, bh) = (width as usize, height as usize);
    let (w, h) = (bw / k as usize, bh / k as usize);
    let k = i64::from(k);
    // Rows first: bh rows of w output pixels.
    let mut rows = vec![0.0f32; bh * w * channels];
    rows.par_chunks_mut(w * channels)
        .enumerate()
        .for_each(|(y, out)| {
            let src = &big[y * bw * channels..(y + 1) * bw * channels];
            for x in 0..w {
                let mut acc = [0.0f32; 3];
                let mut norm = 0.0f32;
                for &(off, wt) in taps {
                    let sx = x as i64 * k + off;
                    if sx < 0 || sx >= bw as i64 {
                        continue;
                    }
                    norm += wt;
                    for (c, a) in acc.iter_mut().enumerate().take(channels) {
                        *a += wt * src[sx as usize * channels + c];
                    }
                }
                for c in 0..channels {
                    out[x * channels + c] = acc[c] / norm;
                }
            }
        });
    // Then columns: h rows of w output pixels from the row-filtered sub-rows.
    let mut out = vec![0.0f32; h * w * channels];
    out.par_chunks_mut(w * channels)
        .enumerate()
        .for_each(|(y, out_row)| {
            let mut norm = 0.0f32;
            for &(off, wt) in taps {
                let sy = y as i64 * k + off;
                if sy < 0 || sy >= bh as i64 {
                    continue;
                }
                norm += wt;
                let src = &rows[sy as usize * w * channels..(sy as usize + 1) * w * channels];
                for (o, v) in out_row.iter_mut().zip(src) {
                    *o += wt * v;
                }
            }
            for o in out_row.iter_mut() {
                *o /= norm;
            }
        });
    out
}

/// Box filter of a k×-supersampled image.
fn downsample(big: &ViewImage, k: u32) -> ViewImage {
    let (w, h) = (big.width / k, big.height / k);
    let n = (k * k) as f32;
    let mut rgb = vec![0.0f32; 3 * w as usize * h as usize];
    let mut alpha = vec![0.0f32; w as usize * h as usize];
    let mut depth = vec![0.0f32; w as usize * h as usize];
    rgb.par_chunks_mut(3 * w as usize)
        .zip(alpha.par_chunks_mut(w as usize))
        .zip(depth.par_chunks_mut(w as usize))
        .enumerate()
        .for_each(|(y, ((rgb_row, alpha_row), depth_row))| {
            for x in 0..w as usize {
                let mut c = [0.0f32; 3];
                let (mut a, mut d, mut covered) = (0.0f32, 0.0f32, 0u32);
                for sy in 0..k as usize {
                    for sx in 0..k as usize {
                        let j = (y * k as usize + sy) * big.width as usize + x * k as usize + sx;
                        for (sum, v) in c.iter_mut().zip(&big.rgb[3 * j..3 * j + 3]) {
                            *sum += v;
                        }
                        a += big.alpha[j];
                        if big.depth[j] > 0.0 {
                            d += big.depth[j];
                            covered += 1;
                        }
                    }
                }
                for (out, sum) in rgb_row[3 * x..3 * x + 3].iter_mut().zip(c) {
                    *out = sum / n;
                }
                alpha_row[x] = a / n;
                depth_row[x] = if covered > 0 { d / covered as f32 } else { 0.0 };
            }
        });
    ViewImage {
        width: w,
        height: h,
        rgb,
        alpha,
        depth,
    }
}

/// Fills colour, alpha and depth from a resolved z-buffer with `shade(id, x, y)` giving the
/// colour of primitive `id` at pixel (x, y).
pub(crate) fn shade_pixels<F>(
    view: &ViewCamera,
    zbuf: &ZBuffer,
    background: [f32; 3],
    shade: F,
) -> ViewImage
where
    F: Fn(u32, u32, u32) -> [f32; 3] + Sync,
{
    let w = view.width as usize;
    let n = view.pixels();
    let mut rgb = vec![0.0f32; 3 * n];
    let mut alpha = vec![0.0f32; n];
    let mut depth = vec![0.0f32; n];
    rgb.par_chunks_mut(3 * w)
        .zip(alpha.par_chunks_mut(w))
        .zip(depth.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, ((rgb_row, alpha_row), depth_row))| {
            for x in 0..w {
                let c = match zbuf.get(y * w + x) {
                    Some((z, id)) => {
                        alpha_row[x] = 1.0;
                        depth_row[x] = z;
                        shade(id, x as u32, y as u32)
                    }
                    None => background,
                };
                rgb_row[3 * x..3 * x + 3].copy_from_slice(&c);
            }
        });
    ViewImage {
        width: view.width,
        height: view.height,
        rgb,
        alpha,
        depth,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The separable Gaussian filter against a direct 2-D weighted sum in f64 (border pixels
    /// renormalised over the sub-pixels inside the image), on a random image, for odd and even k.
    #[test]
    fn separable_gaussian_filter_matches_the_direct_sum() {
        let sigma2 = f64::from(PIXEL_FILTER_VARIANCE);
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        for k in [2u32, 3, 4] {
            let (w, h) = (5usize, 4usize);
            let (bw, bh) = (w * k as usize, h * k as usize);
            let big: Vec<f32> = (0..bw * bh * 3).map(|_| next()).collect();
            let fast = filter_separable(&big, bw as u32, bh as u32, 3, k, &gaussian_taps(k));
            for y in 0..h {
                for x in 0..w {
                    let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                    let mut acc = [0.0f64; 3];
                    let mut norm = 0.0;
                    for sy in 0..bh {
                        for sx in 0..bw {
                            let dx = (sx as f64 + 0.5) / f64::from(k) - cx;
                            let dy = (sy as f64 + 0.5) / f64::from(k) - cy;
                            let reach = 3.0 * sigma2.sqrt();
                            if dx.abs() > reach || dy.abs() > reach {
                                continue;
                            }
                            let wt = (-(dx * dx + dy * dy) / (2.0 * sigma2)).exp();
                            norm += wt;
                            for c in 0..3 {
                                acc[c] += wt * f64::from(big[(sy * bw + sx) * 3 + c]);
                            }
                        }
                    }
                    for c in 0..3 {
                        let direct = acc[c] / norm;
                        let got = f64::from(fast[(y * w + x) * 3 + c]);
                        assert!(
                            (got - direct).abs() < 1e-5,
                            "k {k} ({x}, {y}) {got} {direct}"
                        );
                    }
                }
            }
        }
    }

    /// A constant image stays constant up to its borders; the taps sum to 1 and, for odd k,
    /// are symmetric about the pixel's centre sub-pixel.
    #[test]
    fn gaussian_filter_keeps_constants_and_is_centred() {
        let taps = gaussian_taps(3);
        assert!((taps.iter().map(|t| t.1).sum::<f32>() - 1.0).abs() < 1e-6);
        for &(off, wt) in &taps {
            let mirror = taps.iter().find(|t| t.0 == 2 - off).unwrap();
            assert!((mirror.1 - wt).abs() < 1e-7);
        }
        let big = vec![0.25f32; 12 * 9];
        let out = filter_separable(&big, 12, 9, 1, 3, &taps);
        assert_eq!(out.len(), 4 * 3);
        assert!(out.iter().all(|v| (v - 0.25).abs() < 1e-6), "{out:?}");
    }
}
