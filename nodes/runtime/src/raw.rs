//! Untyped, unjoined consumers: nodes whose input ports are chosen by the launcher (one per
//! recorded output, any schema) and that take every port on its own, in arrival order, without
//! joining ports by sequence number (different outputs count in different sequence spaces, for
//! example a source's packets and the slicer's slices).
//!
//! Such a node takes part in lock-step credit like any consumer: after each batch of arrivals it
//! publishes, per port, how many messages it has consumed (the highest sequence number seen plus
//! one), and `DONE` for a port once its end-of-stream frame arrived, so producers wait for it and
//! nothing is lost. The recorder (`evseg-recorder`) is the user.

use std::sync::atomic::Ordering;
use std::time::Instant;

use evseg_schemas::describe::NodeDescription;
use evseg_schemas::{Envelope, FrameKind, codec};

use crate::config::{Mode, NodeConfig};
use crate::error::{BoxError, RuntimeError};
use crate::node::{RESEND_AFTER, Running, StatsClock, main_wrapper, maybe_stats, note_losses};
use crate::progress::DONE;
use crate::signals;
use crate::transport::{POLL, SeqGaps};

/// A node that takes each input frame as it comes, undecoded.
pub trait RawConsumer {
    /// Called for every data frame received on input `port` (index into the config's inputs),
    /// in arrival order on that port. `frame` is the whole frame as it was on the wire
    /// (envelope and body); `envelope` is its decoded header.
    fn frame(&mut self, port: usize, envelope: &Envelope, frame: &[u8]) -> Result<(), BoxError>;

    /// Called once, after every input has ended.
    fn finish(&mut self) -> Result<(), BoxError> {
        Ok(())
    }
}

/// Per-port consumption counts of an unjoined consumer (what it acknowledges).
#[derive(Debug, Clone, PartialEq)]
pub struct PortProgress {
    consumed: Vec<u64>,
    ended: Vec<bool>,
    changed: Vec<bool>,
    /// Per port, the sequence numbers seen lately (frames published again after a lock-step
    /// stall arrive twice; see [`PortProgress::first_time`]).
    seen: Vec<std::collections::BTreeSet<u64>>,
}

/// How many sequence numbers below the newest one [`PortProgress`] remembers per port (far
/// more than any lock-step window).
const SEEN_SPAN: u64 = 4096;

impl PortProgress {
    /// Progress of `ports` inputs, nothing consumed.
    pub fn new(ports: usize) -> Self {
        Self {
            consumed: vec![0; ports],
            ended: vec![false; ports],
            changed: vec![false; ports],
            seen: vec![std::collections::BTreeSet::new(); ports],
        }
    }

    /// True the first time data frame `seq` arrives on `port`; false for a repeat (a frame
    /// published again by a producer whose consumers stalled), which must not be handed on.
    pub fn first_time(&mut self, port: usize, seq: u64) -> bool {
        let Some(seen) = self.seen.get_mut(port) else {
            return true;
        };
        if !seen.insert(seq) {
            return false;
        }
        let newest = seen.last().copied().unwrap_or(seq);
        while seen
            .first()
            .is_some_and(|&s| s.saturating_add(SEEN_SPAN) < newest)
        {
            seen.pop_first();
        }
        true
    }

    /// Notes a data frame with sequence number `seq` on `port`: consumed becomes `seq + 1`
    /// unless it is already higher (or the port has ended).
    pub fn data(&mut self, port: usize, seq: u64) {
        if let (Some(c), Some(false)) = (self.consumed.get_mut(port), self.ended.get(port)) {
            let n = seq.saturating_add(1);
            if n > *c {
                *c = n;
                self.changed[port] = true;
            }
        }
    }

    /// Notes the end of stream on `port`: it is acknowledged as [`DONE`] from now on.
    pub fn end(&mut self, port: usize) {
        if let Some(e) = self.ended.get_mut(port) {
            *e = true;
            self.consumed[port] = DONE;
            self.changed[port] = true;
        }
    }

    /// True when every port has ended.
    pub fn all_ended(&self) -> bool {
        self.ended.iter().all(|&e| e)
    }

    /// `(port index, consumed)` of every port.
    pub fn all(&self) -> Vec<(usize, u64)> {
        self.consumed.iter().copied().enumerate().collect()
    }

    /// `(port index, consumed)` of the ports that changed since the last call.
    pub fn take_changes(&mut self) -> Vec<(usize, u64)> {
        let mut out = Vec::new();
        for (i, c) in self.changed.iter_mut().enumerate() {
            if std::mem::take(c) {
                out.push((i, self.consumed[i]));
            }
        }
        out
    }
}

/// Runs an unjoined consumer node: `--describe` prints `description`; `--config FILE` runs it.
/// The config's inputs need not be ports of `description` (the launcher chooses them); each
/// input's frames must carry the schema its binding names (the empty name accepts any).
/// Returns the process exit code.
pub fn run_raw_consumer<C: RawConsumer>(
    description: NodeDescription,
    make: impl FnOnce(&NodeConfig) -> Result<C, BoxError>,
) -> std::process::ExitCode {
    main_wrapper(description, false, make, |run, mut consumer| {
        raw_loop(run, &mut consumer)
    })
}

fn raw_loop<C: RawConsumer>(run: Running, consumer: &mut C) -> Result<(), RuntimeError> {
    let inbox = run.inbox.clone();
    let mut progress = PortProgress::new(run.cfg.inputs.len());
    let mut gaps = SeqGaps::new(run.cfg.inputs.len());
    let mut stats_clock = StatsClock::new();
    let mut last_progress = Instant::now();
    let counters = run.counters.clone();
    while !progress.all_ended() {
        if signals::stop_requested() {
            return Err(RuntimeError::Stopped);
        }
        for arrival in inbox.drain(POLL) {
            let binding = &run.cfg.inputs[arrival.port];
            let bytes = arrival.bytes.as_slice();
            let problem = match codec::decode_header(&bytes) {
                Ok((envelope, _)) if envelope.kind == FrameKind::End => {
                    gaps.end(arrival.port, envelope.seq);
                    progress.end(arrival.port);
                    None
                }
                Ok((envelope, _))
                    if (binding.schema.is_empty() || envelope.schema == binding.schema)
                        && !progress.first_time(arrival.port, envelope.seq) =>
                {
                    // A repeat of a frame already handed on.
                    None
                }
                Ok((envelope, _)) if binding.schema.is_empty() || envelope.schema == binding.schema => {
                    counters.count_receipt(arrival.port);
                    gaps.data(arrival.port, envelope.seq);
                    let t0 = Instant::now();
                    consumer
                        .frame(arrival.port, &envelope, &bytes)
                        .map_err(|source| RuntimeError::Logic {
                            node: run.cfg.node.clone(),
                            seq: envelope.seq,
                            source,
                        })?;
                    counters
                        .busy_ns
                        .fetch_add(t0.elapsed().as_nanos() as u64, Ordering::Relaxed);
                    counters.processed.fetch_add(1, Ordering::Relaxed);
                    counters.last_seq.store(envelope.seq, Ordering::Relaxed);
                    progress.data(arrival.port, envelope.seq);
                    None
                }
                Ok((envelope, _)) => Some(RuntimeError::Config(format!(
                    "node {}, input `{}` (key {}): expected {} but received {} v{} from `{}`",
                    run.cfg.node,
                    binding.port,
                    binding.key,
                    binding.schema,
                    envelope.schema,
                    envelope.version,
                    binding.producer
                ))),
                Err(source) => Some(RuntimeError::Decode {
                    node: run.cfg.node.clone(),
                    port: binding.port.clone(),
                    key: binding.key.clone(),
                    source,
                }),
            };
            if let Some(err) = problem {
                counters.refused.fetch_add(1, Ordering::Relaxed);
                if run.cfg.mode == Mode::Lockstep {
                    return Err(err);
                }
                tracing::error!("{err} (message dropped)");
            }
        }
        // Before acknowledging: the launcher learns of the first receipt first.
        note_losses(&run, &inbox, 0, &gaps);
        maybe_stats(&run, &mut stats_clock);
        let changes: Vec<(String, u64)> = progress
            .take_changes()
            .into_iter()
            .map(|(i, n)| (run.cfg.inputs[i].port.clone(), n))
            .collect();
        if !changes.is_empty() {
            run.publish_progress(changes)?;
            last_progress = Instant::now();
        } else if run.cfg.mode == Mode::Lockstep && last_progress.elapsed() >= RESEND_AFTER {
            // Idle: repeat the whole progress (a lost progress message must not stall the
            // producers; they publish their unconsumed frames again after the same time).
            let all = progress
                .all()
                .into_iter()
                .map(|(i, n)| (run.cfg.inputs[i].port.clone(), n))
                .collect();
            run.publish_progress(all)?;
            last_progress = Instant::now();
        }
    }
    let t0 = Instant::now();
    consumer.finish().map_err(|source| RuntimeError::Logic {
        node: run.cfg.node.clone(),
        seq: u64::MAX,
        source,
    })?;
    counters
        .busy_ns
        .fetch_add(t0.elapsed().as_nanos() as u64, Ordering::Relaxed);
    run.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_repeated_frame_is_seen_once() {
        let mut p = PortProgress::new(2);
        assert!(p.first_time(0, 0) && p.first_time(0, 2) && p.first_time(1, 0));
        assert!(!p.first_time(0, 0) && !p.first_time(0, 2));
        // Out of order after a loss: the missing one is still new.
        assert!(p.first_time(0, 1));
    }

    #[test]
    fn each_port_counts_on_its_own_and_ends_with_done() {
        let mut p = PortProgress::new(2);
        p.data(0, 0);
        p.data(0, 1);
        p.data(1, 41);
        assert_eq!(p.take_changes(), vec![(0, 2), (1, 42)]);
        assert_eq!(p.take_changes(), vec![]);
        // An older (or repeated) frame does not move the count back.
        p.data(1, 3);
        assert_eq!(p.take_changes(), vec![]);
        assert!(!p.all_ended());
        p.end(0);
        p.data(0, 7);
        assert_eq!(p.take_changes(), vec![(0, DONE)]);
        p.end(1);
        assert!(p.all_ended());
        // Out-of-range ports are ignored, never a panic.
        p.data(9, 1);
        p.end(9);
    }

    #[test]
    fn no_ports_means_already_finished() {
        assert!(PortProgress::new(0).all_ended());
    }
}
