//! Separable sliding-window image filters.

/// Minimum and maximum of `src` (row-major, `w` x `h`) over square windows of radius `r`
/// clipped at the image border (van Herk / Gil-Werman: a few comparisons per pixel and pass,
/// whatever the radius). `tmp_lo` and `tmp_hi` are scratch images of the same size.
#[allow(clippy::too_many_arguments)]
pub fn window_min_max(
    src_lo: &[f32],
    src_hi: &[f32],
    lo: &mut [f32],
    hi: &mut [f32],
    tmp_lo: &mut [f32],
    tmp_hi: &mut [f32],
    w: usize,
    h: usize,
    r: usize,
) {
    let mut line = Vec::with_capacity(w.max(h));
    let mut out = Vec::with_capacity(w.max(h));
    let mut scratch = Scratch::default();
    for y in 0..h {
        let rows = y * w..(y + 1) * w;
        running(&src_lo[rows.clone()], r, false, &mut out, &mut scratch);
        tmp_lo[rows.clone()].copy_from_slice(&out);
        running(&src_hi[rows.clone()], r, true, &mut out, &mut scratch);
        tmp_hi[rows].copy_from_slice(&out);
    }
    for x in 0..w {
        line.clear();
        line.extend((0..h).map(|y| tmp_lo[y * w + x]));
        running(&line, r, false, &mut out, &mut scratch);
        for (y, v) in out.iter().enumerate() {
            lo[y * w + x] = *v;
        }
        line.clear();
        line.extend((0..h).map(|y| tmp_hi[y * w + x]));
        running(&line, r, true, &mut out, &mut scratch);
        for (y, v) in out.iter().enumerate() {
            hi[y * w + x] = *v;
        }
    }
}

#[derive(Default)]
struct Scratch {
    pre: Vec<f32>,
    suf: Vec<f32>,
}

/// Sliding-window minimum (or maximum when `max`) of radius `r` over one line.
fn running(v: &[f32], r: usize, max: bool, out: &mut Vec<f32>, s: &mut Scratch) {
    let n = v.len();
    let k = 2 * r + 1;
    let fill = if max { f32::NEG_INFINITY } else { f32::INFINITY };
    let pick = |a: f32, b: f32| if max { a.max(b) } else { a.min(b) };
    let padded = n + 2 * r;
    let get = |j: usize| if j < r || j >= r + n { fill } else { v[j - r] };
    s.pre.clear();
    s.pre.resize(padded, fill);
    s.suf.clear();
    s.suf.resize(padded, fill);
    for j in 0..padded {
        s.pre[j] = if j % k == 0 {
            get(j)
        } else {
            pick(s.pre[j - 1], get(j))
        };
    }
    for j in (0..padded).rev() {
        s.suf[j] = if j % k == k - 1 || j == padded - 1 {
            get(j)
        } else {
            pick(s.suf[j + 1], get(j))
        };
    }
    out.clear();
    out.extend((0..n).map(|c| pick(s.suf[c], s.pre[c + 2 * r])));
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
