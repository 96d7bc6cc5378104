//! The real 3DGS file in `testdata/splat-scene`: `gt.ply` (Inria layout, SH degree 3,
//! unnormalised quaternions) with held-out images rendered from it by an independent numpy
//! renderer with the Inria conventions. Our render from the held-out COLMAP cameras must
//! reproduce those images: they are 8-bit PNGs, so a render equal up to quantisation scores
//! ~59 dB (measured: 61–67 dB, the images are mostly dark); 55 dB leaves room for rounding only.
#![allow(clippy::needless_range_loop)] // index loops mirror the maths in these checks
#![allow(clippy::print_stderr)] // tests report what they measured

mod common;

use std::path::{Path, PathBuf};

use splat_core::{Rasterizer, RenderCamera, RenderOptions};

fn data() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene"
    ))
}

/// Parses COLMAP `cameras.txt` + `images.txt` (PINHOLE) into (image name, camera).
fn read_colmap_text(dir: &Path) -> Vec<(String, RenderCamera)> {
    let cams = std::fs::read_to_string(dir.join("cameras.txt")).unwrap();
    let mut intr = std::collections::HashMap::new();
    for line in cams
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
    {
        let w: Vec<&str> = line.split_whitespace().collect();
        assert_eq!(w[1], "PINHOLE");
        let p: Vec<f64> = w[4..8].iter().map(|v| v.parse().unwrap()).collect();
        intr.insert(
            w[0].to_string(),
            (
                w[2].parse::<u32>().unwrap(),
                w[3].parse::<u32>().unwrap(),
                [p[0], p[1], p[2], p[3]],
            ),
        );
    }
    let imgs = std::fs::read_to_string(dir.join("images.txt")).unwrap();
    let mut out = Vec::new();
    let mut lines = imgs.lines().filter(|l| !l.starts_with('#'));
    while let Some(line) = lines.next() {
        if line.trim().is_empty() {
            continue;
        }
        let w: Vec<&str> = line.split_whitespace().collect();
        let v: Vec<f64> = w[1..8].iter().map(|x| x.parse().unwrap()).collect();
        let (width, height, k) = intr[w[8]];
        out.push((
            w[9].to_string(),
            common::camera_from_colmap(
                [v[0], v[1], v[2], v[3]],
                [v[4], v[5], v[6]],
                width,
                height,
                k,
            ),
        ));
        lines.next(); // the POINTS2D line
    }
    out
}

#[test]
fn gt_ply_renders_the_heldout_images() {
    let splats = splat_core::ply::read_splats(&data().join("gt.ply")).unwrap();
    assert_eq!(splats.len(), 4000);
    assert_eq!(splats.sh_degree, 3);
    let views = read_colmap_text(&data().join("heldout/sparse/0"));
    assert_eq!(views.len(), 8);
    let mut r = Rasterizer::new();
    let opts = RenderOptions::default();
    let mut worst = f64::INFINITY;
    for (name, cam) in &views {
        let out = r.forward(&splats, cam, &opts);
        let img = image::open(data().join("heldout/images").join(name))
            .unwrap()
            .to_rgb8();
        assert_eq!((img.width(), img.height()), (cam.width, cam.height));
        let mse: f64 = img
            .as_raw()
            .iter()
            .zip(&out.rgb)
            .map(|(&a, &b)| {
                let d = f64::from(a) / 255.0 - f64::from(b.clamp(0.0, 1.0));
                d * d
            })
            .sum::<f64>()
            / out.rgb.len() as f64;
        let psnr = -10.0 * mse.log10();
        eprintln!("{name}: PSNR {psnr:.2} dB");
        worst = worst.min(psnr);
    }
    assert!(worst > 55.0, "worst held-out PSNR {worst:.2} dB");
}

#[test]
fn gt_through_spz_renders_like_gt_ply() {
    // The SPZ round trip quantises every attribute; rendered from the held-out cameras the model
    // must still look the same. This scene's view dependence is strong (random SH up to degree 3),
    // so the SH bits decide the error. Measured, worst of 8 views against the PLY's own render:
    // Niantic's default 5/4 bits 39.2 dB at 8.56x smaller than the PLY; 6/5 bits 42.5 dB at
    // 7.06x; 8/8 bits 55.7 dB at 5.06x (exact SH: 58.5 dB, the rest of the quantisation).
    use splat_core::spz::{SpzOptions, decode_spz, encode_spz};
    let path = data().join("gt.ply");
    let splats = splat_core::ply::read_splats(&path).unwrap();
    let ply_bytes = std::fs::metadata(&path).unwrap().len() as f64;
    let views = read_colmap_text(&data().join("heldout/sparse/0"));
    let mut r = Rasterizer::new();
    let opts = RenderOptions::default();
    let full_sh = SpzOptions {
        sh1_bits: 8,
        sh_rest_bits: 8,
        ..SpzOptions::default()
    };
    for (options, min_ratio, min_psnr) in [(SpzOptions::default(), 8.0, 38.5), (full_sh, 5.0, 55.0)]
    {
        let bytes = encode_spz(&splats, &options).unwrap();
        let ratio = ply_bytes / bytes.len() as f64;
        let back = decode_spz(Path::new("gt.spz"), &bytes).unwrap().splats;
        let mut worst = f64::INFINITY;
        for (_, cam) in &views {
            let a = r.forward(&splats, cam, &opts).rgb.clone();
            let b = &r.forward(&back, cam, &opts).rgb;
            let mse = a
                .iter()
                .zip(b)
                .map(|(&x, &y)| f64::from(x.clamp(0.0, 1.0) - y.clamp(0.0, 1.0)).powi(2))
                .sum::<f64>()
                / a.len() as f64;
            worst = worst.min(-10.0 * mse.log10());
        }
        eprintln!(
            "SH bits {}/{}: {} bytes, {ratio:.2}x smaller than the PLY, worst view {worst:.2} dB",
            options.sh1_bits,
            options.sh_rest_bits,
            bytes.len()
        );
        assert!(
            ratio > min_ratio,
            "only {ratio:.2}x smaller with {options:?}"
        );
        assert!(
            worst > min_psnr,
            "worst SPZ-vs-PLY PSNR {worst:.2} dB with {options:?}"
        );
    }
}
