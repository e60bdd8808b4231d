//! Keeping batches time-ordered: recordings in the wild contain out-of-order timestamps, and a
//! writer may store events out of order across the blocks a reader takes at a time.

use evseg_schemas::Events;

/// Default of the sources' reorder window ([`ReorderBuffer`]), seconds. EVIMO2's own files and
/// the vendor decoders' output are sorted; a file written by another tool may not be, for
/// example when a simulator writes each render interval's events pixel by pixel. 50 ms covers a
/// generator that renders at 20 Hz or faster, and costs a buffer of 50 ms of events (about 100 k
/// at 2 M events/s).
pub const DEFAULT_REORDER_WINDOW_S: f64 = 0.05;

/// Checks a reorder window (seconds, set by the parameter `reorder_window_ms`): finite and not
/// negative; the error names the parameter in its own unit.
pub fn check_reorder_window(seconds: f64) -> Result<f64, crate::SourceError> {
    if !(seconds.is_finite() && seconds >= 0.0) {
        return Err(crate::SourceError::Param(format!(
            "reorder_window_ms: {} ms must be finite and >= 0",
            seconds * 1e3
        )));
    }
    Ok(seconds)
}

/// Events read ahead of the batches, kept in time order whatever order they were read in.
///
/// A source reads its file past each batch's end by a window (seconds) and pushes what it read
/// here; [`ReorderBuffer::take_before`] then hands out every event stamped before the batch's
/// end, including those stored after later ones, as long as they were stored within the window.
#[derive(Debug, Default)]
pub struct ReorderBuffer {
    pending: Events,
    reordered: u64,
}

impl ReorderBuffer {
    /// Adds events read from the file (any order); keeps the buffer sorted by time (stable, so
    /// events of equal time keep the order they were read in).
    pub fn push(&mut self, mut fresh: Events) {
        self.reordered += sort_by_time(&mut fresh) as u64;
        let in_order = match (self.pending.t.last(), fresh.t.first()) {
            (Some(&last), Some(&first)) => first >= last,
            _ => true,
        };
        let n = fresh.len();
        self.pending.extend_from(&fresh, 0..n);
        if !in_order {
            // Only for input stored out of order: the two sorted runs are sorted together.
            self.reordered += sort_by_time(&mut self.pending) as u64;
        }
    }

    /// Moves the events with `t < t_end` out of the buffer, in time order.
    pub fn take_before(&mut self, t_end: f64) -> Events {
        take_before(&mut self.pending, t_end)
    }

    /// Time of the newest event held, seconds, if any.
    pub fn last_time(&self) -> Option<f64> {
        self.pending.t.last().copied()
    }

    /// Events held.
    pub fn len(&self) -> usize {
        self.pending.len()
    }

    /// True when no event is held.
    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }

    /// Drops every event held (a source that stops early).
    pub fn clear(&mut self) {
        self.pending = Events::default();
    }

    /// Events that were out of order where they were read and were sorted into place (none is
    /// dropped here), counted as the number of descents in each sorted run.
    pub fn reordered(&self) -> u64 {
        self.reordered
    }
}

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
fn take_before(buffer: &mut Events, t_end: f64) -> Events {
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

    fn events(pairs: &[(f64, u16)]) -> Events {
        let mut e = Events::default();
        for &(t, x) in pairs {
            e.push(t, x, 0, 1);
        }
        e
    }

    #[test]
    fn sorts_and_splits() {
        let mut e = events(&[(0.3, 3), (0.1, 1), (0.2, 2), (0.5, 5)]);
        assert_eq!(sort_by_time(&mut e), 1);
        assert_eq!(e.x, vec![1, 2, 3, 5]);
        let head = take_before(&mut e, 0.25);
        assert_eq!(head.x, vec![1, 2]);
        assert_eq!(e.x, vec![3, 5]);
    }

    #[test]
    fn events_read_after_later_ones_are_sorted_into_the_buffer() {
        let mut b = ReorderBuffer::default();
        b.push(events(&[(0.10, 1), (0.30, 3)]));
        // Read later, stamped between the first two: must come out before 0.30.
        b.push(events(&[(0.20, 2), (0.40, 4)]));
        assert_eq!(b.reordered(), 1);
        assert_eq!(b.take_before(0.25).x, vec![1, 2]);
        assert_eq!(b.last_time(), Some(0.40));
        assert_eq!(b.take_before(1.0).x, vec![3, 4]);
        assert!(b.is_empty());
    }

    #[test]
    fn a_bad_window_is_a_parameter_error_in_milliseconds() {
        assert_eq!(check_reorder_window(0.05).ok(), Some(0.05));
        let e = check_reorder_window(-0.001).err().map(|e| e.to_string());
        assert_eq!(
            e.as_deref(),
            Some("reorder_window_ms: -1 ms must be finite and >= 0")
        );
        assert!(check_reorder_window(f64::NAN).is_err());
    }
}
