//! Gaussian smoothing of per-event values on the pixel grid (paper section 3.3, "we first smooth
//! the residuals using a Gaussian filter in the image grid space").
//!
//! Values are summed into a grid of square cells (`cell_px` pixels a side) together with their
//! counts; both grids are blurred with the same separable Gaussian, and the smoothed value at a
//! cell is `blurred sum / blurred count`: the Gaussian-weighted mean of the values around it
//! (normalized convolution), so the event density does not bias the result.

/// A value grid and a count grid over the sensor, blurred.
#[derive(Debug, Clone, PartialEq)]
pub struct SmoothGrid {
    cell_px: u16,
    cols: usize,
    rows: usize,
    sum: Vec<f64>,
    count: Vec<f64>,
}

/// A 1-D Gaussian kernel with peak 1, radius `ceil(3 sigma)`, at most `max_radius` (taps beyond
/// the grid's extent only meet the zeros outside it, so a cap at the grid's size changes
/// nothing, and a huge sigma cannot allocate a huge kernel).
fn kernel(sigma: f64, max_radius: usize) -> Vec<f64> {
    if sigma.is_nan() || sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (3.0 * sigma).ceil().min(max_radius as f64) as i64;
    (-r..=r)
        .map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp())
        .collect()
}

/// Convolves rows (`stride` 1) or columns (`stride` = cols) of `g` with `k`, zero outside.
fn blur_axis(g: &[f64], cols: usize, rows: usize, k: &[f64], along_x: bool) -> Vec<f64> {
    let r = (k.len() / 2) as i64;
    let mut out = vec![0.0; g.len()];
    let (len, lines) = if along_x { (cols, rows) } else { (rows, cols) };
    for line in 0..lines {
        let at = |i: usize| if along_x { line * cols + i } else { i * cols + line };
        for i in 0..len {
            let v = g[at(i)];
            if v == 0.0 {
                continue;
            }
            let lo = (i as i64 - r).max(0) as usize;
            let hi = (i as i64 + r).min(len as i64 - 1) as usize;
            for j in lo..=hi {
                out[at(j)] += v * k[(j as i64 - i as i64 + r) as usize];
            }
        }
    }
    out
}

impl SmoothGrid {
    /// An empty grid over a `width` x `height` pixel sensor with cells of `cell_px` pixels
    /// (`cell_px` >= 1).
    pub fn new(width: u16, height: u16, cell_px: u16) -> Self {
        let cell = cell_px.max(1);
        let cols = usize::from(width).div_ceil(usize::from(cell)).max(1);
        let rows = usize::from(height).div_ceil(usize::from(cell)).max(1);
        Self {
            cell_px: cell,
            cols,
            rows,
            sum: vec![0.0; cols * rows],
            count: vec![0.0; cols * rows],
        }
    }

    fn cell(&self, u: u16, v: u16) -> usize {
        let c = (usize::from(u) / usize::from(self.cell_px)).min(self.cols - 1);
        let r = (usize::from(v) / usize::from(self.cell_px)).min(self.rows - 1);
        r * self.cols + c
    }

    /// Adds `value` at pixel `(u, v)`.
    pub fn add(&mut self, u: u16, v: u16, value: f64) {
        let c = self.cell(u, v);
        self.sum[c] += value;
        self.count[c] += 1.0;
    }

    /// Blurs both grids with a Gaussian of standard deviation `sigma_px` pixels.
    pub fn blur(&mut self, sigma_px: f64) {
        let k = kernel(sigma_px / f64::from(self.cell_px), self.cols.max(self.rows));
        for g in [&mut self.sum, &mut self.count] {
            let h = blur_axis(g, self.cols, self.rows, &k, true);
            *g = blur_axis(&h, self.cols, self.rows, &k, false);
        }
    }

    /// Smoothed value at pixel `(u, v)` and its support (Gaussian-weighted number of values
    /// around it; a value in the same cell counts 1). `None` without support.
    pub fn get(&self, u: u16, v: u16) -> Option<(f64, f64)> {
        let c = self.cell(u, v);
        let n = self.count[c];
        (n > 1e-12).then(|| (self.sum[c] / n, n))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constant_field_stays_constant_and_a_step_is_smoothed() {
        let mut g = SmoothGrid::new(40, 20, 2);
        for u in 0..40 {
            for v in 0..20 {
                g.add(u, v, if u < 20 { 1.0 } else { 3.0 });
            }
        }
        g.blur(3.0);
        // Far from the step: unchanged (normalized convolution handles the borders too).
        assert!((g.get(0, 0).unwrap().0 - 1.0).abs() < 1e-9);
        assert!((g.get(39, 19).unwrap().0 - 3.0).abs() < 1e-9);
        // At the step: the mean of both sides by symmetry (cells 9 and 10 straddle it).
        let (l, r) = (g.get(18, 10).unwrap().0, g.get(20, 10).unwrap().0);
        assert!((l + r - 4.0).abs() < 1e-9 && l > 1.2 && r < 2.8, "{l} {r}");
        // Support: 4 pixels per cell, blurred with peak-1 kernels -> more than 4.
        assert!(g.get(10, 10).unwrap().1 > 4.0);
    }

    #[test]
    fn a_smoothing_wider_than_the_grid_is_the_grids_mean_and_bounded() {
        // 1e300 px once asked for a kernel of 1e300 taps ("capacity overflow"); the kernel
        // stops at the grid's extent, which changes nothing.
        let mut wide = SmoothGrid::new(40, 20, 2);
        wide.add(0, 0, 1.0);
        wide.add(39, 19, 3.0);
        let mut huge = wide.clone();
        wide.blur(1e6);
        huge.blur(1e300);
        for (u, v) in [(0, 0), (20, 10), (39, 19)] {
            let ((h, hn), (w, wn)) = (huge.get(u, v).unwrap(), wide.get(u, v).unwrap());
            assert!((h - 2.0).abs() < 1e-9 && (h - w).abs() < 1e-6 && (hn - wn).abs() < 1e-6);
        }
    }

    #[test]
    fn empty_cells_far_away_have_no_support() {
        let mut g = SmoothGrid::new(100, 10, 1);
        g.add(0, 0, 5.0);
        g.blur(1.0);
        assert_eq!(g.get(0, 0).map(|v| v.0), Some(5.0));
        assert!(g.get(50, 5).is_none());
    }
}
