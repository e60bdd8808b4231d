//! A coarse pixel grid (cells of `cell_px` x `cell_px` pixels): the background merger's warped
//! occupancy and persistent background map, the planar segmenter's previous-foreground mask.

/// A grid of `f32` values over a `width` x `height` pixel sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct CellGrid {
    /// Cell side, pixels.
    pub cell_px: u16,
    /// Cells per row.
    pub cols: usize,
    /// Rows of cells.
    pub rows: usize,
    /// Values, row-major.
    pub values: Vec<f32>,
}

impl CellGrid {
    /// A grid of zeros covering `width` x `height` pixels with cells of `cell_px` (>= 1) pixels.
    pub fn new(width: u16, height: u16, cell_px: u16) -> Self {
        let c = usize::from(cell_px.max(1));
        let cols = usize::from(width).div_ceil(c).max(1);
        let rows = usize::from(height).div_ceil(c).max(1);
        Self {
            cell_px: cell_px.max(1),
            cols,
            rows,
            values: vec![0.0; cols * rows],
        }
    }

    /// True when the grid was made for this sensor size and cell.
    pub fn fits(&self, width: u16, height: u16, cell_px: u16) -> bool {
        let c = usize::from(cell_px.max(1));
        self.cell_px == cell_px.max(1)
            && self.cols == usize::from(width).div_ceil(c).max(1)
            && self.rows == usize::from(height).div_ceil(c).max(1)
    }

    /// Cell index of integer pixel `(x, y)`, `None` outside the grid.
    pub fn cell(&self, x: u16, y: u16) -> Option<usize> {
        let (cx, cy) = (usize::from(x / self.cell_px), usize::from(y / self.cell_px));
        (cx < self.cols && cy < self.rows).then_some(cy * self.cols + cx)
    }

    /// Cell index of sub-pixel position `(x, y)` (pixels), `None` outside the grid.
    pub fn cell_f(&self, x: f64, y: f64) -> Option<usize> {
        if !(x.is_finite() && y.is_finite() && x >= 0.0 && y >= 0.0) {
            return None;
        }
        let c = f64::from(self.cell_px);
        let (cx, cy) = ((x / c) as usize, (y / c) as usize);
        (cx < self.cols && cy < self.rows).then_some(cy * self.cols + cx)
    }

    /// The maximum over each cell's 3x3 neighbourhood (a one-cell dilation).
    pub fn dilated(&self) -> Self {
        self.dilated_by(1)
    }

    /// The maximum over each cell's `(2 r + 1)` x `(2 r + 1)` neighbourhood (an `r`-cell
    /// dilation; `r = 0` is a copy). Separable: a row pass, then a column pass.
    pub fn dilated_by(&self, r: usize) -> Self {
        let rows_done = running_max(&self.values, self.rows, self.cols, self.cols, 1, r);
        let values = running_max(&rows_done, self.cols, self.rows, 1, self.cols, r);
        Self {
            cell_px: self.cell_px,
            cols: self.cols,
            rows: self.rows,
            values,
        }
    }
}

/// The maximum within `r` entries along each of `lines` lines of `len` entries of `src`; line
/// `l`'s entry `k` is `src[l * line_stride + k * step]`.
fn running_max(src: &[f32], lines: usize, len: usize, line_stride: usize, step: usize, r: usize) -> Vec<f32> {
    let mut out = src.to_vec();
    for l in 0..lines {
        for k in 0..len {
            let mut m = f32::MIN;
            for j in k.saturating_sub(r)..=(k + r).min(len - 1) {
                m = m.max(src[l * line_stride + j * step]);
            }
            out[l * line_stride + k * step] = m;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_and_dilation() {
        let mut g = CellGrid::new(10, 7, 4);
        assert_eq!((g.cols, g.rows), (3, 2));
        assert_eq!(g.cell(9, 6), Some(5));
        assert_eq!(g.cell(12, 0), None);
        assert_eq!(g.cell_f(-0.5, 1.0), None);
        assert_eq!(g.cell_f(4.2, 4.0), Some(4));
        g.values[0] = 1.0;
        let d = g.dilated();
        assert_eq!(d.values, vec![1.0, 1.0, 0.0, 1.0, 1.0, 0.0]);
        assert!(g.fits(10, 7, 4) && !g.fits(10, 9, 4));
        let mut wide = CellGrid::new(40, 8, 4);
        wide.values[2] = 1.0;
        assert_eq!(wide.dilated_by(0), wide);
        let two: Vec<f32> = wide.dilated_by(2).values;
        assert_eq!(&two[..10], &[1.0, 1.0, 1.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
        assert_eq!(&two[10..], &two[..10], "the row below, within 2 cells");
    }
}
