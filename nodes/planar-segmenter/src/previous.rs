//! The previous slice's foreground as a weight on the plane fit.
//!
//! The 8-parameter fit assumes the background dominates the slice's equations. A large or
//! densely textured object breaks that: the plane follows the object, its residuals come out
//! small and the 2-means split calls it background. The previous slice's final segmentation
//! (the tracker's labels, a feedback input) says where the objects were; the equations of the
//! events in those places, dilated by how far an object can move in a slice, get a lower weight
//! ([`PreviousParams::weight`]). Only the *fit* changes: every event is still scored by its
//! residual, so a wrong previous segmentation does not carry over by itself.

use evseg_geometry::CellGrid;

/// Settings of the previous-foreground weighting (part of [`crate::PlanarParams`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PreviousParams {
    /// Weight of the equations of events inside the (dilated) previous foreground; 1 = off
    /// (every equation alike, the paper), 0 = excluded. Default 0: the previous segmentation is
    /// the best knowledge of where the objects are; 0.2 kept part of the object's pull on the
    /// fit (hierarchical merger's `examples/method_on_sim.rs`, seed 101, 3 s, mean IoU at 1 /
    /// 0.2 / 0: one-object 0.48 / 0.60 / 0.64, two-objects 0.51 / 0.61 / 0.65, fast-rotation
    /// 0.46 / 0.50 / 0.52, low-contrast 0.37 / 0.48 / 0.47, high-contrast 0.50 / 0.61 / 0.64,
    /// enter-leave 0.69 / 0.76 / 0.80). With the true background's events only (the example's
    /// ORACLE_FIT) the same stages reach 0.73 / 0.70 / 0.61 / 0.64 on the first four: the fit's
    /// contamination by the objects was the planar stage's main loss of recall.
    pub weight: f64,
    /// Cell of the previous-foreground mask, pixels (default 8; a cell is foreground when most
    /// of its previous events were labelled foreground).
    pub cell_px: u16,
    /// Dilation of the mask, pixels, rounded up to whole cells (default 24: an object crossing
    /// the image in half a second moves about 40 px in a 30 ms slice at 640 px width, and the
    /// previous segmentation misses parts of its edges). `examples/method_on_sim.rs`, seed
    /// 101, 3 s, mean IoU at 8 / 16 / 24 / 32 / 40 px: one-object 0.62 / 0.63 / 0.64 / 0.69 /
    /// 0.62, two-objects 0.52 / 0.65 / 0.65 / 0.66 / 0.67, fast-rotation 0.48 / 0.50 / 0.52 /
    /// 0.46 / 0.50, low-contrast 0.40 / 0.47 / 0.47 / 0.49 / 0.62, high-contrast 0.60 / 0.61 /
    /// 0.64 / 0.61 / 0.65, enter-leave 0.79 / 0.80 / 0.80 / 0.79 / 0.79.
    pub dilate_px: u16,
    /// The weighting applies only when at least this share of the fit's equations lies outside
    /// the mask (default 0.05): a previous segmentation that calls nearly the whole image
    /// foreground is more likely wrong than right, and the fit needs equations. Not more: a
    /// large object near the camera does cover most of a slice (at 0.2 one-object fell 0.64 ->
    /// 0.56, low-contrast 0.47 -> 0.39 in the runs above).
    pub min_free_share: f64,
}

impl Default for PreviousParams {
    fn default() -> Self {
        Self {
            weight: 0.0,
            cell_px: 8,
            dilate_px: 24,
            min_free_share: 0.05,
        }
    }
}

/// Where the previous slice's foreground was: a cell mask over the sensor.
#[derive(Debug, Clone, PartialEq)]
pub struct PreviousForeground {
    /// 1 in (dilated) foreground cells, 0 elsewhere.
    mask: CellGrid,
}

impl PreviousForeground {
    /// The mask of the events at integer pixels `(x[i], y[i])` labelled `labels[i]` (0 =
    /// background) on a `width` x `height` sensor; `None` when the lengths differ.
    pub fn new(
        width: u16,
        height: u16,
        x: &[u16],
        y: &[u16],
        labels: &[u32],
        p: &PreviousParams,
    ) -> Option<Self> {
        if x.len() != labels.len() || y.len() != labels.len() {
            return None;
        }
        let mut grid = CellGrid::new(width, height, p.cell_px);
        let mut counts = vec![(0u32, 0u32); grid.values.len()];
        for ((&x, &y), &l) in x.iter().zip(y).zip(labels) {
            if let Some(c) = grid.cell(x, y) {
                counts[c].0 += u32::from(l != 0);
                counts[c].1 += 1;
            }
        }
        for (v, &(fg, all)) in grid.values.iter_mut().zip(&counts) {
            *v = if 2 * fg > all { 1.0 } else { 0.0 };
        }
        let r = usize::from(p.dilate_px).div_ceil(usize::from(grid.cell_px));
        Some(Self {
            mask: grid.dilated_by(r),
        })
    }

    /// True when integer pixel `(x, y)` lies in the (dilated) previous foreground.
    pub fn contains(&self, x: u16, y: u16) -> bool {
        self.mask.cell(x, y).is_some_and(|c| self.mask.values[c] > 0.0)
    }

    /// Multiplies `weights[k]` by `p.weight` for the samples at pixels `pixels[k]` inside the
    /// mask, unless fewer than `p.min_free_share` of them, or fewer than 8 (the planar model's
    /// parameters), lie outside it. Returns whether the weighting was applied.
    pub fn apply(&self, pixels: &[(u16, u16)], weights: &mut [f64], p: &PreviousParams) -> bool {
        let inside: Vec<bool> = pixels.iter().map(|&(x, y)| self.contains(x, y)).collect();
        let free = inside.iter().filter(|&&i| !i).count();
        if (free as f64) < p.min_free_share * pixels.len() as f64 || free < 8 {
            return false;
        }
        for (w, &i) in weights.iter_mut().zip(&inside) {
            if i {
                *w *= p.weight;
            }
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_mask_covers_the_foreground_dilated_and_yields_to_a_mostly_foreground_slice() {
        let p = PreviousParams {
            cell_px: 8,
            dilate_px: 8,
            ..PreviousParams::default()
        };
        // Foreground events in cell (5, 5) (pixels 40..48), background elsewhere.
        let (x, y, l) = (
            vec![42u16, 44, 100, 0],
            vec![42u16, 43, 100, 0],
            vec![3u32, 3, 0, 0],
        );
        let m = PreviousForeground::new(160, 120, &x, &y, &l, &p).unwrap();
        assert!(
            m.contains(43, 41) && m.contains(33, 50),
            "the cell and its neighbours"
        );
        assert!(!m.contains(60, 41) && !m.contains(100, 100));
        assert!(PreviousForeground::new(160, 120, &x, &y, &l[1..], &p).is_none());

        let pixels: Vec<(u16, u16)> = (0..20)
            .map(|i| if i < 4 { (42, 42) } else { (100, 100) })
            .collect();
        let mut w = vec![1.0; 20];
        assert!(m.apply(&pixels, &mut w, &p));
        assert_eq!(w.iter().filter(|&&w| w == 0.0).count(), 4);
        // Mostly foreground: left alone.
        let pixels: Vec<(u16, u16)> = (0..20)
            .map(|i| if i < 18 { (42, 42) } else { (100, 100) })
            .collect();
        let mut w = vec![1.0; 20];
        assert!(!m.apply(&pixels, &mut w, &p));
        assert!(w.iter().all(|&w| w == 1.0));
    }
}
