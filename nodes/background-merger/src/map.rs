//! The persistent background map (paper section 3.4, "Background Identification"): per cell of
//! the image, how much of the recent past was background, kept by an exponential moving average
//! whose weight adapts to how similar the current background is to the map.

use evseg_geometry::CellGrid;

/// The map and its update rule.
#[derive(Debug, Clone, PartialEq)]
pub struct BackgroundMap {
    /// Per-cell background value in [0, 1] (meaningful where `seen` is set).
    pub grid: CellGrid,
    /// Cells observed at least once.
    pub seen: Vec<bool>,
    /// Slices folded in.
    pub updates: u64,
}

/// What one update did.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapUpdate {
    /// IoU of the current background cells with the map's background cells, over cells seen by
    /// both (1 when there was nothing to compare).
    pub similarity: f64,
    /// EMA weight used for the current slice.
    pub alpha: f64,
}

impl BackgroundMap {
    /// An empty map for a `width` x `height` sensor with cells of `cell_px` pixels.
    pub fn new(width: u16, height: u16, cell_px: u16) -> Self {
        let grid = CellGrid::new(width, height, cell_px);
        let n = grid.values.len();
        Self {
            grid,
            seen: vec![false; n],
            updates: 0,
        }
    }

    /// The map value at pixel `(x, y)`, `None` where never observed.
    pub fn value(&self, x: u16, y: u16) -> Option<f32> {
        let c = self.grid.cell(x, y)?;
        self.seen[c].then(|| self.grid.values[c])
    }

    /// Folds in one slice whose per-cell background fraction is `current` (`None` = cell without
    /// events). `alpha = alpha_min + (alpha_max - alpha_min) * similarity`; the very first update
    /// copies the slice.
    pub fn update(
        &mut self,
        current: &[Option<f32>],
        threshold: f32,
        alpha_min: f64,
        alpha_max: f64,
    ) -> MapUpdate {
        let (mut inter, mut union) = (0usize, 0usize);
        for (c, cur) in current.iter().enumerate() {
            let Some(cur) = cur else { continue };
            if !self.seen[c] {
                continue;
            }
            let (a, b) = (*cur >= threshold, self.grid.values[c] >= threshold);
            inter += usize::from(a && b);
            union += usize::from(a || b);
        }
        let similarity = if union == 0 {
            1.0
        } else {
            inter as f64 / union as f64
        };
        let alpha = if self.updates == 0 {
            1.0
        } else {
            alpha_min + (alpha_max - alpha_min) * similarity
        };
        for (c, cur) in current.iter().enumerate() {
            let Some(cur) = *cur else { continue };
            if self.seen[c] {
                let v = &mut self.grid.values[c];
                *v = ((1.0 - alpha) * f64::from(*v) + alpha * f64::from(cur)) as f32;
            } else {
                self.grid.values[c] = cur;
                self.seen[c] = true;
            }
        }
        self.updates += 1;
        MapUpdate { similarity, alpha }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_update_copies_then_alpha_follows_similarity() {
        let mut m = BackgroundMap::new(8, 8, 4); // 2x2 cells
        let u = m.update(&[Some(1.0), Some(1.0), Some(0.0), None], 0.5, 0.1, 0.5);
        assert_eq!(u.alpha, 1.0);
        assert_eq!(m.value(0, 0), Some(1.0));
        assert_eq!(m.value(7, 7), None);
        // The same picture again: similarity 1, alpha_max.
        let u = m.update(&[Some(1.0), Some(1.0), Some(0.0), None], 0.5, 0.1, 0.5);
        assert_eq!((u.similarity, u.alpha), (1.0, 0.5));
        // The opposite picture: similarity 0, the map barely moves.
        let u = m.update(&[Some(0.0), Some(0.0), Some(1.0), Some(1.0)], 0.5, 0.1, 0.5);
        assert_eq!(u.similarity, 0.0);
        assert!((u.alpha - 0.1).abs() < 1e-12);
        assert!((m.value(0, 0).unwrap() - 0.9).abs() < 1e-6);
        assert_eq!(m.value(7, 7), Some(1.0));
    }
}
