//! Compact exports for web viewers: the antimatter15 `.splat` layout (`antimatter15/splat`,
//! `convert.py`): 32 bytes per splat, no header, view-dependent SH dropped. Written and read:
//! reading gives SH degree 0 with the colour, opacity and rotation rounded to 8 bits.

use std::io::Write;
use std::path::Path;

use glam::Vec3;

use crate::ply::MAX_SPLATS;
use crate::{Error, Splats, logit, rgb_to_sh_dc, sh_dc_to_rgb, sigmoid};

/// Bytes per splat in the `.splat` layout.
pub const SPLAT_RECORD_BYTES: usize = 32;

/// Encodes splat `i` as a `.splat` record: f32 position, f32 linear scales, u8 RGBA
/// (rgb = clamp((0.5 + C0·dc)·255), a = sigmoid(opacity)·255), u8 quaternion w, x, y, z
/// (normalised·128 + 128).
#[must_use]
pub fn encode_record(splats: &Splats, i: usize) -> [u8; SPLAT_RECORD_BYTES] {
    let mut r = [0u8; SPLAT_RECORD_BYTES];
    let mut put = |o: usize, v: f32| r[o..o + 4].copy_from_slice(&v.to_le_bytes());
    let m = splats.means[i];
    let s = splats.scale(i);
    for (k, v) in [m.x, m.y, m.z, s.x, s.y, s.z].into_iter().enumerate() {
        put(4 * k, v);
    }
    let to_u8 = |v: f32| (v * 255.0).round().clamp(0.0, 255.0) as u8;
    let rgb = sh_dc_to_rgb(splats.sh_of(i)[0]);
    r[24] = to_u8(rgb[0]);
    r[25] = to_u8(rgb[1]);
    r[26] = to_u8(rgb[2]);
    r[27] = to_u8(sigmoid(splats.opacity_logits[i]));
    let q = splats.rotation(i);
    for (k, c) in [q.w, q.x, q.y, q.z].into_iter().enumerate() {
        r[28 + k] = (c * 128.0 + 128.0).round().clamp(0.0, 255.0) as u8;
    }
    r
}

/// Writes `splats` as a `.splat` file, sorted like the reference converter by
/// exp(Σ log-scale)·sigmoid(opacity), largest first; atomic.
pub fn write_splat(path: &Path, splats: &Splats) -> Result<(), Error> {
    splats.validate()?;
    if let Some(message) = linear_scale_problem(splats, ".splat") {
        return Err(Error::Unwritable {
            path: path.to_path_buf(),
            message,
        });
    }
    let mut order: Vec<usize> = (0..splats.len()).collect();
    let key = |i: usize| {
        let l = splats.log_scales[i];
        -((l.x + l.y + l.z).exp() * sigmoid(splats.opacity_logits[i]))
    };
    order.sort_by(|&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));
    atomic_output::write_atomic_with(path, |w| {
        for i in order {
            w.write_all(&encode_record(splats, i))?;
        }
        Ok(())
    })
    .map_err(|e| Error::io(path, e))
}

/// What a format that stores linear scales (`format`: `.splat`, `.glb`) cannot hold, naming
/// the splat: a scale that overflows or vanishes in f32 (its reader would refuse the infinity or
/// the zero), or an empty model (an empty `.splat` cannot be told from a file cut to nothing,
/// and a glTF accessor holds at least one element). `None` when it can hold them all.
pub(crate) fn linear_scale_problem(splats: &Splats, format: &str) -> Option<String> {
    if splats.is_empty() {
        return Some(format!(
            "the model holds no splats (an empty model), and a {format} file needs at least one"
        ));
    }
    let (i, axis, log) = splats.first_unstorable_linear_scale()?;
    Some(format!(
        "splat {i}: scale_{axis} (log-scale {log:e}) is {} as a linear scale in f32, which \
         {format} stores and its readers refuse",
        if log.is_nan() {
            "not a number"
        } else if log > 0.0 {
            "infinite"
        } else {
            "zero"
        }
    ))
}

/// Reads a `.splat` file (see [`decode_splat`]).
pub fn read_splat(path: &Path) -> Result<Splats, Error> {
    let data = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    decode_splat(path, &data)
}

/// Decodes the bytes of a `.splat` file into splats of SH degree 0, in file order; `path` is
/// used in error messages. The inverse of [`encode_record`]: log-scale = ln(scale), DC from the
/// 8-bit colour, opacity logit from the 8-bit alpha (clamped as [`logit`] does), quaternion
/// (byte − 128)/128, normalised on use like every stored quaternion.
pub fn decode_splat(path: &Path, data: &[u8]) -> Result<Splats, Error> {
    let err = |message: String| Error::DotSplat {
        path: path.to_path_buf(),
        message,
    };
    let (n, rest) = (
        data.len() / SPLAT_RECORD_BYTES,
        data.len() % SPLAT_RECORD_BYTES,
    );
    if rest != 0 {
        return Err(err(format!(
            "{} bytes are not whole {SPLAT_RECORD_BYTES}-byte records: {n} records and {rest} \
             bytes over from byte offset {} (cut short, or not a .splat file)",
            data.len(),
            n * SPLAT_RECORD_BYTES
        )));
    }
    if n == 0 {
        return Err(err("an empty file: no records".into()));
    }
    if n > MAX_SPLATS {
        return Err(err(format!(
            "{n} records (at most {MAX_SPLATS} are accepted)"
        )));
    }
    const NAMES: [&str; 6] = ["x", "y", "z", "scale_0", "scale_1", "scale_2"];
    let mut splats = Splats::new(0);
    for (i, r) in data.chunks_exact(SPLAT_RECORD_BYTES).enumerate() {
        let mut f = [0.0_f32; 6];
        for (k, v) in f.iter_mut().enumerate() {
            *v = f32::from_le_bytes([r[4 * k], r[4 * k + 1], r[4 * k + 2], r[4 * k + 3]]);
            if !v.is_finite() {
                return Err(Error::NonFinite {
                    path: path.to_path_buf(),
                    index: i,
                    property: NAMES[k].into(),
                    value: f64::from(*v),
                });
            }
        }
        if let Some(k) = (3..6).find(|&k| f[k] <= 0.0) {
            return Err(err(format!(
                "record {i} (byte offset {}): {} = {}; scales must be positive",
                i * SPLAT_RECORD_BYTES + 4 * k,
                NAMES[k],
                f[k]
            )));
        }
        let byte = |o: usize| f32::from(r[o]) / 255.0;
        let q = |o: usize| (f32::from(r[o]) - 128.0) / 128.0;
        splats.push(
            Vec3::new(f[0], f[1], f[2]),
            Vec3::new(f[3], f[4], f[5]).map(f32::ln),
            [q(28), q(29), q(30), q(31)],
            logit(byte(27)),
            &[rgb_to_sh_dc([byte(24), byte(25), byte(26)])],
        );
    }
    Ok(splats)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn record_layout_matches_the_reference_converter() {
        let mut s = Splats::new(0);
        let q = glam::Quat::from_rotation_y(0.7);
        s.push(
            Vec3::new(1.0, -2.0, 3.5),
            Vec3::new(0.0, -1.0, 0.5),
            [2.0 * q.w, 2.0 * q.x, 2.0 * q.y, 2.0 * q.z],
            0.0,
            &[rgb_to_sh_dc([1.0, 0.5, 0.0])],
        );
        let r = encode_record(&s, 0);
        let f = |o: usize| f32::from_le_bytes(r[o..o + 4].try_into().unwrap());
        assert_eq!([f(0), f(4), f(8)], [1.0, -2.0, 3.5]);
        assert!((f(12) - 1.0).abs() < 1e-6 && (f(16) - (-1.0f32).exp()).abs() < 1e-6);
        assert_eq!(&r[24..28], &[255, 128, 0, 128]);
        assert_eq!(r[28], (q.w * 128.0 + 128.0).round() as u8);
        assert_eq!(r[29], 128);
        assert_eq!(r[30], (q.y * 128.0 + 128.0).round() as u8);
        assert_eq!(r[31], 128);
    }
}
