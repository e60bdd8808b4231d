//! Allocator settings for nodes that move slices of megabytes.
//!
//! glibc serves large allocations with a fresh `mmap` and returns them with `munmap` on free, so
//! every slice buffer was page-faulted in and zeroed again by the kernel; and it trims the heap
//! eagerly. Keeping blocks up to 32 MiB on the heap and trimming only above 256 MiB made the
//! three-process transport benchmark about 1.5–2x faster on the project's VM (A/B of alternating
//! runs, README). Call once at start-up; a no-op on other C libraries.

/// Largest allocation still served from the heap, bytes (glibc's own ceiling for the setting).
pub const MMAP_THRESHOLD: i32 = 32 << 20;
/// Free heap memory kept before it is returned to the system, bytes.
pub const TRIM_THRESHOLD: i32 = 256 << 20;

/// Applies the settings (glibc only).
pub fn tune_allocator() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: mallopt only changes allocator parameters; called before any threads are started.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, MMAP_THRESHOLD);
        libc::mallopt(libc::M_TRIM_THRESHOLD, TRIM_THRESHOLD);
    }
}
