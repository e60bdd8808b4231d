//! Texture samples 8 at a time with AVX2: [`Texture::sample`] written out in vector
//! operations in the same order (no fused multiply-adds), so the same values lane by lane.
//!
//! Each lane's four bilinear taps come from one 16-byte load of `Texture::quads` (the taps
//! stored together per texel); four hardware gathers of single texels took about twice as
//! long. Paths whose footprint keeps every sample on the finest level (the common case: the
//! texture magnified) skip the level of detail and the second level altogether.
//!
//! Safety: the lane functions are `unsafe` and `#[inline(always)]` rather than
//! `#[target_feature]` (the two cannot be combined): callers must run where AVX2 is
//! available (detected at run time), and inlined into code compiled for AVX2 (the key frames'
//! cast, the unstable renders, the stable paths) their intrinsics inline too, where an
//! out-of-line `#[target_feature]` function cost a call per 8 samples.

use std::arch::x86_64::*;

use super::{LANES, Texture};

/// `floor(x)` as integers and `x - floor(x)`: truncation, minus one where that rounded up
/// (`floor_split` lane by lane, for the |x| < 2^31 that texture coordinates stay within).
#[inline(always)]
unsafe fn floor_split(x: __m256) -> (__m256i, __m256) {
    // SAFETY: callers run where AVX2 is available (see the documentation).
    unsafe {
        let t = _mm256_cvttps_epi32(x);
        let up = _mm256_castps_si256(_mm256_cmp_ps::<_CMP_GT_OQ>(_mm256_cvtepi32_ps(t), x));
        let i = _mm256_add_epi32(t, up);
        (i, _mm256_sub_ps(x, _mm256_cvtepi32_ps(i)))
    }
}

/// Log intensity of `Texture::sample` with footprint `fp` (a vector of 8): the level of detail
/// (`fast_log2` of the footprint in texels, clamped to the baked levels).
#[inline(always)]
unsafe fn level_of_detail(inv_texel: f32, max_level: f32, fp: __m256) -> __m256 {
    // SAFETY: callers run where AVX2 is available (see the documentation).
    unsafe {
        let x = _mm256_max_ps(_mm256_mul_ps(fp, _mm256_set1_ps(inv_texel)), _mm256_set1_ps(1e-6));
        let bits = _mm256_castps_si256(x);
        let e = _mm256_sub_epi32(
            _mm256_and_si256(_mm256_srli_epi32::<23>(bits), _mm256_set1_epi32(255)),
            _mm256_set1_epi32(127),
        );
        let m = _mm256_castsi256_ps(_mm256_or_si256(
            _mm256_and_si256(bits, _mm256_set1_epi32(0x007f_ffff)),
            _mm256_set1_epi32(0x3f80_0000),
        ));
        let lod = _mm256_add_ps(_mm256_cvtepi32_ps(e), _mm256_sub_ps(m, _mm256_set1_ps(1.0)));
        let (zero, max_level) = (_mm256_setzero_ps(), _mm256_set1_ps(max_level));
        let lod = _mm256_blendv_ps(lod, zero, _mm256_cmp_ps::<_CMP_LT_OQ>(lod, zero));
        _mm256_blendv_ps(lod, max_level, _mm256_cmp_ps::<_CMP_GT_OQ>(lod, max_level))
    }
}

impl Texture {
    /// `Texture::bilinear` of 8 points `(u, v)` on levels with texels per metre `scale`, side
    /// `size` and first texel `start` (per lane).
    #[inline(always)]
    unsafe fn bilinear_lanes(
        &self,
        u: __m256,
        v: __m256,
        scale: __m256,
        size: __m256i,
        start: __m256i,
    ) -> __m256 {
        // SAFETY: callers run where AVX2 is available (see the documentation).
        unsafe {
            let mask = _mm256_sub_epi32(size, _mm256_set1_epi32(1));
            let half = _mm256_set1_ps(0.5);
            let (iu, a) = floor_split(_mm256_sub_ps(_mm256_mul_ps(u, scale), half));
            let (iv, b) = floor_split(_mm256_sub_ps(_mm256_mul_ps(v, scale), half));
            let x0 = _mm256_and_si256(iu, mask);
            let y0 = _mm256_and_si256(iv, mask);
            let index = _mm256_add_epi32(_mm256_add_epi32(start, _mm256_mullo_epi32(y0, size)), x0);
            let mut at = [0i32; LANES];
            _mm256_storeu_si256(at.as_mut_ptr().cast(), index);
            let quads = self.quads.as_ptr().cast::<f32>();
            // Every index is a level's start plus a row and a column below its side, so inside
            // `quads` (one entry per texel); each entry is 4 floats.
            let load = |l: usize| _mm_loadu_ps(quads.add(at[l] as usize * 4));
            // Lanes 0..4 in the low halves, 4..8 in the high ones; a 4 x 4 transpose per half
            // turns the rows (one lane's taps) into one vector per tap.
            let r0 = _mm256_set_m128(load(4), load(0));
            let r1 = _mm256_set_m128(load(5), load(1));
            let r2 = _mm256_set_m128(load(6), load(2));
            let r3 = _mm256_set_m128(load(7), load(3));
            let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
            let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
            let pd = _mm256_castps_pd;
            let d00 = _mm256_castpd_ps(_mm256_unpacklo_pd(pd(t0), pd(t2)));
            let d01 = _mm256_castpd_ps(_mm256_unpackhi_pd(pd(t0), pd(t2)));
            let d10 = _mm256_castpd_ps(_mm256_unpacklo_pd(pd(t1), pd(t3)));
            let d11 = _mm256_castpd_ps(_mm256_unpackhi_pd(pd(t1), pd(t3)));
            let top = _mm256_add_ps(d00, _mm256_mul_ps(a, _mm256_sub_ps(d01, d00)));
            let bot = _mm256_add_ps(d10, _mm256_mul_ps(a, _mm256_sub_ps(d11, d10)));
            _mm256_add_ps(top, _mm256_mul_ps(b, _mm256_sub_ps(bot, top)))
        }
    }

    /// [`Texture::sample`] of 8 points: both mip levels a lane may blend are sampled for every
    /// lane and the second is blended in where `sample` would.
    #[inline(always)]
    unsafe fn sample_vec(&self, u: __m256, v: __m256, fp: __m256) -> __m256 {
        // SAFETY: callers run where AVX2 is available (see the documentation).
        unsafe {
            // Unaligned loads of 8 values from arrays of 8.
            let (scales, sizes, starts) = (
                _mm256_loadu_ps(self.lane_scale.as_ptr()),
                _mm256_loadu_si256(self.lane_size.as_ptr().cast()),
                _mm256_loadu_si256(self.lane_start.as_ptr().cast()),
            );
            let level = |l: __m256i| {
                (
                    _mm256_permutevar8x32_ps(scales, l),
                    _mm256_permutevar8x32_epi32(sizes, l),
                    _mm256_permutevar8x32_epi32(starts, l),
                )
            };
            // Footprints of at most one texel: `fast_log2` <= 0, the finest level alone (as
            // below, without the level tables).
            let texels = _mm256_mul_ps(fp, _mm256_set1_ps(self.inv_texel));
            if _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(texels, _mm256_set1_ps(1.0))) == 0 {
                let m0 = &self.mips[0];
                return self.bilinear_lanes(
                    u,
                    v,
                    _mm256_set1_ps(m0.scale),
                    _mm256_set1_epi32(m0.size as i32),
                    _mm256_set1_epi32(m0.start as i32),
                );
            }
            let lod = level_of_detail(self.inv_texel, self.max_level, fp);
            // lod >= 0 (or -0): truncation is `floor_fast`; lod <= 0 gives level 0 with f <= 0,
            // which is `sample`'s level-0 branch.
            let l0 = _mm256_cvttps_epi32(lod);
            let f = _mm256_sub_ps(lod, _mm256_cvtepi32_ps(l0));
            let (scale, size, start) = level(l0);
            let a = self.bilinear_lanes(u, v, scale, size, start);
            let zero = _mm256_setzero_ps();
            let blend = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GT_OQ>(f, zero),
                _mm256_cmp_ps::<_CMP_LT_OQ>(_mm256_cvtepi32_ps(l0), _mm256_set1_ps(self.max_level)),
            );
            if _mm256_movemask_ps(blend) == 0 {
                return a;
            }
            // Lanes that do not blend take their own level again (always a valid level).
            let l1 = _mm256_add_epi32(
                l0,
                _mm256_and_si256(_mm256_castps_si256(blend), _mm256_set1_epi32(1)),
            );
            let (scale, size, start) = level(l1);
            let b = self.bilinear_lanes(u, v, scale, size, start);
            _mm256_blendv_ps(a, _mm256_add_ps(a, _mm256_mul_ps(f, _mm256_sub_ps(b, a))), blend)
        }
    }

    /// [`Texture::sample_lanes`] with AVX2, inlined into its callers (see the module's
    /// safety note).
    #[inline(always)]
    pub(super) unsafe fn sample_lanes_avx2(
        &self,
        u: &[f32; LANES],
        v: &[f32; LANES],
        fp: &[f32; LANES],
    ) -> [f32; LANES] {
        // SAFETY: callers run where AVX2 is available (see the documentation).
        unsafe {
            // Unaligned loads of 8 values from arrays of 8, a store into an array of 8.
            let (u, v, fp) = (
                _mm256_loadu_ps(u.as_ptr()),
                _mm256_loadu_ps(v.as_ptr()),
                _mm256_loadu_ps(fp.as_ptr()),
            );
            let s = self.sample_vec(u, v, fp);
            let mut r = [0.0f32; LANES];
            _mm256_storeu_ps(r.as_mut_ptr(), s);
            r
        }
    }

    /// [`Texture::sample_path`] with AVX2 into `out` (of length `m - 1 >= 1`): 8 samples at a
    /// time, the last group padded with the path's last sample. When the footprint keeps
    /// every sample's level of detail at 0 (`fast_log2` of at most one texel: the footprint
    /// is interpolated between its ends, so it stays below the larger end up to rounding,
    /// which the 0.999 covers), the finest level alone is sampled, which is what `sample`
    /// does there. Inlined into its callers (see the module's safety note).
    #[inline(always)]
    pub(super) unsafe fn sample_path_avx2(
        &self,
        start: [f32; 4],
        delta: [f32; 4],
        m: usize,
        out: &mut [f32],
    ) -> (f32, f32) {
        // SAFETY: callers run where AVX2 is available (see the module's safety note).
        unsafe {
            let n = out.len();
            let mf = _mm256_set1_ps(m as f32);
            let last = _mm256_set1_ps(n as f32);
            let ones = _mm256_set_ps(8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0);
            let (fp0, fp1) = (start[2], start[2] + delta[2]);
            let finest = fp0.max(fp1) * self.inv_texel <= 0.999;
            let m0 = &self.mips[0];
            let (scale0, size0, start0) = (
                _mm256_set1_ps(m0.scale),
                _mm256_set1_epi32(m0.size as i32),
                _mm256_set1_epi32(m0.start as i32),
            );
            let (mut lo, mut hi) = (_mm256_set1_ps(f32::INFINITY), _mm256_set1_ps(f32::NEG_INFINITY));
            let mut j0 = 0;
            while j0 < n {
                // Sample j0 + l + 1 (at most n: the padding repeats the last sample), at f = that / m.
                let at = _mm256_min_ps(_mm256_add_ps(ones, _mm256_set1_ps(j0 as f32)), last);
                let f = _mm256_div_ps(at, mf);
                let along = |k: usize| {
                    _mm256_add_ps(
                        _mm256_set1_ps(start[k]),
                        _mm256_mul_ps(f, _mm256_set1_ps(delta[k])),
                    )
                };
                let (u, v) = (along(0), along(1));
                let s = if finest {
                    self.bilinear_lanes(u, v, scale0, size0, start0)
                } else {
                    self.sample_vec(u, v, along(2))
                };
                let s = _mm256_add_ps(
                    _mm256_add_ps(s, _mm256_set1_ps(start[3])),
                    _mm256_mul_ps(f, _mm256_set1_ps(delta[3])),
                );
                lo = _mm256_min_ps(lo, s);
                hi = _mm256_max_ps(hi, s);
                let mut r = [0.0f32; LANES];
                // An unaligned store of 8 values into an array of 8.
                _mm256_storeu_ps(r.as_mut_ptr(), s);
                let k = (n - j0).min(LANES);
                out[j0..j0 + k].copy_from_slice(&r[..k]);
                j0 += LANES;
            }
            let (mut a, mut b) = ([0.0f32; LANES], [0.0f32; LANES]);
            // Unaligned stores of 8 values into arrays of 8.
            _mm256_storeu_ps(a.as_mut_ptr(), lo);
            _mm256_storeu_ps(b.as_mut_ptr(), hi);
            (
                a.iter().fold(f32::INFINITY, |x, &y| x.min(y)),
                b.iter().fold(f32::NEG_INFINITY, |x, &y| x.max(y)),
            )
        }
    }
}
