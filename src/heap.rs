//! Returning freed heap memory to the operating system between the phases of a large solve.

/// Hands the allocator's free pages back to the operating system.
///
/// glibc's allocator raises its mmap threshold each time a large block is freed, so after the
/// first round of a solve, blocks of up to 32 MiB (support factors, gathered blocks, `nf x m`
/// vectors) come from the per-thread arenas, whose freed pages stay resident. A round frees its
/// support factors just before the next round allocates new ones of another shape; without this
/// the peak resident size carries the last round's free pages on top of the new factors. On the
/// 85k armadillo of `bench scale` (tol 1e-9) the peak fell from 2,114-2,148 to 1,945-1,950 MiB,
/// with the support blocks gathered twice (`bbw/active_set/support_factor.rs`). The pages come
/// back zeroed, which the next round pays for: the 31k armadillo's support factors took 6.7
/// instead of 6.1-6.2 s (9 rounds).
pub(crate) fn return_free_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        extern "C" {
            fn malloc_trim(pad: usize) -> std::ffi::c_int;
        }
        // SAFETY: malloc_trim takes no pointers and only releases pages the allocator holds
        // free; it is safe to call at any time from any thread.
        unsafe {
            malloc_trim(0);
        }
    }
}
