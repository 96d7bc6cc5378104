//! Writers for rendered views: RGB PNG (8- or 16-bit), alpha PNG, depth EXR; all atomic.

use std::path::{Path, PathBuf};

use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder};

use crate::{Error, ViewImage};
use atomic_output::{write_atomic, write_atomic_with};

/// Bits per channel of a PNG.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
pub enum BitDepth {
    /// 8 bits per channel (what trainers expect).
    #[default]
    Eight,
    /// 16 bits per channel (big-endian in the file, as PNG requires).
    Sixteen,
}

/// The files written for one view by [`write_view_images`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ViewFiles {
    /// `<stem>.png`.
    pub rgb: PathBuf,
    /// `<stem>_alpha.png`.
    pub alpha: PathBuf,
    /// `<stem>_depth.exr`.
    pub depth: PathBuf,
}

/// Writes `<dir>/<stem>.png` (RGB), `<dir>/<stem>_alpha.png` (8-bit grey) and
/// `<dir>/<stem>_depth.exr` (channel `Z`, camera z, 0 where nothing is seen).
pub fn write_view_images(
    image: &ViewImage,
    dir: &Path,
    stem: &str,
    bit_depth: BitDepth,
) -> Result<ViewFiles, Error> {
    let files = ViewFiles {
        rgb: dir.join(format!("{stem}.png")),
        alpha: dir.join(format!("{stem}_alpha.png")),
        depth: dir.join(format!("{stem}_depth.exr")),
    };
    write_rgb_png(&files.rgb, image, bit_depth)?;
    write_alpha_png(&files.alpha, image)?;
    write_depth_exr(&files.depth, image)?;
    Ok(files)
}

/// Quantises [0, 1] to an integer in 0..=`max` with rounding (values outside are clamped, NaN
/// gives 0): `(v·max).round()`, without `round`'s libm call, which took about 1 % of a
/// paper-scale frame's views (3M values a view). For x = v·max in [0, 65535] the truncation to
/// an integer and the fraction left (`x − whole`) are exact in f32, so comparing the fraction
/// with ½ rounds half up exactly as `round` does for non-negative values.
pub(crate) fn quantise(v: f32, max: f32) -> u32 {
    let x = v.clamp(0.0, 1.0) * max;
    let whole = x as u32;
    whole + u32::from(x - whole as f32 >= 0.5)
}

/// Writes the colour of a view as an RGB PNG, atomically.
pub fn write_rgb_png(path: &Path, image: &ViewImage, bit_depth: BitDepth) -> Result<(), Error> {
    let png = encode_png_rgb(path, image, bit_depth)?;
    write_atomic(path, &png).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Encodes the colour of a view as RGB PNG bytes (`path` only names errors).
pub(crate) fn encode_png_rgb(
    path: &Path,
    image: &ViewImage,
    bit_depth: BitDepth,
) -> Result<Vec<u8>, Error> {
    check_len(path, image.rgb.len(), 3 * pixels(image))?;
    let bytes: Vec<u8> = match bit_depth {
        BitDepth::Eight => image
            .rgb
            .iter()
            .map(|&v| quantise(v, 255.0) as u8)
            .collect(),
        BitDepth::Sixteen => image
            .rgb
            .iter()
            .flat_map(|&v| (quantise(v, 65535.0) as u16).to_be_bytes())
            .collect(),
    };
    let color = match bit_depth {
        BitDepth::Eight => ExtendedColorType::Rgb8,
        BitDepth::Sixteen => ExtendedColorType::Rgb16,
    };
    encode_png(path, &bytes, image.width, image.height, color)
}

/// Writes the alpha mask of a view as an 8-bit greyscale PNG, atomically.
pub fn write_alpha_png(path: &Path, image: &ViewImage) -> Result<(), Error> {
    check_len(path, image.alpha.len(), pixels(image))?;
    let bytes: Vec<u8> = image
        .alpha
        .iter()
        .map(|&v| quantise(v, 255.0) as u8)
        .collect();
    let png = encode_png(
        path,
        &bytes,
        image.width,
        image.height,
        ExtendedColorType::L8,
    )?;
    write_atomic(path, &png).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes the depth of a view as a single-channel (`Z`, f32) OpenEXR file, atomically.
pub fn write_depth_exr(path: &Path, image: &ViewImage) -> Result<(), Error> {
    use exr::prelude::{
        AnyChannel, AnyChannels, Encoding, FlatSamples, Image, Layer, LayerAttributes, LineOrder,
        SmallVec, WritableImage,
    };
    check_len(path, image.depth.len(), pixels(image))?;
    let channel = AnyChannel::new("Z", FlatSamples::F32(image.depth.clone()));
    let layer = Layer::new(
        (image.width as usize, image.height as usize),
        LayerAttributes::named("depth"),
        // Tiles in increasing order: the encoder compresses them in parallel, and with the
        // preset's unspecified order it wrote them as they finished, so two runs of one view
        // gave files with the same pixels but different bytes.
        Encoding {
            line_order: LineOrder::Increasing,
            ..Encoding::FAST_LOSSLESS
        },
        AnyChannels::sort(SmallVec::from_vec(vec![channel])),
    );
    let exr_image = Image::from_layer(layer);
    let mut failure = None;
    write_atomic_with(path, |w| {
        exr_image.write().to_buffered(w).map_err(|e| {
            let message = e.to_string();
            failure = Some(message.clone());
            std::io::Error::other(message)
        })
    })
    .map_err(|source| match failure {
        Some(message) => Error::Encode {
            path: path.to_path_buf(),
            message,
        },
        None => Error::Io {
            path: path.to_path_buf(),
            source,
        },
    })
}

/// Encodes a PNG in memory.
fn encode_png(
    path: &Path,
    bytes: &[u8],
    width: u32,
    height: u32,
    color: ExtendedColorType,
) -> Result<Vec<u8>, Error> {
    let mut png = Vec::new();
    PngEncoder::new(&mut png)
        .write_image(bytes, width, height, color)
        .map_err(|e| Error::Encode {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
    Ok(png)
}

fn pixels(image: &ViewImage) -> usize {
    image.width as usize * image.height as usize
}

/// Refuses an image whose buffer does not match its size, before anything is written.
fn check_len(path: &Path, got: usize, expected: usize) -> Result<(), Error> {
    if got == expected {
        Ok(())
    } else {
        Err(Error::Encode {
            path: path.to_path_buf(),
            message: format!("buffer holds {got} values, the image size needs {expected}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image() -> ViewImage {
        ViewImage {
            width: 3,
            height: 2,
            rgb: (0..18).map(|i| i as f32 / 17.0).collect(),
            alpha: vec![0.0, 0.5, 1.0, 1.0, 0.25, 0.0],
            depth: vec![0.0, 1.5, 2.25, 1e4, 3.0, 0.0],
        }
    }

    #[test]
    fn pngs_and_exr_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let img = image();
        let files = write_view_images(&img, dir.path(), "v0", BitDepth::Eight).unwrap();
        let rgb = image::open(&files.rgb).unwrap().to_rgb8();
        assert_eq!(rgb.dimensions(), (3, 2));
        for (i, &v) in rgb.as_raw().iter().enumerate() {
            assert_eq!(v, (img.rgb[i] * 255.0).round() as u8);
        }
        let a = image::open(&files.alpha).unwrap().to_luma8();
        assert_eq!(a.as_raw(), &vec![0u8, 128, 255, 255, 64, 0]);
        let exr = exr::prelude::read_first_flat_layer_from_file(&files.depth).unwrap();
        let samples: Vec<f32> = exr.layer_data.channel_data.list[0]
            .sample_data
            .values_as_f32()
            .collect();
        assert_eq!(samples, img.depth);
        // Nothing but the three files.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 3);
    }

    /// A depth map of many tiles (compressed in parallel) written again and again is the same
    /// file byte for byte, and reads back as written. With the tiles in the order they finished,
    /// the offsets table differed from run to run.
    #[test]
    fn depth_exr_files_are_reproducible() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (640u32, 384u32);
        let n = (w * h) as usize;
        let img = ViewImage {
            width: w,
            height: h,
            rgb: vec![0.0; 3 * n],
            alpha: vec![0.0; n],
            // Varied enough that tiles compress to different sizes and take different times.
            depth: (0..n)
                .map(|i| {
                    if i % 7 < 3 {
                        0.0
                    } else {
                        (i % 977) as f32 * 0.37
                    }
                })
                .collect(),
        };
        let first = dir.path().join("a.exr");
        write_depth_exr(&first, &img).unwrap();
        let bytes = std::fs::read(&first).unwrap();
        for k in 0..8 {
            let p = dir.path().join(format!("b{k}.exr"));
            write_depth_exr(&p, &img).unwrap();
            assert!(std::fs::read(&p).unwrap() == bytes, "write {k} differs");
        }
        let exr = exr::prelude::read_first_flat_layer_from_file(&first).unwrap();
        let samples: Vec<f32> = exr.layer_data.channel_data.list[0]
            .sample_data
            .values_as_f32()
            .collect();
        assert_eq!(samples, img.depth);
    }

    #[test]
    fn sixteen_bit_png_keeps_precision() {
        let dir = tempfile::tempdir().unwrap();
        let img = image();
        let p = dir.path().join("v.png");
        write_rgb_png(&p, &img, BitDepth::Sixteen).unwrap();
        let rgb = image::open(&p).unwrap().to_rgb16();
        for (i, &v) in rgb.as_raw().iter().enumerate() {
            assert_eq!(v, (img.rgb[i] * 65535.0).round() as u16);
        }
    }

    /// The libm-free rounding equals `round` of the clamped product: at and around every half
    /// step of both depths, over a stride through every f32 in [0, 1], and outside it.
    #[test]
    fn quantise_rounds_as_round_does() {
        let reference = |v: f32, max: f32| (v.clamp(0.0, 1.0) * max).round() as u32;
        for max in [255.0_f32, 65535.0] {
            for k in 0..max as u32 {
                let half = (k as f32 + 0.5) / max;
                for v in [half.next_down(), half, half.next_up(), k as f32 / max] {
                    assert_eq!(quantise(v, max), reference(v, max), "{v} × {max}");
                }
            }
            for bits in (0..=1.0_f32.to_bits()).step_by(101) {
                let v = f32::from_bits(bits);
                assert_eq!(quantise(v, max), reference(v, max), "{v} × {max}");
            }
            for v in [-1.0, -0.0, 1.0, 1.5, f32::INFINITY, f32::NEG_INFINITY] {
                assert_eq!(quantise(v, max), reference(v, max), "{v} × {max}");
            }
            assert_eq!(quantise(f32::NAN, max), 0);
        }
        // The value just below ½, whose `x + ½` rounds up to 1 in f32.
        assert_eq!(quantise(0.5_f32.next_down(), 1.0), 0);
    }

    #[test]
    fn missing_folder_is_a_clear_error() {
        let err = write_alpha_png(Path::new("/nonexistent/dir/a.png"), &image()).unwrap_err();
        assert!(err.to_string().contains("/nonexistent/dir/a.png"), "{err}");
    }
}
