//! A buffer that parallel tasks write at positions no two of them share: the tile lists' scatter,
//! each tile's run of gradient records and of weights. Rust's slices cannot be split by
//! positions known only while the tasks run, so the tasks share a pointer and each caller
//! promises, at its `unsafe` block, that its positions are its own.

use std::marker::PhantomData;

/// Write access to a slice, shared by tasks that each write their own positions of it.
#[derive(Clone, Copy)]
pub(crate) struct DisjointWrites<'a, T> {
    ptr: *mut T,
    len: usize,
    buffer: PhantomData<&'a mut [T]>,
}

// SAFETY: the pointer comes from a `&'a mut [T]` held for 'a, and every access through it is
// to positions that the caller's `unsafe` block promises no other task touches; sending it to
// other threads is then as sound as sending those disjoint `&mut` pieces.
#[allow(unsafe_code)]
unsafe impl<T: Send> Send for DisjointWrites<'_, T> {}
// SAFETY: as for `Send`: shared use only ever writes disjoint positions.
#[allow(unsafe_code)]
unsafe impl<T: Send> Sync for DisjointWrites<'_, T> {}

impl<'a, T> DisjointWrites<'a, T> {
    /// Takes the whole of `buffer` for the tasks to write.
    pub(crate) fn new(buffer: &'a mut [T]) -> Self {
        Self {
            ptr: buffer.as_mut_ptr(),
            len: buffer.len(),
            buffer: PhantomData,
        }
    }

    /// Writes `value` at `index`.
    ///
    /// # Panics
    /// If `index` is out of bounds.
    ///
    /// # Safety
    /// No other task reads or writes `index` while the buffer is shared.
    #[allow(unsafe_code)]
    pub(crate) unsafe fn write(&self, index: usize, value: T) {
        assert!(index < self.len, "write at {index} of {}", self.len);
        // SAFETY: in bounds (just checked) and, by the caller's promise, this task's own.
        unsafe { self.ptr.add(index).write(value) }
    }

    /// Hints the CPU to fetch positions `start..start + len` (clipped to the buffer) into the
    /// cache; reads nothing, so it needs no promise.
    pub(crate) fn prefetch(&self, start: usize, len: usize) {
        let end = (start + len).min(self.len);
        if start < end {
            crate::prefetch::bytes(
                self.ptr.wrapping_add(start).cast_const().cast(),
                (end - start) * size_of::<T>(),
            );
        }
    }

    /// The run `start..end`, for this task alone.
    ///
    /// # Panics
    /// If the run is not inside the buffer.
    ///
    /// # Safety
    /// No other task reads or writes any position of `start..end` while the buffer is shared.
    #[allow(unsafe_code)]
    pub(crate) unsafe fn run(&self, start: usize, end: usize) -> &'a mut [T] {
        assert!(
            start <= end && end <= self.len,
            "run {start}..{end} of {}",
            self.len
        );
        // SAFETY: inside the buffer (just checked), which lives for 'a, and by the caller's
        // promise no other reference to these positions exists while this one is used.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.add(start), end - start) }
    }
}
