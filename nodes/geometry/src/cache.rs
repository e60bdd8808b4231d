//! Cache hints for the per-event loops that look up a per-pixel table (undistortion, surfaces
//! of active events): events arrive in time order, so consecutive events land on pixels far
//! apart and each lookup would otherwise wait for memory. A hint changes no result.

/// How many events ahead of the one being processed a per-pixel lookup is prefetched: far
/// enough for memory to answer in time, near enough for the lines to stay in the first-level
/// cache.
pub const PREFETCH_AHEAD: usize = 8;

/// Asks the CPU to bring the cache line holding `v` into the first-level cache. Never reads or
/// writes for the program and cannot fault; nothing on targets without the instruction.
#[inline(always)]
pub fn prefetch<T>(v: &T) {
    // SAFETY: SSE is part of every x86_64 target, and a prefetch only hints the cache: it does
    // not access memory for the program and cannot fault, whatever the address.
    #[cfg(target_arch = "x86_64")]
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>((v as *const T).cast::<i8>())
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = v;
}

/// Prefetches what `items[index + PREFETCH_AHEAD]` refers to (nothing past the end): for a loop
/// over references to samples scattered in memory, called with the index being processed.
#[inline(always)]
pub fn prefetch_referent_ahead<T>(items: &[&T], index: usize) {
    if let Some(&ahead) = items.get(index + PREFETCH_AHEAD) {
        prefetch(ahead);
    }
}
