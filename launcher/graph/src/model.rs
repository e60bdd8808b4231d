//! The resolved graph: what the launcher runs once graph.yaml has been checked.
//!
//! Serializing a [`Graph`] (serde) gives its canonical form: the same graph text gives the same
//! JSON, whatever the key order in the YAML, and source positions are left out so that comments
//! and layout do not change it. The launcher writes it to the run folder and hashes it. It reads
//! back with serde (positions then default to 0:0 and `file` to empty).

use std::collections::BTreeMap;

use evseg_schemas::keys;
use serde::{Deserialize, Serialize};

use crate::GraphError;
use crate::diagnostic::{Diagnostic, Span};

/// How the nodes pace each other.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Lossless and deterministic: a producer keeps at most [`Graph::window`] messages in flight
    /// per edge and waits for its consumers' acknowledgements (credits).
    Lockstep,
    /// Sources never wait; each input keeps the newest [`Graph::queue`] messages and drops the
    /// oldest.
    Live,
}

impl Mode {
    /// The name used in graph.yaml.
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Lockstep => "lockstep",
            Mode::Live => "live",
        }
    }
}

/// One machine of a distributed run and its Zenoh endpoints.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Machine {
    /// Machine name (`evseg run --machine NAME` starts this machine's nodes).
    pub name: String,
    /// Zenoh endpoints the router of this machine listens on (`tcp/host:port`).
    pub listen: Vec<String>,
    /// Zenoh endpoints of other machines' routers this machine connects to.
    pub connect: Vec<String>,
}

impl Machine {
    /// Name of the machine used when graph.yaml declares none.
    pub const DEFAULT_NAME: &'static str = "local";
    /// Endpoint of that machine: loopback on Zenoh's customary router port 7447.
    pub const DEFAULT_LISTEN: &'static str = "tcp/127.0.0.1:7447";

    /// The machine used when graph.yaml declares none.
    pub fn default_local() -> Self {
        Machine {
            name: Self::DEFAULT_NAME.to_string(),
            listen: vec![Self::DEFAULT_LISTEN.to_string()],
            connect: Vec::new(),
        }
    }
}

/// Zenoh shared memory between the nodes of one machine (`zenoh.shared_memory` in graph.yaml).
///
/// When enabled, a node's Zenoh session puts every message of at least a few KiB into a
/// shared-memory pool of its own and sends only a reference to consumers on the same machine
/// (Zenoh's "transport optimization"); consumers on other machines, and messages that do not fit
/// in the pool at that moment, go over the network as before. Nothing else changes: the bytes a
/// consumer sees are the same.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct SharedMemory {
    /// Use shared memory for local links (default true).
    pub enabled: bool,
    /// Size of each node's pool, MiB, where the node does not give its own (`pool_mib:` on the
    /// node, [`NodeSpec::pool_mib`]; default [`SharedMemory::DEFAULT_POOL_MIB`]). A message
    /// stays in the pool until every local consumer has released it, so the pool should hold
    /// `window` messages of the largest output: 100k-event slices are 1.3 MB, 1M-event slices
    /// 13 MB (with the simulator's ground truth, about 2.4 MB per 40k-event slice). Zenoh locks
    /// every pool in memory, in the node that creates it and in every node that reads from it.
    pub pool_mib: u32,
}

impl SharedMemory {
    /// Default pool size, MiB: the lock-step window (4) of the largest slices of a 3 M events/s
    /// camera in 30 ms slices, with their ground truth (about 6 MB each). Zenoh 1.x locks
    /// (`mlock`) the whole pool when it creates it, and each consumer locks the pools it reads
    /// too; so a pool costs start-up time and memory whether it is used or not. 64 MiB (the
    /// default until 2026-12-06) locked 1.8 GiB over the default graph's nine nodes (0.9 at 32) and
    /// took 0.28-0.33 s of start-up against 0.18-0.20 s at 32 (`evseg bench pipeline`, 2-core
    /// AMD EPYC VM; throughput 0.87-0.88 -> 0.90-0.93 M events/s, medians of 3 runs). Larger
    /// slices still arrive when the pool is full, through the heap and the socket.
    pub const DEFAULT_POOL_MIB: u32 = 32;

    /// The pool size of `node`, MiB: its own `pool_mib`, else the graph's.
    pub fn pool_mib_of(&self, node: &NodeSpec) -> u32 {
        node.pool_mib.unwrap_or(self.pool_mib)
    }

    /// True for the defaults (left out of the canonical form, so graphs that do not mention
    /// shared memory hash as before).
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }
}

impl Default for SharedMemory {
    fn default() -> Self {
        Self {
            enabled: true,
            pool_mib: Self::DEFAULT_POOL_MIB,
        }
    }
}

/// When the launcher restarts a node whose process failed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Restart {
    /// A failed node fails the run.
    Never,
    /// A node that exits with an error (or is killed by a signal) is started again, at most
    /// [`RestartPolicy::max`] times.
    OnFailure,
}

/// A node's restart policy (`restart: { policy, max }`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct RestartPolicy {
    /// When to restart.
    pub policy: Restart,
    /// Most restarts over the run (meaningful with [`Restart::OnFailure`]).
    pub max: u32,
}

impl RestartPolicy {
    /// Default `max`: three tries ride out a transient fault (a port still in use, a slow
    /// disk) without looping forever on a real bug. Project choice, stated in the graph format.
    pub const DEFAULT_MAX: u32 = 3;

    /// True when a node that has failed after `restarts_done` restarts may be started again.
    pub fn allows_restart(&self, restarts_done: u32) -> bool {
        self.policy == Restart::OnFailure && restarts_done < self.max
    }
}

impl Default for RestartPolicy {
    fn default() -> Self {
        RestartPolicy {
            policy: Restart::Never,
            max: Self::DEFAULT_MAX,
        }
    }
}

/// One wired input port of a node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputSpec {
    /// Port name (from the node's description).
    pub port: String,
    /// Schema name of the messages it takes (equal to the producer output's schema).
    pub schema: String,
    /// Id of the producing node.
    pub from_node: String,
    /// Output name on the producing node.
    pub from_output: String,
    /// True for a feedback edge: the node gets the producer's message of the previous slice
    /// (none for the first slice), and the edge does not count for cycles or ordering.
    pub feedback: bool,
    /// True when the node's description calls the port optional: the node also runs with it
    /// unwired (a replay whose recording lacks its channel leaves it so). Left out of the
    /// canonical form when false, so graphs without optional inputs hash as before.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub optional: bool,
    /// Where the input is wired in graph.yaml (not part of the canonical form).
    #[serde(skip)]
    pub span: Span,
}

/// A node that consumes an output.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Consumer {
    /// Id of the consuming node.
    pub node: String,
    /// Its input port.
    pub port: String,
    /// True when that input is a feedback edge.
    pub feedback: bool,
}

/// One published output of a node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputSpec {
    /// Output name (from the node's description).
    pub name: String,
    /// Schema name of the messages published.
    pub schema: String,
    /// Who reads it, sorted by node id then port. May be empty (published for recording or
    /// viewers only).
    pub consumers: Vec<Consumer>,
}

/// A checked node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NodeSpec {
    /// Node id, unique in the graph, a valid key chunk.
    pub id: String,
    /// Binary that implements it.
    pub binary: String,
    /// Machine it runs on.
    pub machine: String,
    /// Every parameter of the binary: the values given in graph.yaml, defaults for the rest.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Wired inputs, in the order of the binary's description.
    pub inputs: Vec<InputSpec>,
    /// Published outputs, in the order of the binary's description.
    pub outputs: Vec<OutputSpec>,
    /// Restart policy.
    pub restart: RestartPolicy,
    /// Size of this node's shared-memory pool, MiB, where graph.yaml gives one (`pool_mib:` on
    /// the node); `None` = the graph's `zenoh.shared_memory.pool_mib`
    /// ([`SharedMemory::pool_mib_of`]). A node whose outputs are small (per-event labels, a
    /// flow field) needs far less than the source and slicer, whose slices carry the events and
    /// the ground truth; Zenoh locks every pool in memory in its node and in each consumer.
    /// Left out of the canonical form when not given, so graphs without it hash as before.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pool_mib: Option<u32>,
    /// Where the node starts in graph.yaml (not part of the canonical form).
    #[serde(skip)]
    pub span: Span,
    /// Where each parameter given in graph.yaml is (its key), for runtime errors about it
    /// (not part of the canonical form).
    #[serde(skip)]
    pub param_spans: BTreeMap<String, Span>,
}

impl NodeSpec {
    /// The wired input called `port`.
    pub fn input(&self, port: &str) -> Option<&InputSpec> {
        self.inputs.iter().find(|i| i.port == port)
    }

    /// The published output called `name`.
    pub fn output(&self, name: &str) -> Option<&OutputSpec> {
        self.outputs.iter().find(|o| o.name == name)
    }
}

/// A port with the Zenoh key it uses in one graph instance.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct PortKey {
    /// Port name on the node.
    pub port: String,
    /// Schema name of its messages.
    pub schema: String,
    /// Data key (`evseg/<instance>/data/<producer>/<output>`).
    pub key: String,
    /// True for a feedback input (always false for outputs).
    pub feedback: bool,
}

/// Every data key one node reads and writes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct NodeKeys {
    /// Inputs, in the node's input order.
    pub inputs: Vec<PortKey>,
    /// Outputs, in the node's output order.
    pub outputs: Vec<PortKey>,
}

/// What to record (`record: { path, outputs, chunk_bytes, zstd_level }` in graph.yaml).
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize, Deserialize)]
pub struct RecordSpec {
    /// MCAP file to write; a relative path is inside the run folder.
    pub path: String,
    /// Outputs to record as `node/output`, each checked to exist; empty = every output.
    #[serde(default)]
    pub outputs: Vec<String>,
    /// Target uncompressed chunk size, bytes, within
    /// [`evseg_schemas::recording::CHUNK_BYTES_RANGE`]; `None` = the recorder's default (1 MiB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub chunk_bytes: Option<u64>,
    /// zstd level of the chunks, within [`evseg_schemas::recording::ZSTD_LEVEL_RANGE`]; `None` =
    /// the recorder's default (0, zstd's own default level 3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub zstd_level: Option<u32>,
}

/// A checked graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Graph {
    /// File it was read from, as given to the checker (not part of the canonical form).
    #[serde(skip)]
    pub file: String,
    /// Instance name: the `<graph>` chunk of every key.
    pub name: String,
    /// Pacing mode.
    pub mode: Mode,
    /// Lockstep: messages in flight per edge (credits), >= 1.
    pub window: u32,
    /// Live: input queue length per port before the oldest is dropped, >= 1.
    pub queue: u32,
    /// Machines in declaration order (at least one).
    pub machines: Vec<Machine>,
    /// Shared memory between the nodes of one machine.
    #[serde(default, skip_serializing_if = "SharedMemory::is_default")]
    pub shared_memory: SharedMemory,
    /// Nodes in a topological order of the non-feedback edges (producers before consumers; ties
    /// keep the order of the file).
    pub nodes: Vec<NodeSpec>,
    /// Recording of the run, when graph.yaml has a `record:` section (left out of the canonical
    /// form when absent, so graphs without one hash as before).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub record: Option<RecordSpec>,
}

impl Graph {
    /// Default `window`: enough credits to keep a five-stage pipeline busy while bounding memory
    /// to a few slices per edge. Project choice, stated in the graph format.
    pub const DEFAULT_WINDOW: u32 = 4;
    /// Default `queue`: a quarter of a second of 30 ms slices. Project choice, stated in the graph
    /// format.
    pub const DEFAULT_QUEUE: u32 = 8;
    /// Default `mode`: lockstep, so results do not depend on timing.
    pub const DEFAULT_MODE: Mode = Mode::Lockstep;

    /// The same graph under another instance name (for A/B runs and replays). Fails when `name`
    /// is not a valid key chunk (ASCII letters, digits, `-`, `_`).
    pub fn with_instance(mut self, name: &str) -> Result<Graph, GraphError> {
        if !keys::is_valid_chunk(name) {
            return Err(GraphError::InvalidInstance {
                name: name.to_string(),
            });
        }
        self.name = name.to_string();
        Ok(self)
    }

    /// The node called `id`.
    pub fn node(&self, id: &str) -> Option<&NodeSpec> {
        self.nodes.iter().find(|n| n.id == id)
    }

    /// The machine called `name`.
    pub fn machine(&self, name: &str) -> Option<&Machine> {
        self.machines.iter().find(|m| m.name == name)
    }

    /// Nodes assigned to `machine`, in topological order. Empty for an unknown machine.
    pub fn nodes_on(&self, machine: &str) -> Vec<&NodeSpec> {
        self.nodes.iter().filter(|n| n.machine == machine).collect()
    }

    /// Data key of output `output` of node `node` in this instance, if the node publishes it.
    pub fn data_key(&self, node: &str, output: &str) -> Option<String> {
        self.node(node)?.output(output)?;
        Some(keys::data(&self.name, node, output))
    }

    /// Keys node `id` reads (its inputs, i.e. its producers' output keys) and writes.
    pub fn node_keys(&self, id: &str) -> Option<NodeKeys> {
        let node = self.node(id)?;
        let inputs = node
            .inputs
            .iter()
            .map(|i| PortKey {
                port: i.port.clone(),
                schema: i.schema.clone(),
                key: keys::data(&self.name, &i.from_node, &i.from_output),
                feedback: i.feedback,
            })
            .collect();
        let outputs = node
            .outputs
            .iter()
            .map(|o| PortKey {
                port: o.name.clone(),
                schema: o.schema.clone(),
                key: keys::data(&self.name, &node.id, &o.name),
                feedback: false,
            })
            .collect();
        Some(NodeKeys { inputs, outputs })
    }

    /// Every published data key: `(node id, output name, key)` in node order.
    pub fn data_keys(&self) -> Vec<(String, String, String)> {
        self.nodes
            .iter()
            .flat_map(|n| {
                n.outputs.iter().map(|o| {
                    (
                        n.id.clone(),
                        o.name.clone(),
                        keys::data(&self.name, &n.id, &o.name),
                    )
                })
            })
            .collect()
    }

    /// A diagnostic in this graph's file, e.g. for a node that failed at run time:
    /// `graph.diagnostic(node.span, "node `slicer` exited with status 1")`.
    pub fn diagnostic(&self, at: Span, message: impl Into<String>) -> Diagnostic {
        Diagnostic::new(&self.file, at, message)
    }

    /// The canonical form as pretty JSON (also valid YAML 1.2): what the launcher writes to the
    /// run folder and hashes.
    pub fn canonical_json(&self) -> String {
        // Cannot fail: every map key is a string and every number came from a finite value.
        serde_json::to_string_pretty(self).expect("a Graph always serializes to JSON")
    }
}
