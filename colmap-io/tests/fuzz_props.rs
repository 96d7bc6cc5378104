//! Property tests over the COLMAP readers (the stable-toolchain companion of the cargo-fuzz
//! targets in `fuzz/`, see `docs/fuzzing.md`): arbitrary bytes and randomly mutated real files
//! become one of `cameras`, `images` or `points3D` (text and binary) beside the other two, and
//! `read_model_as` reads them. It must return `Ok` or an `Error` that names the file; a panic,
//! a hang or an allocation the file cannot justify fails the test.

use std::path::Path;
use std::sync::OnceLock;

use colmap_io::{Error, Format, read_model_as, write_model};
use proptest::prelude::*;

const SPARSE: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../testdata/colmap/maupertuis/sparse/0"
);
const NAMES: [&str; 3] = ["cameras", "images", "points3D"];

/// The three files of the Maupertuis model in each encoding (binary written by this crate).
fn model_files(format: Format) -> &'static [Vec<u8>; 3] {
    static TEXT: OnceLock<[Vec<u8>; 3]> = OnceLock::new();
    static BINARY: OnceLock<[Vec<u8>; 3]> = OnceLock::new();
    let read = |dir: &Path, ext: &str| {
        NAMES.map(|n| std::fs::read(dir.join(format!("{n}.{ext}"))).unwrap())
    };
    match format {
        Format::Text => TEXT.get_or_init(|| read(Path::new(SPARSE), "txt")),
        Format::Binary => BINARY.get_or_init(|| {
            let rec = colmap_io::read_model(Path::new(SPARSE)).unwrap();
            let dir = tempfile::tempdir().unwrap();
            write_model(dir.path(), &rec, Format::Binary).unwrap();
            read(dir.path(), "bin")
        }),
    }
}

/// Numbers that make readers misbehave when they trust a file.
#[path = "../../fuzz/props/mutation.rs"]
mod mutation;

use mutation::{apply, edit};

/// Writes `files` as a model in a fresh temporary directory and reads it; an error must name
/// one of the model's files.
fn read_files(format: Format, files: [&[u8]; 3]) -> Result<(), TestCaseError> {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in NAMES.iter().zip(files) {
        std::fs::write(
            dir.path().join(format!("{name}.{}", format.extension())),
            bytes,
        )
        .unwrap();
    }
    if let Err(e) = read_model_as(dir.path(), format) {
        let message = e.to_string();
        let named = NAMES
            .iter()
            .any(|n| message.contains(&format!("{n}.{}", format.extension())));
        prop_assert!(named, "error names no model file: {message}");
        prop_assert!(
            matches!(e, Error::Format { .. } | Error::Io { .. }),
            "{e:?}"
        );
    }
    Ok(())
}

/// A valid empty file of each encoding.
fn empty(format: Format) -> &'static [u8] {
    match format {
        Format::Text => b"",
        Format::Binary => &[0; 8],
    }
}

fn format() -> impl Strategy<Value = Format> {
    prop_oneof![Just(Format::Text), Just(Format::Binary)]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn readers_survive_arbitrary_bytes(
        format in format(),
        which in 0usize..3,
        bytes in prop::collection::vec(any::<u8>(), 0..512),
        count in prop::option::of(any::<u64>()),
    ) {
        // Binary files start with a count: half the cases get a (random) one up front.
        let mut data = count.map(|c| c.to_le_bytes().to_vec()).unwrap_or_default();
        data.extend(bytes);
        let mut files = [empty(format); 3];
        files[which] = &data;
        read_files(format, files)?;
    }
}

proptest! {
    // Each case reads the whole Maupertuis model (450 KB of images.txt): few cases.
    #![proptest_config(ProptestConfig::with_cases(24))]

    #[test]
    fn readers_survive_mutated_models(
        format in format(),
        which in 0usize..3,
        edits in prop::collection::vec(edit(), 1..8),
    ) {
        let model = model_files(format);
        let mutated = apply(model[which].clone(), &edits);
        let mut files = [&model[0][..], &model[1][..], &model[2][..]];
        files[which] = &mutated;
        read_files(format, files)?;
    }
}
