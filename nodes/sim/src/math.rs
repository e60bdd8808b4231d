//! The simulator's small maths: the shared rigid-body helpers ([`evseg_geometry::rigid`]:
//! 3-vectors, rotation matrices, quaternions) and branch-free `f32` minimum and maximum for its
//! render loops.

pub use evseg_geometry::rigid::*;

/// Minimum of two floats that are not NaN (a single `minss`; `f32::min` adds NaN handling).
#[inline(always)]
pub fn fmin(a: f32, b: f32) -> f32 {
    if a < b { a } else { b }
}

/// Maximum of two floats that are not NaN (a single `maxss`; `f32::max` adds NaN handling).
#[inline(always)]
pub fn fmax(a: f32, b: f32) -> f32 {
    if a > b { a } else { b }
}
