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
}
