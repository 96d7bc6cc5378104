//! Niantic's SPZ (`nianticlabs/spz`, `src/cc/load-spz.cc`): about a tenth of the size of the
//! Inria PLY with small, bounded quantisation errors. Versions 2 and 3 are one gzip stream;
//! version 4 keeps its header in the clear and compresses each attribute block on its own with
//! zstd. Both are read; version 3 is written by default and version 4 on request
//! ([`SpzOptions::version`]).
//!
//! Versions 2 and 3: one gzip stream holding a 16-byte header (magic `NGSP`, version, point
//! count, SH degree, fractional bits of the positions, flags, a reserved byte) and then one block
//! per attribute. Version 4: a 32-byte header (the same fields, then the number of streams, the
//! byte offset of the table of contents and 12 reserved bytes), optional extension records up to
//! that offset (skipped here: [`SpzModel::skipped_extensions`]), the table (for each stream its
//! compressed and uncompressed sizes, two u64), and the streams, one zstd frame per non-empty
//! block, ending exactly at the end of the file. The blocks, each over all splats in order, are
//! the same in every version: positions (3 × 24-bit signed fixed point), alphas
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
//! Written by hand: no Rust crate writes SPZ (`docs/reference/crates.md`); `flate2` does the gzip
//! and `zstd` the version 4 streams.

use std::io::{Read, Write};
use std::path::Path;

use glam::{Quat, Vec3};

use crate::frame::y_up_frame;
use crate::ply::MAX_SPLATS;
use crate::{Error, Splats, logit, num_sh_coeffs, sigmoid};

/// `NGSP` read as a little-endian u32.
pub const MAGIC: u32 = 0x5053_474e;
/// The version written by default: smallest-three quaternions in a gzip stream.
pub const VERSION: u32 = 3;
/// The version with a clear header and one zstd stream per attribute block.
pub const ZSTD_VERSION: u32 = 4;
/// Bytes of the header at the start of a version 2 or 3 file's decompressed stream.
const HEADER_BYTES: usize = 16;
/// Bytes of a version 4 file's clear header.
const NGSP_HEADER_BYTES: usize = 32;
/// Header flag: extension records follow the version 4 header.
const FLAG_HAS_EXTENSIONS: u8 = 0x2;
/// zstd's compression level for version 4 streams (`load-spz.cc`'s default for `compressZstd`).
const ZSTD_LEVEL: i32 = 12;
/// Full scale of the colour byte: u8 = dc·0.15·255 + 127.5 (`load-spz.cc`'s `colorScale`).
const COLOR_SCALE: f32 = 0.15;
/// Header flag: the model was trained with the antialiased (Mip-Splatting-style) rasteriser.
const FLAG_ANTIALIASED: u8 = 0x1;
/// The largest magnitude of a 24-bit signed integer.
/// The largest coordinate magnitude SPZ's 24-bit fixed-point positions hold (with no
/// fractional bits): 2²³ − 1 units from the origin.
pub const MAX_COORDINATE: f32 = 8_388_607.0;
const MAX_FIXED: f32 = MAX_COORDINATE;
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
    /// The format version written: [`VERSION`] (3, gzip, the default, which every SPZ reader
    /// since 2024 reads) or [`ZSTD_VERSION`] (4, zstd streams).
    pub version: u32,
}

impl Default for SpzOptions {
    fn default() -> Self {
        Self {
            sh1_bits: 5,
            sh_rest_bits: 4,
            fractional_bits: None,
            antialiased: false,
            version: VERSION,
        }
    }
}

/// A model read from an SPZ file, with what its header says.
#[derive(Clone, Debug, PartialEq)]
pub struct SpzModel {
    /// The splats, in this crate's frame.
    pub splats: Splats,
    /// The file's format version (2, 3 or 4).
    pub version: u32,
    /// Fractional bits of the stored positions (their step is 2^−bits).
    pub fractional_bits: u8,
    /// The header's antialiased flag.
    pub antialiased: bool,
    /// A version 4 file held extension records (its flag 0x2), which this reader skips; a
    /// tool's extension can change how the splats are to be read (Niantic's reader warns the
    /// same way when built without them).
    pub skipped_extensions: bool,
}

/// Returns the SPZ bytes of `splats`: a gzip stream (version 3) or a clear header and zstd
/// streams (version 4), as `options` ask.
pub fn encode_spz(splats: &Splats, options: &SpzOptions) -> Result<Vec<u8>, Error> {
    let packed = pack(splats, options)?;
    match options.version {
        VERSION => {
            let mut gz = flate2::write::GzEncoder::new(
                Vec::with_capacity(HEADER_BYTES + packed.body.len() / 2),
                flate2::Compression::default(),
            );
            gz.write_all(&packed.header(VERSION)[..HEADER_BYTES])
                .and_then(|()| gz.write_all(&packed.body))
                .and_then(|()| gz.finish())
                .map_err(|e| Error::Inconsistent(format!("gzip: {e}")))
        }
        ZSTD_VERSION => encode_streams(&packed),
        v => Err(Error::Inconsistent(format!(
            "SPZ version {v}; {VERSION} (gzip) and {ZSTD_VERSION} (zstd streams) are written"
        ))),
    }
}

/// A version 4 file: the clear header, the table of contents and one zstd frame per non-empty
/// attribute block.
fn encode_streams(packed: &Packed) -> Result<Vec<u8>, Error> {
    let blocks: Vec<&[u8]> = packed
        .layout
        .blocks()
        .map(|r| &packed.body[r])
        .filter(|b| !b.is_empty())
        .collect();
    // Each frame carries zstd's content checksum, so a damaged file is refused by its reader
    // (without it a flipped bit in a stream decoded to other values as often as not).
    let zstd_err = |e: std::io::Error| Error::Inconsistent(format!("zstd: {e}"));
    let mut compressor = zstd::bulk::Compressor::new(ZSTD_LEVEL).map_err(zstd_err)?;
    compressor
        .set_parameter(zstd::zstd_safe::CParameter::ChecksumFlag(true))
        .map_err(zstd_err)?;
    let frames = blocks
        .iter()
        .map(|b| compressor.compress(b))
        .collect::<Result<Vec<_>, _>>()
        .map_err(zstd_err)?;
    let mut out = packed.header(ZSTD_VERSION);
    out[15] = blocks.len() as u8;
    out[16..20].copy_from_slice(&(NGSP_HEADER_BYTES as u32).to_le_bytes());
    for (block, frame) in blocks.iter().zip(&frames) {
        out.extend((frame.len() as u64).to_le_bytes());
        out.extend((block.len() as u64).to_le_bytes());
    }
    for frame in &frames {
        out.extend(frame);
    }
    Ok(out)
}

/// Writes `splats` as an SPZ file (version 3, or as `options` ask), atomically.
pub fn write_spz(path: &Path, splats: &Splats, options: &SpzOptions) -> Result<(), Error> {
    let bytes = encode_spz(splats, options)?;
    atomic_output::write_atomic(path, &bytes).map_err(|e| Error::io(path, e))
}

/// Reads an SPZ file (version 2 or 3, gzip container, or version 4, zstd streams).
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
        return decode_streams(path, data);
    }
    // The buffered decoder consumes exactly the gzip member, so what follows it can be seen.
    let mut gz = flate2::bufread::GzDecoder::new(data);
    let mut head = [0u8; HEADER_BYTES];
    gz.read_exact(&mut head)
        .map_err(|e| err(format!("not a gzip stream holding an SPZ header: {e}")))?;
    let header = Header::parse(&head).map_err(err)?;
    if !(2..=3).contains(&header.version) {
        return Err(err(format!(
            "version {} in a gzip stream; versions 2 and 3 are gzip streams (4 keeps its header \
             in the clear)",
            header.version
        )));
    }
    let Header {
        version,
        count: n,
        sh_degree,
        fractional_bits,
        flags,
        ..
    } = header;
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
                // (Reading stops one byte past the promise: how many more is not known.)
                format!("more than {}", layout.total)
            } else {
                body.len().to_string()
            },
            layout.total
        )));
    }
    // An SPZ file is one gzip member: bytes after it (a second file appended, junk) are not
    // part of the model and were ignored.
    let after = gz.into_inner().len();
    if after > 0 {
        return Err(err(format!(
            "{after} bytes after the gzip stream, which ends at byte {} (an SPZ file holds one)",
            data.len() - after
        )));
    }
    let splats = unpack(&body, &layout, n, sh_degree, fractional_bits);
    Ok(SpzModel {
        splats: y_up_frame(&splats),
        version,
        fractional_bits,
        antialiased: flags & FLAG_ANTIALIASED != 0,
        skipped_extensions: false,
    })
}

/// The fields every SPZ header holds, checked.
struct Header {
    version: u32,
    count: usize,
    sh_degree: u32,
    fractional_bits: u8,
    flags: u8,
}

impl Header {
    /// Reads the fields the 16-byte and 32-byte headers share (`head` holds at least 16
    /// bytes) and checks them: the magic, a version of 2 to 4, SH degree at most 3, fractional
    /// bits at most 23 and at most [`MAX_SPLATS`] splats.
    fn parse(head: &[u8]) -> Result<Self, String> {
        let word = |o: usize| u32::from_le_bytes([head[o], head[o + 1], head[o + 2], head[o + 3]]);
        let (magic, version, count) = (word(0), word(4), word(8));
        let (sh_degree, fractional_bits, flags) = (u32::from(head[12]), head[13], head[14]);
        if magic != MAGIC {
            return Err(format!(
                "magic 0x{magic:08x} where an SPZ file has 0x{MAGIC:08x} (`NGSP`)"
            ));
        }
        if !(2..=4).contains(&version) {
            return Err(format!(
                "version {version}; this reader reads versions 2, 3 and 4"
            ));
        }
        if sh_degree > 3 {
            return Err(format!("SH degree {sh_degree}; at most 3 is supported"));
        }
        if fractional_bits > 23 {
            return Err(format!(
                "{fractional_bits} fractional bits in 24-bit positions (at most 23)"
            ));
        }
        let count = count as usize;
        if count > MAX_SPLATS {
            return Err(format!(
                "{count} splats, more than the {MAX_SPLATS} this reader accepts"
            ));
        }
        Ok(Self {
            version,
            count,
            sh_degree,
            fractional_bits,
            flags,
        })
    }
}

/// Decodes a version 4 file: its clear header, table of contents and zstd streams.
fn decode_streams(path: &Path, data: &[u8]) -> Result<SpzModel, Error> {
    let err = |message: String| Error::Spz {
        path: path.to_path_buf(),
        message,
    };
    if data.len() < NGSP_HEADER_BYTES {
        return Err(err(format!(
            "{} bytes: shorter than the {NGSP_HEADER_BYTES}-byte header of a version 4 file",
            data.len()
        )));
    }
    let header = Header::parse(data).map_err(err)?;
    if header.version != ZSTD_VERSION {
        return Err(err(format!(
            "version {} with a clear header; only version {ZSTD_VERSION} keeps its header in the \
             clear (2 and 3 are gzip streams)",
            header.version
        )));
    }
    let streams = usize::from(data[15]);
    let toc = u32::from_le_bytes([data[16], data[17], data[18], data[19]]) as usize;
    let (n, sh_degree) = (header.count, header.sh_degree);
    let layout = Layout::new(n, sh_degree, header.version);
    let blocks: Vec<std::ops::Range<usize>> = layout.blocks().filter(|r| !r.is_empty()).collect();
    if streams != blocks.len() {
        return Err(err(format!(
            "{streams} streams where {n} splats of SH degree {sh_degree} have {} non-empty \
             attribute blocks",
            blocks.len()
        )));
    }
    let toc_end = toc.checked_add(16 * streams).filter(|&e| e <= data.len());
    let Some(toc_end) = toc_end.filter(|_| toc >= NGSP_HEADER_BYTES) else {
        return Err(err(format!(
            "the table of contents at byte {toc} ({streams} entries of 16 bytes) is not between \
             the {NGSP_HEADER_BYTES}-byte header and the end of the {}-byte file",
            data.len()
        )));
    };
    let skipped_extensions = header.flags & FLAG_HAS_EXTENSIONS != 0 && toc > NGSP_HEADER_BYTES;
    let u64_at = |o: usize| {
        let mut b = [0u8; 8];
        b.copy_from_slice(&data[o..o + 8]);
        u64::from_le_bytes(b)
    };
    let mut body = Vec::new();
    let mut offset = toc_end;
    for (i, block) in blocks.iter().enumerate() {
        let (compressed, uncompressed) = (u64_at(toc + 16 * i), u64_at(toc + 16 * i + 8));
        if uncompressed != block.len() as u64 {
            return Err(err(format!(
                "stream {i} holds {uncompressed} bytes where {n} splats need {}",
                block.len()
            )));
        }
        let frame = usize::try_from(compressed)
            .ok()
            .and_then(|c| offset.checked_add(c))
            .filter(|&end| end <= data.len())
            .map(|end| &data[offset..end])
            .ok_or_else(|| {
                err(format!(
                    "stream {i} ({compressed} compressed bytes from byte {offset}) runs past \
                     the end of the {}-byte file",
                    data.len()
                ))
            })?;
        offset += frame.len();
        // Memory grows with what the frame really holds, at most one byte past the table's
        // size, so a table claiming huge blocks costs nothing.
        let before = body.len();
        zstd::stream::read::Decoder::new(frame)
            .and_then(|d| d.take(uncompressed + 1).read_to_end(&mut body))
            .map_err(|e| err(format!("stream {i}: corrupt zstd frame: {e}")))?;
        if body.len() - before != block.len() {
            return Err(err(format!(
                "stream {i} decompresses to {} bytes where its table entry and {n} splats say {}",
                body.len() - before,
                block.len()
            )));
        }
    }
    if offset != data.len() {
        return Err(err(format!(
            "{} bytes after the last stream (the file should end at byte {offset})",
            data.len() - offset
        )));
    }
    let splats = unpack(&body, &layout, n, sh_degree, header.fractional_bits);
    Ok(SpzModel {
        splats: y_up_frame(&splats),
        version: header.version,
        fractional_bits: header.fractional_bits,
        antialiased: header.flags & FLAG_ANTIALIASED != 0,
        skipped_extensions,
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

    /// The attribute blocks' byte ranges in order (positions, alphas, colours, scales,
    /// rotations, SH), the SH block empty at degree 0.
    fn blocks(&self) -> impl Iterator<Item = std::ops::Range<usize>> {
        let starts = [
            0,
            self.alphas,
            self.colors,
            self.scales,
            self.rotations,
            self.sh,
            self.total,
        ];
        (0..6).map(move |k| starts[k]..starts[k + 1])
    }
}

/// A model packed into SPZ's blocks, with what its header says.
struct Packed {
    count: u32,
    sh_degree: u8,
    fractional_bits: u8,
    flags: u8,
    /// The attribute blocks after the header, in order.
    body: Vec<u8>,
    layout: Layout,
}

impl Packed {
    /// The 32-byte header of `version` with the stream count and table offset zero (the
    /// 16-byte header of versions 2 and 3 is its start).
    fn header(&self, version: u32) -> Vec<u8> {
        let mut h = Vec::with_capacity(NGSP_HEADER_BYTES);
        h.extend(MAGIC.to_le_bytes());
        h.extend(version.to_le_bytes());
        h.extend(self.count.to_le_bytes());
        h.extend([self.sh_degree, self.fractional_bits, self.flags, 0]);
        h.resize(NGSP_HEADER_BYTES, 0);
        h
    }
}

/// How many splats SPZ's byte ranges clamp (as Niantic's encoder does) when they are packed:
/// log-scales outside about [−10, 5.94], DC colour coefficients outside about ±3.33, higher SH
/// coefficients outside about [−1, 0.99]. Positions beyond the 24-bit range are refused instead.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SpzClamps {
    /// Splats with a log-scale clamped.
    pub log_scales: usize,
    /// Splats with a DC coefficient clamped.
    pub colours: usize,
    /// Splats with a higher SH coefficient clamped.
    pub sh: usize,
}

impl SpzClamps {
    /// Whether nothing is clamped.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        *self == Self::default()
    }
}

/// Counts what packing `splats` as SPZ would clamp (the same formulas as the packing).
#[must_use]
pub fn clamped_by_spz(splats: &Splats) -> SpzClamps {
    let outside = |code: f32| !(0.0..=255.0).contains(&code.round());
    let k = splats.coeffs_per_splat();
    let mut c = SpzClamps::default();
    for i in 0..splats.len() {
        let ls = splats.log_scales[i].to_array();
        c.log_scales += usize::from(ls.iter().any(|&v| outside(log_scale_code(v))));
        let sh = &splats.sh[i * k..(i + 1) * k];
        c.colours += usize::from(sh[0].iter().any(|&v| outside(colour_code(v))));
        c.sh += usize::from(
            sh[1..]
                .iter()
                .flatten()
                .any(|&v| !(0..=255).contains(&sh_code(v))),
        );
    }
    c
}

/// A log-scale's byte before rounding and clamping: [−10, 5.94] in steps of 1/16.
fn log_scale_code(v: f32) -> f32 {
    (v + 10.0) * 16.0
}

/// A DC colour coefficient's byte before rounding and clamping.
fn colour_code(c: f32) -> f32 {
    c * (COLOR_SCALE * 255.0) + 127.5
}

/// A higher SH coefficient's byte (±1 full scale) before its bucket and clamping.
fn sh_code(x: f32) -> i32 {
    (x * 128.0).round() as i32 + 128
}

/// Rounds to the nearest integer and clamps into a byte (`load-spz.cc`'s `toUint8`).
fn to_u8(x: f32) -> u8 {
    x.round().clamp(0.0, 255.0) as u8
}

/// Quantises an SH coefficient to a byte, ±1 full scale, keeping `bits` bits: the byte is rounded
/// to the centre of its bucket so that zero stays exactly zero.
fn quantize_sh(x: f32, bits: u8) -> u8 {
    let bucket = 1_i32 << (8 - bits);
    let q = sh_code(x);
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

/// The attribute blocks of `splats` (uncompressed), in SPZ's frame, and their header's fields.
fn pack(splats: &Splats, options: &SpzOptions) -> Result<Packed, Error> {
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
    let mut out = Vec::with_capacity(layout.total);
    let flags = if options.antialiased {
        FLAG_ANTIALIASED
    } else {
        0
    };

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
        out.extend(dc.map(|c| to_u8(colour_code(c))));
    }
    for ls in &s.log_scales {
        out.extend(ls.to_array().map(|v| to_u8(log_scale_code(v))));
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
    debug_assert_eq!(out.len(), layout.total);
    Ok(Packed {
        count,
        sh_degree: s.sh_degree as u8,
        fractional_bits: bits,
        flags,
        body: out,
        layout,
    })
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
        // What the packing clamps is what `clamped_by_spz` counts.
        let mut s = Splats::new(1);
        for (scale, dc, rest) in [
            (-2.0, 0.5, 0.5),
            (20.0, 0.5, 0.5),
            (-11.0, 0.5, 0.5),
            (-2.0, 10.0, 0.5),
            (-2.0, 0.5, -1.5),
        ] {
            s.push(
                Vec3::ZERO,
                Vec3::new(-2.0, scale, -2.0),
                [1.0, 0.0, 0.0, 0.0],
                0.0,
                &[[dc, 0.0, 0.0], [0.0, rest, 0.0], [0.0; 3], [0.0; 3]],
            );
        }
        assert_eq!(
            clamped_by_spz(&s),
            SpzClamps {
                log_scales: 2,
                colours: 1,
                sh: 1
            }
        );
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
