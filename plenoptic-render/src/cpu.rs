//! What the CPU running the renderer can do, detected at run time: the drawing, shading and
//! filtering loops have AVX2 instantiations chosen by it, so one binary runs on any x86-64.

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
