//! Reading a dataset folder: COLMAP cameras, images and their masks, as [`View`]s.
//!
//! The layout is `DIR/sparse/0/` (a COLMAP model, text or binary), `DIR/images/NAME` for every
//! image the model registers, and optionally `DIR/masks/NAME` (a grey image of the same size,
//! the coverage, or an image whose alpha channel is the coverage): where `masks/` exists it holds one for every image (a view without one would
//! be read as fully covered beside masked ones, so its absence is an error). Image names are
//! paths relative to `images/` and may not lead out of it. `transcode train`, `transcode eval` and the tests all read
//! datasets through [`read_dataset`], so a dataset means the same thing to each of them.
//!
//! Colour conventions:
//! - an image with a mask in `masks/` holds its colour composited on black (as `transcode views`
//!   writes it): it becomes straight colour by [`View::from_premultiplied`], so whatever the image
//!   holds where the mask is 0 is dropped;
//! - an image with an alpha channel and no mask holds straight colour and its coverage;
//! - any other image covers every pixel (no mask).

use std::path::{Path, PathBuf};

use camera_model::Camera;

use crate::view::{View, scale_intrinsics};

/// What can go wrong reading a dataset folder; each names the file and the problem.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// The COLMAP model could not be read, or an image's camera is missing from it.
    #[error("COLMAP model in {path}: {source}")]
    Colmap {
        /// The model folder (`DIR/sparse/0`).
        path: PathBuf,
        /// The cause (boxed: COLMAP errors are large).
        source: Box<colmap_io::Error>,
    },
    /// The model registers no images.
    #[error("{0} registers no images")]
    Empty(PathBuf),
    /// An image the model registers is not in `images/`.
    #[error("{path}: missing (the COLMAP model registers image {name:?})")]
    MissingImage {
        /// Where the image should be.
        path: PathBuf,
        /// Its name in the model.
        name: String,
    },
    /// An image's name in the model leads out of `images/` (absolute, `..`, or empty).
    #[error(
        "{model}: image {id} is named {name:?}, which leads out of the images folder: a \
         dataset's image names are paths relative to images/"
    )]
    OutsideImages {
        /// The model folder (`DIR/sparse/0`).
        model: PathBuf,
        /// The image's id.
        id: u32,
        /// Its name in the model.
        name: String,
    },
    /// `masks/` exists but holds no mask for an image: that view would be scored and trained as
    /// fully covered while the others are masked.
    #[error(
        "{path}: missing: masks/ holds masks, so every image needs one under its own name (the \
         COLMAP model registers image {name:?})"
    )]
    MissingMask {
        /// Where the mask should be.
        path: PathBuf,
        /// The image's name in the model.
        name: String,
    },
    /// An image or mask file cannot be opened or decoded.
    #[error("{path}: cannot read the image: {problem}")]
    Unreadable {
        /// The file.
        path: PathBuf,
        /// The decoder's or the file system's message.
        problem: String,
    },
    /// An image's size is not its camera's, or a mask's is not its image's.
    #[error("{path} is {width}×{height} but {against} is {want_width}×{want_height}")]
    SizeMismatch {
        /// The image or mask file.
        path: PathBuf,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// What it must match: "its camera" or "its image".
        against: &'static str,
        /// The width it must have.
        want_width: u32,
        /// The height it must have.
        want_height: u32,
    },
    /// The reduction factor is not a finite number ≥ 1.
    #[error("downscale factor {0} must be at least 1")]
    Downscale(f64),
    /// The reduction would leave an image less than a pixel on a side.
    #[error(
        "{path}: its {width}×{height} pixels reduced by {downscale} are less than a pixel on a \
         side; use a factor of at most {most}"
    )]
    ReducedAway {
        /// The image.
        path: PathBuf,
        /// Its width.
        width: u32,
        /// Its height.
        height: u32,
        /// The factor asked for.
        downscale: f64,
        /// The largest factor that leaves a pixel.
        most: u32,
    },
}

/// A dataset folder read into memory.
#[derive(Debug, Clone)]
pub struct Dataset {
    /// One view per registered image, in the model's image-id order, named by the image's name
    /// in the model (its file name under `images/`).
    pub views: Vec<View>,
    /// The COLMAP model (cameras at the images' full size, poses, 3D points).
    pub reconstruction: colmap_io::Reconstruction,
}

/// Reads the dataset in `dir` (layout and colour conventions in the [module docs](self)), every
/// image reduced by `downscale` ≥ 1 with its camera's intrinsics scaled to match.
///
/// # Errors
/// [`DatasetError`] naming the model folder, the image or the mask, and what is wrong with it.
pub fn read_dataset(dir: &Path, downscale: f64) -> Result<Dataset, DatasetError> {
    if !(downscale.is_finite() && downscale >= 1.0) {
        return Err(DatasetError::Downscale(downscale));
    }
    let sparse = dir.join("sparse").join("0");
    let colmap = |source| DatasetError::Colmap {
        path: sparse.clone(),
        source: Box::new(source),
    };
    let reconstruction = colmap_io::read_model(&sparse).map_err(colmap)?;
    if reconstruction.images.is_empty() {
        return Err(DatasetError::Empty(sparse));
    }
    let masks = Some(dir.join("masks")).filter(|m| m.is_dir());
    let mut views = Vec::with_capacity(reconstruction.images.len());
    for (&id, image) in &reconstruction.images {
        let camera = reconstruction.camera_of(id).map_err(colmap)?;
        let relative = image
            .relative_file()
            .ok_or_else(|| DatasetError::OutsideImages {
                model: sparse.clone(),
                id,
                name: image.name.clone(),
            })?;
        let path = dir.join("images").join(relative);
        if path.is_dir() {
            return Err(DatasetError::Unreadable {
                path,
                problem: "it is a folder, not an image file".into(),
            });
        }
        if !path.is_file() {
            return Err(DatasetError::MissingImage {
                path,
                name: image.name.clone(),
            });
        }
        let mask = masks.as_ref().map(|m| m.join(relative));
        if let Some(mask) = mask.as_ref().filter(|m| !m.is_file()) {
            return Err(DatasetError::MissingMask {
                path: mask.clone(),
                name: image.name.clone(),
            });
        }
        views.push(read_view(
            &path,
            mask.as_deref(),
            &image.name,
            camera,
            downscale,
        )?);
    }
    Ok(Dataset {
        views,
        reconstruction,
    })
}

/// A mask's coverage: its alpha channel where it has one (a white RGBA or grey-alpha image
/// whose alpha is the coverage was read as fully covered), else its grey level. A mask whose
/// largest value is one step of its range (0/1 written into an 8- or 16-bit image) is refused:
/// read as coverage it is ≈ 0 everywhere, and the scores flattered a model of the background.
fn mask_coverage(
    path: &Path,
    mask: &image::DynamicImage,
) -> Result<image::ImageBuffer<image::Luma<f32>, Vec<f32>>, DatasetError> {
    let coverage = if mask.color().has_alpha() {
        let rgba = mask.to_rgba32f();
        image::ImageBuffer::from_fn(rgba.width(), rgba.height(), |x, y| {
            image::Luma([rgba.get_pixel(x, y)[3]])
        })
    } else {
        mask.to_luma32f()
    };
    let largest = coverage.pixels().map(|p| p[0]).fold(0.0_f32, f32::max);
    if largest > 0.0 && largest <= 1.5 / 255.0 {
        return Err(DatasetError::Unreadable {
            path: path.to_path_buf(),
            problem: format!(
                "its largest value is {:.6} of full scale: a mask of 0 and 1 rather than 0 and \
                 255 (or 65535); masks hold coverage over the image's whole range",
                largest
            ),
        });
    }
    Ok(coverage)
}

/// Reads one image (and its mask) as a view of `camera`, reduced by `downscale` ≥ 1.
fn read_view(
    path: &Path,
    mask_path: Option<&Path>,
    name: &str,
    camera: Camera,
    downscale: f64,
) -> Result<View, DatasetError> {
    let img = decode(path)?;
    let k = camera.intrinsics;
    check_size(path, &img, "its camera", k.width, k.height)?;
    let mask = match mask_path {
        Some(p) => {
            let m = decode(p)?;
            check_size(p, &m, "its image", img.width(), img.height())?;
            Some(mask_coverage(p, &m)?)
        }
        None => None,
    };
    let has_alpha = img.color().has_alpha();
    let mut rgba = img.into_rgba32f();
    if let Some(mask) = &mask {
        // The mask rides in the alpha channel through the reduction: the filter treats the
        // channels alike, so colour composited on black and its coverage are averaged together.
        for (p, m) in rgba.pixels_mut().zip(mask.pixels()) {
            p[3] = m[0];
        }
    } else if has_alpha {
        // Straight colour with alpha: premultiplied here so the reduction averages colour
        // weighted by coverage (whatever colour a transparent pixel holds adds nothing), and
        // divided back below like a masked image.
        for p in rgba.pixels_mut() {
            let a = p[3];
            for c in &mut p.0[..3] {
                *c *= a;
            }
        }
    }
    let mut intrinsics = k;
    if downscale > 1.0 {
        let w = (f64::from(k.width) / downscale).round() as u32;
        let h = (f64::from(k.height) / downscale).round() as u32;
        if w == 0 || h == 0 {
            return Err(DatasetError::ReducedAway {
                path: path.to_path_buf(),
                width: k.width,
                height: k.height,
                downscale,
                most: k.width.min(k.height),
            });
        }
        // The triangle filter widens its kernel by the reduction factor, so it averages.
        rgba = image::imageops::resize(&rgba, w, h, image::imageops::FilterType::Triangle);
        intrinsics = scale_intrinsics(&k, w, h);
    }
    let camera = Camera::new(intrinsics, camera.pose);
    let px = rgba.as_raw();
    let rgb: Vec<f32> = px
        .chunks_exact(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let view = if mask.is_some() || has_alpha {
        let alpha: Vec<f32> = px.chunks_exact(4).map(|p| p[3]).collect();
        View::from_premultiplied(name.to_string(), camera, &rgb, &alpha)
    } else {
        View::from_straight(name.to_string(), camera, &rgb, None)
    };
    // Decoded 8- and 16-bit images are finite; a float image (EXR) may not be.
    view.map_err(|problem| DatasetError::Unreadable {
        path: path.to_path_buf(),
        problem,
    })
}

/// Opens and decodes an image file, whatever its extension says.
fn decode(path: &Path) -> Result<image::DynamicImage, DatasetError> {
    let unreadable = |e: &dyn std::fmt::Display| DatasetError::Unreadable {
        path: path.to_path_buf(),
        problem: e.to_string(),
    };
    image::ImageReader::open(path)
        .map_err(|e| unreadable(&e))?
        .with_guessed_format()
        .map_err(|e| unreadable(&e))?
        .decode()
        .map_err(|e| unreadable(&e))
}

/// `img` must be `width × height`, the size of `against`.
fn check_size(
    path: &Path,
    img: &image::DynamicImage,
    against: &'static str,
    width: u32,
    height: u32,
) -> Result<(), DatasetError> {
    if (img.width(), img.height()) == (width, height) {
        return Ok(());
    }
    Err(DatasetError::SizeMismatch {
        path: path.to_path_buf(),
        width: img.width(),
        height: img.height(),
        against,
        want_width: width,
        want_height: height,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{Background, TrainConfig};
    use crate::eval::{EvalOptions, evaluate, evaluate_views};
    use crate::trainer::Trainer;
    use camera_model::{Intrinsics, Pose};
    use colmap_io::dataset::{points_without_tracks, reconstruction_from_cameras};
    use glam::Vec3;

    const W: u32 = 16;
    const H: u32 = 12;

    /// Writes a two-view dataset of `W`×`H` RGB PNGs into `dir`: colour composited on black
    /// inside a centred square that the masks cover (with a half-covered rim), and `outside`
    /// where the masks are 0. `masks: false` leaves `masks/` out.
    fn write(dir: &Path, outside: [u8; 3], masks: bool) {
        let cam = Camera::new(Intrinsics::centered(W, H, 20.0, 20.0), Pose::IDENTITY);
        let names = ["a.png", "b.png"];
        let mut rec = reconstruction_from_cameras(names.iter().map(|n| (*n, &cam))).unwrap();
        rec.points3d = points_without_tracks([(glam::DVec3::new(0.0, 0.0, 2.0), [200, 100, 50])]);
        std::fs::create_dir_all(dir.join("images")).unwrap();
        std::fs::create_dir_all(dir.join("sparse/0")).unwrap();
        if masks {
            std::fs::create_dir_all(dir.join("masks")).unwrap();
        }
        for (k, name) in names.iter().enumerate() {
            let cover = |x: u32, y: u32| -> u8 {
                let (dx, dy) = (x.abs_diff(W / 2), y.abs_diff(H / 2));
                match dx.max(dy) {
                    0..=2 => 255,
                    3 => 128,
                    _ => 0,
                }
            };
            let img = image::RgbImage::from_fn(W, H, |x, y| {
                let a = cover(x, y);
                if a == 0 {
                    image::Rgb(outside)
                } else {
                    // Straight colour (200, 60 + 40k, 100) on black.
                    let on_black = |c: u32| (c * u32::from(a) / 255) as u8;
                    image::Rgb([on_black(200), on_black(60 + 40 * k as u32), on_black(100)])
                }
            });
            img.save(dir.join("images").join(name)).unwrap();
            if masks {
                image::GrayImage::from_fn(W, H, |x, y| image::Luma([cover(x, y)]))
                    .save(dir.join("masks").join(name))
                    .unwrap();
            }
        }
        colmap_io::write_model(&dir.join("sparse/0"), &rec, colmap_io::Format::Text).unwrap();
    }

    /// A few splats in front of the identity camera.
    fn splats() -> splat_core::Splats {
        let mut s = splat_core::Splats::new(0);
        for (i, x) in [-0.3f32, 0.0, 0.3].into_iter().enumerate() {
            s.push(
                Vec3::new(x, 0.1 * i as f32, 2.0),
                Vec3::splat(-2.5),
                [1.0, 0.0, 0.0, 0.0],
                0.0,
                &[[0.3, -0.2 + 0.2 * i as f32, 0.1]],
            );
        }
        s
    }

    /// The masks are read, and with them whatever the images hold where the masks are 0 is
    /// dropped: a dataset whose background pixels are not black reads, evaluates and trains
    /// (on black and on random backgrounds) exactly like one whose are.
    #[test]
    fn masked_datasets_ignore_the_images_background() {
        let dir = tempfile::tempdir().unwrap();
        let (black, grey) = (dir.path().join("black"), dir.path().join("grey"));
        write(&black, [0, 0, 0], true);
        write(&grey, [90, 170, 30], true);
        let a = read_dataset(&black, 1.0).unwrap();
        let b = read_dataset(&grey, 1.0).unwrap();
        assert_eq!(a.views, b.views);
        assert_eq!(a.views.len(), 2);
        let v = &a.views[0];
        assert_eq!(v.name, "a.png");
        let (mask, colour) = (v.coverage().unwrap(), v.colour());
        let centre = (H / 2 * W + W / 2) as usize;
        let rim = (H / 2 * W + W / 2 + 3) as usize;
        // 8-bit values are held exactly; others to half a 16-bit step.
        assert_eq!(
            (mask[0], mask[centre], mask[rim]),
            (0.0, 1.0, 128.0 / 255.0)
        );
        // Straight colour: 200/255 in the centre; on the rim ⌊200·128/255⌋ / 128 = 100/128.
        assert_eq!(colour[3 * centre], 200.0 / 255.0);
        assert!((colour[3 * rim] - 100.0 / 128.0).abs() <= 0.5 / 65535.0);
        assert_eq!(&v.image[..3], &[0; 3]);

        let opts = EvalOptions {
            alpha_threshold: 0.5,
            floater_spacings: 2.0,
            antialiased: false,
        };
        let s = splats();
        let (ma, _) = evaluate_views(&s, &a.views, None, &opts).unwrap();
        let (mb, _) = evaluate_views(&s, &b.views, None, &opts).unwrap();
        assert_eq!(ma, mb);
        assert_eq!(ma.views[0].covered_pixels, 7 * 7);
        for background in [Background::Fixed([0.0; 3]), Background::Random] {
            let config = TrainConfig {
                iterations: 4,
                densify: None,
                background,
                ..TrainConfig::default()
            };
            let mut ta = Trainer::new(s.clone(), a.views.clone(), config.clone()).unwrap();
            let mut tb = Trainer::new(s.clone(), b.views.clone(), config).unwrap();
            ta.run(|_| {});
            tb.run(|_| {});
            assert_eq!(ta.splats(), tb.splats(), "{background:?}");
            assert_eq!(
                evaluate(ta.splats(), &a.views, Vec3::ZERO).unwrap(),
                evaluate(tb.splats(), &b.views, Vec3::ZERO).unwrap()
            );
        }

        // Without masks the image is all there is: its background pixels are colour.
        let plain = dir.path().join("plain");
        write(&plain, [90, 170, 30], false);
        let p = read_dataset(&plain, 1.0).unwrap();
        assert!(p.views[0].mask.is_none());
        assert_eq!(p.views[0].colour()[1], 170.0 / 255.0);
    }

    /// An RGBA image without a mask is straight colour with its coverage: it reads as the same
    /// view as the masked RGB image of the same content, whatever colour its transparent pixels
    /// hold, at full size and reduced.
    #[test]
    fn rgba_images_read_like_masked_ones() {
        let dir = tempfile::tempdir().unwrap();
        let (masked, rgba) = (dir.path().join("masked"), dir.path().join("rgba"));
        write(&masked, [0, 0, 0], true);
        write(&rgba, [0, 0, 0], false);
        for name in ["a.png", "b.png"] {
            let on_black = image::open(masked.join("images").join(name))
                .unwrap()
                .to_rgb8();
            let mask = image::open(masked.join("masks").join(name))
                .unwrap()
                .to_luma8();
            let img = image::RgbaImage::from_fn(W, H, |x, y| {
                let (c, a) = (on_black.get_pixel(x, y).0, mask.get_pixel(x, y).0[0]);
                if a == 0 {
                    // Garbage colour under full transparency.
                    return image::Rgba([250, 20, 140, 0]);
                }
                // Straight colour, as PNG stores it.
                let straight =
                    |v: u8| ((f32::from(v) * 255.0 / f32::from(a)).round()).min(255.0) as u8;
                image::Rgba([straight(c[0]), straight(c[1]), straight(c[2]), a])
            });
            img.save(rgba.join("images").join(name)).unwrap();
        }
        for downscale in [1.0, 2.0] {
            let a = read_dataset(&masked, downscale).unwrap().views;
            let b = read_dataset(&rgba, downscale).unwrap().views;
            for (va, vb) in a.iter().zip(&b) {
                let (ma, mb) = (va.mask.as_ref().unwrap(), vb.mask.as_ref().unwrap());
                assert!(ma.iter().zip(mb).all(|(x, y)| x.abs_diff(*y) <= 1));
                let on = |v: &View| v.on_background([0.0; 3]);
                let worst = on(va)
                    .iter()
                    .zip(&on(vb))
                    .map(|(x, y)| (x - y).abs())
                    .fold(0.0f32, f32::max);
                // 8-bit rounding of the straight colour, at most half a step times the coverage.
                assert!(worst < 1.0 / 255.0, "÷{downscale}: {worst}");
            }
        }
    }

    /// Downscaling reduces image and mask together and scales the intrinsics.
    #[test]
    fn downscale_reduces_images_masks_and_cameras() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), [0, 0, 0], true);
        let d = read_dataset(dir.path(), 2.0).unwrap();
        let v = &d.views[1];
        let k = v.camera.intrinsics;
        assert_eq!((k.width, k.height, k.fx, k.cx), (8, 6, 10.0, 4.0));
        assert_eq!(v.image.len(), 3 * 8 * 6);
        let mask = v.mask.as_ref().unwrap();
        assert_eq!(mask.len(), 8 * 6);
        // The corner is far from the square: still uncovered and black; the centre covered.
        assert_eq!((mask[0], &v.image[..3]), (0, &[0u16; 3][..]));
        assert_eq!(mask[3 * 8 + 4], u16::MAX);
        // 16×12 images reduced by 100 would be 0×0 (they were made 1×1 before).
        let e = read_dataset(dir.path(), 100.0).unwrap_err();
        assert!(
            matches!(
                e,
                DatasetError::ReducedAway {
                    width: 16,
                    height: 12,
                    most: 12,
                    ..
                }
            ),
            "{e}"
        );
        assert!(matches!(
            read_dataset(dir.path(), 0.5),
            Err(DatasetError::Downscale(f)) if f == 0.5
        ));
    }

    /// Each broken dataset is refused with an error naming the file and the problem.
    #[test]
    fn broken_datasets_name_the_file_and_the_problem() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        write(root, [0, 0, 0], true);
        let images = root.join("images");
        let masks = root.join("masks");

        // A mask of another size than its image.
        image::GrayImage::new(W + 1, H)
            .save(masks.join("b.png"))
            .unwrap();
        let e = read_dataset(root, 1.0).unwrap_err();
        assert!(
            matches!(&e, DatasetError::SizeMismatch { path, against: "its image", width: 17, .. } if path.ends_with("masks/b.png")),
            "{e}"
        );
        assert!(
            e.to_string().contains("17×12 but its image is 16×12"),
            "{e}"
        );
        std::fs::remove_file(masks.join("b.png")).unwrap();

        // An image of another size than its camera.
        image::RgbImage::new(W, H + 2)
            .save(images.join("a.png"))
            .unwrap();
        let e = read_dataset(root, 1.0).unwrap_err();
        assert!(
            e.to_string()
                .contains("a.png is 16×14 but its camera is 16×12"),
            "{e}"
        );

        // An image that is not a PNG at all, and a missing one.
        std::fs::write(images.join("a.png"), b"not a png").unwrap();
        let e = read_dataset(root, 1.0).unwrap_err();
        assert!(
            matches!(&e, DatasetError::Unreadable { path, .. } if path.ends_with("images/a.png")),
            "{e}"
        );
        std::fs::remove_file(images.join("a.png")).unwrap();
        let e = read_dataset(root, 1.0).unwrap_err();
        assert!(
            matches!(&e, DatasetError::MissingImage { name, .. } if name == "a.png"),
            "{e}"
        );
        assert!(e.to_string().contains("missing"), "{e}");
        // A folder where the image should be is named as one (it was "missing").
        std::fs::create_dir(images.join("a.png")).unwrap();
        let e = read_dataset(root, 1.0).unwrap_err().to_string();
        assert!(
            e.ends_with("a.png: cannot read the image: it is a folder, not an image file"),
            "{e}"
        );
        std::fs::remove_dir(images.join("a.png")).unwrap();

        // masks/ without b's mask (b.png removed above): b was read as fully covered beside
        // masked views, silently.
        write(root, [0, 0, 0], true);
        std::fs::remove_file(masks.join("b.png")).unwrap();
        let e = read_dataset(root, 1.0).unwrap_err();
        assert!(
            matches!(&e, DatasetError::MissingMask { name, path } if name == "b.png" && path.ends_with("masks/b.png")),
            "{e}"
        );
        // Without masks/ at all the images are read as they are.
        std::fs::remove_dir_all(&masks).unwrap();
        assert!(read_dataset(root, 1.0).is_ok());

        // An image name that leads out of images/.
        let sparse = root.join("sparse/0");
        let mut rec = colmap_io::read_model(&sparse).unwrap();
        rec.images.get_mut(&1).unwrap().name = "../secret.png".into();
        image::RgbImage::new(W, H)
            .save(root.join("secret.png"))
            .unwrap();
        colmap_io::write_model(&sparse, &rec, colmap_io::Format::Text).unwrap();
        let e = read_dataset(root, 1.0).unwrap_err();
        assert!(
            matches!(&e, DatasetError::OutsideImages { id: 1, name, .. } if name == "../secret.png"),
            "{e}"
        );

        // No model at all.
        let e = read_dataset(&root.join("nowhere"), 1.0).unwrap_err();
        assert!(
            matches!(&e, DatasetError::Colmap { path, .. } if path.ends_with("sparse/0")),
            "{e}"
        );
    }

    /// Masks that keep their coverage in an alpha channel (white RGBA, grey-alpha) read as the
    /// grey ones (they were read as fully covered); masks of 0 and 1 instead of 0 and 255 are
    /// refused (read as ≈ 0 coverage, they flattered a model of the background).
    #[test]
    fn masks_in_alpha_read_as_grey_ones_and_zero_one_masks_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let root = dir.path();
        write(root, [0, 0, 0], true);
        let masks_of = |root: &Path| -> Vec<Option<Vec<u16>>> {
            read_dataset(root, 1.0)
                .unwrap()
                .views
                .into_iter()
                .map(|v| v.mask)
                .collect()
        };
        let grey = masks_of(root);
        assert!(grey.iter().all(Option::is_some));
        for name in ["a.png", "b.png"] {
            let path = root.join("masks").join(name);
            let m = image::open(&path).unwrap().to_luma8();
            image::RgbaImage::from_fn(W, H, |x, y| {
                image::Rgba([255, 255, 255, m.get_pixel(x, y)[0]])
            })
            .save(&path)
            .unwrap();
        }
        assert_eq!(masks_of(root), grey);
        for name in ["a.png", "b.png"] {
            let path = root.join("masks").join(name);
            let m = image::open(&path).unwrap().to_rgba8();
            image::GrayImage::from_fn(W, H, |x, y| {
                image::Luma([u8::from(m.get_pixel(x, y)[3] > 127)])
            })
            .save(&path)
            .unwrap();
        }
        let e = read_dataset(root, 1.0).unwrap_err().to_string();
        assert!(e.contains("a mask of 0 and 1 rather than 0 and 255"), "{e}");
    }

    /// The real photos in `testdata/` read at an eighth of their size.
    #[test]
    fn reads_the_maupertuis_photos() {
        let dir = Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../testdata/colmap/maupertuis"
        ));
        let d = read_dataset(dir, 8.0).unwrap();
        assert_eq!(d.views.len(), 4);
        let k = d.views[0].camera.intrinsics;
        assert_eq!((k.width, k.height), (240, 135));
        assert!(
            d.views
                .iter()
                .all(|v| v.mask.is_none() && v.check().is_ok())
        );
        assert!(!d.reconstruction.points3d.is_empty());
    }
}
