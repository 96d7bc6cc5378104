//! What the CPU running the renderer can do, detected at run time (the drawing, shading and
//! filtering loops have AVX2 instantiations chosen by it, so one binary runs on any x86-64),
//! and the small idioms that keep those loops in vector lanes.

/// Whether the AVX2 instantiations of the hot loops can run on this CPU (always false off
/// x86-64).
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Asks the CPU to start loading the cache lines of `bytes` (a hint: it never faults and changes
/// no value; a no-op off x86-64). The shading pass reads each visible point's per-camera colours
/// (13 × 12 bytes at 8iVSLF's size), a sparse subset of a 490 MB array that the hardware
/// prefetcher cannot predict, so the loads missed the cache one after another
/// (docs/benchmarks/views.md).
#[inline(always)]
pub(crate) fn prefetch<T>(bytes: &[T]) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        const LINE: usize = 64;
        let start = bytes.as_ptr().cast::<i8>();
        let len = size_of_val(bytes);
        let mut offset = 0;
        // SAFETY: every x86-64 CPU has SSE, and a prefetch reads nothing the program sees: it
        // never faults, whatever the address.
        #[allow(unsafe_code)]
        unsafe {
            while offset < len {
                _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(offset));
                offset += LINE;
            }
            if len > 0 {
                _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(len - 1));
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = bytes;
}

/// The whole number nearest to `v` for `v` in [0, 2²³] (round half to even), by adding 2²³: the
/// sum's float holds it in its low mantissa bits. Outside that range (NaN included) the result
/// is meaningless but harmless. Unlike `as u32`, which saturates and so stayed one lane at a
/// time with its range checks, it is two vector operations, so loops over lanes of f32 that
/// end in integers stay in vectors.
#[inline(always)]
pub(crate) fn small_whole(v: f32) -> u32 {
    const TWO_23: f32 = 8_388_608.0;
    (v + TWO_23).to_bits().wrapping_sub(TWO_23.to_bits())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_whole_is_the_nearest_whole_number() {
        // Every whole number up to 2¹⁶ and a stride of them to 2²³, and values between: the
        // rounding is the float addition's, half to even.
        let wholes = (0..=1u32 << 16).chain((1u32 << 16..=1 << 23).step_by(997));
        for n in wholes.chain([1 << 23]) {
            let v = n as f32;
            assert_eq!(small_whole(v), n, "{v}");
            for frac in [0.25f32, 0.5, 0.75] {
                let x = v + frac;
                if x <= (1 << 23) as f32 && x.fract() != 0.0 {
                    assert_eq!(small_whole(x), x.round_ties_even() as u32, "{x}");
                }
            }
        }
        assert_eq!(small_whole(-0.0), 0);
    }
}
