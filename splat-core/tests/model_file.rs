//! Model files of any format by extension, and the render mode each can or cannot carry.

mod common;

use std::path::Path;

use common::gt_path;
use splat_core::model_file::{Format, read_model, write_model};
use splat_core::{Error, ply, spz};

#[test]
fn formats_are_named_by_their_extension_in_any_case() {
    for (name, want) in [
        ("a.ply", Format::Ply),
        ("a.PLY", Format::Ply),
        ("dir.v2/a.Spz", Format::Spz),
        ("a.splat", Format::Splat),
        ("a.glb", Format::Glb),
    ] {
        assert_eq!(Format::of(Path::new(name)).unwrap(), want, "{name}");
    }
    for (name, shown) in [("a.obj", "`.obj`"), ("model", "(no extension)")] {
        let e = Format::of(Path::new(name)).unwrap_err();
        assert!(matches!(e, Error::UnknownFormat { .. }), "{e:?}");
        let text = e.to_string();
        assert!(
            text.starts_with(&format!("{name}: unknown splat format {shown}")),
            "{text}"
        );
    }
}

#[test]
fn the_render_mode_survives_the_formats_that_can_say_it() {
    let s = ply::read_splats(&gt_path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for antialiased in [false, true] {
        for ext in ["ply", "spz", "splat", "glb"] {
            let p = dir.path().join(format!("m{antialiased}.{ext}"));
            let format = write_model(&p, &s, antialiased, &spz::SpzOptions::default()).unwrap();
            let back = read_model(&p).unwrap();
            assert_eq!(back.format, format);
            assert_eq!(back.splats.len(), s.len(), "{ext}");
            // Only an SPZ has a format version, the one it was written with.
            let version = (format == Format::Spz).then_some(spz::SpzOptions::default().version);
            assert_eq!(back.spz_version, version, "{ext}");
            // The PLY and SPZ readers say what the file says, independently of this module.
            let recorded = match format {
                Format::Ply => ply::read_model(&p).unwrap().antialiased,
                Format::Spz => spz::read_spz(&p).unwrap().antialiased,
                Format::Splat | Format::Glb => false,
            };
            assert_eq!(back.antialiased, recorded, "{ext}");
            assert_eq!(
                back.antialiased,
                antialiased && format.records_antialiased(),
                "{ext}"
            );
        }
    }
    // An SPZ's own options' flag gives way to the model's.
    let p = dir.path().join("flag.spz");
    let options = spz::SpzOptions {
        antialiased: true,
        ..spz::SpzOptions::default()
    };
    write_model(&p, &s, false, &options).unwrap();
    assert!(!read_model(&p).unwrap().antialiased);
}

#[test]
fn an_unknown_extension_writes_nothing() {
    let s = ply::read_splats(&gt_path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.obj");
    assert!(write_model(&p, &s, false, &spz::SpzOptions::default()).is_err());
    assert!(read_model(&p).is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Found by an adversarial sweep: `.splat` and `.glb` store linear scales, so a log-scale of
/// 100 (e¹⁰⁰ overflows f32) or −1e30 (e⁻¹⁰³⁰ is 0) was written as ∞ or 0, which the readers then
/// refused; and an empty model made a 0-byte `.splat` that its reader takes for a cut file.
#[test]
fn what_a_linear_scale_format_cannot_hold_is_refused_before_writing() {
    let gt = ply::read_splats(&gt_path()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    for (log_scale, says) in [(100.0_f32, "infinite"), (-1e30, "zero")] {
        let mut s = gt.clone();
        s.log_scales[7].y = log_scale;
        for ext in ["splat", "glb"] {
            let p = dir.path().join(format!("m.{ext}"));
            let e = write_model(&p, &s, false, &spz::SpzOptions::default()).unwrap_err();
            assert!(matches!(e, Error::Unwritable { .. }), "{e:?}");
            let msg = e.to_string();
            assert!(msg.contains(&format!("m.{ext}")), "{msg}");
            assert!(msg.contains("splat 7: scale_1"), "{msg}");
            assert!(msg.contains(says), "{msg}");
            assert!(!p.exists(), "{ext} written");
        }
        // PLY and SPZ store log-scales: both take the value and read it back.
        for ext in ["ply", "spz"] {
            let p = dir.path().join(format!("m.{ext}"));
            write_model(&p, &s, false, &spz::SpzOptions::default()).unwrap();
            assert_eq!(read_model(&p).unwrap().splats.len(), s.len());
        }
    }
    let empty = splat_core::Splats::new(gt.sh_degree);
    for ext in ["splat", "glb"] {
        let p = dir.path().join(format!("empty.{ext}"));
        let msg = write_model(&p, &empty, false, &spz::SpzOptions::default())
            .unwrap_err()
            .to_string();
        assert!(msg.contains("the model holds no splats"), "{msg}");
        assert!(!p.exists());
    }
}
