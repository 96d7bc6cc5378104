//! Niantic's SPZ (`nianticlabs/spz`, `src/cc/load-spz.cc`), the gzip container of versions 2
//! and 3: about a tenth of the size of the Inria PLY with small, bounded quantisation errors.
//!
//! A file is one gzip stream holding a 16-byte header (magic `NGSP`, version, point count, SH
//! degree, fractional bits of the positions, flags, a reserved byte) and then one block per
//! attribute, each over all splats in order: positions (3 × 24-bit signed fixed point), alphas
//! (u8 of the activated opacity), colours (u8 of the DC coefficient, ±3.33 full scale), log-scales
//! (u8, 1/16 steps from −10), rotations (version 3: the smallest three of the unit quaternion,
//! 9 bits and a sign each, under the 2-bit index of the largest; version 2: x, y, z as u8) and the
//! higher SH bands (u8, ±1 full scale, coefficient-major with the channel innermost).
//!
//! SPZ stores its splats in a right-up-back frame (three.js and OpenGL); this crate's splats are
//! in COLMAP's right-down-forward frame. The two differ by a half turn about x, applied on write
//! and undone on read ([`crate::frame::y_up_frame`]), so a model keeps its place and look in viewers that
//! follow the format. Writing uses the full 24 bits of the positions (the fractional bits are
//! chosen from the largest coordinate) instead of Niantic's fixed 12, since this project's models
//! are often in voxel units of a 4,096 grid, which 12 fractional bits cannot hold.
//!
//! Written by hand: no Rust crate writes SPZ (`docs/reference/crates.md`); `flate2` does the gzip.

use std::io::{Read, Write};
use std::path::Path;

use glam::{Quat, Vec3};

use crate::frame::y_up_frame;
use crate::ply::MAX_SPLATS;
use crate::{Error, Splats, logit, num_sh_coeffs, sigmoid};

/// `NGSP` read as a little-endian u32.
pub const MAGIC: u32 = 0x5053_474e;
/// The version written: smallest-three quaternions in a gzip stream.
pub const VERSION: u32 = 3;
/// Bytes of the header at the start of the decompressed stream.
const HEADER_BYTES: usize = 16;
/// Full scale of the colour byte: u8 = dc·0.15·255 + 127.5 (`load-spz.cc`'s `colorScale`).
const COLOR_SCALE: f32 = 0.15;
/// Header flag: the model was trained with the antialiased (Mip-Splatting-style) rasteriser.
const FLAG_ANTIALIASED: u8 = 0x1;
/// The largest magnitude of a 24-bit signed integer.
const MAX_FIXED: f32 = 8_388_607.0;
/// Bits of each smallest-three component's magnitude (a sign bit comes on top).
const QUAT_BITS: u32 = 9;
const QUAT_MASK: u32 = (1 << QUAT_BITS) - 1;

/// How a model is packed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpzOptions {
    /// Bits kept of each degree-1 SH byte (1..=8; Niantic's default 5).
    pub sh1_bits: u8,
    /// Bits kept of each degree-2 and degree-3 SH byte (1..=8; Niantic's default 4).
    pub sh_rest_bits: u8,
    /// Fractional bits of the fixed-point positions; `None` takes the most that the largest
    /// coordinate leaves room for.
    pub fractional_bits: Option<u8>,
    /// Sets the header's antialiased flag.
    pub antialiased: bool,
}

impl Default for SpzOptions {
    fn default() -> Self {
        Self {
            sh1_bits: 5,
            sh_rest_bits: 4,
            fractional_bits: None,
            antialiased: false,
        }
    }
}

/// A model read from an SPZ file, with what its header says.
#[derive(Clone, Debug, PartialEq)]
pub struct SpzModel {
    /// The splats, in this crate's frame.
    pub splats: Splats,
    /// The file's format version (2 or 3).
    pub version: u32,
    /// Fractional bits of the stored positions (their step is 2^−bits).
    pub fractional_bits: u8,
    /// The header's antialiased flag.
    pub antialiased: bool,
}

/// Returns the SPZ bytes (gzip-compressed) of `splats`.
pub fn encode_spz(splats: &Splats, options: &SpzOptions) -> Result<Vec<u8>, Error> {
    let raw = pack(splats, options)?;
    let mut gz = flate2::write::GzEncoder::new(
        Vec::with_capacity(raw.len() / 2),
        flate2::Compression::default(),
    );
    gz.write_all(&raw)
        .and_then(|()| gz.finish())
        .map_err(|e| Error::Inconsistent(format!("gzip: {e}")))
}

/// Writes `splats` as an SPZ file (version 3), atomically.
pub fn write_spz(path: &Path, splats: &Splats, options: &SpzOptions) -> Result<(), Error> {
    let bytes = encode_spz(splats, options)?;
    atomic_output::write_atomic(path, &bytes).map_err(|e| Error::io(path, e))
}

/// Reads an SPZ file (version 2 or 3, gzip container).
pub fn read_spz(path: &Path) -> Result<SpzModel, Error> {
    let data = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    decode_spz(path, &data)
}

/// Decodes the bytes of an SPZ file; `path` is used in error messages.
pub fn decode_spz(path: &Path, data: &[u8]) -> Result<SpzModel, Error> {
    let err = |message: String| Error::Spz {
        path: path.to_path_buf(),
        message,
    };
    if data.len() >= 4 && u32::from_le_bytes([data[0], data[1], data[2], data[3]]) == MAGIC {
        return Err(err(
            "an uncompressed NGSP header: this is SPZ version 4 (zstd streams), which this reader \
             does not support; versions 2 and 3 (gzip) are read"
                .into(),
        ));
    }
    let mut gz = flate2::read::GzDecoder::new(data);
    let mut head = [0u8; HEADER_BYTES];
    gz.read_exact(&mut head)
        .map_err(|e| err(format!("not a gzip stream holding an SPZ header: {e}")))?;
    let word = |o: usize| u32::from_le_bytes([head[o], head[o + 1], head[o + 2], head[o + 3]]);
    let (magic, version, count) = (word(0), word(4), word(8));
    let (sh_degree, fractional_bits, flags) = (u32::from(head[12]), head[13], head[14]);
    if magic != MAGIC {
        return Err(err(format!(
            "magic 0x{magic:08x} where an SPZ file has 0x{MAGIC:08x} (`NGSP`)"
        )));
    }
    if !(2..=3).contains(&version) {
        return Err(err(format!(
            "version {version}; this reader reads versions 2 and 3"
        )));
    }
    if sh_degree > 3 {
        return Err(err(format!(
            "SH degree {sh_degree}; at most 3 is supported"
        )));
    }
    if fractional_bits > 23 {
        return Err(err(format!(
            "{fractional_bits} fractional bits in 24-bit positions (at most 23)"
        )));
    }
    let n = count as usize;
    if n > MAX_SPLATS {
        return Err(err(format!(
            "{n} splats, more than the {MAX_SPLATS} this reader accepts"
        )));
    }
    let layout = Layout::new(n, sh_degree, version);
    // Read what the stream holds, at most one byte past what the header promises: memory grows
    // with the data that is really there, so a header claiming a huge count costs nothing.
    let mut body = Vec::new();
    gz.by_ref()
        .take(layout.total as u64 + 1)
        .read_to_end(&mut body)
        .map_err(|e| err(format!("corrupt gzip stream: {e}")))?;
    if body.len() != layout.total {
        return Err(err(format!(
            "{} bytes of attributes after the header where {n} splats of SH degree {sh_degree} \
             (version {version}) need {}",
            if body.len() > layout.total {
                "more than".to_string()
            } else {
                body.len().to_string()
            },
            layout.total
        )));
    }
    let splats = unpack(&body, &layout, n, sh_degree, fractional_bits);
    Ok(SpzModel {
        splats: y_up_frame(&splats),
        version,
        fractional_bits,
        antialiased: flags & FLAG_ANTIALIASED != 0,
    })
}

/// Offsets of the attribute blocks in the decompressed stream after the header.
struct Layout {
    alphas: usize,
    colors: usize,
    scales: usize,
    rotations: usize,
    sh: usize,
    total: usize,
    rotation_bytes: usize,
    sh_per_splat: usize,
}

impl Layout {
    fn new(n: usize, sh_degree: u32, version: u32) -> Self {
        let rotation_bytes = if version >= 3 { 4 } else { 3 };
        let sh_per_splat = (num_sh_coeffs(sh_degree) - 1) * 3;
        let alphas = 9 * n;
        let colors = alphas + n;
        let scales = colors + 3 * n;
        let rotations = scales + 3 * n;
        let sh = rotations + rotation_bytes * n;
        Self {
            alphas,
            colors,
            scales,
            rotations,
            sh,
            total: sh + sh_per_splat * n,
            rotation_bytes,
            sh_per_splat,
        }
    }
}

/// Rounds to the nearest integer and clamps into a byte (`load-spz.cc`'s `toUint8`).
fn to_u8(x: f32) -> u8 {
    x.round().clamp(0.0, 255.0) as u8
}

/// Quantises an SH coefficient to a byte, ±1 full scale, keeping `bits` bits: the byte is rounded
/// to the centre of its bucket so that zero stays exactly zero.
fn quantize_sh(x: f32, bits: u8) -> u8 {
    let bucket = 1_i32 << (8 - bits);
    let q = (x * 128.0).round() as i32 + 128;
    let q = (q + bucket / 2) / bucket * bucket;
    q.clamp(0, 255) as u8
}

/// Chooses the fractional bits of the positions: the most that keep every coordinate inside 24
/// signed bits (non-finite coordinates are ignored here and refused by [`pack`] with their index).
fn fractional_bits_for(splats: &Splats) -> Result<u8, Error> {
    let largest = splats
        .means
        .iter()
        .map(|m| m.abs().max_element())
        .fold(0.0_f32, f32::max);
    if largest > MAX_FIXED {
        return Err(Error::Inconsistent(format!(
            "a coordinate of magnitude {largest} does not fit SPZ's 24-bit positions \
             (at most {MAX_FIXED})"
        )));
    }
    let mut bits = 23_u8;
    while bits > 0 && largest * (1_u32 << bits) as f32 > MAX_FIXED {
        bits -= 1;
    }
    Ok(bits)
}

/// Packs a smallest-three quaternion: the index of the largest |component| (x, y, z, w order) in
/// the top 2 bits, then each other component as sign and 9-bit magnitude over [0, √½].
fn pack_quaternion(q: Quat) -> [u8; 4] {
    let c = [q.x, q.y, q.z, q.w];
    let largest = (1..4).fold(
        0,
        |best, i| {
            if c[i].abs() > c[best].abs() { i } else { best }
        },
    );
    // q and −q are the same rotation: flip so the largest component is positive.
    let negate = c[largest] < 0.0;
    let mut word = largest as u32;
    for (i, &v) in c.iter().enumerate() {
        if i != largest {
            let sign = u32::from((v < 0.0) != negate);
            let mag = (QUAT_MASK as f32 * (v.abs() / std::f32::consts::FRAC_1_SQRT_2) + 0.5) as u32;
            word = (word << 10) | (sign << QUAT_BITS) | mag.min(QUAT_MASK);
        }
    }
    word.to_le_bytes()
}

/// Unpacks [`pack_quaternion`]'s word to (w, x, y, z).
fn unpack_quaternion(b: &[u8]) -> [f32; 4] {
    let mut word = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    let largest = (word >> 30) as usize;
    let mut c = [0.0_f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev() {
        if i != largest {
            let mag = (word & QUAT_MASK) as f32 / QUAT_MASK as f32;
            let v = std::f32::consts::FRAC_1_SQRT_2 * mag;
            c[i] = if (word >> QUAT_BITS) & 1 == 1 { -v } else { v };
            sum += c[i] * c[i];
            word >>= 10;
        }
    }
    c[largest] = (1.0 - sum).max(0.0).sqrt();
    [c[3], c[0], c[1], c[2]]
}

/// Unpacks a version-2 quaternion: x, y, z as u8 of the unit quaternion with w ≥ 0.
fn unpack_quaternion_v2(b: &[u8]) -> [f32; 4] {
    let [x, y, z] = [b[0], b[1], b[2]].map(|v| f32::from(v) / 127.5 - 1.0);
    let w = (1.0 - x * x - y * y - z * z).max(0.0).sqrt();
    [w, x, y, z]
}

/// The header and attribute blocks of `splats` (uncompressed), in SPZ's frame.
fn pack(splats: &Splats, options: &SpzOptions) -> Result<Vec<u8>, Error> {
    splats.validate()?;
    for (name, bits) in [
        ("sh1_bits", options.sh1_bits),
        ("sh_rest_bits", options.sh_rest_bits),
    ] {
        if !(1..=8).contains(&bits) {
            return Err(Error::Inconsistent(format!(
                "SPZ {name} = {bits}; it must be 1 to 8"
            )));
        }
    }
    let n = splats.len();
    let count = u32::try_from(n)
        .ok()
        .filter(|_| n <= MAX_SPLATS)
        .ok_or_else(|| Error::Inconsistent(format!("{n} splats are too many for SPZ")))?;
    let s = y_up_frame(splats);
    let bits = match options.fractional_bits {
        Some(b) if b <= 23 => b,
        Some(b) => {
            return Err(Error::Inconsistent(format!(
                "SPZ fractional_bits = {b}; at most 23"
            )));
        }
        None => fractional_bits_for(&s)?,
    };
    let layout = Layout::new(n, s.sh_degree, VERSION);
    let mut out = Vec::with_capacity(HEADER_BYTES + layout.total);
    out.extend(MAGIC.to_le_bytes());
    out.extend(VERSION.to_le_bytes());
    out.extend(count.to_le_bytes());
    let flags = if options.antialiased {
        FLAG_ANTIALIASED
    } else {
        0
    };
    out.extend([s.sh_degree as u8, bits, flags, 0]);

    let step = (1_u32 << bits) as f32;
    for (i, m) in s.means.iter().enumerate() {
        for v in m.to_array() {
            let fixed = (v * step).round();
            if !fixed.is_finite() || fixed.abs() > MAX_FIXED {
                return Err(Error::Inconsistent(format!(
                    "splat {i}: coordinate {v} does not fit 24-bit positions with {bits} \
                     fractional bits"
                )));
            }
            out.extend(&(fixed as i32).to_le_bytes()[..3]);
        }
    }
    out.extend(s.opacity_logits.iter().map(|&o| to_u8(sigmoid(o) * 255.0)));
    let k = s.coeffs_per_splat();
    for i in 0..n {
        let dc = s.sh[i * k];
        out.extend(dc.map(|c| to_u8(c * (COLOR_SCALE * 255.0) + 127.5)));
    }
    for ls in &s.log_scales {
        out.extend(ls.to_array().map(|v| to_u8((v + 10.0) * 16.0)));
    }
    for i in 0..n {
        out.extend(pack_quaternion(s.rotation(i)));
    }
    for i in 0..n {
        for (j, c) in s.sh_of(i)[1..].iter().enumerate() {
            let bits = if j < 3 {
                options.sh1_bits
            } else {
                options.sh_rest_bits
            };
            out.extend(c.map(|v| quantize_sh(v, bits)));
        }
    }
    debug_assert_eq!(out.len(), HEADER_BYTES + layout.total);
    Ok(out)
}

/// Decodes the attribute blocks (in SPZ's frame, not yet turned into this crate's).
fn unpack(body: &[u8], layout: &Layout, n: usize, sh_degree: u32, fractional_bits: u8) -> Splats {
    let step = 1.0 / (1_u32 << fractional_bits) as f32;
    let fixed = |o: usize| {
        // Sign-extend the 24-bit value through the top byte of an i32.
        (i32::from_le_bytes([0, body[o], body[o + 1], body[o + 2]]) >> 8) as f32 * step
    };
    let mut s = Splats::new(sh_degree);
    let k = num_sh_coeffs(sh_degree);
    s.means = (0..n)
        .map(|i| Vec3::new(fixed(9 * i), fixed(9 * i + 3), fixed(9 * i + 6)))
        .collect();
    s.opacity_logits = body[layout.alphas..layout.colors]
        .iter()
        .map(|&a| logit(f32::from(a) / 255.0))
        .collect();
    s.log_scales = body[layout.scales..layout.rotations]
        .chunks_exact(3)
        .map(|b| Vec3::from_array([b[0], b[1], b[2]].map(|v| f32::from(v) / 16.0 - 10.0)))
        .collect();
    s.rotations = body[layout.rotations..layout.sh]
        .chunks_exact(layout.rotation_bytes)
        .map(|b| {
            if layout.rotation_bytes == 4 {
                unpack_quaternion(b)
            } else {
                unpack_quaternion_v2(b)
            }
        })
        .collect();
    s.sh = Vec::with_capacity(n * k);
    for i in 0..n {
        let c = layout.colors + 3 * i;
        s.sh.push([0, 1, 2].map(|ch| (f32::from(body[c + ch]) / 255.0 - 0.5) / COLOR_SCALE));
        let rest = &body[layout.sh + i * layout.sh_per_splat..][..layout.sh_per_splat];
        s.sh.extend(
            rest.chunks_exact(3)
                .map(|b| [b[0], b[1], b[2]].map(|v| (f32::from(v) - 128.0) / 128.0)),
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quaternions_round_trip_within_the_smallest_three_step() {
        let mut seed = 7_u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0
        };
        for _ in 0..10_000 {
            let q = Quat::from_xyzw(next(), next(), next(), next()).normalize();
            let [w, x, y, z] = unpack_quaternion(&pack_quaternion(q));
            let back = Quat::from_xyzw(x, y, z, w);
            // Each small component is within half a step of √½/511; the angle between the
            // rotations is 2·acos(|q·back|).
            let angle = 2.0 * q.dot(back).abs().min(1.0).acos();
            assert!(angle < 4e-3, "{q:?} -> {back:?}: {angle} rad");
        }
    }

    #[test]
    fn sh_quantisation_keeps_zero_and_bucket_centres() {
        assert_eq!(quantize_sh(0.0, 4), 128);
        assert_eq!(quantize_sh(0.0, 5), 128);
        assert_eq!(quantize_sh(-2.0, 8), 0);
        assert_eq!(quantize_sh(2.0, 8), 255);
        for bits in 1..=8 {
            let bucket = 1 << (8 - bits);
            for x in [-0.9_f32, -0.31, 0.05, 0.47, 0.88] {
                // The top bucket's centre can lie past 255 and is clamped, as in Niantic's code.
                let q = i32::from(quantize_sh(x, bits));
                assert!(q % bucket == 0 || q == 255, "{x} at {bits} bits: {q}");
            }
        }
    }
}
