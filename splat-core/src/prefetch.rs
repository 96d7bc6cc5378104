//! Cache hints for the tile loops, which read memory in orders the hardware's prefetchers do
//! not foresee: a tile's splat records scattered over the projection buffer, and the rows of
//! row-major images 16 rows a tile apart; and for the chain, whose per-group records (about
//! 730 bytes each, read in order) the hardware's prefetchers bring too late. A hint reads
//! nothing for the program and never faults, so none of these changes a result.

use crate::project::ChainLanes;
use crate::projected::Projected;

/// Hints the CPU to bring `proj[i]` into the cache (nothing if `i` is out of range).
#[inline(always)]
pub(crate) fn record(proj: &[Projected], i: usize) {
    if let Some(rec) = proj.get(i) {
        // The line the record starts in: the fields the walks read first.
        bytes(std::ptr::from_ref(rec).cast(), 1);
    }
}

/// Hints the CPU to bring the whole record `chain[group]` into the cache (nothing if `group` is
/// out of range).
#[inline(always)]
pub(crate) fn chain(chain: &[ChainLanes], group: usize) {
    if let Some(rec) = chain.get(group) {
        bytes(std::ptr::from_ref(rec).cast(), size_of::<ChainLanes>());
    }
}

/// Hints the CPU to bring the cache lines of `data[start..start + len]` into the cache (the
/// range clipped to `data`).
#[inline(always)]
pub(crate) fn span(data: &[f32], start: usize, len: usize) {
    let end = (start + len).min(data.len());
    if start < end {
        bytes(
            data[start..end].as_ptr().cast(),
            (end - start) * size_of::<f32>(),
        );
    }
}

/// Hints the CPU to bring the cache lines of the `len` bytes from `first` into the cache (a
/// no-op where there is no prefetch hint). A prefetch never faults, so any address will do.
#[inline(always)]
pub(crate) fn bytes(first: *const u8, len: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        const LINE: usize = 64;
        let lead = first as usize % LINE;
        let mut offset = 0;
        while offset < lead + len {
            // SAFETY: prefetching is a hint that never faults or reads the memory for the
            // program, and SSE is part of the x86-64 baseline.
            #[allow(unsafe_code)]
            unsafe {
                std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                    first.wrapping_sub(lead).wrapping_add(offset).cast::<i8>(),
                );
            }
            offset += LINE;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (first, len);
}
