//! The real COLMAP model in `testdata/colmap/maupertuis` (kapture's sample, 4 photos):
//! read it, reproject every observation through `camera-model`, and convert it exactly.
#![allow(clippy::print_stderr)] // tests report what they measured

use std::path::PathBuf;

use colmap_io::{CameraModel, Format, read_model, read_model_as, write_model};

fn model_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../testdata"))
        .join("colmap/maupertuis/sparse/0")
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[test]
fn reads_the_counts_of_the_real_model() {
    let rec = read_model(&model_dir()).unwrap();
    assert_eq!(rec.cameras.len(), 1);
    let cam = &rec.cameras[&1];
    assert_eq!(
        (cam.model, cam.width, cam.height),
        (CameraModel::SimplePinhole, 1919, 1079)
    );
    assert_eq!(cam.params, vec![1847.53, 959.5, 539.5]);
    assert_eq!(rec.images.len(), 4);
    let mut names: Vec<&str> = rec.images.values().map(|im| im.name.as_str()).collect();
    names.sort_unstable();
    assert_eq!(names, ["00.jpg", "01.jpg", "02.jpg", "03.jpg"]);
    assert_eq!(rec.points3d.len(), 1_039);
    assert_eq!(rec.num_observations(), 3_355);
    // The header says "mean observations per image: 838.75" = 3355 / 4.
    let triangulated: usize = rec
        .images
        .values()
        .map(|im| {
            im.points2d
                .iter()
                .filter(|p| p.point3d_id.is_some())
                .count()
        })
        .sum();
    assert_eq!(triangulated, 3_355);
    // Tracks and observations point at each other.
    for (&pid, point) in &rec.points3d {
        for t in &point.track {
            assert_eq!(
                rec.images[&t.image_id].points2d[t.point2d_idx as usize].point3d_id,
                Some(pid)
            );
        }
    }
}

#[test]
fn every_observation_reprojects_within_half_a_pixel_median() {
    let rec = read_model(&model_dir()).unwrap();
    let errors = rec.reprojection_errors().unwrap();
    assert_eq!(errors.len(), 3_355);
    let med = median(errors.clone());
    let mean = errors.iter().sum::<f64>() / errors.len() as f64;
    eprintln!("maupertuis reprojection error: median {med:.4} px, mean {mean:.4} px");
    assert!(med < 0.5, "median reprojection error {med} px");
    // Independent truth: COLMAP stored each point's mean reprojection error (ERROR column).
    // Ours, from the 6-digit rounded poses of the text file, agrees to a few hundredths of a pixel.
    let mut k = 0;
    let mut worst = 0.0f64;
    for point in rec.points3d.values() {
        let n = point.track.len();
        let ours = errors[k..k + n].iter().sum::<f64>() / n as f64;
        worst = worst.max((ours - point.error).abs());
        k += n;
    }
    assert!(
        worst < 0.05,
        "per-point mean error differs from COLMAP's by {worst} px"
    );
    // Every triangulated point is in front of every camera that sees it, inside the image.
    for image in rec.images.values() {
        let cam = rec.camera_of(image.id).unwrap();
        for p in image
            .points2d
            .iter()
            .filter_map(|p| p.point3d_id.map(|id| (p, id)))
        {
            let px = cam
                .project(rec.points3d[&p.1].xyz)
                .expect("point behind its camera");
            assert!(cam.intrinsics.contains(px) || (px - p.0.xy).length() < 2.0);
            assert!(cam.intrinsics.contains(p.0.xy));
        }
    }
}

#[test]
fn converts_to_binary_and_back_exactly() {
    let tmp = tempfile::tempdir().unwrap();
    let original = read_model(&model_dir()).unwrap();
    write_model(&tmp.path().join("bin"), &original, Format::Binary).unwrap();
    let from_bin = read_model_as(&tmp.path().join("bin"), Format::Binary).unwrap();
    assert_eq!(from_bin, original);
    write_model(&tmp.path().join("txt"), &from_bin, Format::Text).unwrap();
    let from_txt = read_model_as(&tmp.path().join("txt"), Format::Text).unwrap();
    assert_eq!(from_txt, original);
    // Bit-exact values: compare the binary encodings of both generations.
    write_model(&tmp.path().join("bin2"), &from_txt, Format::Binary).unwrap();
    for name in ["cameras.bin", "images.bin", "points3D.bin"] {
        let a = std::fs::read(tmp.path().join("bin").join(name)).unwrap();
        let b = std::fs::read(tmp.path().join("bin2").join(name)).unwrap();
        assert!(a == b, "{name} differs after text → binary → text → binary");
    }
    // Every data line of the original text survives with the same numbers.
    for name in ["cameras.txt", "images.txt", "points3D.txt"] {
        let numbers = |path: PathBuf| -> Vec<String> {
            std::fs::read_to_string(path)
                .unwrap()
                .lines()
                .filter(|l| !l.starts_with('#'))
                .flat_map(|l| {
                    l.split_whitespace()
                        .map(|t| t.parse::<f64>().map_or(t.to_string(), |v| v.to_string()))
                        .collect::<Vec<_>>()
                })
                .collect()
        };
        let (mut a, mut b) = (
            numbers(model_dir().join(name)),
            numbers(tmp.path().join("txt").join(name)),
        );
        // Files are ordered by id in ours, in COLMAP's hash order in the original.
        a.sort();
        b.sort();
        assert_eq!(a, b, "{name}");
    }
}
