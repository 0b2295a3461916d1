//! Keeps freed tensor memory in the process instead of handing it back to the kernel.
//!
//! Training allocates and frees tens of megabytes per activation at every step. glibc serves
//! blocks above its mmap threshold with fresh mappings and unmaps them on free, so each step
//! pays page faults and cross-core TLB shootdowns; `hnet bench model` measured a training step
//! about 30 % faster with the settings below (docs/benchmarks.md). glibc's mmap threshold cannot
//! go above 32 MiB, and one 32-channel activation of a batch of 8 pairs at 128 x 128 is 33.5 MB
//! (at 224 x 224, 103 MB), so mappings are turned off: a 128 x 128 training step measured 23 %
//! faster again (docs/benchmarks.md). Training allocates on the main thread, whose heap grows as
//! needed; a block over 64 MiB allocated on another thread (larger than one of glibc's thread
//! heaps) is still mapped, as glibc falls back to a mapping there whatever this setting says.

/// Raises glibc's mmap threshold to its maximum (32 MiB), serves larger blocks from the heap
/// too (no mappings, but for the fallback above), and stops glibc trimming the heap.
pub fn tune() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it is called before any thread starts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 * 1024 * 1024);
        libc::mallopt(libc::M_MMAP_MAX, 0);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
        libc::mallopt(libc::M_TOP_PAD, 256 * 1024 * 1024);
    }
}
