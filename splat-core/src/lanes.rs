//! Eight numbers operated on together: the lanes of the projection's vector code, and the
//! arithmetic that formulas written once for a scalar and for lanes ([`Real`]) share.
//!
//! Every operation on [`F8`] or [`D8`] is a loop over the eight lanes whose body is the scalar
//! operation, so a lane computes exactly what the scalar expression computes (the same IEEE
//! operations in the same order, and Rust never fuses a multiply and an add), while the
//! compiler emits one vector instruction per operation where the CPU has the width (AVX2: one
//! for eight f32, two for eight f64). Written by hand rather than with a SIMD crate: the crates
//! pick their instructions from the features enabled at compile time, while this code runs in
//! both a portable and a run-time-detected AVX2 instantiation of the same source.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// Lanes a vector of the projection holds.
pub(crate) const WIDTH: usize = 8;

/// A number type the shared formulas run on: f32, f64, or eight lanes of either.
pub(crate) trait Real:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// The scalar a lane holds.
    type Scalar: Copy;
    /// The value `x` in every lane.
    fn splat(x: Self::Scalar) -> Self;
    /// The square root, lane by lane.
    fn sqrt(self) -> Self;
    /// The larger of the two, lane by lane, as `f32::max` and `f64::max` take it (a NaN
    /// loses to a number).
    fn max(self, other: Self) -> Self;
}

impl Real for f32 {
    type Scalar = f32;
    #[inline(always)]
    fn splat(x: f32) -> f32 {
        x
    }
    #[inline(always)]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }
    #[inline(always)]
    fn max(self, other: f32) -> f32 {
        f32::max(self, other)
    }
}

impl Real for f64 {
    type Scalar = f64;
    #[inline(always)]
    fn splat(x: f64) -> f64 {
        x
    }
    #[inline(always)]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn max(self, other: f64) -> f64 {
        f64::max(self, other)
    }
}

/// The array of `f(0)`, `f(1)`, …: `std::array::from_fn` as a plain loop that always
/// inlines. (`from_fn`'s closure sits behind several layers of calls, and where the inliner gave
/// up on them the closure ran out of line, compiled without the caller's AVX2, so its floors
/// became library calls.) The closure itself can still be left out of line when its body is
/// large (a matrix-vector product in lanes, for example), and then runs without AVX2 too: such
/// closures carry `#[inline(always)]` (in the projection and its chain that took a fifth off
/// the chain; look for calls in the `_avx2` functions' disassembly after changing one).
#[inline(always)]
pub(crate) fn array<T: Copy + Default, const N: usize>(mut f: impl FnMut(usize) -> T) -> [T; N] {
    let mut r = [T::default(); N];
    for (i, x) in r.iter_mut().enumerate() {
        *x = f(i);
    }
    r
}

/// Which lanes a comparison holds for.
pub(crate) type Mask = [bool; WIDTH];

macro_rules! lanes {
    ($name:ident, $scalar:ty) => {
        #[derive(Clone, Copy, Debug, Default, PartialEq)]
        pub(crate) struct $name(pub [$scalar; WIDTH]);

        // Not every method serves both lane types.
        #[allow(dead_code)]
        impl $name {
            /// `f` of each lane.
            #[inline(always)]
            pub(crate) fn map(self, f: impl Fn($scalar) -> $scalar) -> Self {
                let mut r = self.0;
                for x in &mut r {
                    *x = f(*x);
                }
                Self(r)
            }

            /// The value `f(l)` in lane `l`.
            #[inline(always)]
            pub(crate) fn from_fn(f: impl FnMut(usize) -> $scalar) -> Self {
                Self(array(f))
            }

            /// Where `test(a, b)` holds, lane by lane.
            #[inline(always)]
            pub(crate) fn test(self, other: Self, test: impl Fn($scalar, $scalar) -> bool) -> Mask {
                array(|l| test(self.0[l], other.0[l]))
            }

            /// Which lanes are finite.
            #[inline(always)]
            pub(crate) fn finite(self) -> Mask {
                array(|l| self.0[l].is_finite())
            }

            /// `a` where `mask` holds, else `b`.
            #[inline(always)]
            pub(crate) fn select(mask: Mask, a: Self, b: Self) -> Self {
                Self(array(|l| if mask[l] { a.0[l] } else { b.0[l] }))
            }
        }

        impl Real for $name {
            type Scalar = $scalar;
            #[inline(always)]
            fn splat(x: $scalar) -> Self {
                Self([x; WIDTH])
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                self.map(<$scalar>::sqrt)
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                Self(array(|l| self.0[l].max(other.0[l])))
            }
        }

        impl Neg for $name {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                self.map(|x| -x)
            }
        }

        lanes!(@binary $name, Add, add, +);
        lanes!(@binary $name, Sub, sub, -);
        lanes!(@binary $name, Mul, mul, *);
        lanes!(@binary $name, Div, div, /);
    };
    (@binary $name:ident, $op:ident, $method:ident, $sym:tt) => {
        impl $op for $name {
            type Output = Self;
            #[inline(always)]
            fn $method(self, other: Self) -> Self {
                Self(array(|l| self.0[l] $sym other.0[l]))
            }
        }
    };
}

lanes!(F8, f32);
lanes!(D8, f64);

impl F8 {
    /// Each lane widened to f64 (exact).
    #[inline(always)]
    pub(crate) fn to_f64(self) -> D8 {
        D8(array(|l| f64::from(self.0[l])))
    }
}

impl D8 {
    /// Each lane rounded to f32.
    #[inline(always)]
    #[allow(clippy::cast_possible_truncation)]
    pub(crate) fn to_f32(self) -> F8 {
        F8(array(|l| self.0[l] as f32))
    }
}

/// Lanes where both masks hold.
#[inline(always)]
pub(crate) fn and(a: Mask, b: Mask) -> Mask {
    array(|l| a[l] & b[l])
}

/// Eight rows of numbers, one a lane, turned into lane vectors: `out[c].0[l] = rows[l][c]` for
/// every column c < `out.len()` (each row at least that long). With `AVX2` eight columns at a
/// time go through [`transpose8_avx2`]; element by element the SH coefficients' transposes had
/// cost the projection three instructions an element.
#[inline(always)]
pub(crate) fn rows_to_lanes<const AVX2: bool>(rows: [&[f32]; WIDTH], out: &mut [F8]) {
    let cols = out.len();
    let rows: [&[f32]; WIDTH] = array(|l| &rows[l][..cols]);
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if AVX2 {
        use std::arch::x86_64::{_mm256_loadu_ps, _mm256_storeu_ps};
        while done + WIDTH <= cols {
            // SAFETY: only AVX2 instantiations pass `AVX2`, and they run where `has_avx2()`
            // found the feature; each load reads the 8 numbers rows[l][done..done + 8] and each
            // store writes the 8 lanes of out[done + c], all in bounds (done + 8 ≤ cols).
            #[allow(unsafe_code)]
            unsafe {
                let block = transpose8_avx2(std::array::from_fn(|l| {
                    _mm256_loadu_ps(rows[l][done..done + WIDTH].as_ptr())
                }));
                for (c, v) in block.into_iter().enumerate() {
                    _mm256_storeu_ps(out[done + c].0.as_mut_ptr(), v);
                }
            }
            done += WIDTH;
        }
    }
    for (c, v) in out.iter_mut().enumerate().skip(done) {
        *v = F8(std::array::from_fn(|l| rows[l][c]));
    }
}

/// The 8 × 8 transpose of eight AVX2 vectors (vector i's element j becomes vector j's element
/// i): pairs of rows interleaved, then pairs of pairs, then the 128-bit halves exchanged, 24
/// shuffles in all. Moves numbers only, so their bits are kept.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) fn transpose8_avx2(
    r: [std::arch::x86_64::__m256; WIDTH],
) -> [std::arch::x86_64::__m256; WIDTH] {
    use std::arch::x86_64::{
        _mm256_permute2f128_ps, _mm256_shuffle_ps, _mm256_unpackhi_ps, _mm256_unpacklo_ps,
    };
    // t: in each 128-bit half, rows 2i and 2i + 1 interleaved (low or high two columns).
    let t = [
        _mm256_unpacklo_ps(r[0], r[1]),
        _mm256_unpackhi_ps(r[0], r[1]),
        _mm256_unpacklo_ps(r[2], r[3]),
        _mm256_unpackhi_ps(r[2], r[3]),
        _mm256_unpacklo_ps(r[4], r[5]),
        _mm256_unpackhi_ps(r[4], r[5]),
        _mm256_unpacklo_ps(r[6], r[7]),
        _mm256_unpackhi_ps(r[6], r[7]),
    ];
    // s[j], s[j + 4]: column j of rows 0–3 and 4–7 in the low half, column j + 4 in the high.
    let s = [
        _mm256_shuffle_ps::<0x44>(t[0], t[2]),
        _mm256_shuffle_ps::<0xEE>(t[0], t[2]),
        _mm256_shuffle_ps::<0x44>(t[1], t[3]),
        _mm256_shuffle_ps::<0xEE>(t[1], t[3]),
        _mm256_shuffle_ps::<0x44>(t[4], t[6]),
        _mm256_shuffle_ps::<0xEE>(t[4], t[6]),
        _mm256_shuffle_ps::<0x44>(t[5], t[7]),
        _mm256_shuffle_ps::<0xEE>(t[5], t[7]),
    ];
    [
        _mm256_permute2f128_ps::<0x20>(s[0], s[4]),
        _mm256_permute2f128_ps::<0x20>(s[1], s[5]),
        _mm256_permute2f128_ps::<0x20>(s[2], s[6]),
        _mm256_permute2f128_ps::<0x20>(s[3], s[7]),
        _mm256_permute2f128_ps::<0x31>(s[0], s[4]),
        _mm256_permute2f128_ps::<0x31>(s[1], s[5]),
        _mm256_permute2f128_ps::<0x31>(s[2], s[6]),
        _mm256_permute2f128_ps::<0x31>(s[3], s[7]),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each lane operation gives the scalar operation's bits, for ordinary values, signed
    /// zeros, subnormals, infinities and NaN.
    #[test]
    #[allow(clippy::needless_range_loop)] // a lane's index reads several arrays
    fn lanes_compute_what_the_scalar_operations_compute() {
        let xs = [
            1.5_f32,
            -0.0,
            0.0,
            1e-40,
            f32::INFINITY,
            f32::NAN,
            -3.25e7,
            7.0,
        ];
        let ys = [0.3_f32, 2.0, -0.0, 3e-39, 1.0, 4.0, f32::NAN, -7.0];
        let (a, b) = (F8(xs), F8(ys));
        let same = |got: F8, want: &dyn Fn(f32, f32) -> f32| {
            for l in 0..WIDTH {
                assert_eq!(got.0[l].to_bits(), want(xs[l], ys[l]).to_bits(), "lane {l}");
            }
        };
        same(a + b, &|x, y| x + y);
        same(a - b, &|x, y| x - y);
        same(a * b, &|x, y| x * y);
        same(a / b, &|x, y| x / y);
        same(-a, &|x, _| -x);
        same(Real::sqrt(b), &|_, y| y.sqrt());
        same(Real::max(a, b), &|x, y| x.max(y));
        let wide = a.to_f64();
        for l in 0..WIDTH {
            assert_eq!(wide.0[l].to_bits(), f64::from(xs[l]).to_bits());
            assert_eq!(wide.to_f32().0[l].to_bits(), xs[l].to_bits());
        }
        assert_eq!(a.test(b, |x, y| x < y), array(|l| xs[l] < ys[l]));
        assert_eq!(a.finite(), xs.map(f32::is_finite));
        let mask = [true, false, true, false, true, false, true, false];
        let picked = F8::select(mask, a, b);
        for l in 0..WIDTH {
            let want = if mask[l] { xs[l] } else { ys[l] };
            assert_eq!(picked.0[l].to_bits(), want.to_bits());
        }
    }

    /// Rows to lanes, with AVX2 where the CPU has it and without: every number lands where the
    /// element-by-element definition puts it (column counts of whole, partial and no 8 × 8
    /// blocks), bits and all.
    #[test]
    #[allow(clippy::needless_range_loop)] // a lane's index reads several arrays
    fn rows_turn_into_lanes() {
        let row_data: Vec<Vec<f32>> = (0..WIDTH)
            .map(|l| (0..51).map(|c| (100 * l + c) as f32 + 0.25).collect())
            .collect();
        for cols in [0, 3, 8, 12, 27, 48, 51] {
            let rows: [&[f32]; WIDTH] = array(|l| &row_data[l][..]);
            let mut want = vec![F8::default(); cols];
            rows_to_lanes::<false>(rows, &mut want);
            for (c, v) in want.iter().enumerate() {
                for l in 0..WIDTH {
                    assert_eq!(
                        v.0[l].to_bits(),
                        row_data[l][c].to_bits(),
                        "{cols}: ({l}, {c})"
                    );
                }
            }
            #[cfg(target_arch = "x86_64")]
            if crate::has_avx2() {
                let mut got = vec![F8::default(); cols];
                rows_to_lanes_avx2(rows, &mut got);
                assert_eq!(got, want, "{cols} columns");
            }
        }
    }

    #[cfg(target_arch = "x86_64")]
    fn rows_to_lanes_avx2(rows: [&[f32]; WIDTH], out: &mut [F8]) {
        #[target_feature(enable = "avx2")]
        fn run(rows: [&[f32]; WIDTH], out: &mut [F8]) {
            rows_to_lanes::<true>(rows, out);
        }
        // SAFETY: called only where `has_avx2()` found the feature.
        #[allow(unsafe_code)]
        unsafe {
            run(rows, out);
        }
    }
}
