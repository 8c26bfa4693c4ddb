//! Cache hints: the one place the executors and the rasterizer issue prefetches.

/// A prefetch hint for the cache line of `p`. Any address is fine: a prefetch reads
/// nothing architecturally and never faults, so `p` need not point into an allocation.
#[inline(always)]
pub(crate) fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `prefetcht0` is an SSE instruction (x86_64 baseline) that only hints the
    // cache; it reads nothing architecturally and cannot fault, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
