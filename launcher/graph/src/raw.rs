//! The graph as written: graph.yaml read into typed fields with positions, before anything is
//! checked against node descriptions. Wrong types and unknown keys are reported here; a field
//! that could not be read is left out (so it is reported once, not again as "missing").

use crate::diagnostic::{Problems, Span};
use crate::model::{Graph, Mode, Restart, RestartPolicy, SharedMemory};
use crate::shape::{self, Spanned};
use crate::yaml::{Entry, Node, Value};

const TOP_KEYS: &[&str] = &["name", "mode", "window", "queue", "zenoh", "nodes", "record"];
const RECORD_KEYS: &[&str] = &["path", "outputs", "chunk_bytes", "zstd_level"];
const ZENOH_KEYS: &[&str] = &["machines", "shared_memory"];
const SHARED_MEMORY_KEYS: &[&str] = &["enabled", "pool_mib"];
const MACHINE_KEYS: &[&str] = &["listen", "connect"];
const NODE_KEYS: &[&str] = &[
    "id", "run", "machine", "params", "inputs", "outputs", "restart", "pool_mib",
];
const INPUT_KEYS: &[&str] = &["from", "feedback"];
const RESTART_KEYS: &[&str] = &["policy", "max"];

/// A declared machine.
pub(crate) struct RawMachine {
    pub name: Spanned<String>,
    pub listen: Vec<String>,
    pub connect: Vec<String>,
}

/// One `port: reference` of a node's `inputs:`.
pub(crate) struct RawInput {
    /// Port name and the position of the key.
    pub port: Spanned<String>,
    /// `node/output` text and its position.
    pub from: Spanned<String>,
    pub feedback: bool,
}

/// One node as written.
pub(crate) struct RawNode<'a> {
    pub at: Span,
    pub id: Option<Spanned<String>>,
    pub run: Option<Spanned<String>>,
    pub machine: Option<Spanned<String>>,
    /// Given parameters; `None` when `params:` is not a mapping (already reported), so missing
    /// required parameters are not reported on top.
    pub params: Option<&'a [Entry]>,
    /// Inputs that could be read.
    pub inputs: Vec<RawInput>,
    /// Every port named under `inputs:`, readable or not; `None` when `inputs:` is not a
    /// mapping. Used so that a badly written input is not also reported as missing.
    pub named_ports: Option<Vec<String>>,
    pub outputs: Option<Vec<Spanned<String>>>,
    pub restart: RestartPolicy,
    /// The node's own shared-memory pool size, MiB, when given.
    pub pool_mib: Option<u32>,
}

impl RawNode<'_> {
    /// Where to report something about the whole node: its id, else its start.
    pub(crate) fn anchor(&self) -> Span {
        self.id.as_ref().map_or(self.at, |id| id.at)
    }
}

/// The `record:` section as written.
pub(crate) struct RawRecord {
    /// Where the section is.
    pub at: Span,
    pub path: Option<Spanned<String>>,
    /// `node/output` references; `None` = every output.
    pub outputs: Option<Vec<Spanned<String>>>,
    /// MCAP writer settings, checked against their ranges (`None` when absent or invalid).
    pub chunk_bytes: Option<u64>,
    pub zstd_level: Option<u32>,
}

/// The whole file as written.
pub(crate) struct RawGraph<'a> {
    /// The `record:` section, if any (and readable).
    pub record: Option<RawRecord>,
    pub name: Option<Spanned<String>>,
    pub mode: Mode,
    pub window: u32,
    pub queue: u32,
    /// Declared machines; empty when graph.yaml declares none.
    pub machines: Vec<RawMachine>,
    /// `zenoh.shared_memory`, defaults filled in.
    pub shared_memory: SharedMemory,
    pub nodes: Vec<RawNode<'a>>,
}

/// Reads the document root. `None` only when the root is not a mapping.
pub(crate) fn read<'a>(root: &'a Node, p: &mut Problems) -> Option<RawGraph<'a>> {
    let top = shape::mapping(root, "a graph file", TOP_KEYS, p)?;
    let name = match top.get("name") {
        Some(node) => shape::string(node, "`name`", p),
        None => {
            p.error(top.at, "missing `name` (the instance name, e.g. `name: default`)");
            None
        }
    };
    let mode = top
        .get("mode")
        .and_then(|n| read_mode(n, p))
        .unwrap_or(Graph::DEFAULT_MODE);
    let window = top
        .get("window")
        .and_then(|n| shape::count(n, "`window`", 1, p))
        .unwrap_or(Graph::DEFAULT_WINDOW);
    let queue = top
        .get("queue")
        .and_then(|n| shape::count(n, "`queue`", 1, p))
        .unwrap_or(Graph::DEFAULT_QUEUE);
    let (machines, shared_memory) = top.get("zenoh").map(|n| read_zenoh(n, p)).unwrap_or_default();
    let nodes = match top.get("nodes") {
        Some(node) => read_nodes(node, p),
        None => {
            p.error(top.at, "missing `nodes` (the list of nodes of the graph)");
            Vec::new()
        }
    };
    let record = top.get("record").and_then(|n| read_record(n, p));
    Some(RawGraph {
        record,
        name,
        mode,
        window,
        queue,
        machines,
        shared_memory,
        nodes,
    })
}

fn read_mode(node: &Node, p: &mut Problems) -> Option<Mode> {
    let text = shape::string(node, "`mode`", p)?;
    match text.value.as_str() {
        "lockstep" => Some(Mode::Lockstep),
        "live" => Some(Mode::Live),
        other => {
            p.error(
                text.at,
                format!("unknown mode `{other}`; use `lockstep` or `live`"),
            );
            None
        }
    }
}

fn read_record(node: &Node, p: &mut Problems) -> Option<RawRecord> {
    let fields = shape::mapping(node, "`record`", RECORD_KEYS, p)?;
    let path = match fields.get("path") {
        Some(n) => shape::string(n, "`record.path`", p),
        None => {
            p.error(
                node.at,
                "missing `path` in `record` (the MCAP file to write, e.g. `path: run.mcap`)",
            );
            None
        }
    };
    let outputs = fields
        .get("outputs")
        .and_then(|n| shape::string_list(n, "`record.outputs`", p));
    let chunk_bytes = fields.get("chunk_bytes").and_then(|n| {
        let r = evseg_schemas::recording::CHUNK_BYTES_RANGE;
        shape::count_in(n, "`record.chunk_bytes`", *r.start(), *r.end(), p)
    });
    let zstd_level = fields.get("zstd_level").and_then(|n| {
        let r = evseg_schemas::recording::ZSTD_LEVEL_RANGE;
        shape::count_in(
            n,
            "`record.zstd_level`",
            (*r.start()).into(),
            (*r.end()).into(),
            p,
        )
        .and_then(|v| u32::try_from(v).ok())
    });
    Some(RawRecord {
        at: node.at,
        path,
        outputs,
        chunk_bytes,
        zstd_level,
    })
}

/// The `zenoh:` section: declared machines (empty when none) and the shared-memory settings.
fn read_zenoh(node: &Node, p: &mut Problems) -> (Vec<RawMachine>, SharedMemory) {
    let Some(zenoh) = shape::mapping(node, "`zenoh`", ZENOH_KEYS, p) else {
        return Default::default();
    };
    let shm = zenoh
        .get("shared_memory")
        .map(|n| read_shared_memory(n, p))
        .unwrap_or_default();
    (read_machines(zenoh.get("machines"), p), shm)
}

fn read_machines(machines: Option<&Node>, p: &mut Problems) -> Vec<RawMachine> {
    let Some(machines) = machines else {
        return Vec::new();
    };
    let Some(entries) = shape::entries(machines, "`zenoh.machines`", p) else {
        return Vec::new();
    };
    if entries.is_empty() {
        p.error(
            machines.at,
            "`zenoh.machines` is empty; declare at least one machine or leave it out",
        );
    }
    entries.iter().map(|e| read_machine(e, p)).collect()
}

/// `zenoh.shared_memory: { enabled: true, pool_mib: 32 }`, defaults for what is left out.
fn read_shared_memory(section: &Node, p: &mut Problems) -> SharedMemory {
    let mut shm = SharedMemory::default();
    let Some(fields) = shape::mapping(section, "`zenoh.shared_memory`", SHARED_MEMORY_KEYS, p) else {
        return shm;
    };
    if let Some(b) = fields
        .get("enabled")
        .and_then(|n| shape::boolean(n, "`zenoh.shared_memory.enabled`", p))
    {
        shm.enabled = b;
    }
    if let Some(n) = fields
        .get("pool_mib")
        .and_then(|n| shape::count(n, "`zenoh.shared_memory.pool_mib`", 1, p))
    {
        shm.pool_mib = n;
    }
    shm
}

fn read_machine(entry: &Entry, p: &mut Problems) -> RawMachine {
    let name = Spanned {
        value: entry.key.clone(),
        at: entry.key_at,
    };
    if !evseg_schemas::keys::is_valid_chunk(&name.value) {
        p.error(
            name.at,
            format!(
                "invalid machine name `{}`: use ASCII letters, digits, `-` and `_`",
                name.value
            ),
        );
    }
    let what = format!("machine `{}`", name.value);
    let mut machine = RawMachine {
        name,
        listen: Vec::new(),
        connect: Vec::new(),
    };
    let Some(fields) = shape::mapping(&entry.value, &what, MACHINE_KEYS, p) else {
        return machine;
    };
    for (key, list) in [("listen", &mut machine.listen), ("connect", &mut machine.connect)] {
        let Some(node) = fields.get(key) else { continue };
        for endpoint in shape::string_list(node, &format!("`{key}` of {what}"), p).unwrap_or_default() {
            if is_endpoint(&endpoint.value) {
                list.push(endpoint.value);
            } else {
                p.error(
                    endpoint.at,
                    format!(
                        "`{}` is not a Zenoh endpoint; write `protocol/address`, e.g. `tcp/127.0.0.1:7447`",
                        endpoint.value
                    ),
                );
            }
        }
    }
    machine
}

/// `protocol/address` with a non-empty protocol of letters, digits and `-`, and an address.
fn is_endpoint(text: &str) -> bool {
    match text.split_once('/') {
        Some((protocol, address)) => {
            !protocol.is_empty()
                && protocol.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-')
                && !address.is_empty()
        }
        None => false,
    }
}

fn read_nodes<'a>(node: &'a Node, p: &mut Problems) -> Vec<RawNode<'a>> {
    let Value::Seq(items) = &node.value else {
        p.error(
            node.at,
            format!(
                "`nodes` must be a list of nodes (`- id: ...`), got {}",
                node.describe()
            ),
        );
        return Vec::new();
    };
    if items.is_empty() {
        p.error(node.at, "`nodes` is empty; a graph needs at least one node");
    }
    items.iter().filter_map(|item| read_node(item, p)).collect()
}

fn read_node<'a>(node: &'a Node, p: &mut Problems) -> Option<RawNode<'a>> {
    let fields = shape::mapping(node, "a node", NODE_KEYS, p)?;
    let id = match fields.get("id") {
        Some(n) => shape::string(n, "`id`", p),
        None => {
            p.error(fields.at, "this node has no `id`");
            None
        }
    };
    let run = match fields.get("run") {
        Some(n) => shape::string(n, "`run`", p),
        None => {
            p.error(
                fields.at,
                "this node has no `run` (the binary that implements it)",
            );
            None
        }
    };
    let machine = fields
        .get("machine")
        .and_then(|n| shape::string(n, "`machine`", p));
    let params = match fields.get("params") {
        Some(n) => shape::entries(n, "`params`", p),
        None => Some(&[][..]),
    };
    let (inputs, named_ports) = match fields.get("inputs") {
        Some(n) => read_inputs(n, p),
        None => (Vec::new(), Some(Vec::new())),
    };
    let outputs = fields
        .get("outputs")
        .and_then(|n| shape::string_list(n, "`outputs`", p));
    let restart = fields
        .get("restart")
        .and_then(|n| read_restart(n, p))
        .unwrap_or_default();
    let pool_mib = fields
        .get("pool_mib")
        .and_then(|n| shape::count(n, "`pool_mib`", 1, p));
    Some(RawNode {
        at: node.at,
        id,
        run,
        machine,
        params,
        inputs,
        named_ports,
        outputs,
        restart,
        pool_mib,
    })
}

/// The readable inputs and the names of all ports given (`None` when not a mapping).
fn read_inputs(node: &Node, p: &mut Problems) -> (Vec<RawInput>, Option<Vec<String>>) {
    let Some(entries) = shape::entries(node, "`inputs` (port: node/output)", p) else {
        return (Vec::new(), None);
    };
    let mut inputs = Vec::new();
    for entry in entries {
        let port = Spanned {
            value: entry.key.clone(),
            at: entry.key_at,
        };
        let what = format!("input `{}`", port.value);
        let read = match &entry.value.value {
            Value::Map(_) => read_input_object(&entry.value, &what, p),
            Value::Str(_) => shape::string(&entry.value, &what, p).map(|from| (from, false)),
            _ => {
                let got = entry.value.describe();
                p.error(
                    entry.value.at,
                    format!(
                        "{what} must be `node/output` or `{{ from: node/output, feedback: true }}`, got {got}"
                    ),
                );
                None
            }
        };
        if let Some((from, feedback)) = read {
            inputs.push(RawInput { port, from, feedback });
        }
    }
    (inputs, Some(entries.iter().map(|e| e.key.clone()).collect()))
}

fn read_input_object(node: &Node, what: &str, p: &mut Problems) -> Option<(Spanned<String>, bool)> {
    let fields = shape::mapping(node, what, INPUT_KEYS, p)?;
    let feedback = fields
        .get("feedback")
        .and_then(|n| shape::boolean(n, "`feedback`", p))
        .unwrap_or(false);
    match fields.get("from") {
        Some(n) => shape::string(n, "`from`", p).map(|from| (from, feedback)),
        None => {
            p.error(
                fields.at,
                format!("{what} has no `from` (the `node/output` it reads)"),
            );
            None
        }
    }
}

fn read_restart(node: &Node, p: &mut Problems) -> Option<RestartPolicy> {
    let fields = shape::mapping(node, "`restart`", RESTART_KEYS, p)?;
    let mut restart = RestartPolicy::default();
    if let Some(text) = fields.get("policy").and_then(|n| shape::string(n, "`policy`", p)) {
        restart.policy = match text.value.as_str() {
            "never" => Restart::Never,
            "on-failure" => Restart::OnFailure,
            other => {
                p.error(
                    text.at,
                    format!("unknown restart policy `{other}`; use `never` or `on-failure`"),
                );
                Restart::Never
            }
        };
    }
    if let Some(max) = fields.get("max").and_then(|n| shape::count(n, "`max`", 0, p)) {
        restart.max = max;
    }
    Some(restart)
}
