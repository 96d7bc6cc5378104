//! SPZ (`splat_core::spz`): round trips within the format's quantisation steps, the frame change
//! to SPZ's right-up-back axes checked on the raw bytes, and clear errors for broken files.

use std::io::{Read, Write};
use std::path::Path;

use glam::{Quat, Vec3};
use splat_core::Splats;
use splat_core::spz::{SpzOptions, decode_spz, encode_spz, read_spz, write_spz};

fn gt() -> Splats {
    splat_core::ply::read_splats(Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../testdata/splat-scene/gt.ply"
    )))
    .unwrap()
}

fn gunzip(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    flate2::read::GzDecoder::new(bytes)
        .read_to_end(&mut out)
        .unwrap();
    out
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    gz.write_all(bytes).unwrap();
    gz.finish().unwrap()
}

#[test]
fn every_attribute_comes_back_within_its_quantisation_step() {
    let s = gt();
    let m = decode_spz(
        Path::new("x.spz"),
        &encode_spz(&s, &SpzOptions::default()).unwrap(),
    )
    .unwrap();
    assert_eq!((m.version, m.antialiased), (3, false));
    let b = &m.splats;
    assert_eq!((b.len(), b.sh_degree), (s.len(), s.sh_degree));
    let pos_step = 0.5 / (1_u32 << m.fractional_bits) as f32;
    let k = s.coeffs_per_splat();
    for i in 0..s.len() {
        let d = (s.means[i] - b.means[i]).abs().max_element();
        assert!(d <= pos_step * 1.0001, "splat {i}: position off by {d}");
        for a in 0..3 {
            let (x, y) = (s.log_scales[i][a], b.log_scales[i][a]);
            // 1/16 steps from −10 up to 255/16 − 10; outside, the value is clamped.
            let want = x.clamp(-10.0, 255.0 / 16.0 - 10.0);
            assert!(
                (want - y).abs() <= 1.0 / 32.0 + 1e-5,
                "splat {i}: log-scale {x} -> {y}"
            );
        }
        let (o, p) = (s.opacity(i), b.opacity(i));
        assert!(
            (o - p).abs() <= 0.5 / 255.0 + 1e-5,
            "splat {i}: opacity {o} -> {p}"
        );
        let (q, r) = (s.rotation(i), b.rotation(i));
        let angle = 2.0 * q.dot(r).abs().min(1.0).acos();
        assert!(angle < 4e-3, "splat {i}: rotation off by {angle} rad");
        let dc_step = 0.5 / (0.15 * 255.0);
        for ch in 0..3 {
            let (x, y) = (s.sh[i * k][ch], b.sh[i * k][ch]);
            let want = x.clamp(-127.5 / (0.15 * 255.0), 127.5 / (0.15 * 255.0));
            assert!(
                (want - y).abs() <= dc_step + 1e-5,
                "splat {i}: DC {x} -> {y}"
            );
            for j in 1..k {
                let (x, y) = (s.sh[i * k + j][ch], b.sh[i * k + j][ch]);
                // Degree 1 keeps 5 bits (buckets of 8/128), degrees 2–3 keep 4 (16/128); the
                // byte's range is [−1, 127/128].
                let bucket = if j < 4 { 8.0 } else { 16.0 } / 128.0;
                let want = x.clamp(-1.0, 127.0 / 128.0);
                assert!(
                    (want - y).abs() <= bucket / 2.0 + 1.0 / 256.0 + 1e-5,
                    "splat {i}: SH {j} {x} -> {y}"
                );
            }
        }
    }
}

#[test]
fn the_stored_frame_is_right_up_back() {
    // One splat at (1, 2, 3), turned 90° about y, with a degree-1 SH term along each axis: the
    // raw SPZ bytes hold it a half turn about x away from this crate's right-down-forward frame.
    let mut s = Splats::new(1);
    let q = Quat::from_rotation_y(std::f32::consts::FRAC_PI_2);
    s.push(
        Vec3::new(1.0, 2.0, 3.0),
        Vec3::new(-1.0, -2.0, -3.0),
        [q.w, q.x, q.y, q.z],
        0.0,
        &[
            [0.0; 3],
            [0.5, 0.0, 0.0],
            [0.0, 0.25, 0.0],
            [0.0, 0.0, -0.5],
        ],
    );
    let raw = gunzip(&encode_spz(&s, &SpzOptions::default()).unwrap());
    let bits = raw[13];
    let fixed = |o: usize| {
        let v = i32::from(raw[o]) | i32::from(raw[o + 1]) << 8 | i32::from(raw[o + 2]) << 16;
        let v = if v >= 1 << 23 { v - (1 << 24) } else { v };
        v as f32 / (1_u32 << bits) as f32
    };
    assert_eq!([fixed(16), fixed(19), fixed(22)], [1.0, -2.0, -3.0]);
    // SH bytes follow positions (9), alpha (1), colour (3), scales (3), rotation (4): coefficient
    // 1 (y) and 2 (z) change sign, 3 (x) does not; 5 bits keep 0.5 and 0.25 exactly.
    let sh = &raw[16 + 20..16 + 29];
    assert_eq!(sh, &[64, 128, 128, 128, 96, 128, 128, 128, 64]);
    // Read back, the frame change is undone.
    let back = decode_spz(Path::new("x.spz"), &gzip(&raw)).unwrap().splats;
    let r = back.rotation(0);
    assert!((r.dot(q)).abs() > 0.999_99, "{r:?} vs {q:?}");
}

#[test]
fn written_files_read_back_and_keep_their_flags() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("m.spz");
    let s = gt();
    let opts = SpzOptions {
        antialiased: true,
        fractional_bits: Some(10),
        ..SpzOptions::default()
    };
    write_spz(&p, &s, &opts).unwrap();
    let m = read_spz(&p).unwrap();
    assert!(m.antialiased);
    assert_eq!(m.fractional_bits, 10);
    assert_eq!(m.splats.len(), s.len());
    assert_eq!(
        std::fs::read_dir(dir.path()).unwrap().count(),
        1,
        "a temporary file was left"
    );
}

#[test]
fn models_outside_the_format_are_refused() {
    let mut s = Splats::new(0);
    s.push(
        Vec3::new(1e7, 0.0, 0.0),
        Vec3::ZERO,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        &[[0.0; 3]],
    );
    let e = encode_spz(&s, &SpzOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("24-bit"), "{e}");
    s.means[0] = Vec3::new(f32::NAN, 0.0, 0.0);
    assert!(encode_spz(&s, &SpzOptions::default()).is_err());
    s.means[0] = Vec3::new(100.0, 0.0, 0.0);
    let too_fine = SpzOptions {
        fractional_bits: Some(20),
        ..SpzOptions::default()
    };
    let e = encode_spz(&s, &too_fine).unwrap_err().to_string();
    assert!(
        e.contains("splat 0") && e.contains("20 fractional bits"),
        "{e}"
    );
    let bad_bits = SpzOptions {
        sh1_bits: 0,
        ..SpzOptions::default()
    };
    assert!(
        encode_spz(&s, &bad_bits)
            .unwrap_err()
            .to_string()
            .contains("sh1_bits")
    );
}

#[test]
fn broken_files_give_errors_that_say_what_is_wrong() {
    let good = gunzip(&encode_spz(&gt(), &SpzOptions::default()).unwrap());
    let path = Path::new("bad.spz");
    let check = |bytes: &[u8], want: &str| {
        let e = decode_spz(path, bytes).unwrap_err().to_string();
        assert!(e.starts_with("bad.spz: SPZ: ") && e.contains(want), "{e}");
    };
    check(b"", "gzip");
    check(b"not gzip at all", "gzip");
    check(&gzip(&good[..10]), "gzip stream holding an SPZ header");
    let mut v = good.clone();
    v[0] ^= 0xff;
    check(&gzip(&v), "magic");
    let mut v = good.clone();
    v[4] = 9;
    check(&gzip(&v), "version 9");
    let mut v = good.clone();
    v[12] = 4;
    check(&gzip(&v), "SH degree 4");
    let mut v = good.clone();
    v[13] = 24;
    check(&gzip(&v), "24 fractional bits");
    check(&gzip(&good[..good.len() - 1]), "bytes of attributes");
    let mut v = good.clone();
    v.push(0);
    // The count it passed is named (the message said "more than bytes of attributes").
    let need = good.len() - 16;
    check(&gzip(&v), &format!("more than {need} bytes of attributes"));
    // A header claiming 4 billion splats over a short body: refused, nothing huge allocated.
    let mut v = good.clone();
    v[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
    check(&gzip(&v), "splats, more than");
    let mut v = good.clone();
    v[8..12].copy_from_slice(&100_000_000_u32.to_le_bytes());
    check(&gzip(&v), "need");
    // Version 4's uncompressed header is recognised and named.
    check(&good[..16], "version 4");
    // A truncated gzip stream.
    let z = gzip(&good);
    check(&z[..z.len() / 2], "corrupt gzip stream");
    // Bytes after the gzip stream (a file appended to itself, junk) were ignored.
    let twice = [z.as_slice(), z.as_slice()].concat();
    check(
        &twice,
        &format!(
            "{} bytes after the gzip stream, which ends at byte {}",
            z.len(),
            z.len()
        ),
    );
    check(
        &[z.as_slice(), b"junk"].concat(),
        "4 bytes after the gzip stream",
    );
}

#[test]
fn version_2_files_are_read() {
    // Version 2 stores x, y, z of the unit quaternion with w ≥ 0 as u8 = (c + 1)·127.5 and
    // leaves w to be derived. Build a version-2 file from a version-3 one and check each
    // rotation against that rule evaluated here (in SPZ's frame), then against the original.
    let s = gt();
    let v3 = gunzip(&encode_spz(&s, &SpzOptions::default()).unwrap());
    let n = s.len();
    let rot = 9 * n + n + 3 * n + 3 * n;
    let mut v2 = v3[..16 + rot].to_vec();
    v2[4] = 2;
    let spz_frame = splat_core::frame::y_up_frame(&s);
    let mut expected = Vec::new();
    for i in 0..n {
        let q = spz_frame.rotation(i);
        let q = if q.w < 0.0 { -q } else { q };
        let bytes = [q.x, q.y, q.z].map(|c| ((c + 1.0) * 127.5).round() as u8);
        let [x, y, z] = bytes.map(|b| f64::from(b) / 127.5 - 1.0);
        expected.push([(1.0 - x * x - y * y - z * z).max(0.0).sqrt(), x, y, z]);
        v2.extend(bytes);
    }
    v2.extend_from_slice(&v3[16 + rot + 4 * n..]);
    let m = decode_spz(Path::new("v2.spz"), &gzip(&v2)).unwrap();
    assert_eq!(m.version, 2);
    let read = splat_core::frame::y_up_frame(&m.splats);
    for (i, (got, want)) in read.rotations.iter().zip(&expected).enumerate() {
        for (c, (&got, &want)) in got.iter().zip(want).enumerate() {
            let got = f64::from(got);
            assert!(
                (got - want).abs() < 1e-5,
                "splat {i}: component {c} {got} vs {want}"
            );
        }
    }
    // Everything but the rotations is the same as version 3's.
    let m3 = decode_spz(Path::new("v3.spz"), &gzip(&v3)).unwrap();
    assert_eq!(m.splats.means, m3.splats.means);
    assert_eq!(m.splats.sh, m3.splats.sh);
}

/// Version 4's parts read by hand.
struct V4Parts<'a> {
    header: &'a [u8],
    /// Each table entry: (compressed, uncompressed) sizes.
    entries: Vec<(u64, u64)>,
    frames: Vec<&'a [u8]>,
}

fn v4_parts(bytes: &[u8]) -> V4Parts<'_> {
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let u64_at = |o: usize| u64::from_le_bytes(bytes[o..o + 8].try_into().unwrap());
    let (streams, toc) = (usize::from(bytes[15]), u32_at(16) as usize);
    let entries: Vec<(u64, u64)> = (0..streams)
        .map(|i| (u64_at(toc + 16 * i), u64_at(toc + 16 * i + 8)))
        .collect();
    let mut at = toc + 16 * streams;
    let mut frames = Vec::new();
    for &(c, _) in &entries {
        frames.push(&bytes[at..at + c as usize]);
        at += c as usize;
    }
    assert_eq!(at, bytes.len(), "the last stream ends the file");
    V4Parts {
        header: &bytes[..32],
        entries,
        frames,
    }
}

fn v4_options() -> SpzOptions {
    SpzOptions {
        version: 4,
        ..SpzOptions::default()
    }
}

#[test]
fn version_4_holds_version_3_s_blocks_in_zstd_streams() {
    for degree in [3, 0] {
        let mut s = gt();
        if degree == 0 {
            // The DC coefficient alone: no SH block, so no sixth stream.
            let k = s.coeffs_per_splat();
            s.sh = (0..s.len()).map(|i| s.sh[i * k]).collect();
            s.sh_degree = 0;
        }
        let opts = SpzOptions {
            antialiased: true,
            ..v4_options()
        };
        let v4 = encode_spz(&s, &opts).unwrap();
        let v3 = gunzip(&encode_spz(&s, &SpzOptions { version: 3, ..opts }).unwrap());
        let V4Parts {
            header,
            entries,
            frames,
        } = v4_parts(&v4);
        // The clear header: version 3's 16 bytes with the version changed, the stream count,
        // the table right after the 32 bytes, and zeros.
        assert_eq!(&header[..4], b"NGSP");
        assert_eq!(u32::from_le_bytes(header[4..8].try_into().unwrap()), 4);
        assert_eq!(&header[8..15], &v3[8..15]);
        assert_eq!(header[14] & 1, 1, "antialiased flag");
        assert_eq!(usize::from(header[15]), if degree == 0 { 5 } else { 6 });
        assert_eq!(u32::from_le_bytes(header[16..20].try_into().unwrap()), 32);
        assert!(header[20..].iter().all(|&b| b == 0));
        // Each stream is one zstd frame of the next block of version 3's body, in order.
        let mut body = Vec::new();
        for (&(c, u), frame) in entries.iter().zip(&frames) {
            assert_eq!(c as usize, frame.len());
            let block = zstd::stream::decode_all(*frame).unwrap();
            assert_eq!(block.len() as u64, u);
            body.extend(block);
        }
        assert_eq!(body, v3[16..]);
        // So both read to the same splats.
        let a = decode_spz(Path::new("v4.spz"), &v4).unwrap();
        let b = decode_spz(Path::new("v3.spz"), &gzip(&v3)).unwrap();
        assert_eq!((a.version, b.version), (4, 3));
        assert_eq!(a.splats, b.splats);
        assert!(a.antialiased && !a.skipped_extensions);
    }
    let e = encode_spz(
        &gt(),
        &SpzOptions {
            version: 5,
            ..SpzOptions::default()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("SPZ version 5"), "{e}");
}

#[test]
fn version_4_extension_records_are_skipped_and_said_so() {
    let s = gt();
    let v4 = encode_spz(&s, &v4_options()).unwrap();
    let plain = decode_spz(Path::new("m.spz"), &v4).unwrap();
    // Eight bytes of extension records between the header and the table, flag 0x2 set.
    let mut ext = v4[..32].to_vec();
    ext[14] |= 2;
    ext[16..20].copy_from_slice(&40_u32.to_le_bytes());
    ext.extend([7u8; 8]);
    ext.extend_from_slice(&v4[32..]);
    let m = decode_spz(Path::new("ext.spz"), &ext).unwrap();
    assert!(m.skipped_extensions);
    assert_eq!(m.splats, plain.splats);
}

#[test]
fn broken_version_4_files_give_errors_that_say_what_is_wrong() {
    let good = encode_spz(&gt(), &v4_options()).unwrap();
    let path = Path::new("bad.spz");
    let check = |bytes: &[u8], want: &str| {
        let e = decode_spz(path, bytes).unwrap_err().to_string();
        assert!(e.starts_with("bad.spz: SPZ: ") && e.contains(want), "{e}");
    };
    check(&good[..31], "32-byte header");
    let mut v = good.clone();
    v[4] = 3;
    check(&v, "version 3 with a clear header");
    let mut v = good.clone();
    v[15] = 5;
    check(&v, "5 streams where");
    let mut v = good.clone();
    v[16..20].copy_from_slice(&(good.len() as u32).to_le_bytes());
    check(&v, "table of contents");
    let mut v = good.clone();
    v[16..20].copy_from_slice(&8_u32.to_le_bytes());
    check(&v, "table of contents");
    // The positions' table entry says one byte more than 4,000 splats need.
    let mut v = good.clone();
    v[40..48].copy_from_slice(&36_001_u64.to_le_bytes());
    check(&v, "stream 0 holds 36001 bytes");
    // A compressed size past the end of the file.
    let mut v = good.clone();
    v[32..40].copy_from_slice(&u64::MAX.to_le_bytes());
    check(&v, "runs past the end");
    check(&good[..good.len() - 1], "runs past the end");
    let mut v = good.clone();
    v.push(0);
    check(&v, "1 bytes after the last stream");
    // A frame's bytes damaged: zstd's own check, or the size it decompresses to.
    let mut v = good.clone();
    let first = 32 + 16 * 6;
    for b in &mut v[first + 4..first + 40] {
        *b ^= 0x5a;
    }
    check(&v, "stream 0");
    // One bit flipped anywhere in a frame's compressed bytes: refused (each frame carries
    // zstd's checksum; without it a third of such files were read as other values).
    let parts = v4_parts(&good);
    let mut at = 32 + 16 * parts.entries.len();
    for (i, frame) in parts.frames.iter().enumerate() {
        for k in (0..frame.len()).step_by(frame.len().div_ceil(40).max(1)) {
            let mut v = good.clone();
            v[at + k] ^= 1 << (k % 8);
            let e = decode_spz(path, &v);
            assert!(
                e.is_err(),
                "stream {i}: bit {} of byte {k} flipped was read",
                k % 8
            );
        }
        at += frame.len();
    }
    // A header claiming 200 million splats: refused by the table, nothing huge allocated.
    let mut v = good.clone();
    v[8..12].copy_from_slice(&200_000_000_u32.to_le_bytes());
    check(&v, "stream 0 holds 36000 bytes where 200000000 splats need");
}
