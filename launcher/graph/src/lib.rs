//! Parse and check graph.yaml with file, line and column in every error.
//!
//! [`check_str`] (or [`load`] for a file) reads a graph, asks a [`Resolver`] for the
//! description of each binary it names (the launcher runs `<binary> --describe`), checks
//! everything it can before a process starts — YAML syntax, types, unknown keys, node ids,
//! parameters, ports, wiring and schemas, machines, cycles without a feedback edge — and returns
//! either every problem found, as [`Diagnostic`]s (`file:line:column: error: message`), or the
//! resolved [`Graph`]: defaults filled in, consumers of each output, nodes in topological order.
//!
//! Pure: no Zenoh, no processes. The format is documented on [`check_str`].

#![warn(missing_docs)]

mod check;
mod cycles;
mod diagnostic;
mod model;
mod params;
mod raw;
mod shape;
mod swap;
mod yaml;

use std::path::Path;

pub use check::Resolver;
pub use diagnostic::{Diagnostic, Span};
pub use model::{
    Consumer, Graph, InputSpec, Machine, Mode, NodeKeys, NodeSpec, OutputSpec, PortKey, RecordSpec, Restart,
    RestartPolicy, SharedMemory,
};
pub use swap::{AdaptedSwap, swap_adapted, swap_binary};

use diagnostic::Problems;

/// Why a graph could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// The file could not be read.
    #[error("cannot read graph file {file}: {source}")]
    Io {
        /// Path as given.
        file: String,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The graph has errors; every one found, in file order.
    #[error("{}", render(.0))]
    Invalid(Vec<Diagnostic>),
    /// An instance name given to [`Graph::with_instance`] is not a valid key chunk.
    #[error("invalid instance name `{name}`: use ASCII letters, digits, `-` and `_`")]
    InvalidInstance {
        /// The rejected name.
        name: String,
    },
}

/// One diagnostic per line.
fn render(diagnostics: &[Diagnostic]) -> String {
    diagnostics
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join("\n")
}

/// Reads and checks the graph file at `path`; see [`check_str`]. Diagnostics name the file as
/// `path` is written. A file that is not UTF-8 is reported at the line and column of the first
/// bad byte.
pub fn load(path: &Path, resolver: Resolver<'_>) -> Result<Graph, GraphError> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|source| GraphError::Io {
        file: file.clone(),
        source,
    })?;
    match std::str::from_utf8(&bytes) {
        Ok(text) => check_str(&file, text, resolver),
        Err(e) => {
            let good = &bytes[..e.valid_up_to()];
            let line = 1 + good.iter().filter(|&&b| b == b'\n').count();
            let line_start = good.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
            // The prefix is valid UTF-8, so counting characters of it is exact.
            let column = 1 + String::from_utf8_lossy(&good[line_start..]).chars().count();
            let message = format!(
                "the file is not UTF-8 text (bad byte 0x{:02x} at byte offset {})",
                bytes[e.valid_up_to()],
                e.valid_up_to()
            );
            Err(GraphError::Invalid(vec![Diagnostic::new(
                &file,
                Span::new(line, column),
                message,
            )]))
        }
    }
}

/// Checks the graph in `text`, read from `file_name` (used in diagnostics only).
///
/// The format (unknown keys are errors everywhere):
///
/// ```yaml
/// name: default            # instance name: ASCII letters, digits, - _ (required)
/// mode: lockstep           # lockstep (default) | live
/// window: 4                # lockstep: messages in flight per edge, >= 1
/// queue: 8                 # live: input queue length per port, >= 1
/// zenoh:                   # optional
///   machines:              # default: one machine `local` listening on tcp/127.0.0.1:7447
///     robot: { listen: ["tcp/127.0.0.1:7447"] }
///     base:  { listen: ["tcp/127.0.0.1:7448"], connect: ["tcp/127.0.0.1:7447"] }
///   shared_memory: { enabled: true, pool_mib: 32 }   # local links (the defaults)
/// nodes:
///   - id: slicer           # unique, a key chunk
///     run: evseg-slicer    # binary
///     machine: robot       # default: the first machine declared
///     params: { window_ms: 30 }      # checked against the description; defaults fill the rest
///     inputs:
///       events: source/events        # port: node/output
///       previous: { from: tracker/tracks, feedback: true }
///     outputs: [slices]    # default: every output of the binary
///     restart: { policy: on-failure, max: 3 }   # policy never (default) | on-failure
///     pool_mib: 32         # this node's shared-memory pool, MiB (default: zenoh's pool_mib)
/// ```
///
/// Example with an in-memory resolver (the launcher's runs `<binary> --describe`):
///
/// ```
/// use evseg_schemas::describe::{NodeDescription, OutputPort};
///
/// let describe = |binary: &str| -> Result<NodeDescription, String> {
///     match binary {
///         "evseg-source" => Ok(NodeDescription {
///             binary: binary.into(),
///             summary: "makes events".into(),
///             inputs: vec![],
///             outputs: vec![OutputPort { name: "events".into(), schema: "evseg.EventPacket".into(), doc: "".into() }],
///             params: vec![],
///         }),
///         _ => Err("not found".into()),
///     }
/// };
/// let graph = evseg_graph::check_str("g.yaml", "name: demo\nnodes:\n  - { id: src, run: evseg-source }\n", &describe)
///     .unwrap();
/// assert_eq!(graph.data_key("src", "events").as_deref(), Some("evseg/demo/data/src/events"));
///
/// let err = evseg_graph::check_str("g.yaml", "name: demo\nnodes:\n  - { id: src, run: evseg-sorce }\n", &describe)
///     .unwrap_err();
/// assert_eq!(
///     err.to_string(),
///     "g.yaml:3:21: error: cannot get the description of binary `evseg-sorce`: not found"
/// );
/// ```
pub fn check_str(file_name: &str, text: &str, resolver: Resolver<'_>) -> Result<Graph, GraphError> {
    let mut problems = Problems::new(file_name);
    let graph = match yaml::parse(text, &mut problems) {
        Some(root) => {
            raw::read(&root, &mut problems).and_then(|raw| check::check(&raw, resolver, &mut problems))
        }
        None => {
            if problems.is_empty() {
                problems.error(
                    Span::new(1, 1),
                    "the file holds no graph (expected `name:` and `nodes:`)",
                );
            }
            None
        }
    };
    match graph {
        Some(graph) if problems.is_empty() => Ok(graph),
        _ => Err(GraphError::Invalid(problems.into_sorted())),
    }
}
