//! Density normalization: weights that give every occupied patch of the image the same total
//! weight, whatever number of events its texture fires.

/// Weight 1 / (points in the same `cell_px` cell) per point of `pixels` (column, row) on a
/// `width` x `height` sensor.
pub fn density_weights(
    pixels: impl Iterator<Item = (u16, u16)> + Clone,
    width: u16,
    height: u16,
    cell_px: u16,
) -> Vec<f64> {
    let c = usize::from(cell_px.max(1));
    let cols = usize::from(width).div_ceil(c).max(1);
    let rows = usize::from(height).div_ceil(c).max(1);
    let cell =
        |(x, y): (u16, u16)| (usize::from(y) / c).min(rows - 1) * cols + (usize::from(x) / c).min(cols - 1);
    let mut counts = vec![0u32; cols * rows];
    for p in pixels.clone() {
        counts[cell(p)] += 1;
    }
    pixels.map(|p| 1.0 / f64::from(counts[cell(p)].max(1))).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_cell_weighs_one() {
        let pts = [(0u16, 0u16), (1, 1), (3, 3), (9, 9)];
        let w = density_weights(pts.iter().copied(), 10, 10, 4);
        assert_eq!(w, vec![1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0, 1.0]);
    }
}
