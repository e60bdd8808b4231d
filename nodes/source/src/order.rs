//! Keeping batches time-ordered: recordings in the wild contain a few out-of-order timestamps.

use evseg_schemas::Events;

/// Sorts `events` by time (stable) if needed; returns how many events were out of order.
pub fn sort_by_time(events: &mut Events) -> usize {
    let disorder = events.t.windows(2).filter(|w| w[1] < w[0]).count();
    if disorder == 0 {
        return 0;
    }
    let mut idx: Vec<usize> = (0..events.len()).collect();
    idx.sort_by(|&a, &b| events.t[a].total_cmp(&events.t[b]));
    let mut sorted = Events::with_capacity(events.len());
    for i in idx {
        sorted.push(events.t[i], events.x[i], events.y[i], events.p[i]);
    }
    *events = sorted;
    disorder
}

/// Moves the events with `t < t_end` from the front of `buffer` into a new set (the buffer is
/// time-ordered).
pub fn take_before(buffer: &mut Events, t_end: f64) -> Events {
    let n = buffer.t.partition_point(|&t| t < t_end);
    let mut head = Events::with_capacity(n);
    head.extend_from(buffer, 0..n);
    let mut rest = Events::with_capacity(buffer.len() - n);
    rest.extend_from(buffer, n..buffer.len());
    *buffer = rest;
    head
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorts_and_splits() {
        let mut e = Events::default();
        for (t, x) in [(0.3, 3), (0.1, 1), (0.2, 2), (0.5, 5)] {
            e.push(t, x, 0, 1);
        }
        assert_eq!(sort_by_time(&mut e), 1);
        assert_eq!(e.x, vec![1, 2, 3, 5]);
        let head = take_before(&mut e, 0.25);
        assert_eq!(head.x, vec![1, 2]);
        assert_eq!(e.x, vec![3, 5]);
    }
}
