//! Stream inspection: checks that slices arrive consecutively, that events are time-ordered and
//! inside their slice's window, and keeps a digest of every event so another place of the graph
//! (the source) can be compared with it.

#![warn(missing_docs)]

use evseg_schemas::Slice;
use evseg_schemas::digest::EventDigest;
use serde::{Deserialize, Serialize};

/// Most problems kept verbatim in the report (the count keeps going).
pub const MAX_REPORTED_PROBLEMS: usize = 20;

/// What the inspector found.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct InspectReport {
    /// Slices received.
    pub slices: u64,
    /// Digest of all events received, in order.
    pub digest: EventDigest,
    /// First event time, seconds.
    pub first_t: Option<f64>,
    /// Last event time, seconds.
    pub last_t: Option<f64>,
    /// Problems found (gaps, disorder, events outside their window); the first few verbatim.
    pub problems: Vec<String>,
    /// Number of problems found.
    pub problem_count: u64,
    /// Wall clock at the first slice's arrival, ns since the Unix epoch (throughput figures).
    pub first_arrival_ns: Option<u64>,
    /// Wall clock at the last slice's arrival, ns since the Unix epoch.
    pub last_arrival_ns: Option<u64>,
}

/// Wall clock, ns since the Unix epoch.
pub fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// Checks slices one by one.
#[derive(Debug, Default)]
pub struct Inspector {
    report: InspectReport,
    next_seq: u64,
    last_end: f64,
}

impl Inspector {
    fn problem(&mut self, p: String) {
        self.report.problem_count += 1;
        if self.report.problems.len() < MAX_REPORTED_PROBLEMS {
            self.report.problems.push(p);
        }
    }

    /// Checks slice `seq` covering `[t_start, t_end)` seconds.
    pub fn add(&mut self, seq: u64, t_start: f64, t_end: f64, slice: &Slice) {
        if seq != self.next_seq {
            self.problem(format!("slice {seq} arrived when {} was expected", self.next_seq));
        }
        self.next_seq = seq + 1;
        if t_start < self.last_end {
            self.problem(format!(
                "slice {seq} starts at {t_start} before the previous end {}",
                self.last_end
            ));
        }
        self.last_end = t_end;
        let ev = &slice.events;
        if !ev.is_consistent() {
            self.problem(format!("slice {seq}: columns of different lengths"));
            return;
        }
        let mut prev = self.report.last_t.unwrap_or(f64::NEG_INFINITY);
        let mut disorder = 0;
        let mut outside = 0;
        for &t in &ev.t {
            if t < prev {
                disorder += 1;
            }
            if t < t_start || t >= t_end {
                outside += 1;
            }
            prev = t;
        }
        if disorder > 0 {
            self.problem(format!(
                "slice {seq}: {disorder} events earlier than their predecessor"
            ));
        }
        if outside > 0 {
            self.problem(format!(
                "slice {seq}: {outside} events outside [{t_start}, {t_end})"
            ));
        }
        if let (None, Some(&t)) = (self.report.first_t, ev.t.first()) {
            self.report.first_t = Some(t);
        }
        if let Some(&t) = ev.t.last() {
            self.report.last_t = Some(t);
        }
        self.report.digest.add(ev);
        self.report.slices += 1;
        let now = now_ns();
        self.report.first_arrival_ns.get_or_insert(now);
        self.report.last_arrival_ns = Some(now);
    }

    /// The report so far.
    pub fn report(&self) -> &InspectReport {
        &self.report
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::{CameraInfo, Events};

    fn slice(ts: &[f64]) -> Slice {
        let mut events = Events::default();
        for &t in ts {
            events.push(t, 1, 1, 1);
        }
        let camera = CameraInfo::pinhole(1, 1, 1.0, "test");
        Slice {
            camera,
            events,
            imu: vec![],
            omega: None,
        }
    }

    #[test]
    fn clean_stream_has_no_problems() {
        let mut i = Inspector::default();
        i.add(0, 0.0, 0.1, &slice(&[0.0, 0.05]));
        i.add(1, 0.1, 0.2, &slice(&[0.15]));
        assert_eq!(i.report().problem_count, 0);
        assert_eq!(i.report().digest.count, 3);
    }

    #[test]
    fn gaps_disorder_and_strays_are_found() {
        let mut i = Inspector::default();
        i.add(0, 0.0, 0.1, &slice(&[0.05, 0.01]));
        i.add(2, 0.2, 0.3, &slice(&[0.5]));
        let r = i.report();
        assert_eq!(r.problem_count, 3, "{:?}", r.problems);
    }
}
