//! `transcode convert` on its own input and through a symbolic link.

mod support;

use std::path::PathBuf;

use support::{arg, check, transcode};

fn gt() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene/gt.ply"
    ))
}

/// Found by an adversarial sweep: `convert same.ply same.ply` was not refused, and an output
/// that is a symbolic link was replaced by a regular file instead of writing its target.
#[test]
fn convert_refuses_its_own_input_and_writes_through_a_link() {
    let dir = tempfile::tempdir().unwrap();
    let model = dir.path().join("m.ply");
    std::fs::copy(gt(), &model).unwrap();
    let before = std::fs::read(&model).unwrap();
    let out = transcode(&["convert", &arg(&model), &arg(&model)])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("which this command reads"), "{said}");
    assert_eq!(
        std::fs::read(&model).unwrap(),
        before,
        "the input was touched"
    );

    #[cfg(unix)]
    {
        let target = dir.path().join("target.spz");
        let link = dir.path().join("link.spz");
        std::fs::write(&target, b"old").unwrap();
        std::os::unix::fs::symlink(&target, &link).unwrap();
        check(
            &transcode(&["convert", &arg(&model), &arg(&link)])
                .output()
                .unwrap(),
            "convert through a link",
        );
        assert!(
            std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink(),
            "the link was replaced"
        );
        let written = splat_core::model_file::read_model(&target).unwrap();
        assert_eq!(
            written.splats.len(),
            splat_core::ply::read_splats(&gt()).unwrap().len()
        );
        // A link to the input is the input.
        let to_input = dir.path().join("to_input.ply");
        std::os::unix::fs::symlink(&model, &to_input).unwrap();
        let out = transcode(&["convert", &arg(&model), &arg(&to_input)])
            .output()
            .unwrap();
        assert!(!out.status.success());
        assert_eq!(std::fs::read(&model).unwrap(), before);
    }
}
