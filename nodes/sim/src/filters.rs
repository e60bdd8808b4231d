//! Separable sliding-window image filters.

use crate::math::{fmax, fmin};

/// Minimum and maximum of `src` (row-major, `w` x `h`) over square windows of radius `r`
/// clipped at the image border. `tmp_lo` and `tmp_hi` are unused scratch kept for API
/// compatibility; see [`window_min_max_in_place`].
#[allow(clippy::too_many_arguments)]
pub fn window_min_max(
    src_lo: &[f32],
    src_hi: &[f32],
    lo: &mut [f32],
    hi: &mut [f32],
    _tmp_lo: &mut [f32],
    _tmp_hi: &mut [f32],
    w: usize,
    h: usize,
    r: usize,
) {
    lo[..w * h].copy_from_slice(&src_lo[..w * h]);
    hi[..w * h].copy_from_slice(&src_hi[..w * h]);
    let mut scratch = Vec::new();
    window_min_max_in_place(lo, hi, w, h, r, &mut scratch);
}

/// Replaces `lo` by its minimum and `hi` by its maximum over square windows of radius `r`
/// (row-major `w` x `h` images, windows clipped at the border). Separable sparse-table passes
/// (log2(2r + 1) vectorisable sweeps per axis, whatever the radius; columns in strips that
/// stay in cache); `scratch` is reused.
pub fn window_min_max_in_place(
    lo: &mut [f32],
    hi: &mut [f32],
    w: usize,
    h: usize,
    r: usize,
    scratch: &mut Vec<f32>,
) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is available (checked just above).
        return unsafe { window_min_max_avx2(lo, hi, w, h, r, scratch) };
    }
    window_min_max_with(lo, hi, w, h, r, scratch);
}

/// [`window_min_max_in_place`] compiled with AVX2 (8 lanes per comparison; the same values).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn window_min_max_avx2(lo: &mut [f32], hi: &mut [f32], w: usize, h: usize, r: usize, scratch: &mut Vec<f32>) {
    window_min_max_with(lo, hi, w, h, r, scratch);
}

/// The body of [`window_min_max_in_place`].
#[inline(always)]
fn window_min_max_with(lo: &mut [f32], hi: &mut [f32], w: usize, h: usize, r: usize, scratch: &mut Vec<f32>) {
    if r == 0 {
        return;
    }
    // One scratch buffer: a column strip, then the two padded copies `sliding` works in.
    let strip = STRIP.min(w);
    let (s_len, p_len) = (h * strip, 2 * (w.max(h) + 2 * r) * strip);
    scratch.resize(s_len + p_len, 0.0);
    let (cols, pad) = scratch.split_at_mut(s_len);
    for y in 0..h {
        sliding::<false>(&mut lo[y * w..(y + 1) * w], w, 1, r, pad);
        sliding::<true>(&mut hi[y * w..(y + 1) * w], w, 1, r, pad);
    }
    columns::<false>(lo, w, h, r, cols, pad);
    columns::<true>(hi, w, h, r, cols, pad);
}

/// The column pass of [`sliding`] over the `w` x `h` image `img`, in strips of `STRIP`
/// columns copied to `cols` (a strip and its padded copy `pad` stay in cache).
#[inline(always)]
fn columns<const MAX: bool>(
    img: &mut [f32],
    w: usize,
    h: usize,
    r: usize,
    cols: &mut [f32],
    pad: &mut [f32],
) {
    for c0 in (0..w).step_by(STRIP) {
        let sw = STRIP.min(w - c0);
        let cols = &mut cols[..h * sw];
        for y in 0..h {
            cols[y * sw..(y + 1) * sw].copy_from_slice(&img[y * w + c0..y * w + c0 + sw]);
        }
        sliding::<MAX>(cols, h, sw, r, pad);
        for y in 0..h {
            img[y * w + c0..y * w + c0 + sw].copy_from_slice(&cols[y * sw..(y + 1) * sw]);
        }
    }
}

/// Columns per strip of the column pass of [`window_min_max_in_place`].
const STRIP: usize = 64;

/// Sliding minimum (maximum when `MAX`) over windows of `2r + 1` items, in place. `data` holds
/// `n` items of `stride` values each (item `j` is `data[j * stride..(j + 1) * stride]`); the
/// window runs over items, element-wise.
#[inline(always)]
fn sliding<const MAX: bool>(data: &mut [f32], n: usize, stride: usize, r: usize, pad: &mut [f32]) {
    let fill = if MAX { f32::NEG_INFINITY } else { f32::INFINITY };
    // Log intensities are never NaN: plain comparisons vectorise to single min/max ops.
    let pick = |a: f32, b: f32| if MAX { fmax(a, b) } else { fmin(a, b) };
    let np = n + 2 * r;
    let size = np * stride;
    // Two padded copies: each pass reads one and writes the other (vectorises whatever the
    // distance between the items it combines).
    let (mut cur, mut next) = pad[..2 * size].split_at_mut(size);
    cur[..r * stride].fill(fill);
    cur[(r + n) * stride..].fill(fill);
    cur[r * stride..(r + n) * stride].copy_from_slice(&data[..n * stride]);
    let win = 2 * r + 1;
    // After the pass for `len`, item j holds the extreme of items [j, j + 2 len) (clipped);
    // items past the last combined one keep their values.
    let mut len = 1;
    while len * 2 <= win {
        let (s, m) = (len * stride, (np - len) * stride);
        for ((o, a), b) in next[..m].iter_mut().zip(&cur[..m]).zip(&cur[s..s + m]) {
            *o = pick(*a, *b);
        }
        next[m..].copy_from_slice(&cur[m..]);
        std::mem::swap(&mut cur, &mut next);
        len *= 2;
    }
    // Window [j, j + win) of the padded items = items [j, j + len) and [j + win - len, j + win).
    let off = (win - len) * stride;
    for (j, d) in data[..n * stride].iter_mut().enumerate() {
        *d = pick(cur[j], cur[j + off]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_min_max_matches_brute_force() {
        let (w, h) = (17usize, 11usize);
        let a: Vec<f32> = (0..w * h).map(|i| ((i * 7919) % 31) as f32 - 15.0).collect();
        let b: Vec<f32> = a.iter().map(|v| v + ((*v as i32 % 3) as f32).abs()).collect();
        for r in [0usize, 1, 2, 4, 20] {
            let mut lo = vec![0.0; w * h];
            let mut hi = vec![0.0; w * h];
            let mut t1 = vec![0.0; w * h];
            let mut t2 = vec![0.0; w * h];
            window_min_max(&a, &b, &mut lo, &mut hi, &mut t1, &mut t2, w, h, r);
            for y in 0..h {
                for x in 0..w {
                    let (mut mn, mut mx) = (f32::INFINITY, f32::NEG_INFINITY);
                    for yy in y.saturating_sub(r)..=(y + r).min(h - 1) {
                        for xx in x.saturating_sub(r)..=(x + r).min(w - 1) {
                            mn = mn.min(a[yy * w + xx]);
                            mx = mx.max(b[yy * w + xx]);
                        }
                    }
                    assert_eq!((lo[y * w + x], hi[y * w + x]), (mn, mx), "r {r} at {x},{y}");
                }
            }
        }
    }
}
