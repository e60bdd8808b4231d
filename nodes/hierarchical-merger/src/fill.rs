//! Labels for events without a group (no valid normal flow): the most common label among the
//! labelled events of the 3x3 grid cells around them; where those hold none, of the 5x5, 7x7, ...
//! cells, up to a reach.

use evseg_schemas::Events;

/// Label value of an event still to be filled.
pub const UNLABELLED: u32 = u32::MAX;

/// Replaces every [`UNLABELLED`] entry of `label` (aligned with `events`) by the most common
/// label of the labelled events in the 3x3 cells of `cell_px` pixels around it (ties: the
/// smaller label, so background wins); where those cells hold no labelled event, of the
/// `(2r + 1) x (2r + 1)` cells for the smallest `r` in `2..=reach` that holds one; 0 when none
/// does (`reach` <= 1: only the 3x3 cells).
pub fn fill_unlabelled(
    events: &Events,
    width: u16,
    height: u16,
    cell_px: u16,
    reach: u16,
    label: &mut [u32],
) {
    if !label.contains(&UNLABELLED) {
        return;
    }
    let c = usize::from(cell_px.max(1));
    let cols = usize::from(width).div_ceil(c).max(1);
    let rows = usize::from(height).div_ceil(c).max(1);
    let cell = |i: usize| {
        let (cx, cy) = (usize::from(events.x[i]) / c, usize::from(events.y[i]) / c);
        (cx.min(cols - 1), cy.min(rows - 1))
    };
    let mut counts: Vec<Vec<(u32, u32)>> = vec![Vec::new(); cols * rows];
    for (i, &l) in label.iter().enumerate() {
        if l == UNLABELLED {
            continue;
        }
        let (cx, cy) = cell(i);
        let slot = &mut counts[cy * cols + cx];
        match slot.iter_mut().find(|(k, _)| *k == l) {
            Some((_, n)) => *n += 1,
            None => slot.push((l, 1)),
        }
    }
    let mut tally: Vec<(u32, u32)> = Vec::new();
    // The majority depends only on the cell: computed once per cell with unlabelled events.
    let mut majority: Vec<Option<u32>> = vec![None; cols * rows];
    for (i, l) in label.iter_mut().enumerate() {
        if *l != UNLABELLED {
            continue;
        }
        let (cx, cy) = cell(i);
        if let Some(m) = majority[cy * cols + cx] {
            *l = m;
            continue;
        }
        tally.clear();
        for r in 1..=usize::from(reach.max(1)) {
            // The ring at chessboard distance r (the centre's 3x3 block when r = 1).
            for ny in cy.saturating_sub(r)..=(cy + r).min(rows - 1) {
                for nx in cx.saturating_sub(r)..=(cx + r).min(cols - 1) {
                    if r > 1 && nx.abs_diff(cx) < r && ny.abs_diff(cy) < r {
                        continue;
                    }
                    for &(l, n) in &counts[ny * cols + nx] {
                        match tally.iter_mut().find(|(k, _)| *k == l) {
                            Some((_, m)) => *m += n,
                            None => tally.push((l, n)),
                        }
                    }
                }
            }
            if !tally.is_empty() {
                break;
            }
        }
        *l = tally
            .iter()
            .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
            .map_or(0, |&(l, _)| l);
        majority[cy * cols + cx] = Some(*l);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unlabelled_events_take_the_local_majority() {
        let mut ev = Events::default();
        for (x, y) in [(1, 1), (2, 1), (3, 2), (1, 2), (30, 30), (2, 2), (31, 31)] {
            ev.push(0.0, x, y, 1);
        }
        let mut label = vec![2, 2, 0, UNLABELLED, 5, UNLABELLED, UNLABELLED];
        fill_unlabelled(&ev, 40, 40, 4, 1, &mut label);
        assert_eq!(label, vec![2, 2, 0, 2, 5, 2, 5]);
        let mut alone = vec![UNLABELLED; 7];
        fill_unlabelled(&ev, 40, 40, 4, 3, &mut alone);
        assert!(
            alone.iter().all(|&l| l == 0),
            "nothing labelled at any reach: background"
        );
        let mut alone = vec![UNLABELLED; 7];
        fill_unlabelled(&ev, 40, 40, 4, 1, &mut alone);
        assert!(alone.iter().all(|&l| l == 0));
    }

    #[test]
    fn events_with_empty_3x3_cells_look_further_out_up_to_the_reach() {
        // Cells of 4 px: two labelled events in cell (0, 0) (label 3), one in cell (6, 0)
        // (label 7); the unlabelled ones in cells (3, 0), (4, 0), (3, 3) and (9, 9).
        let mut ev = Events::default();
        for (x, y) in [(1, 1), (2, 2), (25, 1), (13, 1), (17, 1), (13, 13), (37, 37)] {
            ev.push(0.0, x, y, 1);
        }
        let unlabelled = [3, 3, 7, UNLABELLED, UNLABELLED, UNLABELLED, UNLABELLED];
        let filled = |reach| {
            let mut label = unlabelled.to_vec();
            fill_unlabelled(&ev, 40, 40, 4, reach, &mut label);
            label
        };
        // Reach 1: every 3x3 block around the unlabelled events is empty.
        assert_eq!(filled(1), vec![3, 3, 7, 0, 0, 0, 0]);
        // Reach 2: cell (4, 0) reaches cell (6, 0); cell (3, 0) reaches neither (3 away from both).
        assert_eq!(filled(2), vec![3, 3, 7, 0, 7, 0, 0]);
        // Reach 3: cell (3, 0) finds both at distance 3, two events of 3 and one of 7: 3 wins;
        // cell (3, 3) finds both at distance 3 too; cell (9, 9) still nothing.
        assert_eq!(filled(3), vec![3, 3, 7, 3, 7, 3, 0]);
        // The first ring that holds labelled events decides: cell (4, 0) keeps 7 although 3 is
        // more common further out.
        assert_eq!(filled(6)[4], 7);
    }
}
