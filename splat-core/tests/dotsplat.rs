//! The antimatter15 `.splat` layout (`splat_core::export`): written files read back within the
//! format's 8-bit steps, and broken files give errors naming the file and the problem.

use std::path::Path;

use splat_core::Splats;
use splat_core::export::{
    SPLAT_RECORD_BYTES, decode_splat, encode_record, read_splat, write_splat,
};

fn gt() -> Splats {
    splat_core::ply::read_splats(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene/gt.ply"
    )))
    .unwrap()
}

#[test]
fn written_files_read_back_within_the_8_bit_steps() {
    let s = gt();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("gt.splat");
    write_splat(&p, &s).unwrap();
    assert_eq!(
        std::fs::metadata(&p).unwrap().len(),
        (s.len() * SPLAT_RECORD_BYTES) as u64
    );
    let b = read_splat(&p).unwrap();
    assert_eq!((b.len(), b.sh_degree), (s.len(), 0));
    // The writer sorts by size and opacity; positions are stored exactly, so they pair splats.
    let key = |m: glam::Vec3| m.to_array().map(f32::to_bits);
    let mut by_pos: Vec<usize> = (0..b.len()).collect();
    by_pos.sort_by_key(|&j| key(b.means[j]));
    for i in 0..s.len() {
        let j = by_pos[by_pos
            .binary_search_by_key(&key(s.means[i]), |&j| key(b.means[j]))
            .unwrap()];
        assert_eq!(s.means[i], b.means[j]);
        // Linear scales are stored as f32: exp then ln.
        let d = (s.log_scales[i] - b.log_scales[j]).abs().max_element();
        assert!(d <= 1e-5, "splat {i}: log-scale off by {d}");
        // Colour and opacity: half an 8-bit step (colours clamped to [0, 1] first).
        let want = splat_core::sh_dc_to_rgb(s.sh_of(i)[0]).map(|c| c.clamp(0.0, 1.0));
        let got = splat_core::sh_dc_to_rgb(b.sh_of(j)[0]);
        for c in 0..3 {
            assert!(
                (want[c] - got[c]).abs() <= 0.5 / 255.0 + 1e-6,
                "splat {i}: colour {want:?} vs {got:?}"
            );
        }
        let o = s.opacity(i).clamp(1e-6, 1.0 - 1e-6);
        assert!(
            (o - b.opacity(j)).abs() <= 0.5 / 255.0 + 1e-6,
            "splat {i}: opacity {o} vs {}",
            b.opacity(j)
        );
        // Rotation: each component of the unit quaternion within half a step of 1/128, so the
        // angle between the two is small.
        let (q, r) = (s.rotation(i), b.rotation(j));
        assert!(
            q.dot(r).abs() >= 0.9995,
            "splat {i}: rotation {q} vs {r} (dot {})",
            q.dot(r)
        );
    }
    // Records re-encode to the same bytes: the reader inverts the writer's quantisation.
    let bytes = std::fs::read(&p).unwrap();
    for j in 0..b.len() {
        let r = encode_record(&b, j);
        let at = j * SPLAT_RECORD_BYTES;
        assert_eq!(&r[..24], &bytes[at..at + 24], "record {j}: floats");
        assert_eq!(&r[24..28], &bytes[at + 24..at + 28], "record {j}: RGBA");
    }
}

#[test]
fn broken_files_give_errors_naming_the_file_and_problem() {
    let mut s = Splats::new(0);
    for k in 0..3 {
        s.push(
            glam::Vec3::splat(k as f32),
            glam::Vec3::ZERO,
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            &[[0.0; 3]],
        );
    }
    let good: Vec<u8> = (0..3).flat_map(|i| encode_record(&s, i)).collect();
    let path = Path::new("bad.splat");
    let err = |b: &[u8]| decode_splat(path, b).unwrap_err().to_string();
    assert_eq!(
        err(&good[..good.len() - 5]),
        "bad.splat: .splat: 91 bytes are not whole 32-byte records: 2 records and 27 bytes over \
         from byte offset 64 (cut short, or not a .splat file)"
    );
    assert_eq!(err(&[]), "bad.splat: .splat: an empty file: no records");
    let mut b = good.clone();
    b[32 + 8..32 + 12].copy_from_slice(&f32::NAN.to_le_bytes());
    assert_eq!(err(&b), "bad.splat: vertex 1, property z: NaN");
    let mut b = good.clone();
    b[64 + 16..64 + 20].copy_from_slice(&f32::NEG_INFINITY.to_le_bytes());
    assert_eq!(err(&b), "bad.splat: vertex 2, property scale_1: -inf");
    let mut b = good;
    b[12..16].copy_from_slice(&0.0f32.to_le_bytes());
    assert_eq!(
        err(&b),
        "bad.splat: .splat: record 0 (byte offset 12): scale_0 = 0; scales must be positive"
    );
}
