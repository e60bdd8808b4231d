//! The Zenoh side of a node: the session, the inbox its subscribers fill, and the credit book
//! that makes lock-step runs lossless.

use std::collections::{HashMap, HashSet, VecDeque};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use zenoh::Wait;
use zenoh::sample::SampleKind;

use crate::config::{NodeConfig, ZenohSettings};
use crate::error::RuntimeError;
use crate::join::FrameBytes;
use crate::progress::{DONE, Progress};
use crate::signals;

/// Subscriptions a component keeps alive by holding them.
pub type Handles = Vec<Box<dyn std::any::Any + Send>>;

/// How often blocking waits wake up to check for stop requests and vanished peers.
pub const POLL: Duration = Duration::from_millis(50);

fn zerr(e: impl std::fmt::Display) -> RuntimeError {
    RuntimeError::Zenoh(e.to_string())
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    // A poisoned lock only means another thread panicked while holding it; the data is plain
    // counters and queues, still usable.
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Opens a Zenoh session with the given settings; multicast scouting is off, endpoints are explicit.
pub fn open_session(z: &ZenohSettings) -> Result<zenoh::Session, RuntimeError> {
    let mut config = zenoh::Config::default();
    let list = |v: &[String]| serde_json::to_string(v).unwrap_or_else(|_| "[]".into());
    config
        .insert_json5("mode", &format!("\"{}\"", z.mode))
        .map_err(zerr)?;
    config
        .insert_json5("scouting/multicast/enabled", "false")
        .map_err(zerr)?;
    config
        .insert_json5("connect/endpoints", &list(&z.connect))
        .map_err(zerr)?;
    config
        .insert_json5("listen/endpoints", &list(&z.listen))
        .map_err(zerr)?;
    // Keep retrying the connection to the router for a while instead of failing at once: the
    // launcher may still be binding its port.
    config.insert_json5("connect/timeout_ms", "10000").map_err(zerr)?;
    let shm = &z.shared_memory;
    config
        .insert_json5("transport/shared_memory/enabled", &shm.enabled.to_string())
        .map_err(zerr)?;
    config
        .insert_json5(
            "transport/shared_memory/transport_optimization/enabled",
            &shm.enabled.to_string(),
        )
        .map_err(zerr)?;
    config
        .insert_json5(
            "transport/shared_memory/transport_optimization/pool_size",
            &shm.pool_bytes.max(1).to_string(),
        )
        .map_err(zerr)?;
    config
        .insert_json5("connect/exit_on_failure", "true")
        .map_err(zerr)?;
    zenoh::open(config).wait().map_err(zerr)
}

/// A received frame: which input port, and the raw bytes.
pub struct Arrival {
    /// Index of the input port in the node config.
    pub port: usize,
    /// Encoded frame.
    pub bytes: FrameBytes,
}

#[derive(Default)]
struct InboxState {
    queues: Vec<VecDeque<FrameBytes>>,
    dropped: u64,
}

/// Frames received by the node's subscribers, per port. In live mode each port's queue is
/// bounded and the oldest frame is dropped (and counted) when it overflows.
pub struct Inbox {
    state: Mutex<InboxState>,
    ready: Condvar,
    bound: Option<usize>,
}

impl Inbox {
    /// An inbox for `ports` inputs; `bound` = live-mode queue length, `None` = unbounded.
    pub fn new(ports: usize, bound: Option<usize>) -> Arc<Self> {
        Arc::new(Self {
            state: Mutex::new(InboxState {
                queues: vec![VecDeque::new(); ports],
                dropped: 0,
            }),
            ready: Condvar::new(),
            bound,
        })
    }

    fn push(&self, port: usize, bytes: FrameBytes) {
        let mut s = lock(&self.state);
        if let Some(q) = s.queues.get_mut(port) {
            q.push_back(bytes);
            if let Some(bound) = self.bound
                && q.len() > bound
            {
                q.pop_front();
                s.dropped += 1;
            }
        }
        self.ready.notify_all();
    }

    /// Takes every queued frame, oldest first per port; waits up to `timeout` for one.
    pub fn drain(&self, timeout: Duration) -> Vec<Arrival> {
        let mut s = lock(&self.state);
        if s.queues.iter().all(|q| q.is_empty()) {
            s = self
                .ready
                .wait_timeout(s, timeout)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
        let mut out = Vec::new();
        for (port, q) in s.queues.iter_mut().enumerate() {
            out.extend(q.drain(..).map(|bytes| Arrival { port, bytes }));
        }
        out
    }

    /// Frames dropped so far by queue overflow.
    pub fn dropped(&self) -> u64 {
        lock(&self.state).dropped
    }
}

/// Live mode: counts input messages that never arrived, from gaps in each input port's
/// sequence numbers. Every producer numbers a port's data frames in increasing order from 0 and
/// its end frame carries the count, so a jump from `k` to `k + n` means `n - 1` messages went
/// missing: dropped by the transport under congestion (live-mode publishers never wait), or by
/// the producer itself (a slice it dropped is also missing downstream).
#[derive(Debug, Clone)]
pub struct SeqGaps {
    next: Vec<u64>,
    missing: u64,
}

impl SeqGaps {
    /// Gap counts of `ports` inputs, nothing seen.
    pub fn new(ports: usize) -> Self {
        Self {
            next: vec![0; ports],
            missing: 0,
        }
    }

    /// Notes data frame `seq` on `port` (a late or repeated frame counts nothing).
    pub fn data(&mut self, port: usize, seq: u64) {
        if let Some(next) = self.next.get_mut(port)
            && seq >= *next
        {
            self.missing += seq - *next;
            *next = seq.saturating_add(1);
        }
    }

    /// Notes the end frame on `port`, which says `count` data frames were published.
    pub fn end(&mut self, port: usize, count: u64) {
        if let Some(next) = self.next.get_mut(port)
            && count > *next
        {
            self.missing += count - *next;
            *next = count;
        }
    }

    /// Messages missing so far, all ports.
    pub fn missing(&self) -> u64 {
        self.missing
    }
}

/// Declares one subscriber per input port, each feeding `inbox`; none for `skip_port` (a test
/// hook: [`crate::node::DEAF_ONCE_ENV`]).
pub fn subscribe_inputs(
    session: &zenoh::Session,
    cfg: &NodeConfig,
    inbox: &Arc<Inbox>,
    skip_port: Option<&str>,
) -> Result<Vec<zenoh::pubsub::Subscriber<()>>, RuntimeError> {
    let mut subs = Vec::new();
    for (i, input) in cfg.inputs.iter().enumerate() {
        if skip_port == Some(input.port.as_str()) {
            continue;
        }
        let inbox = inbox.clone();
        let sub = session
            .declare_subscriber(input.key.clone())
            .callback(move |sample| {
                if sample.kind() == SampleKind::Put {
                    inbox.push(i, FrameBytes::from_payload(sample.payload()));
                }
            })
            .wait()
            .map_err(zerr)?;
        subs.push(sub);
    }
    Ok(subs)
}

#[derive(Default)]
struct BookState {
    /// (consumer node, consumer port) -> messages consumed (or DONE).
    consumed: HashMap<(String, String), u64>,
    /// Nodes whose liveliness token is present.
    alive: HashSet<String>,
    /// Nodes whose token has been seen at least once.
    seen: HashSet<String>,
    /// Nodes whose token disappeared, and when.
    gone_since: HashMap<String, Instant>,
}

impl BookState {
    /// True when `node` was alive once and has been gone for longer than [`CONSUMER_GRACE`].
    fn has_left(&self, node: &str) -> bool {
        self.seen.contains(node)
            && !self.alive.contains(node)
            && self
                .gone_since
                .get(node)
                .is_some_and(|t| t.elapsed() > CONSUMER_GRACE)
    }
}

/// How long a consumer may be absent (for example while the launcher restarts it) before a
/// producer waiting for it gives up.
pub const CONSUMER_GRACE: Duration = Duration::from_secs(10);

/// The credit book of a producer: what each consumer of each output has consumed, and who is
/// alive. Lock-step publishing waits here.
pub struct CreditBook {
    state: Mutex<BookState>,
    changed: Condvar,
}

impl CreditBook {
    /// Subscribes to the progress keys of every consumer of `cfg`'s outputs, and to the
    /// instance's liveliness tokens. The returned handles must be kept alive.
    pub fn start(session: &zenoh::Session, cfg: &NodeConfig) -> Result<(Arc<Self>, Handles), RuntimeError> {
        let book = Arc::new(Self {
            state: Mutex::new(BookState::default()),
            changed: Condvar::new(),
        });
        let mut handles: Handles = Vec::new();
        let mut ack_keys: Vec<&str> = cfg
            .outputs
            .iter()
            .flat_map(|o| o.consumers.iter().map(|c| c.ack_key.as_str()))
            .collect();
        ack_keys.sort_unstable();
        ack_keys.dedup();
        for key in ack_keys {
            let b = book.clone();
            let sub = session
                .declare_subscriber(key.to_string())
                .callback(move |sample| {
                    let bytes = sample.payload().to_bytes();
                    if let Ok(p) = serde_json::from_slice::<Progress>(&bytes) {
                        b.record(&p);
                    }
                })
                .wait()
                .map_err(zerr)?;
            handles.push(Box::new(sub));
        }
        let b = book.clone();
        let live_prefix = cfg
            .live_key
            .rsplit_once('/')
            .map(|(p, _)| p.to_string())
            .unwrap_or_default();
        let sub = session
            .liveliness()
            .declare_subscriber(format!("{live_prefix}/*"))
            .history(true)
            .callback(move |sample| {
                let key = sample.key_expr().as_str();
                let node = key.rsplit('/').next().unwrap_or("").to_string();
                let mut s = lock(&b.state);
                if sample.kind() == SampleKind::Put {
                    s.alive.insert(node.clone());
                    s.gone_since.remove(&node);
                    s.seen.insert(node);
                } else {
                    s.alive.remove(&node);
                    s.gone_since.insert(node, Instant::now());
                }
                b.changed.notify_all();
            })
            .wait()
            .map_err(zerr)?;
        handles.push(Box::new(sub));
        Ok((book, handles))
    }

    fn record(&self, p: &Progress) {
        let mut s = lock(&self.state);
        for (port, count) in &p.consumed {
            let e = s.consumed.entry((p.node.clone(), port.clone())).or_insert(0);
            *e = (*e).max(*count);
        }
        self.changed.notify_all();
    }

    /// True when `node` was alive once and has been gone for longer than [`CONSUMER_GRACE`]
    /// (its process ended, or it lost the network for that long).
    pub fn has_left(&self, node: &str) -> bool {
        lock(&self.state).has_left(node)
    }

    /// True when `node`'s liveliness token is present now (false before it first appeared, and
    /// at once, with no [`CONSUMER_GRACE`], after it closed its session or lost its link).
    pub fn is_alive(&self, node: &str) -> bool {
        lock(&self.state).alive.contains(node)
    }

    /// Messages consumed by `node`'s `port` so far (0 when unknown, [`DONE`] when finished).
    pub fn consumed(&self, node: &str, port: &str) -> u64 {
        lock(&self.state)
            .consumed
            .get(&(node.to_string(), port.to_string()))
            .copied()
            .unwrap_or(0)
    }

    /// The fewest messages consumed by any of `consumers` ((node, port, feedback); 0 when
    /// unknown, finished ones left out; `u64::MAX` when all have finished).
    pub fn check_min(&self, consumers: &[(String, String, bool)]) -> u64 {
        let s = lock(&self.state);
        consumers
            .iter()
            .map(|(c, p, _)| s.consumed.get(&(c.clone(), p.clone())).copied().unwrap_or(0))
            .filter(|&n| n != DONE)
            .min()
            .unwrap_or(u64::MAX)
    }

    /// Evaluates `pred` on the consumption counts now, without waiting.
    pub fn check(&self, pred: impl FnOnce(&HashMap<(String, String), u64>) -> bool) -> bool {
        pred(&lock(&self.state).consumed)
    }

    /// Waits until `pred` holds for the book, checking stop requests and vanished consumers.
    /// `watch` names the consumers that must stay alive while waiting (node, output port).
    /// Returns `Ok(false)` on timeout.
    pub fn wait_until(
        &self,
        node: &str,
        watch: &[(String, String)],
        timeout: Option<Duration>,
        mut pred: impl FnMut(&HashMap<(String, String), u64>, &HashSet<String>) -> bool,
    ) -> Result<bool, RuntimeError> {
        let start = Instant::now();
        let mut s = lock(&self.state);
        loop {
            if pred(&s.consumed, &s.alive) {
                return Ok(true);
            }
            if signals::stop_requested() {
                return Err(RuntimeError::Stopped);
            }
            for (consumer, port) in watch {
                if s.has_left(consumer) {
                    let finished = s.consumed.iter().any(|((n, _), c)| n == consumer && *c == DONE);
                    if !finished {
                        return Err(RuntimeError::ConsumerGone {
                            node: node.to_string(),
                            port: port.clone(),
                            consumer: consumer.clone(),
                        });
                    }
                }
            }
            if let Some(t) = timeout
                && start.elapsed() >= t
            {
                return Ok(false);
            }
            s = self
                .changed
                .wait_timeout(s, POLL)
                .map(|(g, _)| g)
                .unwrap_or_else(|p| p.into_inner().0);
        }
    }
}

/// Frames at least this large are written straight into the session's shared-memory pool;
/// smaller ones go through a heap buffer (Zenoh still moves them to shared memory if it finds
/// that worth it). 64 KiB: below it the copy costs less than the pool's bookkeeping.
pub const SHM_DIRECT_MIN_BYTES: usize = 64 * 1024;

/// The session's shared-memory pool (the one Zenoh's transport optimisation uses, sized by
/// [`crate::config::ShmSettings::pool_bytes`]).
pub type ShmPool = Arc<zenoh::shm::ShmProvider<zenoh::shm::PosixShmProviderBackend>>;

/// How long a node waits at start-up for its session's shared-memory pool to be created.
pub const SHM_POOL_WAIT: Duration = Duration::from_secs(2);

/// The session's shared-memory pool, or `None` when shared memory is off or the pool is not
/// ready within [`SHM_POOL_WAIT`] (then every frame goes through the heap; logged).
///
/// Polls the session's provider state instead of waiting on it: Zenoh creates the pool in the
/// background and hands it over through a one-message channel; waiting on that channel would
/// take the message away from the session, whose own transport optimisation (moving smaller
/// frames to shared memory) would then never see the pool ready.
pub fn shm_pool(session: &zenoh::Session, enabled: bool) -> Option<ShmPool> {
    use zenoh::shm::ShmProviderState;
    if !enabled {
        return None;
    }
    let start = Instant::now();
    loop {
        match session.get_shm_provider() {
            ShmProviderState::Ready(pool) => return Some(pool),
            ShmProviderState::Initializing(_) if start.elapsed() < SHM_POOL_WAIT => {
                std::thread::sleep(Duration::from_millis(1));
            }
            state => {
                tracing::warn!(
                    ?state,
                    "shared memory enabled but its pool is not available; large frames go through the heap"
                );
                return None;
            }
        }
    }
}

/// Encodes a frame into a Zenoh payload: a large frame is written once, straight into a
/// shared-memory buffer of `pool` (a consumer on the same machine maps it, a remote one gets
/// it over the socket); otherwise, or when the pool is full at the moment, into a heap buffer.
/// Saves the copy of every large frame that Zenoh's transport would otherwise make into its
/// pool (a quarter of the slicer's time at 100k-event slices).
pub fn encode_payload<T: evseg_schemas::Message>(
    pool: Option<&ShmPool>,
    envelope: &evseg_schemas::codec::Envelope,
    msg: &T,
) -> Result<zenoh::bytes::ZBytes, evseg_schemas::codec::CodecError> {
    use evseg_schemas::codec;
    let len = codec::encoded_len(envelope, Some(msg))?;
    if let Some(pool) = pool
        && len >= SHM_DIRECT_MIN_BYTES
        && let Ok(mut buf) = pool.alloc(len).with_policy::<zenoh::shm::GarbageCollect>().wait()
        && buf.len() == len
    {
        codec::encode_into_slice(envelope, Some(msg), &mut buf)?;
        return Ok(zenoh::bytes::ZBytes::from(buf));
    }
    Ok(zenoh::bytes::ZBytes::from(codec::encode_with(
        envelope,
        Some(msg),
    )?))
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::codec;
    use evseg_schemas::{EventPacket, Events};

    #[test]
    fn gaps_count_what_never_arrived_including_a_lost_start_and_end() {
        let mut g = SeqGaps::new(2);
        g.data(0, 2); // 0 and 1 lost
        g.data(0, 3);
        g.data(0, 3); // a repeat counts nothing
        g.data(0, 6); // 4 and 5 lost
        g.data(0, 5); // late: nothing
        g.data(1, 0);
        g.end(1, 1);
        assert_eq!(g.missing(), 4);
        g.end(0, 9); // 7 and 8 never came
        assert_eq!(g.missing(), 6);
    }

    fn packet(n: usize) -> EventPacket {
        let mut events = Events::with_capacity(n);
        for i in 0..n {
            events.push(i as f64 * 1e-6, (i % 640) as u16, (i % 480) as u16, (i % 2) as u8);
        }
        EventPacket {
            camera: evseg_schemas::CameraInfo::pinhole(640, 480, 320.0, "test"),
            events,
            imu: vec![],
        }
    }

    fn session(shm: bool) -> zenoh::Session {
        let settings = ZenohSettings {
            mode: "peer".into(),
            connect: vec![],
            listen: vec![],
            shared_memory: crate::config::ShmSettings {
                enabled: shm,
                pool_bytes: 8 << 20,
            },
        };
        open_session(&settings).unwrap()
    }

    #[test]
    fn large_frames_are_encoded_into_shared_memory_small_ones_on_the_heap() {
        let s = session(true);
        let pool = shm_pool(&s, true);
        assert!(pool.is_some(), "shared memory was enabled");
        for (n, in_shm) in [(20_000, true), (100, false)] {
            let p = packet(n);
            let env = codec::data_envelope::<EventPacket>(1, 0.0, 1.0);
            let payload = encode_payload(pool.as_ref(), &env, &p).unwrap();
            assert_eq!(payload.as_shm().is_some(), in_shm, "{n} events");
            let bytes = payload.to_bytes();
            assert_eq!(&bytes[..], &codec::encode_with(&env, Some(&p)).unwrap()[..]);
            assert_eq!(codec::decode::<EventPacket>(&bytes).unwrap().body.unwrap(), p);
        }
    }

    #[test]
    fn a_frame_larger_than_the_pool_falls_back_to_the_heap() {
        let s = session(true);
        let pool = shm_pool(&s, true);
        // 13 bytes per event: 1M events do not fit an 8 MiB pool.
        let p = packet(1_000_000);
        let env = codec::data_envelope::<EventPacket>(0, 0.0, 1.0);
        let payload = encode_payload(pool.as_ref(), &env, &p).unwrap();
        assert!(payload.as_shm().is_none());
        assert_eq!(
            codec::decode::<EventPacket>(&payload.to_bytes())
                .unwrap()
                .body
                .unwrap(),
            p
        );
    }

    #[test]
    fn taking_the_pool_leaves_it_ready_for_the_session_itself() {
        let s = session(true);
        assert!(shm_pool(&s, true).is_some());
        // Zenoh's transport asks for the same pool; it must see it ready, not initializing.
        assert!(matches!(
            s.get_shm_provider(),
            zenoh::shm::ShmProviderState::Ready(_)
        ));
    }

    #[test]
    fn without_shared_memory_there_is_no_pool() {
        let s = session(false);
        assert!(shm_pool(&s, false).is_none());
    }
}
