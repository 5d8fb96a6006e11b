//! Clean vector state after faer's matrix kernels.
//!
//! faer's dense products (through the `gemm` crate) pick AVX-512 kernels on
//! processors that have them and can return with the upper halves of the
//! vector registers dirty. Until a `vzeroupper`, every switch on that
//! thread between the crate's SSE code and the VEX-encoded routines of the
//! C library (`expf`, `floorf`, `atan2f`, ... which glibc picks for these
//! processors) pays an SSE/AVX transition penalty. Measured on the planar
//! `jump_surface` benchmark (1 thread, AVX-512 machine): the seam
//! refinement's appearance analysis took 85 ms after the jump-map analysis
//! had run its products on the same thread, against 22 ms when the jump map
//! came from the cache — the same code, the same data; `expf` alone 27 ×
//! slower. [`after_faer`] after every faer call ends that.

/// Zeroes the upper halves of the vector registers of the calling thread
/// (`vzeroupper`) when the processor has AVX; nothing otherwise. Call it
/// on the thread that ran a faer product, after the product. Costs a cycle;
/// results do not change (no live value is in the upper halves between
/// calls).
#[inline]
pub fn after_faer() {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx") {
            // SAFETY: the processor supports AVX (checked just above).
            unsafe { zero_upper() }
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn zero_upper() {
    std::arch::x86_64::_mm256_zeroupper();
}
