//! Labels for events without a group (no valid normal flow): the most common label among the
//! labelled events of the 3x3 grid cells around them.

use evseg_schemas::Events;

/// Label value of an event still to be filled.
pub const UNLABELLED: u32 = u32::MAX;

/// Replaces every [`UNLABELLED`] entry of `label` (aligned with `events`) by the most common
/// label of the labelled events in the 3x3 cells of `cell_px` pixels around it (ties: the
/// smaller label, so background wins), or 0 when there are none.
pub fn fill_unlabelled(events: &Events, width: u16, height: u16, cell_px: u16, label: &mut [u32]) {
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
        for ny in cy.saturating_sub(1)..=(cy + 1).min(rows - 1) {
            for nx in cx.saturating_sub(1)..=(cx + 1).min(cols - 1) {
                for &(l, n) in &counts[ny * cols + nx] {
                    match tally.iter_mut().find(|(k, _)| *k == l) {
                        Some((_, m)) => *m += n,
                        None => tally.push((l, n)),
                    }
                }
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
        fill_unlabelled(&ev, 40, 40, 4, &mut label);
        assert_eq!(label, vec![2, 2, 0, 2, 5, 2, 5]);
        let mut alone = vec![UNLABELLED; 7];
        fill_unlabelled(&ev, 40, 40, 4, &mut alone);
        assert!(alone.iter().all(|&l| l == 0));
    }
}
