//! The scalar codec: PLY values to and from `f64`, in binary (either endianness) and ASCII.
//!
//! `f64` holds every value of every PLY scalar type exactly, so decoding never loses anything;
//! encoding rounds and saturates integers and narrows `float` the way Rust's `as` does.

use std::fmt::Write as _;

use crate::ScalarType;

/// Reads one binary scalar of type `ty` from the start of `bytes`.
///
/// # Panics
/// When `bytes` holds fewer than `ty.size()` bytes (callers check the record length first).
#[inline(always)]
#[must_use]
pub fn read_binary(bytes: &[u8], ty: ScalarType, big_endian: bool) -> f64 {
    macro_rules! get {
        ($t:ty, $n:literal) => {{
            let mut a = [0u8; $n];
            a.copy_from_slice(&bytes[..$n]);
            f64::from(if big_endian {
                <$t>::from_be_bytes(a)
            } else {
                <$t>::from_le_bytes(a)
            })
        }};
    }
    match ty {
        ScalarType::I8 => f64::from(bytes[0] as i8),
        ScalarType::U8 => f64::from(bytes[0]),
        ScalarType::I16 => get!(i16, 2),
        ScalarType::U16 => get!(u16, 2),
        ScalarType::I32 => get!(i32, 4),
        ScalarType::U32 => get!(u32, 4),
        ScalarType::F32 => get!(f32, 4),
        ScalarType::F64 => get!(f64, 8),
    }
}

/// Encodes `v` as `ty` into `out` (integers rounded and saturated, `float` narrowed).
///
/// # Panics
/// When `out` is not exactly `ty.size()` bytes long.
#[inline(always)]
pub fn write_binary(out: &mut [u8], v: f64, ty: ScalarType, big_endian: bool) {
    macro_rules! put {
        ($x:expr) => {{
            let x = $x;
            out.copy_from_slice(&if big_endian {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            });
        }};
    }
    match ty {
        ScalarType::I8 => put!(v.round() as i8),
        ScalarType::U8 => put!(v.round() as u8),
        ScalarType::I16 => put!(v.round() as i16),
        ScalarType::U16 => put!(v.round() as u16),
        ScalarType::I32 => put!(v.round() as i32),
        ScalarType::U32 => put!(v.round() as u32),
        ScalarType::F32 => put!(v as f32),
        ScalarType::F64 => put!(v),
    }
}

/// Parses one ASCII token as `ty`, exactly: integers must be in the type's range, and `float`
/// is parsed as `f32` (not via `f64`, which could round twice). `None` when it is not one.
#[must_use]
pub fn parse_ascii(token: &str, ty: ScalarType) -> Option<f64> {
    let int = |lo: i64, hi: i64| {
        token
            .parse::<i64>()
            .ok()
            .filter(|v| (lo..=hi).contains(v))
            .map(|v| v as f64)
    };
    match ty {
        ScalarType::I8 => int(i8::MIN.into(), i8::MAX.into()),
        ScalarType::U8 => int(0, u8::MAX.into()),
        ScalarType::I16 => int(i16::MIN.into(), i16::MAX.into()),
        ScalarType::U16 => int(0, u16::MAX.into()),
        ScalarType::I32 => int(i32::MIN.into(), i32::MAX.into()),
        ScalarType::U32 => int(0, u32::MAX.into()),
        ScalarType::F32 => token.parse::<f32>().ok().map(f64::from),
        ScalarType::F64 => token.parse::<f64>().ok(),
    }
}

/// Appends `v` formatted as `ty` to `text`: integers rounded, floats in Rust's shortest
/// round-trip form, so [`parse_ascii`] reads back exactly the value written.
pub fn write_ascii(text: &mut String, v: f64, ty: ScalarType) {
    let _ = match ty {
        ScalarType::F32 => write!(text, "{}", v as f32),
        ScalarType::F64 => write!(text, "{v}"),
        _ => write!(text, "{}", v.round() as i64),
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    const ALL: [ScalarType; 8] = [
        ScalarType::I8,
        ScalarType::U8,
        ScalarType::I16,
        ScalarType::U16,
        ScalarType::I32,
        ScalarType::U32,
        ScalarType::F32,
        ScalarType::F64,
    ];

    #[test]
    fn binary_round_trips_in_both_endiannesses() {
        for ty in ALL {
            for big in [false, true] {
                for v in [0.0, 1.0, 100.0, 127.0] {
                    let mut b = vec![0u8; ty.size()];
                    write_binary(&mut b, v, ty, big);
                    assert_eq!(read_binary(&b, ty, big), v, "{ty:?} big={big}");
                }
            }
        }
        let mut b = [0u8; 2];
        write_binary(&mut b, 258.0, ScalarType::U16, true);
        assert_eq!(b, [1, 2]);
        write_binary(&mut b, 258.0, ScalarType::U16, false);
        assert_eq!(b, [2, 1]);
        assert_eq!(read_binary(&[0xff], ScalarType::I8, false), -1.0);
    }

    #[test]
    fn integers_round_and_saturate() {
        let mut b = [0u8; 1];
        write_binary(&mut b, 300.0, ScalarType::U8, false);
        assert_eq!(b, [255]);
        write_binary(&mut b, 2.5, ScalarType::U8, false);
        assert_eq!(b, [3]);
        let mut text = String::new();
        write_ascii(&mut text, 2.4, ScalarType::I32);
        assert_eq!(text, "2");
    }

    #[test]
    fn ascii_round_trips_and_checks_ranges() {
        for (v, ty) in [(0.1f32 as f64, ScalarType::F32), (0.1, ScalarType::F64)] {
            let mut text = String::new();
            write_ascii(&mut text, v, ty);
            assert_eq!(parse_ascii(&text, ty), Some(v), "{text}");
        }
        assert_eq!(parse_ascii("255", ScalarType::U8), Some(255.0));
        assert_eq!(parse_ascii("256", ScalarType::U8), None);
        assert_eq!(parse_ascii("-1", ScalarType::U32), None);
        assert_eq!(parse_ascii("1.5", ScalarType::I16), None);
        assert_eq!(parse_ascii("x", ScalarType::F64), None);
    }
}
