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
