//! `evseg run`: check a graph, start a Zenoh router, start this machine's nodes, watch them.

use std::collections::BTreeMap;
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use evseg_graph::{Graph, NodeSpec};
use evseg_runtime::config::{
    ConsumerRef, InputBinding, NodeConfig, OutputBinding, ShmSettings, ZenohSettings,
};
use evseg_runtime::progress::Stats;
use evseg_runtime::{Mode, signals};
use evseg_schemas::keys;
use zenoh::Wait;

use crate::resolve::BinaryResolver;
use crate::supervise::{Fleet, NodeProcess, describe_status, stop_all};

/// Lines of a crashed node's log shown in the report.
pub const CRASH_LOG_LINES: usize = 20;

/// How long a finished run waits for nodes' final stats still on their way through the router.
const FINAL_STATS_WAIT: Duration = Duration::from_secs(2);

/// The progress line shows a node's time inside its current slice once it exceeds this,
/// seconds.
const SHOW_COMPUTING_AFTER_S: f64 = 3.0;

/// What `evseg run` was asked to do.
#[derive(Debug, Clone, Default)]
pub struct RunOptions {
    /// Graph file.
    pub graph: PathBuf,
    /// Start only the nodes of this machine (and use its endpoints).
    pub machine: Option<String>,
    /// Instance name (default: the graph's `name`).
    pub instance: Option<String>,
    /// Run folder (default: a new one under `runs/`).
    pub out: Option<PathBuf>,
    /// Router endpoints to listen on, replacing the machine's.
    pub listen: Vec<String>,
    /// Router endpoints to connect to, replacing the machine's.
    pub connect: Vec<String>,
    /// Parameter overrides `node.param=value` (value parsed as JSON, else taken as a string).
    pub set: Vec<String>,
    /// No progress display.
    pub quiet: bool,
    /// Record into this MCAP file (overrides the graph's `record.path`).
    pub record: Option<PathBuf>,
    /// Replay a recording into the nodes downstream of a replay point instead of running the
    /// replay point and its upstream (`evseg replay`).
    pub replay: Option<crate::replay::ReplaySpec>,
    /// When the launcher restarts a starving node or stops a stalled run.
    pub watchdog: crate::watchdog::WatchdogSettings,
}

/// How a run ended.
#[derive(Debug)]
pub struct RunOutcome {
    /// The run folder.
    pub dir: PathBuf,
    /// Final statistics per node (as last published).
    pub stats: BTreeMap<String, Stats>,
    /// Wall time, seconds, from the moment every node of this machine was spawned to the end.
    pub seconds: f64,
    /// Wall clock at the start of `seconds`, nanoseconds since the Unix epoch.
    pub started_unix_ns: u64,
    /// The MCAP recording written by this machine's recorder, if the run was recorded.
    pub recording: Option<PathBuf>,
    /// Whether this machine's nodes ran with shared memory (the graph's setting, unless the
    /// locked-memory limit turned it off; see [`crate::shm_limit`]).
    pub shared_memory: bool,
    /// What the launcher restarted during the run (a failed node under its restart policy, or
    /// a starving one by the start-up watchdog), one message each; the run's wall time
    /// includes their waits.
    pub restarts: Vec<String>,
}

/// Loads and checks `path`, asking each binary for its description.
pub fn load_graph(path: &Path, resolver: &BinaryResolver) -> anyhow::Result<Graph> {
    let describe = |b: &str| resolver.describe(b).map(|(_, d)| d);
    Ok(evseg_graph::load(path, &describe)?)
}

/// Applies `node.param=value` overrides, checking node and parameter exist.
pub(crate) fn apply_overrides(graph: &mut Graph, sets: &[String]) -> anyhow::Result<()> {
    apply_overrides_of(graph, sets, "--set")
}

/// [`apply_overrides`] with the errors naming the command-line flag `flag` the overrides came
/// from (`evseg ab`'s `--set-b`).
pub(crate) fn apply_overrides_of(graph: &mut Graph, sets: &[String], flag: &str) -> anyhow::Result<()> {
    for s in sets {
        let (lhs, value) = s
            .split_once('=')
            .with_context(|| format!("{flag} `{s}`: expected node.param=value"))?;
        let (node, param) = lhs
            .split_once('.')
            .with_context(|| format!("{flag} `{s}`: expected node.param=value"))?;
        let spec = graph
            .nodes
            .iter_mut()
            .find(|n| n.id == node)
            .with_context(|| format!("{flag} `{s}`: the graph has no node `{node}`"))?;
        let old = spec.params.get(param).with_context(|| {
            let known: Vec<&String> = spec.params.keys().collect();
            format!("{flag} `{s}`: node `{node}` has no parameter `{param}` (known: {known:?})")
        })?;
        let new =
            serde_json::from_str(value).unwrap_or_else(|_| serde_json::Value::String(value.to_string()));
        let same_kind = std::mem::discriminant(old) == std::mem::discriminant(&new) || old.is_null();
        if !same_kind {
            bail!("{flag} `{s}`: parameter `{param}` of `{node}` takes values like {old}, got {new}");
        }
        spec.params.insert(param.to_string(), new);
    }
    Ok(())
}

/// A loopback TCP port that was free a moment ago (bound to `127.0.0.1:0` and released): what
/// benchmarks and A/B runs listen on, so that they run beside another graph on its default port.
pub fn free_loopback_port() -> anyhow::Result<u16> {
    let l = std::net::TcpListener::bind("127.0.0.1:0").context("cannot bind a loopback port")?;
    Ok(l.local_addr()
        .context("cannot read the bound loopback port")?
        .port())
}

/// `tcp/127.0.0.1:<port>` with [`free_loopback_port`].
pub fn free_loopback_endpoint() -> anyhow::Result<String> {
    Ok(format!("tcp/127.0.0.1:{}", free_loopback_port()?))
}

/// The endpoint a node on this machine uses to reach the router listening on `listen`.
pub fn local_endpoint(listen: &str) -> String {
    listen
        .replace("/0.0.0.0:", "/127.0.0.1:")
        .replace("/[::]:", "/[::1]:")
}

/// Builds the config a node gets.
pub fn node_config(graph: &Graph, node: &NodeSpec, router: &[String], run_dir: &Path) -> NodeConfig {
    let instance = &graph.name;
    NodeConfig {
        instance: instance.clone(),
        node: node.id.clone(),
        mode: match graph.mode {
            evseg_graph::Mode::Lockstep => Mode::Lockstep,
            evseg_graph::Mode::Live => Mode::Live,
        },
        window: u64::from(graph.window),
        queue: graph.queue as usize,
        zenoh: ZenohSettings {
            mode: "peer".into(),
            connect: router.iter().map(|e| local_endpoint(e)).collect(),
            listen: vec!["tcp/127.0.0.1:0".into()],
            shared_memory: ShmSettings {
                enabled: graph.shared_memory.enabled,
                pool_bytes: u64::from(graph.shared_memory.pool_mib_of(node)) << 20,
            },
        },
        params: node.params.clone(),
        inputs: node
            .inputs
            .iter()
            .map(|i| InputBinding {
                port: i.port.clone(),
                key: keys::data(instance, &i.from_node, &i.from_output),
                schema: i.schema.clone(),
                feedback: i.feedback,
                producer: i.from_node.clone(),
            })
            .collect(),
        outputs: node
            .outputs
            .iter()
            .map(|o| OutputBinding {
                port: o.name.clone(),
                key: crate::replay::output_key(instance, node, &o.name),
                schema: o.schema.clone(),
                consumers: o
                    .consumers
                    .iter()
                    .map(|c| ConsumerRef {
                        node: c.node.clone(),
                        port: c.port.clone(),
                        feedback: c.feedback,
                        ack_key: keys::ack(instance, &c.node),
                    })
                    .collect(),
            })
            .collect(),
        ack_key: keys::ack(instance, &node.id),
        live_key: keys::live(instance, &node.id),
        stats_key: keys::stats(instance, &node.id),
        run_dir: run_dir.to_path_buf(),
    }
}

fn open_router(listen: &[String], connect: &[String]) -> anyhow::Result<zenoh::Session> {
    let settings = ZenohSettings {
        mode: "router".into(),
        connect: connect.to_vec(),
        listen: listen.to_vec(),
        shared_memory: ShmSettings::default(),
    };
    let mut config = zenoh::Config::default();
    let list = |v: &[String]| serde_json::to_string(v).unwrap_or_else(|_| "[]".into());
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v)
            .map_err(|e| anyhow::anyhow!("zenoh config {k}: {e}"))
    };
    set(&mut config, "mode", "\"router\"")?;
    set(&mut config, "scouting/multicast/enabled", "false")?;
    set(&mut config, "listen/endpoints", &list(&settings.listen))?;
    set(&mut config, "connect/endpoints", &list(&settings.connect))?;
    // Another launcher of the graph may start later: keep trying to reach it.
    set(&mut config, "connect/exit_on_failure", "false")?;
    set(&mut config, "connect/timeout_ms", "-1")?;
    set(&mut config, "listen/exit_on_failure", "true")?;
    // A router's open sleeps `scouting/delay` (Zenoh's default 500 ms) after binding. A
    // launcher with no other machine to connect to has nothing to wait for, so its runs start
    // 0.5 s sooner without it. With other machines the sleep stays: it lets the link to their
    // routers come up before the nodes start; without it `tests/distributed.rs` took 29 s once
    // and failed once in seven runs (a consumer on the other machine unseen for 60 s).
    if settings.connect.is_empty() {
        set(&mut config, "scouting/delay", "0")?;
    }
    zenoh::open(config).wait().map_err(|e| {
        anyhow::anyhow!("cannot start the Zenoh router (listen {listen:?}, connect {connect:?}): {e}; is another run using the port? Set zenoh.machines in graph.yaml or --listen")
    })
}

/// Progress display on the terminal.
struct Display {
    tty: bool,
    quiet: bool,
    last: Instant,
    drawn: bool,
}

impl Display {
    fn update(&mut self, elapsed: f64, order: &[String], stats: &BTreeMap<String, Stats>, force: bool) {
        if self.quiet {
            return;
        }
        let every = if self.tty {
            Duration::from_millis(250)
        } else {
            Duration::from_secs(5)
        };
        if !force && self.last.elapsed() < every {
            return;
        }
        self.last = Instant::now();
        let mut line = format!("[{elapsed:6.1}s]");
        let (mut dropped, mut refused, mut missed) = (0, 0, 0);
        for id in order {
            match stats.get(id) {
                Some(s) => {
                    let mark = if s.finished { "✓" } else { "" };
                    line.push_str(&format!(" {id}:{}{mark}", s.processed));
                    // A slice that has lasted a while: the node is computing, not stuck.
                    if let Some(c) = s.computing_s.filter(|&c| c >= SHOW_COMPUTING_AFTER_S) {
                        line.push_str(&format!("(computing {c:.0}s)"));
                    }
                    dropped += s.dropped;
                    refused += s.refused;
                    missed += s.missed;
                }
                None => line.push_str(&format!(" {id}:-")),
            }
        }
        if dropped + refused + missed > 0 {
            line.push_str(&format!("  dropped {dropped} refused {refused} missed {missed}"));
        }
        let mut err = std::io::stderr();
        if self.tty {
            let _ = write!(err, "\r\x1b[2K{line}");
            self.drawn = true;
        } else {
            let _ = writeln!(err, "{line}");
        }
        let _ = err.flush();
    }

    fn clear(&mut self) {
        if self.drawn {
            let _ = writeln!(std::io::stderr());
            self.drawn = false;
        }
    }
}

/// Runs a graph until its nodes on this machine have finished, one fails, or a stop signal.
pub fn run(opts: &RunOptions) -> anyhow::Result<RunOutcome> {
    signals::install();
    let graph_dir = opts.graph.parent().map(Path::to_path_buf).unwrap_or_default();
    let resolver = BinaryResolver::new(&graph_dir);
    let mut graph = load_graph(&opts.graph, &resolver)?;
    if let Some(name) = &opts.instance {
        graph = graph.with_instance(name)?;
    }
    apply_overrides(&mut graph, &opts.set)?;
    // A replay's recording is checked before anything is created or started.
    let replay = match &opts.replay {
        Some(spec) if opts.machine.is_some() => {
            bail!("replay runs every remaining node on this machine; --machine is not supported ({spec:?})")
        }
        Some(spec) => Some(crate::replay::ReplayPlan::new(&graph, spec, &opts.set)?),
        None => None,
    };
    let machine = match &opts.machine {
        Some(m) => graph.machine(m).cloned().with_context(|| {
            let names: Vec<&str> = graph.machines.iter().map(|m| m.name.as_str()).collect();
            format!("{}: no machine `{m}` (declared: {names:?})", opts.graph.display())
        })?,
        None => graph.machines[0].clone(),
    };
    let listen = if opts.listen.is_empty() {
        machine.listen.clone()
    } else {
        opts.listen.clone()
    };
    let connect = if opts.connect.is_empty() {
        machine.connect.clone()
    } else {
        opts.connect.clone()
    };
    if listen.is_empty() {
        bail!(
            "machine `{}` has no listen endpoint; nodes need a router to connect to",
            machine.name
        );
    }
    let dir = crate::rundir::create(opts.out.as_deref(), &graph.name, opts.machine.as_deref())?;
    std::fs::write(
        dir.join("graph.resolved.json"),
        serde_json::to_string_pretty(&graph)?,
    )?;
    if let Ok(text) = std::fs::read(&opts.graph) {
        std::fs::write(dir.join("graph.yaml"), text)?;
    }
    let recording = crate::record::recording_path(opts.record.as_deref(), &graph, &dir)?;
    let mut recorder_here = None;
    if let Some(path) = &recording {
        // With `--record` the recorder runs with this launcher; with the graph's `record:`
        // section every launcher adds it the same way, on the first machine.
        let on = if opts.record.is_some() {
            machine.name.clone()
        } else {
            graph.machines[0].name.clone()
        };
        // The section's outputs and writer settings also apply with `--record`.
        let record = graph.record.clone().unwrap_or_default();
        let metadata = run_metadata(&graph, &opts.graph, &machine.name);
        let (with_recorder, id) = crate::record::add_recorder(&graph, path, &record, &on, metadata)?;
        graph = with_recorder;
        if on == machine.name {
            recorder_here = Some(path.clone());
        }
        tracing::info!(recorder = %id, file = %path.display(), "recording");
    }
    if let Some(plan) = &replay {
        graph = plan.apply(&graph, &machine.name)?;
    }
    if recording.is_some() || replay.is_some() {
        // graph.resolved.json stays the graph as the user wrote it (its hash identifies the run
        // in recordings); what was started, with the recorder or the replay source, is here.
        std::fs::write(
            dir.join("graph.started.json"),
            serde_json::to_string_pretty(&graph)?,
        )?;
    }
    let nodes: Vec<NodeSpec> = match &opts.machine {
        Some(m) => graph.nodes_on(m).into_iter().cloned().collect(),
        None => graph.nodes.clone(),
    };

    if let Some(why) = crate::shm_limit::over_limit(&nodes, &graph.shared_memory, &opts.graph) {
        tracing::warn!(
            "shared memory is off for this run: {why}; frames go over the loopback sockets instead"
        );
        graph.shared_memory.enabled = false;
    }

    let session = open_router(&listen, &connect)?;
    let stats: Arc<Mutex<BTreeMap<String, Stats>>> = Arc::default();
    let sink = stats.clone();
    let _stats_sub = session
        .declare_subscriber(keys::stats_all(&graph.name))
        .callback(move |sample| {
            if let Ok(s) = serde_json::from_slice::<Stats>(&sample.payload().to_bytes())
                && let Ok(mut map) = sink.lock()
            {
                map.insert(s.node.clone(), s);
            }
        })
        .wait()
        .map_err(|e| anyhow::anyhow!("zenoh: {e}"))?;

    tracing::info!(graph = %opts.graph.display(), instance = %graph.name, machine = %machine.name, nodes = nodes.len(), dir = %dir.display(), "starting");
    let mut fleet = Fleet(Vec::new());
    // Consumers first, so producers find them quickly.
    for node in nodes.iter().rev() {
        let (binary, _) = resolver
            .describe(&node.binary)
            .map_err(|e| anyhow::anyhow!("node `{}`: {e}", node.id))?;
        let cfg = node_config(&graph, node, &listen, &dir);
        let cfg_path = dir.join("config").join(format!("{}.json", node.id));
        std::fs::write(&cfg_path, serde_json::to_string_pretty(&cfg)?)?;
        let log = dir.join("logs").join(format!("{}.log", node.id));
        let origin = node_origin(&opts.graph, node);
        let p = NodeProcess::spawn(&node.id, &binary, &cfg_path, &log, origin)
            .with_context(|| format!("cannot start node `{}` ({})", node.id, binary.display()))?;
        fleet.0.push(p);
    }
    let order: Vec<String> = nodes.iter().map(|n| n.id.clone()).collect();
    let mut display = Display {
        tty: std::io::stderr().is_terminal(),
        quiet: opts.quiet,
        last: Instant::now(),
        drawn: false,
    };
    let start = Instant::now();
    let started_unix_ns = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let policies: BTreeMap<String, evseg_graph::RestartPolicy> =
        nodes.iter().map(|n| (n.id.clone(), n.restart)).collect();
    let mut watchdog = crate::watchdog::Watchdog::new(opts.watchdog, start);
    let mut restarts: Vec<String> = Vec::new();
    let lockstep = graph.mode == evseg_graph::Mode::Lockstep;
    let mut peers = crate::peers::PeerWatch::new(
        &graph,
        &opts.graph.display().to_string(),
        opts.machine.as_deref(),
        &listen,
        &connect,
    );
    loop {
        if signals::stop_requested() {
            display.clear();
            eprintln!("stopping: signal received");
            stop_all(&mut fleet.0);
            bail!("run stopped by signal; logs in {}", dir.join("logs").display());
        }
        let mut failed = None;
        for p in fleet.0.iter_mut() {
            if let Some(status) = p.poll()
                && !status.success()
            {
                let policy = &policies[&p.id];
                if policy.allows_restart(p.restarts) {
                    tracing::warn!(node = %p.id, status = %describe_status(&status), restart = p.restarts + 1, "node failed; restarting");
                    eprintln!(
                        "node `{}` failed ({}); restart {} of {}",
                        p.id,
                        describe_status(&status),
                        p.restarts + 1,
                        policy.max
                    );
                    restarts.push(format!("node `{}` failed ({})", p.id, describe_status(&status)));
                    p.restart()
                        .with_context(|| format!("cannot restart node `{}`", p.id))?;
                } else {
                    failed = Some((p.id.clone(), status, p.origin.clone(), last_log_lines(p)));
                    break;
                }
            }
        }
        if let Some((id, status, origin, last_lines)) = failed {
            display.clear();
            stop_all(&mut fleet.0);
            bail!(
                "node `{id}` ({origin}) failed with {}\n{last_lines}",
                describe_status(&status)
            );
        }
        let snapshot = stats.lock().map(|m| m.clone()).unwrap_or_default();
        if fleet.0.iter_mut().all(|p| p.poll().is_some_and(|s| s.success())) {
            display.update(start.elapsed().as_secs_f64(), &order, &snapshot, true);
            display.clear();
            break;
        }
        let running: Vec<String> = fleet
            .0
            .iter_mut()
            .filter_map(|p| p.poll().is_none().then(|| p.id.clone()))
            .collect();
        let here = |id: &str| running.iter().any(|r| r == id);
        for action in watchdog.check(Instant::now(), &graph.nodes, &here, &snapshot, lockstep) {
            match action {
                crate::watchdog::Action::Restart { node, why } => {
                    display.clear();
                    tracing::warn!(node = %node, "{why}");
                    eprintln!("{why}");
                    restarts.push(why);
                    if let Some(p) = fleet.0.iter_mut().find(|p| p.id == node) {
                        p.respawn()
                            .with_context(|| format!("cannot restart node `{node}`"))?;
                    }
                }
                crate::watchdog::Action::Stop(why) => {
                    display.clear();
                    stop_all(&mut fleet.0);
                    bail!("{why}\nlogs in {}", dir.join("logs").display());
                }
                crate::watchdog::Action::GiveUp { node, why } => {
                    display.clear();
                    stop_all(&mut fleet.0);
                    let log = fleet.0.iter().find(|p| p.id == node).map(last_log_lines);
                    bail!(
                        "{why}{}\nlogs in {}",
                        log.map(|l| format!("\n{l}")).unwrap_or_default(),
                        dir.join("logs").display()
                    );
                }
            }
        }
        if peers.pending() && start.elapsed() >= crate::peers::PEER_WARN_AFTER {
            let routers = session.info().routers_zid().wait().count();
            if let Some(warning) = peers.check(start.elapsed(), routers, &snapshot) {
                display.clear();
                eprintln!("{warning}");
            }
        }
        display.update(start.elapsed().as_secs_f64(), &order, &snapshot, false);
        std::thread::sleep(Duration::from_millis(50));
    }
    let seconds = start.elapsed().as_secs_f64();
    // A node's last stats travel through the router and may arrive after its process has
    // exited (seen under load: a summary without the inspector's row); wait a little for every
    // node's `finished` stats. A node that never sends them (a foreign binary) costs the wait.
    let deadline = Instant::now() + FINAL_STATS_WAIT;
    let mut final_stats = stats.lock().map(|m| m.clone()).unwrap_or_default();
    while !order
        .iter()
        .all(|id| final_stats.get(id).is_some_and(|s| s.finished))
        && Instant::now() < deadline
    {
        std::thread::sleep(Duration::from_millis(10));
        final_stats = stats.lock().map(|m| m.clone()).unwrap_or_default();
    }
    let _ = session.close().wait();
    Ok(RunOutcome {
        dir,
        stats: final_stats,
        seconds,
        started_unix_ns,
        recording: recorder_here,
        shared_memory: graph.shared_memory.enabled,
        restarts,
    })
}

/// Where a node comes from, for messages: its place in the graph file (`graph.yaml:41:5`), or,
/// for a node the launcher added (no place in the file), what it was added for.
fn node_origin(graph_file: &Path, node: &NodeSpec) -> String {
    if node.span.line > 0 {
        return format!("{}:{}:{}", graph_file.display(), node.span.line, node.span.column);
    }
    let why = match node.binary.as_str() {
        crate::record::RECORDER_BINARY => {
            let file = node.params.get("path").and_then(|p| p.as_str()).unwrap_or("?");
            format!("to record the run into {file}")
        }
        crate::replay::REPLAY_BINARY => "to replay the recording".to_string(),
        _ => "to the graph".to_string(),
    };
    format!("{}, added by the launcher {why}", node.binary)
}

/// The run's facts stored in a recording (`evseg.run` metadata record).
fn run_metadata(graph: &Graph, file: &Path, machine: &str) -> serde_json::Map<String, serde_json::Value> {
    let mut m = serde_json::Map::new();
    let mut put = |k: &str, v: String| {
        m.insert(k.to_string(), serde_json::Value::String(v));
    };
    put("graph_hash", crate::record::graph_hash(&graph.canonical_json()));
    put("graph_hash_algorithm", "fnv1a-64 of graph.resolved.json".into());
    put("evseg_version", env!("CARGO_PKG_VERSION").into());
    put("instance", graph.name.clone());
    put("mode", graph.mode.as_str().into());
    put("window", graph.window.to_string());
    put("queue", graph.queue.to_string());
    put("machine", machine.to_string());
    put("graph_file", file.display().to_string());
    put("started_utc", crate::rundir::timestamp());
    put("command", std::env::args().collect::<Vec<_>>().join(" "));
    m
}

/// The warnings and errors one node logged during a run (`logs/<node>.log`).
#[derive(Debug, Clone, PartialEq)]
pub struct LoggedProblems {
    /// The node (its log file's name).
    pub node: String,
    /// Lines at level WARN from evseg's own code.
    pub warnings: usize,
    /// Lines at level ERROR from evseg's own code.
    pub errors: usize,
    /// The first of those lines' messages (target and text, without the time stamp).
    pub first: String,
    /// WARN and ERROR lines of the libraries (Zenoh's transport notices, say).
    pub library: usize,
    /// Panics of any thread of the node (Rust's `thread '...' panicked at` lines), and the
    /// first of those lines.
    pub panics: usize,
    /// The first panic line.
    pub first_panic: String,
}

/// What the nodes of the run in `dir` logged at WARN or ERROR, per node with any, sorted by
/// node: evseg's own lines counted and the first quoted, the libraries' only counted. Lines
/// are read as `tracing` writes them (`<time> <LEVEL> <target>: <message>`); others are passed
/// over.
pub fn logged_problems(dir: &Path) -> Vec<LoggedProblems> {
    let mut logs: Vec<PathBuf> = std::fs::read_dir(dir.join("logs"))
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "log"))
        .collect();
    logs.sort();
    let mut out = Vec::new();
    for path in logs {
        // A log cut inside a character (a node killed mid-write) is still read.
        let Ok(bytes) = std::fs::read(&path) else {
            continue;
        };
        let text = String::from_utf8_lossy(&bytes);
        let node = path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        let mut p = LoggedProblems {
            node,
            warnings: 0,
            errors: 0,
            first: String::new(),
            library: 0,
            panics: 0,
            first_panic: String::new(),
        };
        for line in text.lines() {
            if line.starts_with("thread '") && line.contains(" panicked at ") {
                p.panics += 1;
                if p.first_panic.is_empty() {
                    p.first_panic = line.to_string();
                }
                continue;
            }
            // Past the time stamp: the level, then `target: message`.
            let rest = line.trim_start_matches(|c: char| !c.is_whitespace()).trim_start();
            let Some((level, message)) = rest.split_once(' ') else {
                continue;
            };
            let (warn, error) = (level == "WARN", level == "ERROR");
            if !(warn || error) {
                continue;
            }
            let message = message.trim_start();
            if !message.starts_with("evseg") {
                p.library += 1;
                continue;
            }
            p.warnings += usize::from(warn);
            p.errors += usize::from(error);
            if p.first.is_empty() {
                p.first = message.to_string();
            }
        }
        if p.warnings + p.errors + p.library + p.panics > 0 {
            out.push(p);
        }
    }
    out
}

/// [`logged_problems`] of the run in `dir` as lines for a person: one per node with evseg
/// warnings or errors (the counts and the first message, cut at 300 characters), then, with
/// `library`, one counting the libraries' warnings; empty when there are none.
pub fn problem_lines(dir: &Path, library: bool) -> Vec<String> {
    let count = |n: usize, what: &str| format!("{n} {what}{}", if n == 1 { "" } else { "s" });
    let problems = logged_problems(dir);
    let cut = |text: &str| {
        let mut first: String = text.chars().take(300).collect();
        if text.chars().count() > 300 {
            first.push_str(" ...");
        }
        first
    };
    let mut lines: Vec<String> = Vec::new();
    for p in &problems {
        if p.warnings + p.errors > 0 {
            lines.push(format!(
                "{}: {}, {}; first: {}",
                p.node,
                count(p.warnings, "warning"),
                count(p.errors, "error"),
                cut(&p.first)
            ));
        }
        if p.panics > 0 {
            lines.push(format!(
                "{}: {}; first: {}",
                p.node,
                count(p.panics, "panic"),
                cut(&p.first_panic)
            ));
        }
    }
    let from_libraries: usize = problems.iter().map(|p| p.library).sum();
    if library && from_libraries > 0 {
        lines.push(format!(
            "{} of the libraries (Zenoh) in the logs",
            count(from_libraries, "warning")
        ));
    }
    lines
}

/// Markdown reports the nodes wrote into the run folder (`*/report.md`, one level down).
pub fn reports(dir: &Path) -> Vec<PathBuf> {
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path().join("report.md"))
        .filter(|p| p.is_file())
        .collect();
    found.sort();
    found
}

/// The normal-flow nodes' scores of a run (`normal-flow-score-<node>.json`, written by every
/// normal-flow estimator given the truth) side by side as a Markdown table, one row per node;
/// `None` when the run has none. A file that does not parse is a row saying so.
pub fn flow_comparison(dir: &Path) -> Option<String> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("normal-flow-score-") && n.ends_with(".json"))
        })
        .collect();
    if files.is_empty() {
        return None;
    }
    files.sort();
    let mut s = String::from(
        "normal flow against the truth (all events; boundary = within 2 px of an object edge):\n\
         | node | estimator | coverage | sign-correct | median circle angle (deg) | median relative magnitude error | boundary sign-correct |\n\
         |---|---|---:|---:|---:|---:|---:|\n",
    );
    for path in files {
        let parsed = std::fs::read(&path)
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok());
        let Some(v) = parsed else {
            s.push_str(&format!("| {} | unreadable | | | | | |\n", path.display()));
            continue;
        };
        let text = |p: &str| v.pointer(p).and_then(|x| x.as_str()).unwrap_or("?").to_string();
        let num = |p: &str| {
            v.pointer(p)
                .and_then(serde_json::Value::as_f64)
                .map_or_else(|| "n/a".to_string(), |x| format!("{x:.3}"))
        };
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} |\n",
            text("/node"),
            text("/estimator"),
            num("/score/all/coverage"),
            num("/score/all/sign_correct_rate"),
            num("/score/all/circle_angle_error_deg_median"),
            num("/score/all/relative_magnitude_error_median"),
            num("/score/boundary/sign_correct_rate"),
        ));
    }
    Some(s)
}

/// `last lines of LOG:` and the last [`CRASH_LOG_LINES`] lines of `p`'s log, indented: what a
/// failed or given-up node's error shows.
fn last_log_lines(p: &crate::supervise::NodeProcess) -> String {
    format!(
        "last lines of {}:\n{}",
        p.log.display(),
        indent(&p.log_tail(CRASH_LOG_LINES))
    )
}

fn indent(text: &str) -> String {
    text.lines()
        .map(|l| format!("    {l}"))
        .collect::<Vec<_>>()
        .join("\n")
}

/// A per-node summary table of a finished run.
pub fn summary(outcome: &RunOutcome, order: &[String]) -> String {
    let mut s =
        String::from("node                 processed  published  dropped  refused   busy s   missed\n");
    for id in order {
        if let Some(st) = outcome.stats.get(id) {
            s.push_str(&format!(
                "{id:<20} {:>9}  {:>9}  {:>7}  {:>7}  {:>7.2}  {:>7}\n",
                st.processed, st.published, st.dropped, st.refused, st.busy_s, st.missed
            ));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_node_the_launcher_added_is_named_by_what_it_is_for_not_by_line_zero() {
        let node = |binary: &str, line: usize| -> NodeSpec {
            let mut n: NodeSpec = serde_json::from_value(serde_json::json!({
                "id": "n", "binary": binary, "machine": "local",
                "params": {"path": "/data/run.mcap"}, "inputs": [], "outputs": [],
                "restart": {"policy": "never", "max": 3},
            }))
            .unwrap();
            n.span = evseg_graph::Span::new(line, 5);
            n
        };
        let g = Path::new("graph.yaml");
        assert_eq!(node_origin(g, &node("evseg-slicer", 41)), "graph.yaml:41:5");
        assert_eq!(
            node_origin(g, &node(crate::record::RECORDER_BINARY, 0)),
            "evseg-recorder, added by the launcher to record the run into /data/run.mcap"
        );
        assert_eq!(
            node_origin(g, &node(crate::replay::REPLAY_BINARY, 0)),
            "evseg-replay, added by the launcher to replay the recording"
        );
    }

    #[test]
    fn logged_problems_count_evseg_warnings_and_errors_per_node_and_quote_the_first() {
        let dir = tempfile::tempdir().unwrap();
        let logs = dir.path().join("logs");
        std::fs::create_dir_all(&logs).unwrap();
        std::fs::write(
            logs.join("source.log"),
            "2026-12-07T09:37:21.033727Z  INFO evseg_source::evimo2: IMU check: inconclusive\n\
             2026-12-07T09:37:21.033772Z  WARN evseg_source::evimo2: /x: the folder has no IMU samples\n\
             2026-12-07T09:37:22.000000Z ERROR evseg_source: a bad packet\n\
             2026-12-07T09:37:23.283490Z  WARN zenoh::api::admin: Unable to find transport\n\
             not a tracing line\n",
        )
        .unwrap();
        // A log cut inside a character is still read.
        let mut flow = b"2026-12-07T09:37:21Z  INFO evseg_normal_flow: fine\n".to_vec();
        flow.extend_from_slice(&[0xE2, 0x82]);
        std::fs::write(logs.join("flow.log"), flow).unwrap();
        std::fs::write(
            logs.join("slicer.log"),
            "2026-12-07T09:37:21Z  WARN evseg_slicer: slices=3\n",
        )
        .unwrap();
        let found = logged_problems(dir.path());
        assert_eq!(found.len(), 2, "{found:?}");
        assert_eq!(
            found[1],
            LoggedProblems {
                node: "source".into(),
                warnings: 1,
                errors: 1,
                first: "evseg_source::evimo2: /x: the folder has no IMU samples".into(),
                library: 1,
                panics: 0,
                first_panic: String::new(),
            }
        );
        assert_eq!((found[0].node.as_str(), found[0].warnings), ("slicer", 1));
        assert!(logged_problems(&dir.path().join("none")).is_empty());
    }

    #[test]
    fn a_panic_in_a_nodes_log_is_counted_and_listed() {
        let dir = tempfile::tempdir().unwrap();
        let logs = dir.path().join("logs");
        std::fs::create_dir_all(&logs).unwrap();
        std::fs::write(
            logs.join("tracker.log"),
            "2026-12-07T09:37:21Z  INFO evseg_runtime::node: stopped on request\n\
             thread 'net-0' (4242) panicked at static_init-1.0.4/src/generic_lazy.rs:954:45:\n\
             called `Result::unwrap()` on an `Err` value: AccessError\n",
        )
        .unwrap();
        let found = logged_problems(dir.path());
        assert_eq!((found.len(), found[0].panics, found[0].warnings), (1, 1, 0));
        let lines = problem_lines(dir.path(), true);
        assert_eq!(
            lines,
            [
                "tracker: 1 panic; first: thread 'net-0' (4242) panicked at static_init-1.0.4/src/generic_lazy.rs:954:45:"
            ]
        );
    }

    #[test]
    fn flow_comparison_has_a_row_per_score_file_and_names_an_unreadable_one() {
        let dir = tempfile::tempdir().unwrap();
        assert!(flow_comparison(dir.path()).is_none());
        std::fs::write(
            dir.path().join("normal-flow-score-a.json"),
            r#"{"node":"a","estimator":"plane-fit","score":{"all":{"coverage":0.5,"sign_correct_rate":0.97},"boundary":{}}}"#,
        )
        .unwrap();
        std::fs::write(dir.path().join("normal-flow-score-b.json"), "{ not json").unwrap();
        let table = flow_comparison(dir.path()).unwrap();
        assert!(
            table.contains("| a | plane-fit | 0.500 | 0.970 | n/a | n/a | n/a |"),
            "{table}"
        );
        assert!(table.contains("normal-flow-score-b.json | unreadable"), "{table}");
    }

    #[test]
    fn wildcard_listen_becomes_loopback_for_local_nodes() {
        assert_eq!(local_endpoint("tcp/0.0.0.0:7447"), "tcp/127.0.0.1:7447");
        assert_eq!(local_endpoint("tcp/[::]:7447"), "tcp/[::1]:7447");
        assert_eq!(local_endpoint("tcp/127.0.0.1:9"), "tcp/127.0.0.1:9");
    }
}
