//! The nearest-surface search of 8 rays at once with AVX2: `FrameGeom::search_lanes` written
//! out in vector operations in the same order (no fused multiply-adds, the same comparisons
//! and tie rules), so the same results lane by lane. The compiler had left the lane loops of
//! the generic search mostly scalar (one plane or box test per lane and branch).
//!
//! Safety: these functions are `unsafe` and `#[inline(always)]` rather than
//! `#[target_feature]` (the two cannot be combined): callers must run where AVX2 is available
//! (detected at run time), and inlined into code compiled for AVX2 their intrinsics inline
//! too; the callers outside such code (edge sub-rays, masks) are compiled for AVX2 themselves.

use std::arch::x86_64::*;

use super::{FrameGeom, LaneSearch};
use crate::texture::LANES;

/// `a[0] * x + a[1] * y + a[2]` in lanes (the order of `dot3`).
#[inline(always)]
unsafe fn dot3(a: &[f32; 3], x: __m256, y: __m256) -> __m256 {
    // SAFETY: callers run where AVX2 is available (see the module's safety note).
    unsafe {
        _mm256_add_ps(
            _mm256_add_ps(
                _mm256_mul_ps(_mm256_set1_ps(a[0]), x),
                _mm256_mul_ps(_mm256_set1_ps(a[1]), y),
            ),
            _mm256_set1_ps(a[2]),
        )
    }
}

/// `b` where `mask` is set, else `a` (integer lanes).
#[inline(always)]
unsafe fn select_i(a: __m256i, b: __m256i, mask: __m256) -> __m256i {
    // SAFETY: callers run where AVX2 is available (see the module's safety note).
    unsafe {
        _mm256_castps_si256(_mm256_blendv_ps(
            _mm256_castsi256_ps(a),
            _mm256_castsi256_ps(b),
            mask,
        ))
    }
}

impl FrameGeom {
    /// `FrameGeom::search_lanes` of 8 rays with AVX2.
    #[inline(always)]
    pub(super) unsafe fn search_lanes_avx2(
        &self,
        x: &[f32; LANES],
        y: &[f32; LANES],
        px: &[i32; LANES],
        py: &[i32; LANES],
    ) -> LaneSearch<LANES> {
        // SAFETY: callers run where AVX2 is available (see the module's safety note).
        unsafe {
            // Unaligned loads of 8 values from arrays of 8.
            let (x, y, px, py) = (
                _mm256_loadu_ps(x.as_ptr()),
                _mm256_loadu_ps(y.as_ptr()),
                _mm256_loadu_si256(px.as_ptr().cast()),
                _mm256_loadu_si256(py.as_ptr().cast()),
            );
            let none = _mm256_set1_epi32(-1);
            let mut best_inv = _mm256_setzero_ps();
            let mut best_plane = none;
            for (i, p) in self.planes.iter().enumerate() {
                let inv = dot3(&p.a, x, y);
                let better = _mm256_cmp_ps::<_CMP_GT_OQ>(inv, best_inv);
                best_inv = _mm256_blendv_ps(best_inv, inv, better);
                best_plane = select_i(best_plane, _mm256_set1_epi32(i as i32), better);
            }
            let no_plane = _mm256_castsi256_ps(_mm256_cmpeq_epi32(best_plane, none));
            let mut s = _mm256_blendv_ps(
                _mm256_div_ps(_mm256_set1_ps(1.0), best_inv),
                _mm256_set1_ps(f32::INFINITY),
                no_plane,
            );
            let mut best_box = none;
            let mut box_face = _mm256_setzero_si256();
            let mut box_db = [_mm256_setzero_ps(); 3];
            for (j, b) in self.boxes.iter().enumerate() {
                // bbox[0] <= px <= bbox[2] and bbox[1] <= py <= bbox[3] (pixel boxes lie well
                // inside the i32 range, so the +-1 cannot overflow).
                let within = |v: __m256i, lo: i32, hi: i32| {
                    _mm256_and_si256(
                        _mm256_cmpgt_epi32(v, _mm256_set1_epi32(lo - 1)),
                        _mm256_cmpgt_epi32(_mm256_set1_epi32(hi + 1), v),
                    )
                };
                let inside = _mm256_castsi256_ps(_mm256_and_si256(
                    within(px, b.bbox[0], b.bbox[2]),
                    within(py, b.bbox[1], b.bbox[3]),
                ));
                if _mm256_movemask_ps(inside) == 0 {
                    continue;
                }
                let db = [
                    dot3(&b.r_bc[0], x, y),
                    dot3(&b.r_bc[1], x, y),
                    dot3(&b.r_bc[2], x, y),
                ];
                let mut t_in = _mm256_set1_ps(f32::NEG_INFINITY);
                let mut t_out = _mm256_set1_ps(f32::INFINITY);
                let mut axis = _mm256_setzero_si256();
                for (k, row) in db.iter().enumerate() {
                    let (lo_k, hi_k) = (-b.half[k] - b.o_b[k], b.half[k] - b.o_b[k]);
                    let inv = _mm256_div_ps(_mm256_set1_ps(1.0), *row);
                    let t1 = _mm256_mul_ps(_mm256_set1_ps(lo_k), inv);
                    let t2 = _mm256_mul_ps(_mm256_set1_ps(hi_k), inv);
                    let ordered = _mm256_cmp_ps::<_CMP_LT_OQ>(t1, t2);
                    let lo = _mm256_blendv_ps(t2, t1, ordered);
                    let hi = _mm256_blendv_ps(t1, t2, ordered);
                    let later = _mm256_cmp_ps::<_CMP_GT_OQ>(lo, t_in);
                    t_in = _mm256_blendv_ps(t_in, lo, later);
                    axis = select_i(axis, _mm256_set1_epi32(k as i32), later);
                    // `t_out.min(hi)`: `hi` when smaller, else `t_out` (never NaN); a NaN `hi`
                    // leaves `t_out`, as `f32::min` does.
                    t_out = _mm256_min_ps(hi, t_out);
                }
                let hit = _mm256_and_ps(
                    _mm256_and_ps(inside, _mm256_cmp_ps::<_CMP_LE_OQ>(t_in, t_out)),
                    _mm256_and_ps(
                        _mm256_cmp_ps::<_CMP_GT_OQ>(t_in, _mm256_setzero_ps()),
                        _mm256_cmp_ps::<_CMP_LT_OQ>(t_in, s),
                    ),
                );
                if _mm256_movemask_ps(hit) == 0 {
                    continue;
                }
                s = _mm256_blendv_ps(s, t_in, hit);
                best_box = select_i(best_box, _mm256_set1_epi32(j as i32), hit);
                // Face 2 axis + (db[axis] < 0).
                let on = |k: i32| _mm256_castsi256_ps(_mm256_cmpeq_epi32(axis, _mm256_set1_epi32(k)));
                let db_axis = _mm256_blendv_ps(_mm256_blendv_ps(db[0], db[1], on(1)), db[2], on(2));
                let negative = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_LT_OQ>(db_axis, _mm256_setzero_ps()));
                let face = _mm256_sub_epi32(_mm256_add_epi32(axis, axis), negative);
                box_face = select_i(box_face, face, hit);
                for k in 0..3 {
                    box_db[k] = _mm256_blendv_ps(box_db[k], db[k], hit);
                }
            }
            let mut out = LaneSearch {
                best_plane: [0; LANES],
                best_box: [0; LANES],
                box_face: [0; LANES],
                box_db: [[0.0; LANES]; 3],
                s: [0.0; LANES],
            };
            // Unaligned stores of 8 values into arrays of 8.
            _mm256_storeu_si256(out.best_plane.as_mut_ptr().cast(), best_plane);
            _mm256_storeu_si256(out.best_box.as_mut_ptr().cast(), best_box);
            _mm256_storeu_si256(out.box_face.as_mut_ptr().cast(), box_face);
            _mm256_storeu_ps(out.s.as_mut_ptr(), s);
            for (d, v) in out.box_db.iter_mut().zip(box_db) {
                _mm256_storeu_ps(d.as_mut_ptr(), v);
            }
            out
        }
    }
}
