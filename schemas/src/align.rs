//! Checks that per-event inputs fit their slice: the rule "per-event arrays are aligned index for
//! index with the slice's events" in one place, for every stage that takes them.

use crate::messages::{Events, NormalFlow};

/// A per-event input that does not fit its slice.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AlignError {
    /// The event columns have different lengths.
    #[error("slice events have columns of different lengths")]
    EventColumns,
    /// The flow columns have different lengths, or a different length from the events.
    #[error("normal flow has nx/ny/confidence lengths {nx}/{ny}/{confidence} for {events} events")]
    FlowLength {
        /// Length of `nx`.
        nx: usize,
        /// Length of `ny`.
        ny: usize,
        /// Length of `confidence`.
        confidence: usize,
        /// Events in the slice.
        events: usize,
    },
    /// An event lies outside the sensor.
    #[error("event {index} at pixel ({x}, {y}) is outside the {width}x{height} sensor")]
    EventOutside {
        /// Event index in the slice.
        index: usize,
        /// Column, pixels.
        x: u16,
        /// Row, pixels.
        y: u16,
        /// Sensor width, pixels.
        width: u16,
        /// Sensor height, pixels.
        height: u16,
    },
}

/// Checks that `events` has consistent columns and `flow` one entry per event.
pub fn check_flow(events: &Events, flow: &NormalFlow) -> Result<(), AlignError> {
    if !events.is_consistent() {
        return Err(AlignError::EventColumns);
    }
    let n = events.len();
    if flow.nx.len() != n || flow.ny.len() != n || flow.confidence.len() != n {
        return Err(AlignError::FlowLength {
            nx: flow.nx.len(),
            ny: flow.ny.len(),
            confidence: flow.confidence.len(),
            events: n,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misaligned_inputs_are_named() {
        let mut e = Events::default();
        e.push(0.0, 1, 2, 1);
        let mut f = NormalFlow {
            nx: vec![0.0],
            ny: vec![0.0],
            confidence: vec![1.0],
        };
        assert_eq!(check_flow(&e, &f), Ok(()));
        f.ny.clear();
        assert_eq!(
            check_flow(&e, &f),
            Err(AlignError::FlowLength {
                nx: 1,
                ny: 0,
                confidence: 1,
                events: 1
            })
        );
        e.x.push(3);
        assert_eq!(check_flow(&e, &f), Err(AlignError::EventColumns));
    }
}
