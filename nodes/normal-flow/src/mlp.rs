//! Bias-free ReLU MLP on batches of rows, hand-written f32 loops. The inner loops run over the
//! contiguous output dimension (`y[o] += x[i] * w[i][o]`) so they vectorise; on x86-64 CPUs with
//! AVX-512F (or AVX2) and FMA a copy compiled for those features is chosen at run time.

/// The loss of one row: `(row, output p, gradient dL/dp written here) -> loss`.
pub type LossGrad<'a> = dyn FnMut(usize, [f32; 2], &mut [f32; 2]) -> f32 + 'a;

const BLOCK_COLS: usize = 16;

/// `y = x w` for `rows` rows: `x` is `rows x n_in` row-major, `w` is `n_in x n_out` input-major,
/// `y` is `rows x n_out` (overwritten); ReLU applied when `relu`.
pub fn layer(x: &[f32], w: &[f32], y: &mut [f32], rows: usize, n_in: usize, n_out: usize, relu: bool) {
    debug_assert!(x.len() >= rows * n_in && w.len() == n_in * n_out && y.len() >= rows * n_out);
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            unsafe { layer_avx512(x, w, y, rows, n_in, n_out, relu) };
            return;
        }
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            unsafe { layer_avx2(x, w, y, rows, n_in, n_out, relu) };
            return;
        }
    }
    layer_generic::<false, 4>(x, w, y, rows, n_in, n_out, relu);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx2,fma")]
fn layer_avx512(x: &[f32], w: &[f32], y: &mut [f32], rows: usize, n_in: usize, n_out: usize, relu: bool) {
    layer_generic::<true, 8>(x, w, y, rows, n_in, n_out, relu);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn layer_avx2(x: &[f32], w: &[f32], y: &mut [f32], rows: usize, n_in: usize, n_out: usize, relu: bool) {
    layer_generic::<true, 4>(x, w, y, rows, n_in, n_out, relu);
}

#[inline(always)]
fn madd<const FMA: bool>(a: f32, b: f32, c: f32) -> f32 {
    if FMA { a.mul_add(b, c) } else { a * b + c }
}

/// `R` rows x [`BLOCK_COLS`] columns of accumulators per block (`R` independent FMA chains per
/// column vector: 8 with AVX-512's 32 registers, 4 with AVX2's 16).
#[inline(always)]
fn layer_generic<const FMA: bool, const R: usize>(
    x: &[f32],
    w: &[f32],
    y: &mut [f32],
    rows: usize,
    n_in: usize,
    n_out: usize,
    relu: bool,
) {
    let mut r0 = 0;
    while r0 < rows {
        let nr = (rows - r0).min(R);
        let mut o0 = 0;
        if nr == R {
            let xs: [&[f32]; R] = std::array::from_fn(|r| &x[(r0 + r) * n_in..(r0 + r + 1) * n_in]);
            while o0 + BLOCK_COLS <= n_out {
                let mut acc = [[0.0f32; BLOCK_COLS]; R];
                for (i, wrow) in w.chunks_exact(n_out).enumerate().take(n_in) {
                    let Some(wr) = wrow.get(o0..o0 + BLOCK_COLS) else {
                        break;
                    };
                    for (a, xr) in acc.iter_mut().zip(&xs) {
                        let xv = xr[i];
                        for (k, &wv) in wr.iter().enumerate() {
                            a[k] = madd::<FMA>(xv, wv, a[k]);
                        }
                    }
                }
                for (r, a) in acc.iter().enumerate() {
                    let dst = &mut y[(r0 + r) * n_out + o0..(r0 + r) * n_out + o0 + BLOCK_COLS];
                    for (d, &v) in dst.iter_mut().zip(a) {
                        *d = if relu { v.max(0.0) } else { v };
                    }
                }
                o0 += BLOCK_COLS;
            }
        }
        if o0 < n_out {
            if n_out == 2 && o0 == 0 && n_in.is_multiple_of(8) {
                // The output layer: per row, 8 lanes of (input, output) pairs, summed at the end.
                for r in r0..r0 + nr {
                    let xr = &x[r * n_in..(r + 1) * n_in];
                    let mut acc = [0.0f32; 16];
                    for (xc, wc) in xr.chunks_exact(8).zip(w.chunks_exact(16)) {
                        for j in 0..8 {
                            acc[2 * j] = madd::<FMA>(xc[j], wc[2 * j], acc[2 * j]);
                            acc[2 * j + 1] = madd::<FMA>(xc[j], wc[2 * j + 1], acc[2 * j + 1]);
                        }
                    }
                    let (mut s0, mut s1) = (0.0f32, 0.0f32);
                    for j in 0..8 {
                        s0 += acc[2 * j];
                        s1 += acc[2 * j + 1];
                    }
                    y[2 * r] = if relu { s0.max(0.0) } else { s0 };
                    y[2 * r + 1] = if relu { s1.max(0.0) } else { s1 };
                }
            } else {
                // Remaining columns (and partial row blocks): row by row.
                for r in r0..r0 + nr {
                    let xr = &x[r * n_in..(r + 1) * n_in];
                    for o in o0..n_out {
                        let mut a = 0.0f32;
                        for (&xv, wrow) in xr.iter().zip(w.chunks_exact(n_out)) {
                            a = madd::<FMA>(xv, wrow[o], a);
                        }
                        y[r * n_out + o] = if relu { a.max(0.0) } else { a };
                    }
                }
            }
        }
        r0 += nr;
    }
}

/// Scratch buffers of [`forward`] for up to `rows` rows.
#[derive(Debug, Clone, Default)]
pub struct Scratch {
    a: Vec<f32>,
    b: Vec<f32>,
}

/// Runs the MLP (`sizes`, `layers` as in [`crate::LearnedWeights`]) on `rows` rows of `x`
/// (`rows x sizes[0]`), writing `rows x 2` outputs into `out`.
pub fn forward(
    sizes: &[usize],
    layers: &[Vec<f32>],
    x: &[f32],
    rows: usize,
    out: &mut [f32],
    s: &mut Scratch,
) {
    let last = layers.len() - 1;
    let widest = sizes.iter().copied().max().unwrap_or(0);
    s.a.resize(rows * widest, 0.0);
    s.b.resize(rows * widest, 0.0);
    for (k, w) in layers.iter().enumerate() {
        let (n_in, n_out) = (sizes[k], sizes[k + 1]);
        let relu = k != last;
        match (k == 0, k == last) {
            (true, true) => layer(x, w, out, rows, n_in, n_out, relu),
            (true, false) => layer(x, w, &mut s.a, rows, n_in, n_out, relu),
            (false, true) => layer(&s.a, w, out, rows, n_in, n_out, relu),
            (false, false) => {
                layer(&s.a, w, &mut s.b, rows, n_in, n_out, relu);
                std::mem::swap(&mut s.a, &mut s.b);
            }
        }
    }
}

/// Forward and backward pass of a batch for training: returns the summed loss and adds the
/// gradient of the summed loss to `grads` (same shapes as `layers`). `loss_grad(row, p, dp)`
/// returns the loss of output `p` (2 values) and writes its gradient into `dp`.
pub fn backprop(
    sizes: &[usize],
    layers: &[Vec<f32>],
    x: &[f32],
    rows: usize,
    grads: &mut [Vec<f32>],
    loss_grad: &mut LossGrad<'_>,
) -> f64 {
    #[cfg(target_arch = "x86_64")]
    {
        if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
            // SAFETY: the CPU supports the features the function is compiled for.
            return unsafe { backprop_avx2(sizes, layers, x, rows, grads, loss_grad) };
        }
    }
    backprop_generic(sizes, layers, x, rows, grads, loss_grad)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn backprop_avx2(
    sizes: &[usize],
    layers: &[Vec<f32>],
    x: &[f32],
    rows: usize,
    grads: &mut [Vec<f32>],
    loss_grad: &mut LossGrad<'_>,
) -> f64 {
    backprop_generic(sizes, layers, x, rows, grads, loss_grad)
}

#[inline(always)]
fn backprop_generic(
    sizes: &[usize],
    layers: &[Vec<f32>],
    x: &[f32],
    rows: usize,
    grads: &mut [Vec<f32>],
    loss_grad: &mut LossGrad<'_>,
) -> f64 {
    let nl = layers.len();
    // Activations: acts[0] = x, acts[k] = output of layer k.
    let mut acts: Vec<Vec<f32>> = Vec::with_capacity(nl + 1);
    acts.push(x[..rows * sizes[0]].to_vec());
    for (k, w) in layers.iter().enumerate() {
        let mut y = vec![0.0f32; rows * sizes[k + 1]];
        layer_generic::<false, 4>(&acts[k], w, &mut y, rows, sizes[k], sizes[k + 1], k + 1 != nl);
        acts.push(y);
    }
    // Output gradient.
    let mut loss = 0.0f64;
    let mut delta = vec![0.0f32; rows * 2];
    let out = &acts[nl];
    for r in 0..rows {
        let mut dp = [0.0f32; 2];
        loss += f64::from(loss_grad(r, [out[2 * r], out[2 * r + 1]], &mut dp));
        delta[2 * r] = dp[0];
        delta[2 * r + 1] = dp[1];
    }
    for k in (0..nl).rev() {
        let (n_in, n_out) = (sizes[k], sizes[k + 1]);
        let a = &acts[k];
        // dW[i][o] += a[r][i] * delta[r][o]
        let g = &mut grads[k];
        for r in 0..rows {
            let dr = &delta[r * n_out..(r + 1) * n_out];
            for i in 0..n_in {
                let av = a[r * n_in + i];
                if av != 0.0 {
                    let gi = &mut g[i * n_out..(i + 1) * n_out];
                    for (gv, &dv) in gi.iter_mut().zip(dr) {
                        *gv += av * dv;
                    }
                }
            }
        }
        if k == 0 {
            break;
        }
        // delta_prev[r][i] = sum_o delta[r][o] w[i][o], masked by relu(a > 0); computed with the
        // transposed weights so the inner loop runs over contiguous i (vectorises).
        let w = &layers[k];
        let mut wt = vec![0.0f32; n_in * n_out];
        for i in 0..n_in {
            for o in 0..n_out {
                wt[o * n_in + i] = w[i * n_out + o];
            }
        }
        let mut prev = vec![0.0f32; rows * n_in];
        for r in 0..rows {
            let pr = &mut prev[r * n_in..(r + 1) * n_in];
            for o in 0..n_out {
                let dv = delta[r * n_out + o];
                if dv != 0.0 {
                    for (pv, &wv) in pr.iter_mut().zip(&wt[o * n_in..(o + 1) * n_in]) {
                        *pv += dv * wv;
                    }
                }
            }
            for (pv, &av) in pr.iter_mut().zip(&a[r * n_in..(r + 1) * n_in]) {
                if av <= 0.0 {
                    *pv = 0.0;
                }
            }
        }
        delta = prev;
    }
    loss
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layer_matches_naive() {
        for (rows, n_in, n_out) in [(7, 5, 19), (9, 16, 2), (4, 24, 33), (17, 40, 48)] {
            check_layer(rows, n_in, n_out);
        }
    }

    fn check_layer(rows: usize, n_in: usize, n_out: usize) {
        let x: Vec<f32> = (0..rows * n_in)
            .map(|i| ((i * 37 % 11) as f32 - 5.0) * 0.1)
            .collect();
        let w: Vec<f32> = (0..n_in * n_out)
            .map(|i| ((i * 13 % 7) as f32 - 3.0) * 0.2)
            .collect();
        let mut y = vec![0.0; rows * n_out];
        layer(&x, &w, &mut y, rows, n_in, n_out, true);
        for r in 0..rows {
            for o in 0..n_out {
                let s: f32 = (0..n_in).map(|i| x[r * n_in + i] * w[i * n_out + o]).sum();
                assert!((y[r * n_out + o] - s.max(0.0)).abs() < 1e-5, "{r} {o}");
            }
        }
    }

    #[test]
    fn backprop_matches_finite_differences() {
        let sizes = [3usize, 4, 2];
        let layers = vec![
            (0..12)
                .map(|i| ((i * 7 % 5) as f32 - 2.0) * 0.3 + 0.05)
                .collect::<Vec<f32>>(),
            (0..8)
                .map(|i| ((i * 3 % 5) as f32 - 2.0) * 0.4 + 0.03)
                .collect::<Vec<f32>>(),
        ];
        let x = [0.5f32, -0.2, 0.9, -0.7, 0.3, 0.4];
        // Loss: sum of squares of the outputs.
        let mut lg = |_r: usize, p: [f32; 2], dp: &mut [f32; 2]| {
            dp[0] = 2.0 * p[0];
            dp[1] = 2.0 * p[1];
            p[0] * p[0] + p[1] * p[1]
        };
        let mut grads = vec![vec![0.0; 12], vec![0.0; 8]];
        let base = backprop(&sizes, &layers, &x, 2, &mut grads, &mut lg);
        for k in 0..2 {
            for j in 0..layers[k].len() {
                let mut l2 = layers.clone();
                l2[k][j] += 1e-3;
                let mut g2 = vec![vec![0.0; 12], vec![0.0; 8]];
                let up = backprop(&sizes, &l2, &x, 2, &mut g2, &mut lg);
                let fd = (up - base) / 1e-3;
                assert!(
                    (fd - f64::from(grads[k][j])).abs() < 2e-2,
                    "layer {k} weight {j}: {fd} vs {}",
                    grads[k][j]
                );
            }
        }
    }
}
