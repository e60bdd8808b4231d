//! Which recorded frame to publish next.
//!
//! Frames arrive from the file in recorded order and wait in one queue per output. The next frame
//! published is, among the heads of the queues (so each output keeps its recorded order), the
//! earliest recorded one that may go now: it has lock-step credit and, when the replay is paced,
//! its recorded publish time (scaled by the speed) has come. Publishing across outputs strictly
//! in file order could wait forever: a frame's recorded time is taken before its producer waited
//! for credit, so the file may list a frame before one its consumers needed first.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// A recorded frame waiting to be published.
#[derive(Debug, Clone, PartialEq)]
pub struct Pending {
    /// Output index (the replay node's config outputs).
    pub port: usize,
    /// Position in the recording among the replayed frames, from 0 (recorded order).
    pub order: u64,
    /// Index of the frame on its channel, from 0 (for error messages).
    pub index: u64,
    /// Recorded publish time, ns since the Unix epoch (MCAP log time).
    pub log_ns: u64,
    /// Sequence number from the frame's envelope.
    pub seq: u64,
    /// End of the frame's sensor time span, seconds (from its envelope).
    pub t_end: f64,
    /// The whole frame (envelope and body) as recorded.
    pub bytes: Vec<u8>,
}

/// Per-output queues of recorded frames.
#[derive(Debug, Default)]
pub struct Scheduler {
    queues: Vec<VecDeque<Pending>>,
    held: usize,
}

impl Scheduler {
    /// Queues for `ports` outputs, all empty.
    pub fn new(ports: usize) -> Self {
        Self {
            queues: vec![VecDeque::new(); ports],
            held: 0,
        }
    }

    /// Queues `frame` behind the earlier frames of its output (a frame for an unknown output
    /// is ignored).
    pub fn push(&mut self, frame: Pending) {
        if let Some(q) = self.queues.get_mut(frame.port) {
            q.push_back(frame);
            self.held += 1;
        }
    }

    /// Frames waiting, all outputs.
    pub fn held(&self) -> usize {
        self.held
    }

    /// True when some output has no frame waiting (more of the file may be needed to find it).
    pub fn has_empty_queue(&self) -> bool {
        self.queues.iter().any(VecDeque::is_empty)
    }

    /// The output whose head frame is the earliest recorded one for which `ready` holds, if
    /// any. `ready` is asked about heads in recorded order and not after the first yes.
    pub fn pick<E>(&self, mut ready: impl FnMut(&Pending) -> Result<bool, E>) -> Result<Option<usize>, E> {
        let mut heads: Vec<&Pending> = self.queues.iter().filter_map(VecDeque::front).collect();
        heads.sort_by_key(|p| p.order);
        for head in heads {
            if ready(head)? {
                return Ok(Some(head.port));
            }
        }
        Ok(None)
    }

    /// Takes the head frame of output `port`.
    pub fn pop(&mut self, port: usize) -> Option<Pending> {
        let frame = self.queues.get_mut(port)?.pop_front()?;
        self.held -= 1;
        Some(frame)
    }

    /// Heads of the queues (for pacing: the earliest due time among them).
    pub fn heads(&self) -> impl Iterator<Item = &Pending> {
        self.queues.iter().filter_map(VecDeque::front)
    }
}

/// Playback pacing: recorded publish times scaled by `1 / speed`, from the first frame on.
#[derive(Debug, Clone)]
pub struct Pacing {
    /// Playback speed: 1 = recorded publish-time pacing, 2 = twice as fast; `None` = as fast
    /// as credits allow.
    speed: Option<f64>,
    /// Recorded time (ns since the Unix epoch) and wall-clock instant of the pacing origin.
    origin: Option<(u64, Instant)>,
}

impl Pacing {
    /// Pacing at `speed` (must be finite and > 0), or unpaced for `None`.
    pub fn new(speed: Option<f64>) -> Self {
        Self { speed, origin: None }
    }

    /// When a frame recorded at `log_ns` is due; the first frame asked about sets the origin
    /// (due at once, as is any frame recorded before it). `None` when unpaced.
    pub fn due(&mut self, log_ns: u64, now: Instant) -> Option<Instant> {
        let speed = self.speed?;
        let (t0, start) = *self.origin.get_or_insert((log_ns, now));
        let recorded = Duration::from_nanos(log_ns.saturating_sub(t0));
        Some(start + recorded.div_f64(speed))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(port: usize, order: u64) -> Pending {
        Pending {
            port,
            order,
            index: order,
            log_ns: order * 1_000_000,
            seq: order,
            t_end: order as f64,
            bytes: vec![order as u8],
        }
    }

    #[test]
    fn the_earliest_ready_head_goes_and_each_output_keeps_its_order() {
        let mut s = Scheduler::new(3);
        for (port, order) in [(0, 0), (0, 1), (1, 2), (0, 3), (1, 4), (2, 5)] {
            s.push(frame(port, order));
        }
        assert_eq!(s.held(), 6);
        assert!(!s.has_empty_queue());
        let all = |_: &Pending| Ok::<_, ()>(true);
        assert_eq!(s.pick(all), Ok(Some(0)));
        // Output 0 has no credit: the earliest other head (order 2 on output 1) goes, never the
        // later frames of output 0.
        let mut asked = Vec::new();
        let no_0 = |p: &Pending| {
            asked.push(p.order);
            Ok::<_, ()>(p.port != 0)
        };
        assert_eq!(s.pick(no_0), Ok(Some(1)));
        assert_eq!(
            asked,
            [0, 2],
            "heads asked in recorded order, stopping at the first yes"
        );
        assert_eq!(s.pop(1).map(|p| p.order), Some(2));
        assert_eq!(s.pop(0).map(|p| p.order), Some(0));
        assert_eq!(s.pop(0).map(|p| p.order), Some(1));
        assert_eq!(s.pick(all), Ok(Some(0)), "order 3 before 4 and 5");
        assert_eq!(s.pick(|_| Ok::<_, ()>(false)), Ok(None));
        assert_eq!(s.pick(|_| Err::<bool, _>("stop")), Err("stop"));
        assert_eq!(s.held(), 3);
        assert_eq!(s.pop(0).map(|p| p.order), Some(3));
        assert!(s.has_empty_queue());
        assert_eq!(s.pop(0), None);
        assert_eq!(s.pop(7), None);
        s.push(frame(9, 9));
        assert_eq!(s.held(), 2, "a frame for an unknown output is ignored");
    }

    #[test]
    fn pacing_scales_recorded_times_from_the_first_frame() {
        let start = Instant::now();
        let mut unpaced = Pacing::new(None);
        assert_eq!(unpaced.due(5, start), None);
        let mut p = Pacing::new(Some(2.0));
        assert_eq!(p.due(1_000_000_000, start), Some(start));
        let later = start + Duration::from_secs(9);
        assert_eq!(
            p.due(1_500_000_000, later),
            Some(start + Duration::from_millis(250)),
            "0.5 s recorded at speed 2 is 0.25 s after the origin, whenever asked"
        );
        assert_eq!(
            p.due(10, later),
            Some(start),
            "recorded before the origin: due at once"
        );
    }
}
