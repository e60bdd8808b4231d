//! The node lifecycle: command line, session, ports, the processing loop, end of stream.
//!
//! A stage implements [`Stage`] (inputs to outputs, one joined slice at a time) or [`Source`]
//! (produces until exhausted), and its `main` calls [`run_stage`] or [`run_source`] with its
//! [`NodeDescription`]. Everything else (Zenoh, joins, credits, stats, shutdown) happens here.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use evseg_schemas::describe::NodeDescription;
use evseg_schemas::{Message, codec};
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::qos::CongestionControl;

use crate::config::{Mode, NodeConfig};
use crate::error::{BoxError, RuntimeError};
use crate::join::{JoinState, Joined, Joiner, RawFrame};
use crate::progress::{DONE, Progress, Stats};
use crate::signals;
use crate::transport::{
    CreditBook, Inbox, POLL, SeqGaps, ShmPool, encode_payload, open_session, shm_pool, subscribe_inputs,
};

/// How long a producer waits at start-up for its consumers to appear before failing.
pub const STARTUP_TIMEOUT: Duration = Duration::from_secs(60);
/// Lock-step: a producer waiting this long for credit publishes the unconsumed frames again,
/// and an idle consumer repeats its last progress this often (a lost message must not stop
/// the graph). Long against a normal slice (tens of ms), short against a test's patience.
pub const RESEND_AFTER: Duration = Duration::from_secs(1);
/// Lock-step: resends of the same unconsumed frames after which a producer also says what
/// commonly makes consumers lose every frame (not only a slow consumer: a slice takes tens of
/// milliseconds, ten resends are ten seconds).
pub const STALL_HINT_AFTER_RESENDS: u32 = 10;
/// A finished node repeats its final progress this often while its producers are still there.
pub const DONE_REPEAT: Duration = Duration::from_millis(200);
/// How long a finished node waits at most for its producers to leave (see `Running::finish`).
pub const LINGER_TIMEOUT: Duration = Duration::from_secs(30);
/// How long a finished node waits for its consumers to finish before leaving anyway.
pub const DRAIN_TIMEOUT: Duration = Duration::from_secs(600);

/// A stage: called once per joined slice.
pub trait Stage {
    /// Processes one joined slice; publishes results through `out`.
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError>;

    /// Called once after the last slice; may publish final results.
    fn finish(&mut self, _out: &mut Outputs) -> Result<(), BoxError> {
        Ok(())
    }
}

/// A source: called repeatedly until it reports exhaustion.
pub trait Source {
    /// Produces the next batch through `out`; returns `false` when there is nothing more.
    fn step(&mut self, out: &mut Outputs) -> Result<bool, BoxError>;
}

/// The inputs of one joined slice, decoded on demand.
pub struct Inputs<'a> {
    cfg: &'a NodeConfig,
    joined: &'a Joined,
}

impl Inputs<'_> {
    /// Sequence number of the slice.
    pub fn seq(&self) -> u64 {
        self.joined.seq
    }

    /// Sensor time span of the slice `[start, end)`, seconds.
    pub fn span(&self) -> (f64, f64) {
        (self.joined.t_start, self.joined.t_end)
    }

    fn index(&self, port: &str) -> Result<usize, RuntimeError> {
        self.cfg
            .inputs
            .iter()
            .position(|i| i.port == port)
            .ok_or_else(|| RuntimeError::NoPort {
                node: self.cfg.node.clone(),
                direction: "input",
                port: port.to_string(),
            })
    }

    /// True when `port` is connected in the graph.
    pub fn is_connected(&self, port: &str) -> bool {
        self.index(port).is_ok()
    }

    /// The message on `port`, or `None` when the port is unconnected or is a feedback input
    /// without a previous message.
    pub fn get_opt<T: Message>(&self, port: &str) -> Result<Option<T>, RuntimeError> {
        let Ok(i) = self.index(port) else { return Ok(None) };
        let Some(frame) = &self.joined.frames[i] else {
            return Ok(None);
        };
        let decoded = codec::decode::<T>(&frame.bytes.as_slice()).map_err(|source| RuntimeError::Decode {
            node: self.cfg.node.clone(),
            port: port.to_string(),
            key: self.cfg.inputs[i].key.clone(),
            source,
        })?;
        Ok(decoded.body)
    }

    /// The message on `port`; an error if there is none.
    pub fn get<T: Message>(&self, port: &str) -> Result<T, RuntimeError> {
        self.get_opt(port)?.ok_or_else(|| RuntimeError::NoPort {
            node: self.cfg.node.clone(),
            direction: "input (with a message)",
            port: port.to_string(),
        })
    }

    /// The sensor time span of the message on `port`, if present.
    pub fn span_of(&self, port: &str) -> Option<(f64, f64)> {
        let i = self.index(port).ok()?;
        self.joined.frames[i]
            .as_ref()
            .map(|f| (f.envelope.t_start, f.envelope.t_end))
    }
}

struct OutPort {
    publisher: zenoh::pubsub::Publisher<'static>,
    /// Live mode only: a publisher on the same key that blocks instead of dropping under
    /// congestion, for the end-of-stream frame (a dropped end would leave consumers waiting).
    end_publisher: Option<zenoh::pubsub::Publisher<'static>>,
    /// (consumer node, consumer port, feedback)
    consumers: Vec<(String, String, bool)>,
    /// Lock-step only: the last `window` frames published (sequence number, payload), to be
    /// published again if the consumers stall (a lost frame).
    recent: std::collections::VecDeque<(u64, ZBytes)>,
    /// The end-of-stream frame once published (published again while consumers stall).
    end_frame: Option<Vec<u8>>,
    sent: u64,
    t_end: f64,
}

/// The outputs of a node. Publishing in lock-step mode waits for credit from every consumer.
pub struct Outputs {
    node: String,
    mode: Mode,
    window: u64,
    ports: Vec<(String, OutPort)>,
    book: Arc<CreditBook>,
    consumers_ready: bool,
    published: Arc<AtomicU64>,
    /// Nanoseconds spent waiting for consumers (credits, liveliness) since the last
    /// [`Outputs::take_waited_ns`]: not the node's own work, so not counted as busy.
    waited_ns: u64,
    /// The session's shared-memory pool, large frames are encoded straight into it.
    shm: Option<ShmPool>,
    /// Lock-step fault injection for tests: `(port, seq)` of one frame that is kept for
    /// publishing again but not published the first time, from the environment variable
    /// [`DROP_FRAME_ENV`] (`node/port/seq`, this node's entry only).
    drop_once: Option<(String, u64)>,
    /// The node's stats, published again each time a lock-step wait for credit times out: a
    /// producer blocked there runs no loop that would publish them, and the launcher then saw
    /// its counters from before the block (a slicer that "published 0" in a stalled run).
    stats_while_blocked: Option<StatsSource>,
}

/// Environment variable that makes a node lose one frame of its own in lock-step mode, as a
/// transport would (`node/port/seq`): for tests of the recovery from lost frames.
pub const DROP_FRAME_ENV: &str = "EVSEG_TEST_DROP_FRAME";

/// Environment variable that makes a node never report that it finished one of its inputs
/// (`node/port`): its final progress for that port is left out, as if every copy of it were
/// lost in transit; for tests of the producer's drain when the consumer exits.
pub const DROP_DONE_ENV: &str = "EVSEG_TEST_DROP_DONE";

/// Environment variable that makes a node declare none of its input subscriptions once
/// (`node=marker-file`), or none for one input port (`node/port=marker-file`): deaf while the
/// marker file does not exist; the node creates it, so the node started again after it
/// subscribes normally. With no marker (`node=`) it is deaf at every start. As if its
/// subscriptions (or one of them) had never reached its producers: for tests of the
/// launcher's start-up watchdog.
pub const DEAF_ONCE_ENV: &str = "EVSEG_TEST_DEAF_ONCE";

/// Which input subscriptions [`DEAF_ONCE_ENV`] leaves undeclared.
#[derive(Debug, PartialEq)]
enum Deaf {
    /// Every input.
    All,
    /// The input port of this name.
    Port(String),
}

/// What [`DEAF_ONCE_ENV`] makes this node deaf to, when it names this node (or one of its
/// ports) and its marker did not exist yet (it is created).
fn deaf_once_from_env(node: &str) -> Option<Deaf> {
    let v = std::env::var(DEAF_ONCE_ENV).ok()?;
    let (target, marker) = v.split_once('=')?;
    let deaf = match target.split_once('/') {
        Some((n, port)) if n == node => Deaf::Port(port.to_string()),
        None if target == node => Deaf::All,
        _ => return None,
    };
    if marker.is_empty() {
        return Some(deaf);
    }
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(marker)
        .is_ok()
        .then_some(deaf)
}

/// Environment variable that makes a node's logic take `seconds` longer on one slice
/// (`node/seq=seconds`), as a slow configuration would: for tests of how a long slice is
/// reported (the heartbeat and the launcher's stall message).
pub const SLOW_SLICE_ENV: &str = "EVSEG_TEST_SLOW_SLICE";

/// This node's entry of [`SLOW_SLICE_ENV`]: the slice and the extra time.
fn slow_slice_from_env(node: &str) -> Option<(u64, Duration)> {
    let v = std::env::var(SLOW_SLICE_ENV).ok()?;
    let (target, seconds) = v.split_once('=')?;
    let (n, seq) = target.split_once('/')?;
    let seconds: f64 = seconds.parse().ok()?;
    (n == node && seconds.is_finite() && seconds >= 0.0)
        .then(|| Some((seq.parse().ok()?, Duration::from_secs_f64(seconds))))
        .flatten()
}

/// The input port of this node named by [`DROP_DONE_ENV`], if any.
fn drop_done_from_env(node: &str) -> Option<String> {
    let v = std::env::var(DROP_DONE_ENV).ok()?;
    let (n, port) = v.split_once('/')?;
    (n == node).then(|| port.to_string())
}

/// This node's entry of [`DROP_FRAME_ENV`], if any.
fn drop_once_from_env(node: &str) -> Option<(String, u64)> {
    let v = std::env::var(DROP_FRAME_ENV).ok()?;
    let mut parts = v.splitn(3, '/');
    let (n, port, seq) = (parts.next()?, parts.next()?, parts.next()?);
    if n != node {
        return None;
    }
    Some((port.to_string(), seq.parse().ok()?))
}

impl Outputs {
    /// Nanoseconds spent waiting for consumers since the last call, and resets the count.
    fn take_waited_ns(&mut self) -> u64 {
        std::mem::take(&mut self.waited_ns)
    }

    fn port_mut(&mut self, port: &str) -> Result<&mut OutPort, RuntimeError> {
        let node = self.node.clone();
        self.ports
            .iter_mut()
            .find(|(n, _)| n == port)
            .map(|(_, p)| p)
            .ok_or(RuntimeError::NoPort {
                node,
                direction: "output",
                port: port.to_string(),
            })
    }

    /// True when output `port` is wired in the graph (publishing to an unwired port is allowed
    /// and costs nothing but the encoding).
    pub fn has(&self, port: &str) -> bool {
        self.ports.iter().any(|(n, _)| n == port)
    }

    fn watch_list(&self) -> Vec<(String, String)> {
        self.ports
            .iter()
            .flat_map(|(name, p)| p.consumers.iter().map(move |(c, _, _)| (c.clone(), name.clone())))
            .collect()
    }

    fn wait_consumers_alive(&mut self) -> Result<(), RuntimeError> {
        if self.consumers_ready {
            return Ok(());
        }
        let needed: Vec<String> = self.watch_list().into_iter().map(|(c, _)| c).collect();
        let timeout = match self.mode {
            Mode::Lockstep => STARTUP_TIMEOUT,
            Mode::Live => Duration::from_secs(10),
        };
        let ok = self.book.wait_until(&self.node, &[], Some(timeout), |_, alive| {
            needed.iter().all(|n| alive.contains(n))
        })?;
        if !ok && self.mode == Mode::Lockstep {
            return Err(RuntimeError::Zenoh(format!(
                "node {}: consumers {needed:?} did not appear within {}s",
                self.node,
                timeout.as_secs()
            )));
        }
        self.consumers_ready = true;
        Ok(())
    }

    /// Publishes `msg` on `port` as sequence number `seq` covering `[t_start, t_end)` seconds.
    pub fn send<T: Message>(
        &mut self,
        port: &str,
        seq: u64,
        t_start: f64,
        t_end: f64,
        msg: &T,
    ) -> Result<(), RuntimeError> {
        if !self.has(port) {
            return Ok(());
        }
        let envelope = codec::data_envelope::<T>(seq, t_start, t_end);
        let payload =
            encode_payload(self.shm.as_ref(), &envelope, msg).map_err(|source| RuntimeError::Encode {
                node: self.node.clone(),
                port: port.to_string(),
                source,
            })?;
        self.publish(port, seq, t_end, payload)
    }

    /// Publishes an already encoded frame (replay): `bytes` is a whole frame (envelope and
    /// body, `evseg_schemas::codec`) whose envelope says `seq` and `t_end`; in lock-step mode
    /// waits for credit like [`Outputs::send`]. The end-of-stream frame sent when the node
    /// finishes counts `seq + 1` frames and ends at the largest `t_end` seen.
    pub fn send_bytes(
        &mut self,
        port: &str,
        seq: u64,
        t_end: f64,
        bytes: Vec<u8>,
    ) -> Result<(), RuntimeError> {
        self.publish(port, seq, t_end, bytes.into())
    }

    fn publish(&mut self, port: &str, seq: u64, t_end: f64, payload: ZBytes) -> Result<(), RuntimeError> {
        let waiting = Instant::now();
        self.wait_consumers_alive()?;
        let (mode, window, node) = (self.mode, self.window, self.node.clone());
        let book = self.book.clone();
        let watch = self.watch_list();
        let consumers = self.port_mut(port)?.consumers.clone();
        if mode == Mode::Lockstep {
            // A frame or a progress message lost in transit would stop a lock-step graph for
            // good (every producer waiting for credit, every consumer for input): when no
            // credit comes for RESEND_AFTER, the frames the slowest consumer has not consumed
            // are published again (consumers drop the duplicates, and repeat their progress
            // while idle, see `stage_loop`).
            // Resends in a row of frames from the same one on (no consumer progress between).
            let mut resends_from_same = 0u32;
            let mut last_from = None;
            let counters = self.stats_while_blocked.as_ref().map(|s| s.counters.clone());
            let _waiting = counters.as_deref().map(CreditWait::new);
            while !book.wait_until(&node, &watch, Some(RESEND_AFTER), |consumed, _| {
                has_credit(consumed, &consumers, seq, window)
            })? {
                let from = book.check_min(&consumers);
                resends_from_same = if last_from == Some(from) {
                    resends_from_same + 1
                } else {
                    1
                };
                last_from = Some(from);
                if let Some(stats) = &self.stats_while_blocked {
                    stats.publish(false);
                }
                let frames = self.port_mut(port)?.publish_recent_again(from)?;
                // The other ports' unconsumed frames too: a consumer restarted by the launcher
                // (its first process consumed nothing) needs every input again, and a producer
                // waiting here publishes nothing else (seen: a restarted evaluator never got the
                // slicer's `truth` frames its first process had received).
                for (other, from, frames) in self.republish_unconsumed(Some(port))? {
                    tracing::debug!(node = %node, port = other, from, frames, blocked = port, "published the unconsumed frames again");
                }
                if frames > 0 && resends_from_same == STALL_HINT_AFTER_RESENDS {
                    tracing::warn!(
                        node = %node,
                        port,
                        from,
                        "the consumers of this port are alive but have taken none of these frames in {} resends; if that lasts, their transport drops the frames: shared memory that a consumer cannot map (its locked-memory limit, `ulimit -l`) does so without an error. `zenoh: {{ shared_memory: {{ enabled: false }} }}` in graph.yaml tells",
                        STALL_HINT_AFTER_RESENDS
                    );
                }
                if frames > 0 {
                    let consumed: Vec<String> = consumers
                        .iter()
                        .map(|(c, cp, _)| format!("{c}/{cp}={}", book.consumed(c, cp)))
                        .collect();
                    tracing::warn!(
                        node = %node,
                        port,
                        from,
                        frames,
                        ?consumed,
                        "no credit for {:?}: published the unconsumed frames again",
                        RESEND_AFTER
                    );
                }
            }
            let p = self.port_mut(port)?;
            p.recent.push_back((seq, payload.clone()));
            while p.recent.len() as u64 > window {
                p.recent.pop_front();
            }
        }
        let waited = waiting.elapsed().as_nanos() as u64;
        let dropped = mode == Mode::Lockstep
            && self
                .drop_once
                .as_ref()
                .is_some_and(|(dp, ds)| dp == port && *ds == seq);
        if dropped {
            self.drop_once = None;
            tracing::warn!(node = %node, port, seq, "frame not published ({DROP_FRAME_ENV})");
        }
        let p = self.port_mut(port)?;
        if !dropped {
            p.publisher
                .put(payload)
                .wait()
                .map_err(|e| RuntimeError::Zenoh(e.to_string()))?;
        }
        p.sent = p.sent.max(seq + 1);
        p.t_end = p.t_end.max(t_end);
        self.waited_ns += waited;
        self.published.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    /// Lock-step: publishes again, on every port but `except`, the recent frames some consumer
    /// has not consumed yet. Returns `(port, first frame, frames)` of each port that published
    /// any.
    fn republish_unconsumed(&self, except: Option<&str>) -> Result<Vec<(&str, u64, usize)>, RuntimeError> {
        let mut done = Vec::new();
        for (port, p) in self
            .ports
            .iter()
            .filter(|(name, _)| Some(name.as_str()) != except)
        {
            let from = self.book.check_min(&p.consumers);
            if from >= p.sent {
                continue;
            }
            let frames = p.publish_recent_again(from)?;
            if frames > 0 {
                done.push((port.as_str(), from, frames));
            }
        }
        Ok(done)
    }

    /// Lock-step: publishes again, on every port, the recent frames some consumer has not
    /// consumed yet. For a node that has been idle (waiting for input) for [`RESEND_AFTER`]: a
    /// lost frame of a node that still has credit would otherwise never be sent again, and a
    /// graph with a feedback loop then stops for good (the consumer of the lost frame waits
    /// for it, this node waits for input that depends on it). Consumers drop duplicates.
    /// Returns the number of frames published.
    pub fn publish_unconsumed_again(&mut self) -> Result<usize, RuntimeError> {
        if self.mode != Mode::Lockstep {
            return Ok(0);
        }
        let done = self.republish_unconsumed(None)?;
        for &(port, from, frames) in &done {
            tracing::warn!(
                node = %self.node,
                port = %port,
                from,
                frames,
                "idle for {:?} with frames not consumed: published them again",
                RESEND_AFTER
            );
        }
        Ok(done.iter().map(|&(_, _, frames)| frames).sum())
    }

    /// True when publishing frame `seq` on `port` now would not wait: in lock-step mode every
    /// consumer of `port` has consumed more than `seq - window` messages (or finished); in live
    /// mode always. Waits (once) for the consumers to appear, like the first publish does.
    /// With [`Outputs::wait_progress`] this lets a node that publishes pre-encoded frames on
    /// several outputs (replay) publish whichever output has credit instead of blocking on one.
    pub fn credit_available(&mut self, port: &str, seq: u64) -> Result<bool, RuntimeError> {
        self.wait_consumers_alive()?;
        if self.mode == Mode::Live {
            return Ok(true);
        }
        let (window, book) = (self.window, self.book.clone());
        let p = self.port_mut(port)?;
        Ok(book.check(|consumed| has_credit(consumed, &p.consumers, seq, window)))
    }

    /// Waits at most `timeout` (and at most [`POLL`]) for news from consumers (progress or
    /// liveliness), so a caller polling [`Outputs::credit_available`] does not spin. Fails when
    /// a stop was requested or a consumer vanished for longer than its grace time.
    pub fn wait_progress(&self, timeout: Duration) -> Result<(), RuntimeError> {
        let watch = self.watch_list();
        let mut first = true;
        // The predicate is evaluated once at entry and then after every wake-up (a change of
        // the book or the poll interval): returning on the second evaluation waits for one.
        self.book
            .wait_until(&self.node, &watch, Some(timeout.min(POLL)), |_, _| {
                !std::mem::replace(&mut first, false)
            })?;
        Ok(())
    }

    /// Publishes end-of-stream frames on every output.
    fn end_all(&mut self, schemas: &HashMap<String, String>) -> Result<(), RuntimeError> {
        self.wait_consumers_alive()?;
        for (name, p) in &mut self.ports {
            let schema = schemas.get(name).cloned().unwrap_or_default();
            let bytes =
                codec::encode_end_named(&schema, p.sent, p.t_end).map_err(|source| RuntimeError::Encode {
                    node: self.node.clone(),
                    port: name.clone(),
                    source,
                })?;
            p.put_end(bytes.clone())?;
            p.end_frame = Some(bytes);
        }
        Ok(())
    }

    /// Publishes again, on every port with an unfinished consumer, the frames its slowest
    /// unfinished consumer has not consumed (lock-step) and the end-of-stream frame: called
    /// while the consumers stay silent for [`RESEND_AFTER`] after the end, since a lost end
    /// frame (or a lost last progress) would otherwise keep both sides waiting.
    fn publish_unfinished_again(&self, exited: &[String]) -> Result<(), RuntimeError> {
        for (name, p) in &self.ports {
            let waiting: Vec<(String, String, bool)> = p
                .consumers
                .iter()
                .filter(|(c, _, _)| !exited.contains(c))
                .cloned()
                .collect();
            let from = self.book.check_min(&waiting);
            if from == u64::MAX {
                continue;
            }
            tracing::warn!(
                node = %self.node,
                port = %name,
                from,
                "consumers silent for {:?} after the end: publishing the unconsumed frames and the end again",
                RESEND_AFTER
            );
            p.publish_recent_again(from)?;
            if let Some(end) = &p.end_frame {
                p.put_end(end.clone())?;
            }
        }
        Ok(())
    }

    /// Waits until every consumer reports it has finished (so nothing sent is lost on exit).
    /// `repeat_own_done` runs with each resend: the node's own final progress, repeated, since
    /// two nodes of a feedback loop each wait here for the other's, and one lost progress
    /// message (Zenoh drops under congestion) otherwise held both for [`DRAIN_TIMEOUT`] (seen
    /// once in `evseg bench`: planar and background merger, 600 s).
    ///
    /// A consumer that exits during this wait without its final progress having arrived counts
    /// as finished (with a warning): once it is gone nothing can be delivered to it any more,
    /// and whether it ended well is its exit status, which the launcher checks. Seen in `evseg
    /// bench`: the planar segmenter, the feedback consumer of the background merger's last
    /// slice (which it never needs), exited after its final progress was dropped, and the
    /// merger failed the run with "consumer gone".
    ///
    /// A feedback consumer is not kept waiting for (a consumer that may be restarted gets
    /// [`CONSUMER_GRACE`] to come back): it does not linger for its feedback producers (they are
    /// downstream of it and wait here for it, see `Running::linger_until_producers_left`), so
    /// leaving right after its one final progress is its normal way to end, and feedback frame
    /// `k` serves its slice `k + 1`, so the last frame is one it never consumes. Such a consumer
    /// whose token is gone with at most that last frame unconsumed counts as finished at once.
    /// Seen in `evseg bench pipeline` about once in 30 runs: the planar segmenter's single
    /// final progress was lost as it closed its session, and the background merger waited out
    /// the grace time, 3.6 s of work taking 14.7 s.
    fn wait_consumers_done(&self, repeat_own_done: impl Fn()) -> Result<(), RuntimeError> {
        // (consumer node, consumer port, feedback, frames published on the port)
        let mut list: Vec<(String, String, bool, u64)> = self
            .ports
            .iter()
            .flat_map(|(_, p)| {
                p.consumers
                    .iter()
                    .map(|(c, cp, fb)| (c.clone(), cp.clone(), *fb, p.sent))
            })
            .collect();
        let mut exited: Vec<String> = Vec::new();
        let start = Instant::now();
        let mut ok = false;
        while start.elapsed() < DRAIN_TIMEOUT {
            // No watch list: a consumer that left is handled below, whether or not some of its
            // final progress arrived (the book's own "gone" test skips consumers with any).
            // Whether it came true is checked again below, outside the book's lock.
            self.book
                .wait_until(&self.node, &[], Some(RESEND_AFTER), |consumed, alive| {
                    list.iter().all(|(c, cp, feedback, sent)| {
                        let n = consumed.get(&(c.clone(), cp.clone())).copied().unwrap_or(0);
                        n == DONE || (*feedback && feedback_consumer_done(n, *sent, alive.contains(c)))
                    })
                })?;
            let mut i = 0;
            while let Some((c, cp, feedback, sent)) = list.get(i) {
                let n = self.book.consumed(c, cp);
                if n != DONE && *feedback && feedback_consumer_done(n, *sent, self.book.is_alive(c)) {
                    tracing::info!(
                        node = %self.node,
                        consumer = %c,
                        port = %cp,
                        "feedback consumer left with only the last frame unconsumed (one it never \
                         needs) and its final progress not arrived: counted as finished"
                    );
                    let consumer = c.clone();
                    list.remove(i);
                    if !list.iter().any(|(c, ..)| *c == consumer) {
                        exited.push(consumer);
                    }
                } else {
                    i += 1;
                }
            }
            // Again outside the lock: a consumer that came back in between is waited for.
            ok = list.iter().all(|(c, cp, ..)| self.book.consumed(c, cp) == DONE);
            if ok {
                break;
            }
            let mut left: Vec<String> = Vec::new();
            for (c, cp, ..) in &list {
                if self.book.consumed(c, cp) != DONE && self.book.has_left(c) && !left.contains(c) {
                    left.push(c.clone());
                }
            }
            for consumer in left {
                tracing::warn!(
                    node = %self.node,
                    %consumer,
                    "consumer exited before its final progress arrived; counted as finished \
                     (its exit status tells whether it ended well)"
                );
                list.retain(|(c, ..)| *c != consumer);
                exited.push(consumer);
            }
            repeat_own_done();
            self.publish_unfinished_again(&exited)?;
        }
        if !ok {
            tracing::warn!(node = %self.node, "consumers did not finish within {}s", DRAIN_TIMEOUT.as_secs());
        }
        Ok(())
    }
}

impl OutPort {
    /// Publishes again the remembered frames numbered `from` or later (as fresh copies, see
    /// [`fresh_copy`]); returns how many.
    fn publish_recent_again(&self, from: u64) -> Result<usize, RuntimeError> {
        let mut n = 0;
        for (_, bytes) in self.recent.iter().filter(|(s, _)| *s >= from) {
            self.publisher
                .put(fresh_copy(bytes))
                .wait()
                .map_err(|e| RuntimeError::Zenoh(e.to_string()))?;
            n += 1;
        }
        Ok(n)
    }

    /// Publishes an end-of-stream frame (on the blocking publisher in live mode: a dropped end
    /// would leave consumers waiting).
    fn put_end(&self, bytes: Vec<u8>) -> Result<(), RuntimeError> {
        self.end_publisher
            .as_ref()
            .unwrap_or(&self.publisher)
            .put(bytes)
            .wait()
            .map_err(|e| RuntimeError::Zenoh(e.to_string()))
    }
}

/// True when a feedback consumer that has consumed `consumed` of the `sent` frames of a
/// finished producer's port can be counted as finished without its final progress: it has
/// left (`alive` false) and the only frame it may not have consumed is the last, which a
/// feedback consumer never needs (feedback frame `k` serves its slice `k + 1`).
fn feedback_consumer_done(consumed: u64, sent: u64, alive: bool) -> bool {
    !alive && consumed.saturating_add(1) >= sent
}

/// Marks the node's counters as waiting for credit while alive.
struct CreditWait<'a>(&'a Counters);

impl<'a> CreditWait<'a> {
    fn new(c: &'a Counters) -> Self {
        c.waiting_for_credit.store(true, Ordering::Relaxed);
        Self(c)
    }
}

impl Drop for CreditWait<'_> {
    fn drop(&mut self) {
        self.0.waiting_for_credit.store(false, Ordering::Relaxed);
    }
}

/// A heap copy of a frame to publish again. Never the same buffer: a frame in shared memory
/// that a consumer could not read once stays unreadable. Zenoh's shared-memory watchdog marks
/// a buffer invalid for good when a process misses its 100 ms confirmation deadline (a starved
/// process on a loaded machine), and the receiving transport then drops the message with only
/// a debug log; publishing that buffer again would be dropped again every time (seen: a
/// lock-step graph stalled for minutes). A copy is placed in a fresh buffer.
fn fresh_copy(bytes: &ZBytes) -> ZBytes {
    ZBytes::from(bytes.to_bytes().into_owned())
}

/// Lock-step credit rule: frame `seq` may go out when every consumer has consumed more than
/// `seq - window` messages of it (or has finished).
fn has_credit(
    consumed: &HashMap<(String, String), u64>,
    consumers: &[(String, String, bool)],
    seq: u64,
    window: u64,
) -> bool {
    consumers.iter().all(|(c, cp, _)| {
        let n = consumed.get(&(c.clone(), cp.clone())).copied().unwrap_or(0);
        n == DONE || seq < n.saturating_add(window)
    })
}

/// Parsed command line of a node binary.
enum Cli {
    Describe,
    Run(PathBuf),
}

fn parse_cli() -> Result<Cli, RuntimeError> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.as_slice() {
        [a] if a == "--describe" => Ok(Cli::Describe),
        [a, path] if a == "--config" => Ok(Cli::Run(PathBuf::from(path))),
        _ => Err(RuntimeError::Config(
            "usage: <node> --describe | <node> --config <file> (nodes are started by `evseg run`)".into(),
        )),
    }
}

/// The node's log filter (`RUST_LOG`, default `info`), reloadable so that the session's
/// teardown can be quietened ([`quieten_zenoh_teardown`]).
static LOG_FILTER: std::sync::OnceLock<(
    String,
    tracing_subscriber::reload::Handle<tracing_subscriber::EnvFilter, tracing_subscriber::Registry>,
)> = std::sync::OnceLock::new();

fn init_tracing() {
    use tracing_subscriber::layer::SubscriberExt;
    use tracing_subscriber::util::SubscriberInitExt;
    // The directives in force (an unparsable RUST_LOG falls back to `info`), kept so that
    // the teardown's filter extends them.
    let directives = std::env::var("RUST_LOG")
        .ok()
        .filter(|d| tracing_subscriber::EnvFilter::try_new(d).is_ok())
        .unwrap_or_else(|| "info".into());
    let (filter, handle) =
        tracing_subscriber::reload::Layer::new(tracing_subscriber::EnvFilter::new(&directives));
    let initialised = tracing_subscriber::registry()
        .with(filter)
        .with(
            tracing_subscriber::fmt::layer()
                .with_writer(std::io::stderr)
                // Colours only on a terminal: under `evseg run` stderr is the node's log file,
                // which a user reads or greps, and escape codes there are noise.
                .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr())),
        )
        .try_init();
    if initialised.is_ok() {
        let _ = LOG_FILTER.set((directives, handle));
    }
}

/// Turns off the log of Zenoh's session module before the node closes its session: messages
/// that arrive while it closes (other nodes repeating their final progress until this one is
/// gone) are logged there as errors ("Received Data for unknown expr_id"), which said nothing
/// about the run and made finished runs' logs look failed.
fn quieten_zenoh_teardown() {
    if let Some((directives, handle)) = LOG_FILTER.get()
        && let Ok(quiet) =
            tracing_subscriber::EnvFilter::try_new(format!("{directives},zenoh::api::session=off"))
    {
        let _ = handle.reload(quiet);
    }
}

/// How long a finishing node waits for the launcher's stats subscriber to be known before its
/// last stats are sent anyway (only a node run without a launcher waits this long).
const FINAL_STATS_MATCH_WAIT: Duration = Duration::from_secs(2);

/// Shared counters published on the stats key.
#[derive(Default)]
pub(crate) struct Counters {
    pub(crate) received: AtomicU64,
    /// `received` per input port, in the order of the node's inputs.
    pub(crate) received_by_port: Vec<AtomicU64>,
    pub(crate) processed: AtomicU64,
    pub(crate) refused: AtomicU64,
    pub(crate) dropped: AtomicU64,
    pub(crate) missed: AtomicU64,
    pub(crate) last_seq: AtomicU64,
    pub(crate) busy_ns: AtomicU64,
    /// When the node's logic began its current slice (or source step); `None` between them.
    pub(crate) in_slice_since: std::sync::Mutex<Option<Instant>>,
    /// True while a lock-step publish waits for credit (not the node's own work).
    pub(crate) waiting_for_credit: std::sync::atomic::AtomicBool,
}

impl Counters {
    /// Marks the start (`true`) or the end of a slice (or source step) of the node's logic.
    pub(crate) fn mark_slice(&self, started: bool) {
        if let Ok(mut since) = self.in_slice_since.lock() {
            *since = started.then(Instant::now);
        }
    }

    /// Seconds inside the current slice, when the node is computing (in a slice and not
    /// waiting for credit).
    fn computing_s(&self) -> Option<f64> {
        if self.waiting_for_credit.load(Ordering::Relaxed) {
            return None;
        }
        let since = *self.in_slice_since.lock().ok()?;
        since.map(|t| t.elapsed().as_secs_f64())
    }

    /// Counts a data message received on input `port`.
    pub(crate) fn count_receipt(&self, port: usize) {
        self.received.fetch_add(1, Ordering::Relaxed);
        if let Some(c) = self.received_by_port.get(port) {
            c.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// What a node's [`Stats`] are read from, and where they go: shared by the node's loop and its
/// outputs' lock-step wait for credit.
#[derive(Clone)]
struct StatsSource {
    node: String,
    /// The node's input port names, in order.
    ports: Vec<String>,
    session: zenoh::Session,
    key: String,
    counters: Arc<Counters>,
    published: Arc<AtomicU64>,
    /// When the node started (subscriptions declared): [`Stats::up_s`].
    started: Instant,
}

impl StatsSource {
    fn stats(&self, finished: bool) -> Stats {
        let c = &self.counters;
        let last = c.last_seq.load(Ordering::Relaxed);
        Stats {
            node: self.node.clone(),
            received: c.received.load(Ordering::Relaxed),
            received_by_port: self
                .ports
                .iter()
                .zip(&c.received_by_port)
                .map(|(port, n)| (port.clone(), n.load(Ordering::Relaxed)))
                .collect(),
            published: self.published.load(Ordering::Relaxed),
            processed: c.processed.load(Ordering::Relaxed),
            dropped: c.dropped.load(Ordering::Relaxed),
            missed: c.missed.load(Ordering::Relaxed),
            refused: c.refused.load(Ordering::Relaxed),
            last_seq: if last == u64::MAX { None } else { Some(last) },
            busy_s: c.busy_ns.load(Ordering::Relaxed) as f64 * 1e-9,
            finished,
            up_s: self.started.elapsed().as_secs_f64(),
            computing_s: c.computing_s(),
        }
    }

    fn publish(&self, finished: bool) {
        if let Ok(json) = serde_json::to_vec(&self.stats(finished)) {
            // Express: the final stats go out before the session closes, not in a batch.
            let _ = self.session.put(self.key.clone(), json).express(true).wait();
        }
    }
}

pub(crate) struct Running {
    pub(crate) cfg: NodeConfig,
    session: zenoh::Session,
    outputs: Outputs,
    pub(crate) counters: Arc<Counters>,
    schemas: HashMap<String, String>,
    pub(crate) inbox: Arc<Inbox>,
    stats_source: StatsSource,
    /// Set to end the heartbeat thread ([`spawn_heartbeat`]).
    heartbeat: Arc<std::sync::atomic::AtomicBool>,
    _handles: Vec<Box<dyn std::any::Any + Send>>,
    _token: zenoh::liveliness::LivelinessToken,
}

impl Drop for Running {
    /// Closes the session however the node ends (finished, stopped on request, failed), so that
    /// Zenoh's threads are idle when the process exits: a session left open made a node stopped
    /// by the launcher panic now and then in a Zenoh thread while the process tore down its
    /// statics (`static_init` AccessError in `net-0`).
    fn drop(&mut self) {
        self.heartbeat.store(true, Ordering::Relaxed);
        if !self.session.is_closed() {
            quieten_zenoh_teardown();
            let _ = self.session.close().wait();
        }
    }
}

impl Running {
    fn stats(&self, finished: bool) -> Stats {
        self.stats_source.stats(finished)
    }

    fn publish_stats(&self, finished: bool) {
        self.stats_source.publish(finished);
    }

    /// The last stats, once the launcher's subscriber is known to this session (at most
    /// [`FINAL_STATS_MATCH_WAIT`]): a node that runs for a few milliseconds can otherwise finish
    /// before the subscriber's declaration reaches it, and Zenoh drops a put that matches no
    /// known subscriber (seen under load: a run summary without the node's row).
    fn publish_final_stats(&self) {
        let Ok(json) = serde_json::to_vec(&self.stats(true)) else {
            return;
        };
        let Ok(publisher) = self
            .session
            .declare_publisher(self.cfg.stats_key.clone())
            .congestion_control(CongestionControl::Block)
            .express(true)
            .wait()
        else {
            self.publish_stats(true);
            return;
        };
        let deadline = Instant::now() + FINAL_STATS_MATCH_WAIT;
        while Instant::now() < deadline {
            match publisher.matching_status().wait() {
                Ok(m) if !m.matching() => std::thread::sleep(Duration::from_millis(5)),
                _ => break,
            }
        }
        let _ = publisher.put(json).wait();
    }

    pub(crate) fn publish_progress(&self, consumed: Vec<(String, u64)>) -> Result<(), RuntimeError> {
        let p = Progress {
            node: self.cfg.node.clone(),
            consumed,
        };
        let json = serde_json::to_vec(&p).map_err(|e| RuntimeError::Config(e.to_string()))?;
        self.session
            .put(self.cfg.ack_key.clone(), json)
            // Progress is tiny and on the critical path of lock-step credit: never wait in a batch.
            .express(true)
            .wait()
            .map_err(|e| RuntimeError::Zenoh(e.to_string()))
    }

    pub(crate) fn finish(mut self) -> Result<(), RuntimeError> {
        self.outputs.end_all(&self.schemas)?;
        let silent = drop_done_from_env(&self.cfg.node);
        let done: Vec<(String, u64)> = self
            .cfg
            .inputs
            .iter()
            .filter(|i| silent.as_deref() != Some(i.port.as_str()))
            .map(|i| (i.port.clone(), DONE))
            .collect();
        self.publish_progress(done.clone())?;
        self.publish_stats(true);
        self.outputs.wait_consumers_done(|| {
            let _ = self.publish_progress(done.clone());
        })?;
        self.publish_final_stats();
        self.linger_until_producers_left(done);
        quieten_zenoh_teardown();
        let _ = self.session.close().wait();
        Ok(())
    }

    /// Stays until the producers of the node's (non-feedback) inputs have left, repeating the
    /// final progress every [`DONE_REPEAT`], at most [`LINGER_TIMEOUT`]: a producer leaves only
    /// once it knows every consumer finished, and a single progress message sent just before
    /// the session closes can be lost (seen under load while Zenoh peers were still linking
    /// up: the producer then waited for a consumer that had finished). Feedback producers are
    /// left out: they are downstream and wait for this node themselves.
    fn linger_until_producers_left(&self, done: Vec<(String, u64)>) {
        let mut producers: Vec<&str> = self
            .cfg
            .inputs
            .iter()
            .filter(|i| !i.feedback)
            .map(|i| i.producer.as_str())
            .collect();
        producers.sort_unstable();
        producers.dedup();
        let start = Instant::now();
        loop {
            let gone = self
                .outputs
                .book
                .wait_until(&self.cfg.node, &[], Some(DONE_REPEAT), |_, alive| {
                    producers.iter().all(|p| !alive.contains(*p))
                })
                .unwrap_or(true);
            if gone {
                return;
            }
            if start.elapsed() >= LINGER_TIMEOUT {
                tracing::warn!(node = %self.cfg.node, ?producers, "producers still running {}s after this node finished; leaving", LINGER_TIMEOUT.as_secs());
                return;
            }
            let _ = self.publish_progress(done.clone());
        }
    }
}

/// Reads and checks the config. `fixed_ports`: the config's inputs and outputs must be ports of
/// `description` (false only for nodes whose ports are chosen by the launcher: the recorder's
/// inputs, the replay source's outputs, see [`crate::raw`]).
pub(crate) fn load_config(
    description: &NodeDescription,
    path: &std::path::Path,
    fixed_ports: bool,
) -> Result<NodeConfig, RuntimeError> {
    let cfg = NodeConfig::load(path)?;
    if cfg.window == 0 || cfg.queue == 0 {
        return Err(RuntimeError::Config(format!(
            "{}: window and queue must be >= 1",
            path.display()
        )));
    }
    for i in &cfg.inputs {
        if fixed_ports && description.input(&i.port).is_none() {
            return Err(RuntimeError::Config(format!(
                "node {}: config names unknown input `{}`",
                cfg.node, i.port
            )));
        }
    }
    for o in &cfg.outputs {
        if fixed_ports && description.output(&o.port).is_none() {
            return Err(RuntimeError::Config(format!(
                "node {}: config names unknown output `{}`",
                cfg.node, o.port
            )));
        }
    }
    Ok(cfg)
}

/// Opens the node's Zenoh session, its ports, its shared-memory pool and its liveliness token.
pub(crate) fn connect(cfg: NodeConfig) -> Result<Running, RuntimeError> {
    let session = open_session(&cfg.zenoh)?;
    let (book, mut handles) = CreditBook::start(&session, &cfg)?;
    let cc = match cfg.mode {
        Mode::Lockstep => CongestionControl::Block,
        Mode::Live => CongestionControl::Drop,
    };
    let mut ports = Vec::new();
    let mut schemas = HashMap::new();
    for o in &cfg.outputs {
        let publisher = session
            .declare_publisher(o.key.clone())
            .congestion_control(cc)
            // Slices are large and complete when published; batching them only adds latency.
            .express(true)
            .wait()
            .map_err(|e| RuntimeError::Zenoh(e.to_string()))?;
        let end_publisher = match cfg.mode {
            Mode::Lockstep => None,
            Mode::Live => Some(
                session
                    .declare_publisher(o.key.clone())
                    .congestion_control(CongestionControl::Block)
                    .express(true)
                    .wait()
                    .map_err(|e| RuntimeError::Zenoh(e.to_string()))?,
            ),
        };
        let consumers = o
            .consumers
            .iter()
            .map(|c| (c.node.clone(), c.port.clone(), c.feedback))
            .collect();
        schemas.insert(o.port.clone(), o.schema.clone());
        ports.push((
            o.port.clone(),
            OutPort {
                publisher,
                end_publisher,
                consumers,
                recent: std::collections::VecDeque::new(),
                end_frame: None,
                sent: 0,
                t_end: 0.0,
            },
        ));
    }
    let outputs = Outputs {
        node: cfg.node.clone(),
        mode: cfg.mode,
        window: cfg.window,
        ports,
        book,
        consumers_ready: false,
        published: Arc::new(AtomicU64::new(0)),
        waited_ns: 0,
        shm: shm_pool(&session, cfg.zenoh.shared_memory.enabled),
        drop_once: drop_once_from_env(&cfg.node),
        stats_while_blocked: None,
    };
    let counters = Arc::new(Counters {
        last_seq: AtomicU64::new(u64::MAX),
        received_by_port: cfg.inputs.iter().map(|_| AtomicU64::new(0)).collect(),
        ..Counters::default()
    });
    // Input subscribers are declared before the liveliness token, so a producer that sees the
    // token knows its data will be received.
    let bound = match cfg.mode {
        Mode::Lockstep => None,
        Mode::Live => Some(cfg.queue),
    };
    let inbox = Inbox::new(cfg.inputs.len(), bound);
    let deaf = deaf_once_from_env(&cfg.node);
    match &deaf {
        Some(Deaf::All) => {
            tracing::warn!(node = %cfg.node, "input subscriptions not declared ({DEAF_ONCE_ENV})")
        }
        Some(Deaf::Port(port)) => {
            tracing::warn!(node = %cfg.node, %port, "input subscription not declared ({DEAF_ONCE_ENV})")
        }
        None => {}
    }
    if deaf != Some(Deaf::All) {
        let skip = match &deaf {
            Some(Deaf::Port(port)) => Some(port.as_str()),
            _ => None,
        };
        for s in subscribe_inputs(&session, &cfg, &inbox, skip)? {
            handles.push(Box::new(s));
        }
    }
    let token = session
        .liveliness()
        .declare_token(cfg.live_key.clone())
        .wait()
        .map_err(|e| RuntimeError::Zenoh(e.to_string()))?;
    tracing::info!(node = %cfg.node, mode = ?cfg.mode, inputs = cfg.inputs.len(), outputs = cfg.outputs.len(), "started");
    let stats_source = StatsSource {
        node: cfg.node.clone(),
        ports: cfg.inputs.iter().map(|i| i.port.clone()).collect(),
        session: session.clone(),
        key: cfg.stats_key.clone(),
        counters: counters.clone(),
        published: outputs.published.clone(),
        started: Instant::now(),
    };
    let mut outputs = outputs;
    outputs.stats_while_blocked = Some(stats_source.clone());
    let heartbeat = spawn_heartbeat(stats_source.clone());
    Ok(Running {
        cfg,
        session,
        outputs,
        counters,
        schemas,
        inbox,
        stats_source,
        heartbeat,
        _handles: handles,
        _token: token,
    })
}

/// How often a node inside a long slice publishes its stats from [`spawn_heartbeat`]'s thread.
const HEARTBEAT: Duration = Duration::from_secs(1);

/// Starts the thread that publishes the node's stats every [`HEARTBEAT`] while its logic has
/// been inside one slice for longer than that: the node's loop publishes them only between
/// slices, so without it a node computing a long slice looked to the launcher like one waiting
/// for input (a stall message that blamed its inputs). Ends when the returned flag is set.
fn spawn_heartbeat(stats: StatsSource) -> Arc<std::sync::atomic::AtomicBool> {
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = stop.clone();
    let spawned = std::thread::Builder::new()
        .name("evseg-heartbeat".into())
        .spawn(move || {
            let tick = Duration::from_millis(100);
            let mut last = Instant::now();
            while !flag.load(Ordering::Relaxed) {
                std::thread::sleep(tick);
                if last.elapsed() >= HEARTBEAT
                    && stats
                        .counters
                        .computing_s()
                        .is_some_and(|s| s >= HEARTBEAT.as_secs_f64())
                {
                    stats.publish(false);
                    last = Instant::now();
                }
            }
        });
    if let Err(e) = spawned {
        tracing::warn!("no heartbeat thread ({e}): a long slice will not be reported while it runs");
    }
    stop
}

/// Runs a stage node: `--describe` prints `description` as JSON; `--config FILE` runs it.
/// `make` builds the stage from the node config (its parameters). Returns the process exit code.
pub fn run_stage<S: Stage>(
    description: NodeDescription,
    make: impl FnOnce(&NodeConfig) -> Result<S, BoxError>,
) -> std::process::ExitCode {
    main_wrapper(description, true, make, |run, mut stage| {
        stage_loop(run, &mut stage)
    })
}

/// Runs a source node (see [`run_stage`]).
pub fn run_source<S: Source>(
    description: NodeDescription,
    make: impl FnOnce(&NodeConfig) -> Result<S, BoxError>,
) -> std::process::ExitCode {
    main_wrapper(description, true, make, |run, mut source| {
        source_loop(run, &mut source)
    })
}

/// Runs a source whose outputs the launcher chooses (the replay source, `evseg-replay`): like
/// [`run_source`], but the config's outputs need not be ports of `description` (any name, any
/// schema). The source publishes pre-encoded frames with [`Outputs::send_bytes`], checking
/// [`Outputs::credit_available`] first so that it never blocks on one output while another
/// could go; ends of stream are sent on every output when it is exhausted, as for any source.
pub fn run_raw_source<S: Source>(
    description: NodeDescription,
    make: impl FnOnce(&NodeConfig) -> Result<S, BoxError>,
) -> std::process::ExitCode {
    main_wrapper(description, false, make, |run, mut source| {
        source_loop(run, &mut source)
    })
}

/// The `main` of every node binary: `--describe`, or `--config FILE`: reads and checks the
/// config, builds the node's state with `make`, connects ([`connect`]) and runs `body`. The
/// state is built before connecting so that a node's own set-up (reading a recording, baking
/// the simulator's textures, loading weights) overlaps the other nodes' start-up instead of
/// following its own, and a bad parameter stops the node before it joins the network.
pub(crate) fn main_wrapper<T>(
    description: NodeDescription,
    fixed_ports: bool,
    make: impl FnOnce(&NodeConfig) -> Result<T, BoxError>,
    body: impl FnOnce(Running, T) -> Result<(), RuntimeError>,
) -> std::process::ExitCode {
    crate::memory::tune_allocator();
    init_tracing();
    signals::install();
    let cli = match parse_cli() {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{}: {e}", description.binary);
            return std::process::ExitCode::from(2);
        }
    };
    match cli {
        Cli::Describe => match serde_json::to_string_pretty(&description) {
            Ok(s) => {
                use std::io::Write;
                match writeln!(std::io::stdout().lock(), "{s}") {
                    // A reader that stopped early (`--describe | head`) wanted no more.
                    Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
                        eprintln!("{}: cannot write the description: {e}", description.binary);
                        std::process::ExitCode::FAILURE
                    }
                    _ => std::process::ExitCode::SUCCESS,
                }
            }
            Err(e) => {
                eprintln!("{e}");
                std::process::ExitCode::FAILURE
            }
        },
        Cli::Run(path) => {
            let result = load_config(&description, &path, fixed_ports).and_then(|cfg| {
                let made = make(&cfg).map_err(|e| in_node(&cfg.node, e))?;
                body(connect(cfg)?, made)
            });
            let code = match result {
                Ok(()) => {
                    tracing::info!("finished");
                    0
                }
                Err(RuntimeError::Stopped) => {
                    tracing::info!("stopped on request");
                    130
                }
                Err(e) => {
                    tracing::error!("{e}");
                    eprintln!("error: {e}");
                    1
                }
            };
            exit_without_teardown(code)
        }
    }
}

/// Ends a node process that ran with exit status `code`, without the C library's exit
/// handlers. Everything of the node is finished by now (its session closed, its files
/// written and closed; the logs go to unbuffered stderr); what the handlers would still do is
/// tear down Zenoh's lazily created statics (`static_init`) while Zenoh's runtime threads may
/// still touch them. In about 2 of 25 runs stopped at start-up by a bad parameter, a node that
/// was being stopped panicked there ("thread 'net-0' panicked at static_init ... AccessError"),
/// which `evseg run` then reported as a panic of that node.
fn exit_without_teardown(code: u8) -> ! {
    use std::io::Write;
    let _ = std::io::stdout().lock().flush();
    let _ = std::io::stderr().lock().flush();
    // SAFETY: `_exit` ends the process at once; no Rust state is used after it.
    unsafe { libc::_exit(i32::from(code)) }
}

/// When a node's loop last published its stats, and whether they have reported its first
/// input yet ([`maybe_stats`]).
pub(crate) struct StatsClock {
    last: Instant,
    receipt_announced: bool,
}

impl StatsClock {
    /// A clock whose half second starts now.
    pub(crate) fn new() -> Self {
        Self {
            last: Instant::now(),
            receipt_announced: false,
        }
    }
}

/// Publishes the node's stats every half second, and at once when its first input has
/// arrived: the launcher's start-up watchdog restarts a node whose stats say it received
/// nothing, so that news must not wait for the next half-second tick. Called after a loop's
/// drain of its inbox and before it acknowledges anything.
pub(crate) fn maybe_stats(run: &Running, clock: &mut StatsClock) {
    let first_receipt = !clock.receipt_announced && run.counters.received.load(Ordering::Relaxed) > 0;
    clock.receipt_announced |= first_receipt;
    if first_receipt || clock.last.elapsed() >= Duration::from_millis(500) {
        run.publish_stats(false);
        clock.last = Instant::now();
    }
}

fn source_loop<S: Source>(mut run: Running, source: &mut S) -> Result<(), RuntimeError> {
    let mut stats_clock = StatsClock::new();
    loop {
        if signals::stop_requested() {
            return Err(RuntimeError::Stopped);
        }
        let t0 = Instant::now();
        run.counters.mark_slice(true);
        let step = source.step(&mut run.outputs);
        run.counters.mark_slice(false);
        let more = step.map_err(|e| match e.downcast::<RuntimeError>() {
            Ok(rt) => *rt,
            Err(source) => RuntimeError::Logic {
                node: run.cfg.node.clone(),
                seq: run.outputs.published.load(Ordering::Relaxed),
                source,
            },
        })?;
        let waited = run.outputs.take_waited_ns();
        run.counters.busy_ns.fetch_add(
            (t0.elapsed().as_nanos() as u64).saturating_sub(waited),
            Ordering::Relaxed,
        );
        run.counters.processed.fetch_add(1, Ordering::Relaxed);
        maybe_stats(&run, &mut stats_clock);
        if !more {
            break;
        }
    }
    run.finish()
}

fn stage_loop<S: Stage>(mut run: Running, stage: &mut S) -> Result<(), RuntimeError> {
    let inbox = run.inbox.clone();
    let ports: Vec<(String, bool)> = run
        .cfg
        .inputs
        .iter()
        .map(|i| (i.port.clone(), i.feedback))
        .collect();
    let mut joiner = Joiner::new(&ports, run.cfg.mode == Mode::Live);
    let slow_slice = slow_slice_from_env(&run.cfg.node);
    let mut gaps = SeqGaps::new(ports.len());
    let mut stats_clock = StatsClock::new();
    // The last progress published and when (repeated while idle in lock-step mode).
    let mut last_progress: Option<(Vec<(String, u64)>, Instant)> = None;
    loop {
        if signals::stop_requested() {
            return Err(RuntimeError::Stopped);
        }
        if run.cfg.mode == Mode::Lockstep
            && let Some((consumed, at)) = &mut last_progress
            && at.elapsed() >= RESEND_AFTER
        {
            run.publish_progress(consumed.clone())?;
            run.outputs.publish_unconsumed_again()?;
            *at = Instant::now();
        }
        for arrival in inbox.drain(POLL) {
            let binding = &run.cfg.inputs[arrival.port];
            let header = codec::decode_header(&arrival.bytes.as_slice());
            match header {
                Ok((envelope, _))
                    if envelope.schema == binding.schema
                        || envelope.kind == evseg_schemas::FrameKind::End =>
                {
                    if envelope.kind == evseg_schemas::FrameKind::Data {
                        run.counters.count_receipt(arrival.port);
                        gaps.data(arrival.port, envelope.seq);
                    } else {
                        gaps.end(arrival.port, envelope.seq);
                    }
                    joiner.push(
                        arrival.port,
                        RawFrame {
                            envelope,
                            bytes: arrival.bytes,
                        },
                    );
                }
                Ok((envelope, _)) => {
                    run.counters.refused.fetch_add(1, Ordering::Relaxed);
                    let msg = format!(
                        "node {}, input `{}` (key {}): expected {} but received {} v{} from `{}`",
                        run.cfg.node,
                        binding.port,
                        binding.key,
                        binding.schema,
                        envelope.schema,
                        envelope.version,
                        binding.producer
                    );
                    if run.cfg.mode == Mode::Lockstep {
                        return Err(RuntimeError::Config(msg));
                    }
                    tracing::error!("{msg} (message dropped)");
                }
                Err(e) => {
                    run.counters.refused.fetch_add(1, Ordering::Relaxed);
                    let err = RuntimeError::Decode {
                        node: run.cfg.node.clone(),
                        port: binding.port.clone(),
                        key: binding.key.clone(),
                        source: e,
                    };
                    if run.cfg.mode == Mode::Lockstep {
                        return Err(err);
                    }
                    tracing::error!("{err} (message dropped)");
                }
            }
        }
        // Before processing: the launcher learns of the first receipt before this node
        // acknowledges (consumes) anything.
        note_losses(&run, &inbox, joiner.dropped(), &gaps);
        maybe_stats(&run, &mut stats_clock);
        loop {
            let state = joiner
                .poll()
                .map_err(|e| RuntimeError::Config(format!("node {}: {e}", run.cfg.node)))?;
            match state {
                JoinState::Waiting => break,
                JoinState::Finished => {
                    let t0 = Instant::now();
                    run.counters.mark_slice(true);
                    let done = stage.finish(&mut run.outputs);
                    run.counters.mark_slice(false);
                    done.map_err(|e| logic_error(&run, u64::MAX, e))?;
                    let waited = run.outputs.take_waited_ns();
                    run.counters.busy_ns.fetch_add(
                        (t0.elapsed().as_nanos() as u64).saturating_sub(waited),
                        Ordering::Relaxed,
                    );
                    note_losses(&run, &inbox, joiner.dropped(), &gaps);
                    return run.finish();
                }
                JoinState::Ready(joined) => {
                    let t0 = Instant::now();
                    let inputs = Inputs {
                        cfg: &run.cfg,
                        joined: &joined,
                    };
                    run.counters.mark_slice(true);
                    if let Some((seq, extra)) = slow_slice
                        && seq == joined.seq
                    {
                        std::thread::sleep(extra);
                    }
                    let done = stage.process(&inputs, &mut run.outputs);
                    run.counters.mark_slice(false);
                    done.map_err(|e| logic_error(&run, joined.seq, e))?;
                    let waited = run.outputs.take_waited_ns();
                    run.counters.busy_ns.fetch_add(
                        (t0.elapsed().as_nanos() as u64).saturating_sub(waited),
                        Ordering::Relaxed,
                    );
                    run.counters.processed.fetch_add(1, Ordering::Relaxed);
                    run.counters.last_seq.store(joined.seq, Ordering::Relaxed);
                    let consumed = run
                        .cfg
                        .inputs
                        .iter()
                        .map(|i| {
                            (
                                i.port.clone(),
                                if i.feedback { joined.seq } else { joined.seq + 1 },
                            )
                        })
                        .collect::<Vec<_>>();
                    run.publish_progress(consumed.clone())?;
                    last_progress = Some((consumed, Instant::now()));
                }
            }
        }
    }
}

/// Stores the node's loss counters: `dropped` = its own queue overflows plus `joins_dropped`,
/// `missed` = the input messages that never reached its queue (live mode only: in lock-step
/// mode nothing is lost, and a frame published again after a stall arrives out of order). The
/// gaps the loop sees include the queue's own drops, which are therefore taken off.
pub(crate) fn note_losses(run: &Running, inbox: &Inbox, joins_dropped: u64, gaps: &SeqGaps) {
    let queue = inbox.dropped();
    run.counters
        .dropped
        .store(queue + joins_dropped, Ordering::Relaxed);
    if run.cfg.mode == Mode::Live {
        run.counters
            .missed
            .store(gaps.missing().saturating_sub(queue), Ordering::Relaxed);
    }
}

/// A node set-up error `e` as a runtime error naming `node`: a [`RuntimeError::Param`] (which
/// already names it) as it is, anything else prefixed with the node.
pub(crate) fn in_node(node: &str, e: BoxError) -> RuntimeError {
    match e.downcast::<RuntimeError>() {
        Ok(e) if matches!(*e, RuntimeError::Param { .. }) => *e,
        Ok(e) => RuntimeError::Config(format!("node {node}: {e}")),
        Err(e) => RuntimeError::Config(format!("node {node}: {e}")),
    }
}

fn logic_error(run: &Running, seq: u64, e: BoxError) -> RuntimeError {
    match e.downcast::<RuntimeError>() {
        Ok(rt) => *rt,
        Err(source) => RuntimeError::Logic {
            node: run.cfg.node.clone(),
            seq,
            source,
        },
    }
}

#[cfg(test)]
mod credit_tests {
    use super::*;

    #[test]
    fn credit_allows_window_frames_beyond_the_slowest_consumer() {
        let consumers = vec![
            ("a".to_string(), "in".to_string(), false),
            ("b".into(), "x".into(), false),
        ];
        let mut consumed = HashMap::new();
        // Nothing heard yet: the first `window` frames may go.
        assert!(has_credit(&consumed, &consumers, 1, 2));
        assert!(!has_credit(&consumed, &consumers, 2, 2));
        consumed.insert(("a".to_string(), "in".to_string()), 5);
        consumed.insert(("b".to_string(), "x".to_string()), 1);
        assert!(has_credit(&consumed, &consumers, 2, 2));
        assert!(!has_credit(&consumed, &consumers, 3, 2), "b is the slowest");
        consumed.insert(("b".to_string(), "x".to_string()), DONE);
        assert!(has_credit(&consumed, &consumers, 6, 2));
        assert!(!has_credit(&consumed, &consumers, 7, 2));
        assert!(has_credit(&consumed, &[], 99, 1), "no consumer, no wait");
    }
}

#[cfg(test)]
mod set_up_error_tests {
    use super::*;

    #[test]
    fn a_set_up_error_names_the_node_once() {
        let param: BoxError = Box::new(RuntimeError::Param {
            node: "background".into(),
            name: "limit".into(),
            reason: "expected u32".into(),
        });
        assert_eq!(
            in_node("background", param).to_string(),
            "node background: parameter `limit`: expected u32"
        );
        let other: BoxError = "no camera table".into();
        assert_eq!(
            in_node("background", other).to_string(),
            "node background: no camera table"
        );
        let config: BoxError = Box::new(RuntimeError::Config("bad file".into()));
        assert_eq!(
            in_node("background", config).to_string(),
            "node background: bad file"
        );
    }
}
