//! Property tests over the 3DGS PLY and SPZ readers (the stable-toolchain companions of the
//! cargo-fuzz targets `splat_ply` and `splat_spz` in `fuzz/`, see `docs/fuzzing.md`): arbitrary
//! bytes and randomly mutated real files go into `ply::parse_splats` and `spz::decode_spz`. Each
//! must return `Ok` or an `Error` that names the file; a panic, a hang or an allocation the file
//! cannot justify fails the test.

use std::path::Path;

use proptest::prelude::*;
use splat_core::{Error, ply};

/// The first `n` splats of the test scene's `gt.ply` (Inria's layout: 62 floats per splat),
/// with the header's vertex count set to `n`.
fn gt_cut(n: usize) -> Vec<u8> {
    let gt = include_bytes!("../../testdata/splat-scene/gt.ply");
    let body = gt.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
    let header = std::str::from_utf8(&gt[..body])
        .unwrap()
        .replace("element vertex 4000\n", &format!("element vertex {n}\n"));
    assert!(
        header.contains(&format!("element vertex {n}\n")),
        "gt.ply's header changed"
    );
    let mut out = header.into_bytes();
    out.extend(&gt[body..body + n * 62 * 4]);
    out
}

/// A two-splat ASCII file with SH degree 0.
const ASCII_SEED: &[u8] = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n\
property float y\nproperty float z\nproperty float f_dc_0\nproperty float f_dc_1\n\
property float f_dc_2\nproperty float opacity\nproperty float scale_0\nproperty float scale_1\n\
property float scale_2\nproperty float rot_0\nproperty float rot_1\nproperty float rot_2\n\
property float rot_3\nend_header\n0 0 0 0.1 0.2 0.3 0 -3 -3 -3 1 0 0 0\n\
1 1 1 -0.1 0 0.5 2 -2 -4 -1 0.7 0.7 0 0\n";

/// Numbers that make readers misbehave when they trust a file.
#[path = "../../fuzz/props/mutation.rs"]
mod mutation;

use mutation::{apply, edit};

/// Parses `bytes`; an error must name the file.
fn parse(bytes: &[u8]) -> Result<(), TestCaseError> {
    if let Err(e) = ply::parse_splats(Path::new("props-input.ply"), bytes) {
        let message = e.to_string();
        prop_assert!(
            message.contains("props-input.ply"),
            "error does not name the file: {message}"
        );
        prop_assert!(!matches!(e, Error::Inconsistent(_)), "{e:?}");
    }
    Ok(())
}

/// The content (header and attributes, before gzip) of an SPZ of `n` splats of the test scene.
fn spz_content(n: usize) -> Vec<u8> {
    let splats = ply::parse_splats(Path::new("gt-cut.ply"), &gt_cut(n)).unwrap();
    let spz = splat_core::spz::encode_spz(&splats, &Default::default()).unwrap();
    let mut content = Vec::new();
    std::io::Read::read_to_end(&mut flate2::read::GzDecoder::new(&spz[..]), &mut content).unwrap();
    content
}

/// Compresses `content` as an SPZ file and decodes it; an error must name the file.
fn decode_spz(content: &[u8]) -> Result<(), TestCaseError> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    std::io::Write::write_all(&mut gz, content).unwrap();
    let file = gz.finish().unwrap();
    if let Err(e) = splat_core::spz::decode_spz(Path::new("props-input.spz"), &file) {
        let message = e.to_string();
        prop_assert!(
            message.contains("props-input.spz"),
            "error does not name the file: {message}"
        );
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn spz_reader_survives_mutated_content(edits in prop::collection::vec(edit(), 1..8)) {
        decode_spz(&apply(spz_content(3), &edits))?;
    }

    #[test]
    fn spz_reader_survives_mutated_version_4_files(edits in prop::collection::vec(edit(), 1..8)) {
        // Version 4 keeps its header and table in the clear: mutate the file itself.
        let options = splat_core::spz::SpzOptions {
            version: splat_core::spz::ZSTD_VERSION,
            ..Default::default()
        };
        let splats = ply::parse_splats(Path::new("gt-cut.ply"), &gt_cut(3)).unwrap();
        let file = splat_core::spz::encode_spz(&splats, &options).unwrap();
        if let Err(e) = splat_core::spz::decode_spz(Path::new("props-input.spz"), &apply(file, &edits)) {
            prop_assert!(e.to_string().contains("props-input.spz"), "{e}");
        }
    }

    #[test]
    fn spz_reader_survives_arbitrary_bytes(
        header in prop::sample::select(vec![Vec::new(), spz_content(0)]),
        body in prop::collection::vec(any::<u8>(), 0..512),
        compress in any::<bool>(),
    ) {
        let mut bytes = header;
        bytes.extend(body);
        if compress {
            decode_spz(&bytes)?;
        } else if let Err(e) = splat_core::spz::decode_spz(Path::new("props-input.spz"), &bytes) {
            prop_assert!(e.to_string().contains("props-input.spz"), "{e}");
        }
    }

    #[test]
    fn reader_survives_arbitrary_bytes(
        header in prop::sample::select(vec![
            Vec::new(),
            b"ply\n".to_vec(),
            gt_cut(0),
            ASCII_SEED[..ASCII_SEED.windows(11).position(|w| w == b"end_header\n").unwrap() + 11].to_vec(),
        ]),
        body in prop::collection::vec(any::<u8>(), 0..768),
    ) {
        let mut bytes = header;
        bytes.extend(body);
        parse(&bytes)?;
    }

    #[test]
    fn reader_survives_mutated_files(
        ascii in any::<bool>(),
        edits in prop::collection::vec(edit(), 1..8),
    ) {
        let original = if ascii { ASCII_SEED.to_vec() } else { gt_cut(3) };
        parse(&apply(original, &edits))?;
    }
}
