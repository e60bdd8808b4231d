//! Joining several inputs by slice sequence number.
//!
//! A node with inputs `a`, `b` and a feedback input `f` is called for slice `k` with `a[k]`,
//! `b[k]` and `f[k-1]` (none for the first slice). In lock-step mode the joiner waits for
//! exactly those; in live mode it takes the newest sequence number that every main input has,
//! drops older incomplete sets (counted), and gives feedback inputs the newest earlier message.

use std::collections::BTreeMap;

use evseg_schemas::{Envelope, FrameKind};

/// The bytes of a received frame: Zenoh's own buffer when it is contiguous (no copy), or an
/// owned copy otherwise.
#[derive(Debug, Clone)]
pub enum FrameBytes {
    /// Owned bytes.
    Owned(Vec<u8>),
    /// A contiguous Zenoh payload.
    Zenoh(zenoh::bytes::ZBytes),
}

impl FrameBytes {
    /// From a Zenoh payload, copying only when it is not contiguous.
    pub fn from_payload(payload: &zenoh::bytes::ZBytes) -> Self {
        match payload.to_bytes() {
            std::borrow::Cow::Borrowed(_) => Self::Zenoh(payload.clone()),
            std::borrow::Cow::Owned(v) => Self::Owned(v),
        }
    }

    /// The bytes.
    pub fn as_slice(&self) -> std::borrow::Cow<'_, [u8]> {
        match self {
            Self::Owned(v) => std::borrow::Cow::Borrowed(v),
            Self::Zenoh(z) => z.to_bytes(),
        }
    }
}

/// One received frame: its envelope and its full bytes (envelope included).
#[derive(Debug, Clone)]
pub struct RawFrame {
    /// Decoded header.
    pub envelope: Envelope,
    /// The encoded frame, as received.
    pub bytes: FrameBytes,
}

/// A complete set of inputs for one slice.
#[derive(Debug, Clone)]
pub struct Joined {
    /// Sequence number of the slice.
    pub seq: u64,
    /// Sensor time span `[t_start, t_end)` of the slice, seconds.
    pub t_start: f64,
    /// End of the span, seconds.
    pub t_end: f64,
    /// Per input port (config order): the frame, or `None` for a feedback input without one.
    pub frames: Vec<Option<RawFrame>>,
}

/// What the joiner has for the node now.
#[derive(Debug)]
pub enum JoinState {
    /// A complete set is ready.
    Ready(Joined),
    /// All main inputs have ended and everything was handed out.
    Finished,
    /// Waiting for more frames.
    Waiting,
}

/// Inputs that cannot be joined (lock-step only).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("input `{ended}` ended after {count} messages but input `{other}` has message {count}")]
pub struct JoinError {
    /// Port that ended early.
    pub ended: String,
    /// Its message count.
    pub count: u64,
    /// Port that has more.
    pub other: String,
}

#[derive(Debug, Default)]
struct Port {
    name: String,
    feedback: bool,
    pending: BTreeMap<u64, RawFrame>,
    end: Option<u64>,
}

/// Joins frames from several ports by sequence number.
#[derive(Debug)]
pub struct Joiner {
    ports: Vec<Port>,
    next: u64,
    /// False until the first set was handed out: a node (re)started in the middle of a stream
    /// begins at the oldest sequence number all its main inputs have.
    started: bool,
    live: bool,
    dropped: u64,
}

impl Joiner {
    /// A joiner for ports `(name, feedback)`; `live` selects the live-mode policy.
    pub fn new(ports: &[(String, bool)], live: bool) -> Self {
        Self {
            ports: ports
                .iter()
                .map(|(name, feedback)| Port {
                    name: name.clone(),
                    feedback: *feedback,
                    ..Port::default()
                })
                .collect(),
            next: 0,
            started: false,
            live,
            dropped: 0,
        }
    }

    /// Frames dropped because their set could never be completed (live mode).
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Adds a received frame on port `port`.
    pub fn push(&mut self, port: usize, frame: RawFrame) {
        let Some(p) = self.ports.get_mut(port) else { return };
        match frame.envelope.kind {
            FrameKind::End => p.end = Some(frame.envelope.seq),
            FrameKind::Data => {
                // A frame older than what was already handed out can only be a duplicate: in
                // lock-step mode a frame published again after a stall (not a loss), in live
                // mode one that came too late (counted).
                if !p.feedback && frame.envelope.seq < self.next {
                    if self.live {
                        self.dropped += 1;
                    }
                    return;
                }
                // A feedback frame older than the previous slice's is no longer needed.
                if p.feedback && self.started && frame.envelope.seq.saturating_add(1) < self.next {
                    return;
                }
                p.pending.insert(frame.envelope.seq, frame);
            }
        }
    }

    fn main_ports(&self) -> impl Iterator<Item = &Port> {
        self.ports.iter().filter(|p| !p.feedback)
    }

    /// The next complete set, if any.
    pub fn poll(&mut self) -> Result<JoinState, JoinError> {
        if self.main_ports().next().is_none() {
            return Ok(JoinState::Finished);
        }
        let seq = if self.live {
            match self.live_step() {
                LiveStep::Take(s) => s,
                LiveStep::Wait => return Ok(JoinState::Waiting),
                LiveStep::Finish => return Ok(JoinState::Finished),
            }
        } else {
            if !self.started {
                match self.first_common() {
                    Some(first) => self.next = first,
                    None => return Ok(JoinState::Waiting),
                }
            }
            self.next
        };
        // Lock-step: every main port must have `seq`, or have ended at exactly `seq`.
        let mut ended = None;
        let mut present = None;
        for p in self.main_ports() {
            if p.pending.contains_key(&seq) {
                present = Some(p.name.clone());
            } else if let Some(c) = p.end
                && c <= seq
            {
                ended = Some((p.name.clone(), c));
            } else {
                return Ok(JoinState::Waiting);
            }
        }
        match (ended, present) {
            (Some((ended, count)), Some(other)) => return Err(JoinError { ended, count, other }),
            (Some(_), None) => return Ok(JoinState::Finished),
            _ => {}
        }
        // Feedback ports: message seq-1.
        let mut frames = Vec::with_capacity(self.ports.len());
        for p in &self.ports {
            if !p.feedback {
                continue;
            }
            if seq == 0 {
                continue;
            }
            let want = seq - 1;
            let have = p.pending.contains_key(&want);
            let over = p.end.is_some_and(|c| c <= want);
            if !have && !over && !self.live {
                return Ok(JoinState::Waiting);
            }
        }
        let live = self.live;
        let mut t_span = None;
        for p in &mut self.ports {
            if p.feedback {
                let f = if seq == 0 {
                    None
                } else if live {
                    let newest = p.pending.range(..seq).next_back().map(|(k, _)| *k);
                    newest.and_then(|k| {
                        p.pending = p.pending.split_off(&k);
                        p.pending.get(&k).cloned()
                    })
                } else {
                    let f = p.pending.remove(&(seq - 1));
                    p.pending = p.pending.split_off(&seq);
                    f
                };
                frames.push(f);
            } else {
                let f = p.pending.remove(&seq);
                if t_span.is_none() {
                    t_span = f.as_ref().map(|f| (f.envelope.t_start, f.envelope.t_end));
                }
                frames.push(f);
            }
        }
        self.next = seq + 1;
        self.started = true;
        let (t_start, t_end) = t_span.unwrap_or((0.0, 0.0));
        Ok(JoinState::Ready(Joined {
            seq,
            t_start,
            t_end,
            frames,
        }))
    }

    /// Lock-step start: once every main port has a frame (or has ended), the oldest of their
    /// first sequence numbers.
    fn first_common(&self) -> Option<u64> {
        let mut first = None::<u64>;
        for p in self.main_ports() {
            match (p.pending.keys().next(), p.end) {
                (Some(&k), _) => first = Some(first.map_or(k, |f| f.min(k))),
                (None, Some(c)) => first = Some(first.map_or(c, |f| f.min(c))),
                (None, None) => return None,
            }
        }
        first
    }

    /// Live mode: the newest sequence number every main port can have, dropping older partial
    /// sets (counted). Frames of one port arrive in order (they may be lost, not overtaken), so
    /// the newest frame of the port that is furthest behind bounds what can still complete. A
    /// set waits only while that bound can still move: once the ports that hold it have ended,
    /// the newest set complete among the frames held is taken, and when none is, nothing can
    /// complete any more and the node is finished (the frames held are counted as dropped).
    /// Before, a run whose slow stage ended on a set another port had lost waited forever.
    fn live_step(&mut self) -> LiveStep {
        if self.main_ports().any(|p| p.end.is_some() && p.pending.is_empty()) {
            return self.live_finish();
        }
        let mut cand: Option<u64> = None;
        for p in self.main_ports() {
            match p.pending.keys().next_back() {
                Some(&newest) => cand = Some(cand.map_or(newest, |c| c.min(newest))),
                None => return LiveStep::Wait,
            }
        }
        let Some(cand) = cand else { return LiveStep::Wait };
        let complete = |j: &Self, s: u64| j.main_ports().all(|p| p.pending.contains_key(&s));
        let take = if complete(self, cand) {
            cand
        } else {
            // The ports whose newest frame is `cand` may still receive newer ones.
            let bound_can_move = self
                .main_ports()
                .any(|p| p.end.is_none() && p.pending.keys().next_back() == Some(&cand));
            if bound_can_move {
                return LiveStep::Wait;
            }
            let Some(&older) = self.main_ports().min_by_key(|p| p.pending.len()).and_then(|p| {
                p.pending
                    .range(..cand)
                    .rev()
                    .find(|(s, _)| complete(self, **s))
                    .map(|(s, _)| s)
            }) else {
                return self.live_finish();
            };
            older
        };
        let mut dropped = 0;
        for p in self.ports.iter_mut().filter(|p| !p.feedback) {
            let keep = p.pending.split_off(&take);
            dropped += p.pending.len() as u64;
            p.pending = keep;
        }
        self.dropped += dropped;
        LiveStep::Take(take)
    }

    /// Live mode: no set can complete any more; the frames held are dropped (counted).
    fn live_finish(&mut self) -> LiveStep {
        for p in self.ports.iter_mut().filter(|p| !p.feedback) {
            self.dropped += p.pending.len() as u64;
            p.pending.clear();
        }
        LiveStep::Finish
    }
}

/// What live mode does next.
enum LiveStep {
    /// Hand out the set of this sequence number.
    Take(u64),
    /// Wait for more frames.
    Wait,
    /// No set can complete any more.
    Finish,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(seq: u64, kind: FrameKind) -> RawFrame {
        RawFrame {
            envelope: Envelope {
                schema: "s".into(),
                version: 1,
                kind,
                seq,
                t_start: seq as f64,
                t_end: seq as f64 + 1.0,
                publish_ns: 0,
            },
            bytes: FrameBytes::Owned(vec![seq as u8]),
        }
    }

    fn ready(j: &mut Joiner) -> Joined {
        match j.poll().unwrap() {
            JoinState::Ready(x) => x,
            other => panic!("expected ready, got {other:?}"),
        }
    }

    #[test]
    fn lockstep_ignores_frames_published_again() {
        let mut j = Joiner::new(&[("a".into(), false), ("prev".into(), true)], false);
        j.push(0, frame(0, FrameKind::Data));
        assert_eq!(ready(&mut j).seq, 0);
        // Published again after a stall: already handed out, not a drop.
        j.push(0, frame(0, FrameKind::Data));
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        j.push(1, frame(0, FrameKind::Data));
        j.push(0, frame(1, FrameKind::Data));
        j.push(0, frame(1, FrameKind::Data));
        assert_eq!(ready(&mut j).seq, 1);
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        assert_eq!(j.dropped(), 0);
    }

    #[test]
    fn lockstep_joins_by_seq_in_order() {
        let mut j = Joiner::new(&[("a".into(), false), ("b".into(), false)], false);
        j.push(0, frame(1, FrameKind::Data));
        j.push(0, frame(0, FrameKind::Data));
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        j.push(1, frame(0, FrameKind::Data));
        let x = ready(&mut j);
        assert_eq!(x.seq, 0);
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        j.push(1, frame(1, FrameKind::Data));
        assert_eq!(ready(&mut j).seq, 1);
        j.push(0, frame(2, FrameKind::End));
        j.push(1, frame(2, FrameKind::End));
        assert!(matches!(j.poll().unwrap(), JoinState::Finished));
    }

    #[test]
    fn feedback_gets_previous_slice() {
        let mut j = Joiner::new(&[("a".into(), false), ("fb".into(), true)], false);
        j.push(0, frame(0, FrameKind::Data));
        j.push(0, frame(1, FrameKind::Data));
        let x = ready(&mut j);
        assert_eq!(x.seq, 0);
        assert!(x.frames[1].is_none());
        // Slice 1 needs feedback 0.
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        j.push(1, frame(0, FrameKind::Data));
        let x = ready(&mut j);
        assert_eq!(x.seq, 1);
        assert_eq!(x.frames[1].as_ref().unwrap().envelope.seq, 0);
    }

    #[test]
    fn a_restarted_node_resumes_at_the_first_common_seq() {
        let mut j = Joiner::new(&[("a".into(), false), ("b".into(), false)], false);
        j.push(0, frame(7, FrameKind::Data));
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        j.push(1, frame(7, FrameKind::Data));
        assert_eq!(ready(&mut j).seq, 7);
    }

    #[test]
    fn inconsistent_ends_are_an_error() {
        let mut j = Joiner::new(&[("a".into(), false), ("b".into(), false)], false);
        j.push(0, frame(0, FrameKind::End));
        j.push(1, frame(0, FrameKind::Data));
        let e = j.poll().unwrap_err();
        assert_eq!(e.ended, "a");
        assert_eq!(e.other, "b");
    }

    #[test]
    fn live_finishes_when_the_ends_leave_no_set_to_complete() {
        // The slow port's last frame (5) was lost on the other port: nothing can complete.
        let mut j = Joiner::new(&[("fast".into(), false), ("slow".into(), false)], true);
        for s in [4, 6, 7] {
            j.push(0, frame(s, FrameKind::Data));
        }
        j.push(1, frame(5, FrameKind::Data));
        assert!(
            matches!(j.poll().unwrap(), JoinState::Waiting),
            "the slow port may still send 6"
        );
        j.push(1, frame(6, FrameKind::End));
        assert!(matches!(j.poll().unwrap(), JoinState::Finished));
        assert_eq!(j.dropped(), 4);
    }

    #[test]
    fn live_takes_an_older_complete_set_once_the_bound_cannot_move() {
        let mut j = Joiner::new(&[("fast".into(), false), ("slow".into(), false)], true);
        for s in [3, 4, 6] {
            j.push(0, frame(s, FrameKind::Data));
        }
        j.push(1, frame(3, FrameKind::Data));
        j.push(1, frame(5, FrameKind::Data));
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        j.push(1, frame(6, FrameKind::End));
        assert_eq!(ready(&mut j).seq, 3);
        // Left: 4 and 6 on `fast`, 5 on `slow`; `slow` ended, so none of them can complete.
        assert!(matches!(j.poll().unwrap(), JoinState::Finished));
        assert_eq!(j.dropped(), 3);
    }

    #[test]
    fn live_waits_for_a_port_that_has_not_ended() {
        let mut j = Joiner::new(&[("a".into(), false), ("b".into(), false)], true);
        j.push(0, frame(0, FrameKind::Data));
        j.push(0, frame(1, FrameKind::End));
        assert!(matches!(j.poll().unwrap(), JoinState::Waiting));
        j.push(1, frame(0, FrameKind::Data));
        assert_eq!(ready(&mut j).seq, 0);
        j.push(1, frame(1, FrameKind::End));
        assert!(matches!(j.poll().unwrap(), JoinState::Finished));
        assert_eq!(j.dropped(), 0);
    }

    #[test]
    fn live_skips_incomplete_sets_and_counts_them() {
        let mut j = Joiner::new(&[("a".into(), false), ("b".into(), false)], true);
        j.push(0, frame(0, FrameKind::Data));
        j.push(0, frame(1, FrameKind::Data));
        j.push(0, frame(2, FrameKind::Data));
        j.push(1, frame(2, FrameKind::Data));
        let x = ready(&mut j);
        assert_eq!(x.seq, 2);
        assert_eq!(j.dropped(), 2);
        j.push(0, frame(3, FrameKind::End));
        j.push(1, frame(3, FrameKind::End));
        assert!(matches!(j.poll().unwrap(), JoinState::Finished));
    }
}
