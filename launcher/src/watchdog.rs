//! Keeping a run from waiting forever.
//!
//! Twice a lock-step run hung at start-up (once in `evseg run`, once in a CI test): one node
//! (the background merger) logged "started" and never received a frame, while every producer
//! published its unconsumed frames again each second; no process failed, so nothing ended the
//! run. The node's subscriptions had most likely never reached its producers' sessions (Zenoh
//! drops a put that matches no subscriber it knows of). Two rules, checked by the launcher from
//! the nodes' stats:
//!
//! - **start-up**: a node of this machine that is up (its stats arrive) and has received nothing
//!   while a producer of one of its (non-feedback) inputs has published for
//!   [`WatchdogSettings::startup`] is restarted: its new session declares its subscriptions
//!   afresh, and lock-step producers publish what it has not consumed again. Nothing is lost: it
//!   had consumed nothing (a node publishes its stats as soon as its first input arrives, before
//!   it acknowledges it). After [`WatchdogSettings::startup_restarts`] such restarts the run
//!   stops, naming the node. A node whose stats have not arrived yet is not judged: it may
//!   still be starting (seen in CI: a debug-build slicer on a loaded 2-core machine restarted
//!   after a 3 s limit before its first stats, having in fact consumed frames; the run then
//!   waited forever). After a restart, the previous process's last stats (told apart by
//!   [`Stats::up_s`]) are not judged either.
//! - **start-up, one input missing** (lock-step only): a node of this machine that is up and
//!   has processed nothing while *every* producer of its (non-feedback) inputs has published
//!   for twice [`WatchdogSettings::startup`] is restarted the same way (the same restart
//!   count). A lock-step node that has every input of its first slice processes it at once, so
//!   one of its subscriptions never reached its producer; it may have received its other
//!   inputs, which the first rule cannot tell from progress. Seen twice in about 136 runs of
//!   `evseg bench pipeline`: the evaluator (or six consumers) never received the slicer's
//!   frames while they received the other producers' (`docs/speed-history.md`, session 40).
//!   Nothing is lost here either: a node acknowledges a frame only once it has processed it.
//!   Twice the limit leaves room for a slow first slice in a debug build; a node whose
//!   heartbeat says it is computing ([`Stats::computing_s`]) is not judged by this rule. A producer whose
//!   own stats have not arrived (or are stale) counts as having published when a node
//!   downstream of it has published, since no lock-step node publishes before all of its
//!   inputs' producers have (in both stalls the launcher had the slicer's stats from before
//!   it blocked waiting for credit, "published 0": a blocked producer sent none until
//!   2026-12-07, and a stats message can still be lost).
//! - **stall**: when no node's published, processed or finished counters change for
//!   [`WatchdogSettings::stall`], the run stops with every node's counters, instead of waiting
//!   forever. In live mode only once every source has finished (before that a source may
//!   idle: a camera with nothing to see); a live run hung that way about once in six when a
//!   slow stage ended on a slice another input had lost (fixed in the joiner since). Receipts
//!   do not count: a stalled lock-step graph keeps receiving the duplicates its idle producers
//!   publish again each second. A node whose heartbeat says it
//!   has been computing one slice ([`Stats::computing_s`]) is named as busy, not as waiting.

use std::collections::{BTreeMap, BTreeSet};
use std::time::{Duration, Instant};

use evseg_graph::NodeSpec;
use evseg_runtime::progress::Stats;

/// Default [`WatchdogSettings::startup`], seconds.
pub const DEFAULT_STARTUP_S: f64 = 20.0;
/// Default [`WatchdogSettings::stall`], seconds.
pub const DEFAULT_STALL_S: f64 = 120.0;

/// When the launcher intervenes. `None` turns a rule off.
#[derive(Debug, Clone, Copy)]
pub struct WatchdogSettings {
    /// How long a node may go without any input while its producers publish (default 20 s:
    /// a node receives its first frame within a second of its producer's first publication
    /// when the transport works, even in debug builds on a loaded 2-core machine).
    pub startup: Option<Duration>,
    /// The second start-up rule (a lock-step node with every input's producer publishing that
    /// has processed nothing) waits twice this.
    /// Start-up restarts per node before the run is stopped (default 2).
    pub startup_restarts: u32,
    /// How long a lock-step run may go with no counter of any node changing (default 120 s:
    /// far above the slowest slice of any stage seen, a few seconds in debug builds).
    pub stall: Option<Duration>,
}

impl Default for WatchdogSettings {
    fn default() -> Self {
        Self {
            startup: Some(Duration::from_secs_f64(DEFAULT_STARTUP_S)),
            startup_restarts: 2,
            stall: Some(Duration::from_secs_f64(DEFAULT_STALL_S)),
        }
    }
}

impl WatchdogSettings {
    /// Settings from command-line seconds (0 = rule off).
    pub fn from_seconds(startup_s: f64, stall_s: f64) -> anyhow::Result<Self> {
        let rule = |s: f64, what: &str| -> anyhow::Result<Option<Duration>> {
            if !s.is_finite() || s < 0.0 {
                anyhow::bail!("{what} must be a number of seconds >= 0 (0 = off), got {s}");
            }
            Ok((s > 0.0).then(|| Duration::from_secs_f64(s)))
        };
        Ok(Self {
            startup: rule(startup_s, "--startup-timeout")?,
            stall: rule(stall_s, "--stall-timeout")?,
            ..Self::default()
        })
    }
}

/// What the launcher must do.
#[derive(Debug, PartialEq)]
pub enum Action {
    /// Restart this node (of this machine); `why` is for the user.
    Restart { node: String, why: String },
    /// Stop the run with this message.
    Stop(String),
    /// Stop the run: `node` (of this machine) still starves after its start-up restarts; `why`
    /// is for the user (the launcher adds the last lines of the node's log).
    GiveUp { node: String, why: String },
}

/// The watchdog's memory between checks.
pub struct Watchdog {
    settings: WatchdogSettings,
    /// Node -> since when a start-up rule has held for it, and which.
    starving_since: BTreeMap<String, (Instant, Starving)>,
    /// Start-up restarts done per node.
    restarts: BTreeMap<String, u32>,
    /// Node -> its [`Stats::up_s`] when it was restarted: stats that old or older are its
    /// previous process's.
    restarted_up_s: BTreeMap<String, f64>,
    /// The counters last seen, and when they last changed.
    last_counters: Vec<(String, [u64; 3])>,
    last_change: Instant,
}

impl Watchdog {
    /// A watchdog whose clock starts at `now`.
    pub fn new(settings: WatchdogSettings, now: Instant) -> Self {
        Self {
            settings,
            starving_since: BTreeMap::new(),
            restarts: BTreeMap::new(),
            restarted_up_s: BTreeMap::new(),
            last_counters: Vec::new(),
            last_change: now,
        }
    }

    /// Checks the rules at `now`. `nodes`: every node of the graph; `running_here`: true for the
    /// nodes this launcher started that still run; `stats`: the nodes' last stats;
    /// `lockstep`: the graph's mode. A node without stats is left alone by the start-up rule
    /// (it may still be starting, or be a foreign node that publishes none); the stall rule
    /// still ends a lock-step run that waits for it forever.
    pub fn check(
        &mut self,
        now: Instant,
        nodes: &[NodeSpec],
        running_here: &dyn Fn(&str) -> bool,
        stats: &BTreeMap<String, Stats>,
        lockstep: bool,
    ) -> Vec<Action> {
        let mut actions = Vec::new();
        if let Some(limit) = self.settings.startup {
            let published = published_nodes(nodes, stats);
            let seen = Seen {
                stats,
                published: &published,
                lockstep,
            };
            for node in nodes {
                if let Some(a) = self.check_startup(now, limit, node, running_here, &seen) {
                    actions.push(a);
                }
            }
        }
        if actions.iter().any(|a| matches!(a, Action::Restart { .. })) {
            self.last_change = now;
        }
        let counters: Vec<(String, [u64; 3])> = stats
            .iter()
            .map(|(id, s)| (id.clone(), [s.published, s.processed, u64::from(s.finished)]))
            .collect();
        if counters != self.last_counters {
            self.last_counters = counters;
            self.last_change = now;
        }
        // Live mode: a source may idle (a camera with nothing to see), so only once every
        // source has finished can nothing more come.
        let sources_done = || {
            nodes
                .iter()
                .filter(|n| n.inputs.iter().all(|i| i.feedback))
                .all(|n| stats.get(&n.id).is_some_and(|s| s.finished))
        };
        if (lockstep || sources_done())
            && let Some(limit) = self.settings.stall
            && now.duration_since(self.last_change) >= limit
        {
            actions.push(Action::Stop(stall_message(limit, nodes, stats, lockstep)));
        }
        actions
    }

    fn check_startup(
        &mut self,
        now: Instant,
        limit: Duration,
        node: &NodeSpec,
        running_here: &dyn Fn(&str) -> bool,
        seen: &Seen,
    ) -> Option<Action> {
        let id = node.id.as_str();
        let mut producers: Vec<&str> = node
            .inputs
            .iter()
            .filter(|i| !i.feedback)
            .map(|i| i.from_node.as_str())
            .collect();
        producers.sort_unstable();
        producers.dedup();
        let Some(own) = seen.stats.get(id) else {
            self.starving_since.remove(id);
            return None;
        };
        if let Some(&before) = self.restarted_up_s.get(id) {
            if own.up_s >= before {
                // The previous process's last stats: the new one is not up yet.
                self.starving_since.remove(id);
                return None;
            }
            self.restarted_up_s.remove(id);
        }
        let fed: Vec<&str> = producers
            .iter()
            .copied()
            .filter(|p| seen.published.contains(*p))
            .collect();
        // A node known to have published has consumed input, whatever its (possibly stale)
        // stats say: restarting it would lose what it consumed.
        let starving = if !running_here(id) || fed.is_empty() || seen.published.contains(id) {
            None
        } else if own.received == 0 {
            Some(Starving::NothingReceived)
        } else if seen.lockstep
            && own.processed == 0
            && fed.len() == producers.len()
            && own.computing_s.is_none()
        {
            // (A node whose heartbeat says it is computing has its first slice: it is busy,
            // not missing an input; restarting it would only start that slice again.)
            Some(Starving::NothingProcessed)
        } else {
            None
        };
        let Some(starving) = starving else {
            self.starving_since.remove(id);
            return None;
        };
        let since = match self.starving_since.get(id) {
            Some(&(t, kind)) if kind == starving => t,
            _ => {
                self.starving_since.insert(id.to_string(), (now, starving));
                now
            }
        };
        let waited = now.duration_since(since);
        let limit = match starving {
            Starving::NothingReceived => limit,
            Starving::NothingProcessed => limit * 2,
        };
        if waited < limit {
            return None;
        }
        let done = self.restarts.entry(id.to_string()).or_insert(0);
        let secs = waited.as_secs_f64();
        let (why, cause) = match starving {
            Starving::NothingReceived => (
                format!(
                    "node `{id}` received nothing in {secs:.0} s while {} published",
                    fed.join(", ")
                ),
                "its subscriptions never reached its producers",
            ),
            Starving::NothingProcessed => (
                format!(
                    "node `{id}` processed nothing in {secs:.0} s although every producer of its \
                     inputs ({}) has published{}",
                    fed.join(", "),
                    silent_inputs(own)
                ),
                "one of its subscriptions never reached its producer",
            ),
        };
        if *done >= self.settings.startup_restarts {
            return Some(Action::GiveUp {
                node: id.to_string(),
                why: format!("{why}, after {done} restart(s); {cause}"),
            });
        }
        *done += 1;
        self.starving_since.remove(id);
        self.restarted_up_s.insert(id.to_string(), own.up_s);
        Some(Action::Restart {
            node: id.to_string(),
            why: format!("{why}; restarting it (start-up restart {done})"),
        })
    }
}

/// Which start-up rule holds for a node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Starving {
    /// It has received nothing while a producer of its inputs has published.
    NothingReceived,
    /// Lock-step: it has processed nothing while every producer of its inputs has published.
    NothingProcessed,
}

/// What the start-up rules read of the run at one check.
struct Seen<'a> {
    stats: &'a BTreeMap<String, Stats>,
    /// [`published_nodes`].
    published: &'a BTreeSet<String>,
    lockstep: bool,
}

/// The nodes known to have published: those whose stats say so, and every producer of a
/// (non-feedback) input of such a node, transitively (a node publishes a slice only once it
/// has that slice of every such input, so its producers published first, whatever their own
/// stats, which may be late or lost, say).
fn published_nodes(nodes: &[NodeSpec], stats: &BTreeMap<String, Stats>) -> BTreeSet<String> {
    let mut published: BTreeSet<String> = stats
        .iter()
        .filter(|(_, s)| s.published > 0)
        .map(|(id, _)| id.clone())
        .collect();
    loop {
        let before = published.len();
        let upstream: Vec<String> = nodes
            .iter()
            .filter(|n| published.contains(&n.id))
            .flat_map(|n| n.inputs.iter().filter(|i| !i.feedback))
            .map(|i| i.from_node.clone())
            .collect();
        published.extend(upstream);
        if published.len() == before {
            return published;
        }
    }
}

/// `", nothing received on `a`, `b`"` for the input ports of `s` that have received nothing
/// while others have; empty when none (or the node does not count per port).
fn silent_inputs(s: &Stats) -> String {
    let silent: Vec<String> = s
        .received_by_port
        .iter()
        .filter(|&(_, &n)| n == 0)
        .map(|(port, _)| format!("`{port}`"))
        .collect();
    if silent.is_empty() || silent.len() == s.received_by_port.len() {
        String::new()
    } else {
        format!(", nothing received on {}", silent.join(", "))
    }
}

/// The message of a stalled run: every node's counters.
fn stall_message(
    limit: Duration,
    nodes: &[NodeSpec],
    stats: &BTreeMap<String, Stats>,
    lockstep: bool,
) -> String {
    let what = if lockstep {
        "lock-step run stalled"
    } else {
        "live run stalled after its sources finished"
    };
    let computing: Vec<String> = nodes
        .iter()
        .filter_map(|n| {
            let s = stats.get(&n.id)?;
            s.computing_s
                .map(|c| format!("`{}` has been computing one slice for {c:.0} s", n.id))
        })
        .collect();
    let mut text = if computing.is_empty() {
        format!(
            "no node made progress for {:.0} s ({what}); counters per node:",
            limit.as_secs_f64()
        )
    } else {
        format!(
            "no node made progress for {:.0} s: {} (busy, not waiting for input; if a slice \
             of this configuration can take that long, raise --stall-timeout); counters per node:",
            limit.as_secs_f64(),
            computing.join(", ")
        )
    };
    for n in nodes {
        let line = match stats.get(&n.id) {
            Some(s) => format!(
                "received {}, published {}, processed {}, last seq {}{}{}",
                s.received,
                s.published,
                s.processed,
                s.last_seq.map_or("-".into(), |q| q.to_string()),
                if s.finished { ", finished" } else { "" },
                match s.computing_s {
                    Some(c) => format!(", computing a slice for {c:.0} s"),
                    None => silent_inputs(s),
                }
            ),
            None => "no stats received".into(),
        };
        text += &format!("\n  {}: {line}", n.id);
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(id: &str, from: &[(&str, bool)]) -> NodeSpec {
        serde_json::from_value(serde_json::json!({
            "id": id, "binary": "x", "machine": "local", "params": {},
            "inputs": from.iter().enumerate().map(|(k, (p, fb))| serde_json::json!({
                "port": format!("in{k}"), "schema": "s", "from_node": p, "from_output": "o",
                "feedback": fb})).collect::<Vec<_>>(),
            "outputs": [], "restart": {"policy": "never", "max": 3},
        }))
        .unwrap()
    }

    fn stats(id: &str, received: u64, published: u64) -> (String, Stats) {
        (
            id.to_string(),
            Stats {
                node: id.to_string(),
                received,
                published,
                ..Stats::default()
            },
        )
    }

    fn settings() -> WatchdogSettings {
        WatchdogSettings {
            startup: Some(Duration::from_secs(20)),
            startup_restarts: 1,
            stall: Some(Duration::from_secs(120)),
        }
    }

    fn up(id: &str, received: u64, up_s: f64) -> Stats {
        Stats {
            up_s,
            ..stats(id, received, 0).1
        }
    }

    #[test]
    fn a_node_fed_but_receiving_nothing_is_restarted_then_the_run_stopped() {
        let nodes = [node("src", &[]), node("a", &[("src", false)])];
        let t0 = Instant::now();
        let mut w = Watchdog::new(settings(), t0);
        let all = |_: &str| true;
        let mut st: BTreeMap<String, Stats> = [stats("src", 0, 0)].into();
        st.insert("a".into(), up("a", 0, 1.0));
        // Nothing published yet: no waiting starts.
        assert!(
            w.check(t0 + Duration::from_secs(30), &nodes, &all, &st, true)
                .is_empty()
        );
        st.insert("src".into(), stats("src", 0, 3).1);
        let t1 = t0 + Duration::from_secs(31);
        assert!(w.check(t1, &nodes, &all, &st, true).is_empty());
        assert!(
            w.check(t1 + Duration::from_secs(19), &nodes, &all, &st, true)
                .is_empty()
        );
        st.insert("a".into(), up("a", 0, 50.0));
        let a = w.check(t1 + Duration::from_secs(20), &nodes, &all, &st, true);
        assert!(
            matches!(&a[..], [Action::Restart { node, why }] if node == "a" && why.contains("src published")),
            "{a:?}"
        );
        // The previous process's last stats (up 50 s) do not start the clock again.
        let t2 = t1 + Duration::from_secs(20);
        assert!(
            w.check(t2 + Duration::from_secs(100), &nodes, &all, &st, true)
                .is_empty()
        );
        // The new process is up: it gets its own 20 s; then the run stops.
        st.insert("a".into(), up("a", 0, 0.5));
        let t3 = t2 + Duration::from_secs(101);
        assert!(w.check(t3, &nodes, &all, &st, true).is_empty());
        st.insert("a".into(), up("a", 0, 10.5));
        assert!(
            w.check(t3 + Duration::from_secs(10), &nodes, &all, &st, true)
                .is_empty()
        );
        let a = w.check(t3 + Duration::from_secs(20), &nodes, &all, &st, true);
        assert!(
            // (the stall rule fires too: nothing was published for 120 s)
            matches!(&a[..], [Action::GiveUp { node, why: m }, ..] if node == "a" && m.contains("`a`") && m.contains("1 restart")),
            "{a:?}"
        );
    }

    /// The CI failure this guards against: a node still starting (no stats yet) was restarted
    /// although it was about to consume its first frames.
    #[test]
    fn a_node_whose_stats_have_not_arrived_is_not_restarted() {
        let nodes = [node("src", &[]), node("a", &[("src", false)])];
        let t0 = Instant::now();
        let mut w = Watchdog::new(settings(), t0);
        let all = |_: &str| true;
        let mut st: BTreeMap<String, Stats> = [stats("src", 0, 7)].into();
        assert!(w.check(t0, &nodes, &all, &st, true).is_empty());
        assert!(
            w.check(t0 + Duration::from_secs(60), &nodes, &all, &st, true)
                .is_empty(),
            "no stats: not judged"
        );
        // Up at last, with nothing received: its 20 s start now, not at t0.
        st.insert("a".into(), up("a", 0, 0.5));
        let t1 = t0 + Duration::from_secs(61);
        assert!(w.check(t1, &nodes, &all, &st, true).is_empty());
        assert!(
            w.check(t1 + Duration::from_secs(19), &nodes, &all, &st, true)
                .is_empty()
        );
        assert!(matches!(
            &w.check(t1 + Duration::from_secs(20), &nodes, &all, &st, true)[..],
            [Action::Restart { .. }]
        ));
    }

    #[test]
    fn receiving_feedback_only_other_machines_and_live_nodes_without_stats_are_left_alone() {
        let nodes = [
            node("src", &[]),
            node("a", &[("src", false)]),
            node("b", &[("src", true)]),
        ];
        let t0 = Instant::now();
        let later = t0 + Duration::from_secs(100);
        let all = |_: &str| true;
        let mut progressing = stats("a", 1, 0);
        progressing.1.processed = 1;
        let fed: BTreeMap<String, Stats> = [stats("src", 0, 5), progressing, stats("b", 0, 0)].into();
        let mut w = Watchdog::new(settings(), t0);
        w.check(t0, &nodes, &all, &fed, true);
        assert!(
            w.check(later, &nodes, &all, &fed, true).is_empty(),
            "a received and processed, b is feedback only"
        );
        let starving: BTreeMap<String, Stats> = [stats("src", 0, 5), stats("a", 0, 0)].into();
        let not_here = |id: &str| id != "a";
        let mut w = Watchdog::new(settings(), t0);
        w.check(t0, &nodes, &not_here, &starving, true);
        assert!(
            w.check(later, &nodes, &not_here, &starving, true).is_empty(),
            "a runs elsewhere"
        );
        let no_stats: BTreeMap<String, Stats> = [stats("src", 0, 5)].into();
        let mut w = Watchdog::new(settings(), t0);
        w.check(t0, &nodes, &all, &no_stats, false);
        assert!(
            w.check(later, &nodes, &all, &no_stats, false).is_empty(),
            "live, no stats"
        );
    }

    /// Live mode: a run whose sources still run may idle; once they have all finished, a run
    /// in which nothing changes for the stall limit is stopped.
    #[test]
    fn a_live_run_stalls_only_after_its_sources_finished() {
        let nodes = [node("src", &[]), node("a", &[("src", false)])];
        let t0 = Instant::now();
        let all = |_: &str| true;
        let mut st: BTreeMap<String, Stats> = [stats("src", 0, 5), stats("a", 5, 3)].into();
        let mut w = Watchdog::new(settings(), t0);
        assert!(w.check(t0, &nodes, &all, &st, false).is_empty());
        let late = t0 + Duration::from_secs(500);
        assert!(
            w.check(late, &nodes, &all, &st, false).is_empty(),
            "the source may idle"
        );
        st.get_mut("src").unwrap().finished = true;
        // Finishing is a change: the clock starts again.
        let t1 = late + Duration::from_secs(1);
        assert!(w.check(t1, &nodes, &all, &st, false).is_empty());
        let a = w.check(t1 + Duration::from_secs(120), &nodes, &all, &st, false);
        assert!(
            matches!(&a[..], [Action::Stop(m)] if m.contains("live run stalled after its sources finished")),
            "{a:?}"
        );
    }

    /// The stalls of `evseg bench pipeline` (session 40): the evaluator received the tracker's
    /// frames but never the slicer's, and the slicer's stats had stopped reaching the launcher
    /// (it looked as if it had published nothing) while the flow, downstream of it, published.
    #[test]
    fn a_lockstep_node_with_every_producer_publishing_that_processes_nothing_is_restarted() {
        let nodes = [
            node("src", &[]),
            node("slicer", &[("src", false)]),
            node("flow", &[("slicer", false)]),
            node("eval", &[("slicer", false), ("flow", false), ("eval", true)]),
        ];
        let t0 = Instant::now();
        let all = |_: &str| true;
        let mut eval = up("eval", 40, 1.0);
        eval.received_by_port = [("in0".to_string(), 40), ("in1".to_string(), 0)].into();
        let st: BTreeMap<String, Stats> = [
            stats("slicer", 1, 0),
            stats("flow", 4, 3),
            ("eval".to_string(), eval.clone()),
        ]
        .into();
        let mut w = Watchdog::new(settings(), t0);
        assert!(w.check(t0, &nodes, &all, &st, true).is_empty());
        assert!(
            w.check(t0 + Duration::from_secs(39), &nodes, &all, &st, true)
                .is_empty(),
            "twice the start-up limit"
        );
        let a = w.check(t0 + Duration::from_secs(40), &nodes, &all, &st, true);
        assert!(
            matches!(&a[..], [Action::Restart { node, why }]
                if node == "eval" && why.contains("processed nothing") && why.contains("flow, slicer")
                    && why.contains("nothing received on `in1`")),
            "{a:?}"
        );
        // Not while a producer has not published yet (the flow still on its first slice), not
        // in live mode (a live node may drop what it cannot join), and not once it processed.
        let waiting: BTreeMap<String, Stats> = [
            stats("slicer", 1, 2),
            stats("flow", 4, 0),
            ("eval".to_string(), eval.clone()),
        ]
        .into();
        let mut w = Watchdog::new(settings(), t0);
        w.check(t0, &nodes, &all, &waiting, true);
        let a = w.check(t0 + Duration::from_secs(100), &nodes, &all, &waiting, true);
        assert!(
            !a.iter()
                .any(|a| matches!(a, Action::Restart { node, .. } if node == "eval")),
            "{a:?}"
        );
        let mut w = Watchdog::new(settings(), t0);
        w.check(t0, &nodes, &all, &st, false);
        assert!(
            w.check(t0 + Duration::from_secs(100), &nodes, &all, &st, false)
                .is_empty()
        );
        // Not while its heartbeat says it is computing its first slice (a slow parameter).
        let mut busy = st.clone();
        if let Some(e) = busy.get_mut("eval") {
            e.computing_s = Some(35.0);
        }
        let mut w = Watchdog::new(settings(), t0);
        w.check(t0, &nodes, &all, &busy, true);
        assert!(
            w.check(t0 + Duration::from_secs(100), &nodes, &all, &busy, true)
                .is_empty()
        );
        let mut done = st.clone();
        if let Some(e) = done.get_mut("eval") {
            e.processed = 1;
        }
        let mut w = Watchdog::new(settings(), t0);
        w.check(t0, &nodes, &all, &done, true);
        assert!(
            w.check(t0 + Duration::from_secs(100), &nodes, &all, &done, true)
                .is_empty()
        );
    }

    /// The inputs a waiting node never received are named; none when all or none arrived, or
    /// when the node does not count per port.
    #[test]
    fn the_inputs_that_never_arrived_are_named() {
        let mut s = stats("a", 5, 0).1;
        assert_eq!(silent_inputs(&s), "");
        s.received_by_port = [("slices".into(), 0), ("truth".into(), 5), ("tracks".into(), 0)].into();
        assert_eq!(silent_inputs(&s), ", nothing received on `slices`, `tracks`");
        s.received_by_port = [("slices".into(), 0), ("truth".into(), 0)].into();
        assert_eq!(silent_inputs(&s), "", "nothing at all: the first rule's case");
    }

    #[test]
    fn a_producer_counts_as_published_when_a_node_downstream_of_it_has() {
        let nodes = [
            node("src", &[]),
            node("slicer", &[("src", false)]),
            node("flow", &[("slicer", false), ("back", true)]),
            node("back", &[("flow", false)]),
        ];
        let st: BTreeMap<String, Stats> = [stats("flow", 1, 2), stats("back", 0, 0)].into();
        let p = published_nodes(&nodes, &st);
        assert_eq!(
            p.into_iter().collect::<Vec<_>>(),
            ["flow", "slicer", "src"],
            "not `back`: feedback"
        );
    }

    #[test]
    fn a_lockstep_run_without_progress_is_stopped_naming_every_node() {
        let nodes = [node("src", &[]), node("a", &[("src", false)])];
        let t0 = Instant::now();
        let mut w = Watchdog::new(settings(), t0);
        let all = |_: &str| true;
        let mut st: BTreeMap<String, Stats> = [stats("src", 0, 4), stats("a", 2, 1)].into();
        assert!(w.check(t0, &nodes, &all, &st, true).is_empty());
        assert!(
            w.check(t0 + Duration::from_secs(100), &nodes, &all, &st, true)
                .is_empty()
        );
        st.insert("a".into(), stats("a", 3, 2).1);
        assert!(
            w.check(t0 + Duration::from_secs(119), &nodes, &all, &st, true)
                .is_empty(),
            "progress"
        );
        // Duplicates received (producers publishing their unconsumed frames again) are not
        // progress.
        st.insert("a".into(), stats("a", 9, 2).1);
        assert!(
            w.check(t0 + Duration::from_secs(200), &nodes, &all, &st, false)
                .is_empty(),
            "live"
        );
        let a = w.check(t0 + Duration::from_secs(239), &nodes, &all, &st, true);
        assert!(
            matches!(&a[..], [Action::Stop(m)] if m.contains("a: received 9, published 2") && m.contains("src:")
                && !m.contains("nothing received on")),
            "{a:?}"
        );
        let off = WatchdogSettings::from_seconds(0.0, 0.0).unwrap();
        let mut w = Watchdog::new(off, t0);
        assert!(
            w.check(t0 + Duration::from_secs(9999), &nodes, &all, &st, true)
                .is_empty()
        );
        assert!(WatchdogSettings::from_seconds(-1.0, 5.0).is_err());
    }

    #[test]
    fn a_stall_names_a_node_computing_a_long_slice_instead_of_its_inputs() {
        let nodes = [node("src", &[]), node("a", &[("src", false)])];
        let t0 = Instant::now();
        let mut w = Watchdog::new(settings(), t0);
        let all = |_: &str| true;
        let mut st: BTreeMap<String, Stats> = [stats("src", 0, 5), stats("a", 3, 2)].into();
        assert!(w.check(t0, &nodes, &all, &st, true).is_empty());
        st.get_mut("a").unwrap().computing_s = Some(119.6);
        let a = w.check(t0 + Duration::from_secs(120), &nodes, &all, &st, true);
        assert!(
            matches!(&a[..], [Action::Stop(m)] if m.contains("`a` has been computing one slice for 120 s")
                && m.contains("--stall-timeout")
                && m.contains("a: received 3, published 2, processed 0, last seq -, computing a slice for 120 s")),
            "{a:?}"
        );
        // Without the heartbeat's figure the message is the plain stall.
        st.get_mut("a").unwrap().computing_s = None;
        let a = w.check(t0 + Duration::from_secs(121), &nodes, &all, &st, true);
        assert!(
            matches!(&a[..], [Action::Stop(m)] if m.contains("lock-step run stalled") && !m.contains("computing")),
            "{a:?}"
        );
    }
}
