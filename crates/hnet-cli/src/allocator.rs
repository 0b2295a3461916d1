//! Keeps freed tensor memory in the process instead of handing it back to the kernel.
//!
//! Training allocates and frees tens of megabytes per activation at every step. glibc serves
//! blocks above its mmap threshold with fresh mappings and unmaps them on free, so each step
//! pays page faults and cross-core TLB shootdowns; `hnet bench model` measured a training step
//! about 30 % faster with the settings below (docs/benchmarks.md).

/// Raises glibc's mmap threshold to its maximum (32 MiB) and stops it trimming the heap.
pub fn tune() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; it is called before any thread starts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 * 1024 * 1024);
        libc::mallopt(libc::M_TRIM_THRESHOLD, i32::MAX);
        libc::mallopt(libc::M_TOP_PAD, 256 * 1024 * 1024);
    }
}
