//! What the processor can run, checked once at run time: kernels compiled for wider vector
//! instructions are chosen only where the CPU has them, so one wheel runs on every x86-64.

/// Whether this CPU runs the AVX2/FMA kernels (`#[target_feature(enable = "avx2,fma")]`).
pub(crate) fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}
