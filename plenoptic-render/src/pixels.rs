//! From primitives to pixels, shared by the cloud and mesh renderers: shading a resolved z-buffer
//! into a [`ViewImage`], and supersampling with a box filter.

use camera_model::Camera;
use rayon::prelude::*;

use crate::camera::{ViewCamera, scaled_camera};
use crate::zbuffer::ZBuffer;
use crate::{Error, ViewImage, ViewOptions};

/// Renders at `opts.supersample`× and box-filters down: colour and alpha are averaged over the
/// k×k sub-pixels, depth over the covered ones.
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
    Ok(downsample(&big, k))
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
