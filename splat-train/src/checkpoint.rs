//! Checkpoints: the whole state of a run, so that resuming gives the same result as not stopping.
//!
//! Layout (little endian): the 8 bytes `SPLTCKPT`, a u32 version, a u64 header length, a JSON
//! header (run state including the generator, splat count, SH degree, lengths), then f32 blocks:
//! means, log-scales, rotations, opacity logits, SH; the Adam first and second moments of each
//! in the same order; the strategy's statistics; last, a u64 checksum of every byte before it.
//! Values are stored bit-exactly.
//!
//! Files are written through a temporary sibling and renamed, so a killed writer leaves the
//! previous checkpoint whole; the exact length and the checksum catch a file that was truncated
//! or altered afterwards, which is refused rather than resumed from.

use std::fs;
use std::path::Path;
use std::sync::Arc;

use serde::{Deserialize, Serialize};
use splat_core::{Splats, num_sh_coeffs};

use crate::adam::Moments;
use crate::config::TrainConfig;
use crate::error::Error;
use crate::state::{ParamState, SplatMoments};
use crate::trainer::{RunState, Trainer};
use crate::view::View;

const MAGIC: &[u8; 8] = b"SPLTCKPT";
/// Version 2 added the trailing checksum.
const VERSION: u32 = 2;
/// Bytes of the trailing checksum.
const CHECKSUM_LEN: usize = 8;
/// Refuse headers beyond this size before allocating (a corrupt length must not allocate GiBs).
const MAX_HEADER: u64 = 1 << 30;

#[derive(Debug, Serialize, Deserialize)]
struct Header {
    run: RunState,
    splats: usize,
    sh_degree: u32,
    views: usize,
    strategy_values: usize,
}

/// Writes `trainer`'s state to `path` atomically (temporary sibling, fsync, rename).
pub(crate) fn save(trainer: &Trainer, path: &Path) -> Result<(), Error> {
    let st = &trainer.state;
    let strategy = trainer
        .strategy
        .as_ref()
        .map(|s| s.export_state())
        .unwrap_or_default();
    let header = Header {
        run: trainer.run.clone(),
        splats: st.len(),
        sh_degree: st.splats.sh_degree,
        views: trainer.views().len(),
        strategy_values: strategy.len(),
    };
    let json = serde_json::to_vec(&header)
        .map_err(|e| Error::Config(format!("checkpoint header cannot be encoded: {e}")))?;
    let mut buf =
        Vec::with_capacity(20 + json.len() + 4 * 3 * (st.len() * 14 + st.splats.sh.len() * 3));
    buf.extend_from_slice(MAGIC);
    buf.extend_from_slice(&VERSION.to_le_bytes());
    buf.extend_from_slice(&(json.len() as u64).to_le_bytes());
    buf.extend_from_slice(&json);
    let s = &st.splats;
    let m = &st.moments;
    let blocks: [&[f32]; 16] = [
        bytemuck::cast_slice(&s.means),
        bytemuck::cast_slice(&s.log_scales),
        s.rotations.as_flattened(),
        &s.opacity_logits,
        s.sh.as_flattened(),
        &m.means.m,
        &m.log_scales.m,
        &m.rotations.m,
        &m.opacity_logits.m,
        &m.sh.m,
        &m.means.v,
        &m.log_scales.v,
        &m.rotations.v,
        &m.opacity_logits.v,
        &m.sh.v,
        &strategy,
    ];
    for b in blocks {
        for v in b {
            buf.extend_from_slice(&v.to_le_bytes());
        }
    }
    let sum = checksum(&buf);
    buf.extend_from_slice(&sum.to_le_bytes());
    atomic_output::write_atomic(path, &buf).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a checkpoint and rebuilds the trainer on `views` with `config`.
pub(crate) fn load(
    path: &Path,
    views: Arc<Vec<View>>,
    config: TrainConfig,
) -> Result<Trainer, Error> {
    let bytes = fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let bad = |offset: usize, problem: String| Error::Checkpoint {
        path: path.to_path_buf(),
        offset: offset as u64,
        problem,
    };
    let body = verified_body(&bytes).map_err(|(o, p)| bad(o, p))?;
    let (header, hend) = read_header(body, views.len()).map_err(|(o, p)| bad(o, p))?;
    let (state, strategy) = read_state(&body[hend..], &header);
    let mut trainer = Trainer::new(state.splats.clone(), views, config)?;
    trainer
        .restore(state, header.run, &strategy)
        .map_err(|p| bad(hend, p))?;
    Ok(trainer)
}

/// A refusal: the byte offset and the problem.
type Refusal = (usize, String);

/// The file's body (without its checksum) once the magic, the version and the checksum are
/// right: a damaged file must not be half-read before it is refused.
fn verified_body(bytes: &[u8]) -> Result<&[u8], Refusal> {
    if bytes.len() < 20 + CHECKSUM_LEN || &bytes[..8] != MAGIC {
        return Err((
            0,
            "not a splat-train checkpoint (magic SPLTCKPT missing)".into(),
        ));
    }
    let version = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]);
    if version != VERSION {
        return Err((8, format!("version {version}, this build reads {VERSION}")));
    }
    let body = bytes.len() - CHECKSUM_LEN;
    let mut sum8 = [0u8; 8];
    sum8.copy_from_slice(&bytes[body..]);
    if u64::from_le_bytes(sum8) != checksum(&bytes[..body]) {
        return Err((
            body,
            "checksum mismatch: the file is truncated or damaged".into(),
        ));
    }
    Ok(&bytes[..body])
}

/// The JSON header and the offset where the data after it starts, checked against `views`
/// views and against the data's length.
fn read_header(bytes: &[u8], views: usize) -> Result<(Header, usize), Refusal> {
    let mut len8 = [0u8; 8];
    len8.copy_from_slice(&bytes[12..20]);
    let hlen = u64::from_le_bytes(len8);
    if hlen > MAX_HEADER || 20 + hlen > bytes.len() as u64 {
        return Err((
            12,
            format!(
                "header length {hlen} exceeds the file ({} bytes)",
                bytes.len()
            ),
        ));
    }
    let hend = 20 + hlen as usize;
    let header: Header = serde_json::from_slice(&bytes[20..hend])
        .map_err(|e| (20, format!("header is not valid: {e}")))?;
    if header.sh_degree > 3 {
        return Err((20, format!("SH degree {} exceeds 3", header.sh_degree)));
    }
    if header.views != views {
        return Err((
            20,
            format!("saved with {} views, resumed with {views}", header.views),
        ));
    }
    if header.run.order.iter().any(|&v| v as usize >= views)
        || header.run.cursor > header.run.order.len()
    {
        return Err((20, "view order refers to views that do not exist".into()));
    }
    let floats = state_floats(&header);
    let expected = floats.checked_mul(4).and_then(|b| b.checked_add(hend));
    if expected != Some(bytes.len()) {
        return Err((
            hend,
            format!(
                "{} bytes of data, expected {} for {} splats",
                bytes.len() - hend,
                floats * 4,
                header.splats
            ),
        ));
    }
    Ok((header, hend))
}

/// Floats of each parameter group of `header.splats` splats: means, log-scales, rotations,
/// opacity logits, SH coefficients.
fn group_sizes(header: &Header) -> [usize; 5] {
    let n = header.splats;
    let k = num_sh_coeffs(header.sh_degree);
    [3 * n, 3 * n, 4 * n, n, 3 * k * n]
}

/// Floats after the header: the parameters, both Adam moments, and the strategy's values.
fn state_floats(header: &Header) -> usize {
    3 * group_sizes(header).iter().sum::<usize>() + header.strategy_values
}

/// The parameters, their moments and the strategy's values from `data` (exactly
/// [`state_floats`] little-endian floats, checked by [`read_header`]).
fn read_state(data: &[u8], header: &Header) -> (ParamState, Vec<f32>) {
    let sizes = group_sizes(header);
    let mut cursor = 0;
    let mut take = |count: usize| -> Vec<f32> {
        let v = data[cursor..cursor + 4 * count]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        cursor += 4 * count;
        v
    };
    let means = take(sizes[0]);
    let log_scales = take(sizes[1]);
    let rotations = take(sizes[2]);
    let opacity_logits = take(sizes[3]);
    let sh = take(sizes[4]);
    let m: Vec<Vec<f32>> = sizes.iter().map(|&s| take(s)).collect();
    let v: Vec<Vec<f32>> = sizes.iter().map(|&s| take(s)).collect();
    let strategy = take(header.strategy_values);
    let splats = Splats {
        means: bytemuck::cast_slice(&means).to_vec(),
        log_scales: bytemuck::cast_slice(&log_scales).to_vec(),
        rotations: rotations
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect(),
        opacity_logits,
        sh_degree: header.sh_degree,
        sh: sh.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
    };
    let mut mv = m.into_iter().zip(v).map(|(m, v)| Moments { m, v });
    let mut next = || mv.next().unwrap_or_default();
    let moments = SplatMoments {
        means: next(),
        log_scales: next(),
        rotations: next(),
        opacity_logits: next(),
        sh: next(),
    };
    (ParamState { splats, moments }, strategy)
}

/// FNV-1a over little-endian 64-bit words (the tail zero-padded), seeded with the length.
///
/// Each step (xor a word, multiply by an odd constant) is a bijection of the running value, so a
/// change confined to one word always changes the result; that and the exact length check are
/// what a damaged file has to get past. It guards against accidents, not against forgery.
fn checksum(bytes: &[u8]) -> u64 {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;
    let mut h = OFFSET ^ bytes.len() as u64;
    let mut words = bytes.chunks_exact(8);
    for w in &mut words {
        let mut b = [0u8; 8];
        b.copy_from_slice(w);
        h = (h ^ u64::from_le_bytes(b)).wrapping_mul(PRIME);
    }
    let rest = words.remainder();
    if !rest.is_empty() {
        let mut b = [0u8; 8];
        b[..rest.len()].copy_from_slice(rest);
        h = (h ^ u64::from_le_bytes(b)).wrapping_mul(PRIME);
    }
    h
}

// The trainer's checkpoint methods live here, beside the format, so that the trainer does not
// depend on its own serialisation.
impl Trainer {
    /// Writes the whole run state to `path` atomically (this module's format).
    ///
    /// # Errors
    /// [`Error::Io`] when the file cannot be written.
    pub fn save_checkpoint(&self, path: &Path) -> Result<(), Error> {
        save(self, path)
    }

    /// Continues the run saved at `path` on the same `views` with `config` (its iteration count
    /// and time budget may differ from the saved run's).
    ///
    /// # Errors
    /// [`Error::Checkpoint`] when the file is malformed or does not match the views and
    /// configuration, and the errors of [`Trainer::new`].
    pub fn resume(
        path: &Path,
        views: impl Into<Arc<Vec<View>>>,
        config: TrainConfig,
    ) -> Result<Self, Error> {
        load(path, views.into(), config)
    }
}
