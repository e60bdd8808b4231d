//! What the launcher hands a node: its keys, its wiring, its parameters and the run's settings.
//!
//! The launcher writes one JSON file per node into the run folder and starts the node with
//! `--config <file>`. Nodes never compute keys themselves, so replay and A/B remap for free.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::RuntimeError;

/// How the graph trades completeness for latency.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Lossless and deterministic: producers hold at most `window` messages in flight per edge and
    /// wait for their consumers' progress.
    Lockstep,
    /// Sources never wait; a stage that falls behind drops its oldest input and counts the drops.
    Live,
}

/// Zenoh connection settings of a node.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ZenohSettings {
    /// Zenoh mode of the node's session (`client` or `peer`).
    pub mode: String,
    /// Endpoints to connect to (the launcher's router on this machine).
    pub connect: Vec<String>,
    /// Endpoints to listen on (peers only; empty for clients).
    #[serde(default)]
    pub listen: Vec<String>,
    /// Shared memory for links to nodes on the same machine.
    #[serde(default)]
    pub shared_memory: ShmSettings,
}

/// Zenoh shared memory of one session: large messages to consumers on the same machine are
/// placed in a pool of the session's own and only a reference crosses the socket.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShmSettings {
    /// Use shared memory where the consumer supports it.
    pub enabled: bool,
    /// Pool size, bytes. A message that does not fit at the moment goes over the socket.
    pub pool_bytes: u64,
}

impl Default for ShmSettings {
    /// Enabled, 32 MiB (the graph's default, `evseg_graph::SharedMemory::DEFAULT_POOL_MIB`,
    /// which the launcher passes to every node; this one serves configs made without a graph).
    fn default() -> Self {
        Self {
            enabled: true,
            pool_bytes: 32 << 20,
        }
    }
}

/// One consumer of an output: a node's input port.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConsumerRef {
    /// Consumer node id.
    pub node: String,
    /// Consumer input port.
    pub port: String,
    /// True when the consumer takes this output as a feedback input (previous slice).
    pub feedback: bool,
    /// The consumer's progress key.
    pub ack_key: String,
}

/// One input port of the node, bound to a key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputBinding {
    /// Port name.
    pub port: String,
    /// Key expression it subscribes to.
    pub key: String,
    /// Schema name the port expects.
    pub schema: String,
    /// Feedback input: for slice `k` the node gets the producer's message `k - 1`.
    pub feedback: bool,
    /// Producer node id (for messages).
    pub producer: String,
}

/// One output port of the node, bound to a key.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OutputBinding {
    /// Port name.
    pub port: String,
    /// Key expression it publishes on.
    pub key: String,
    /// Schema name of its messages.
    pub schema: String,
    /// Who consumes it (for lock-step credits and start-up).
    pub consumers: Vec<ConsumerRef>,
}

/// Everything a node needs to run in a graph.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct NodeConfig {
    /// Graph instance name (part of every key).
    pub instance: String,
    /// This node's id.
    pub node: String,
    /// Lock-step or live.
    pub mode: Mode,
    /// Lock-step credit: messages in flight per edge (>= 1).
    pub window: u64,
    /// Live mode: input queue length per port before the oldest is dropped (>= 1).
    pub queue: usize,
    /// Zenoh settings.
    pub zenoh: ZenohSettings,
    /// Parameters (defaults filled in by the launcher).
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Input bindings.
    pub inputs: Vec<InputBinding>,
    /// Output bindings.
    pub outputs: Vec<OutputBinding>,
    /// Key this node publishes its progress on.
    pub ack_key: String,
    /// Key of this node's liveliness token.
    pub live_key: String,
    /// Key this node publishes statistics on.
    pub stats_key: String,
    /// Folder of the run (logs, reports); nodes may write files below it.
    pub run_dir: PathBuf,
}

impl NodeConfig {
    /// A config of node `node` with `params` and nothing else (no inputs, outputs or peers,
    /// lock-step, window 1, an empty run folder): for checking a node's parameter handling
    /// without a graph.
    pub fn with_params(node: &str, params: serde_json::Map<String, serde_json::Value>) -> Self {
        Self {
            instance: "i".into(),
            node: node.into(),
            mode: Mode::Lockstep,
            window: 1,
            queue: 1,
            zenoh: ZenohSettings {
                mode: "peer".into(),
                connect: vec![],
                listen: vec![],
                shared_memory: ShmSettings::default(),
            },
            params,
            inputs: vec![],
            outputs: vec![],
            ack_key: String::new(),
            live_key: String::new(),
            stats_key: String::new(),
            run_dir: PathBuf::new(),
        }
    }

    /// Reads a config file written by the launcher.
    pub fn load(path: &Path) -> Result<Self, RuntimeError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| RuntimeError::Config(format!("cannot read {}: {e}", path.display())))?;
        serde_json::from_str(&text)
            .map_err(|e| RuntimeError::Config(format!("{}: invalid node config: {e}", path.display())))
    }

    /// Parameter `name` converted to `T`; the error names the node and the parameter.
    pub fn param<T: serde::de::DeserializeOwned>(&self, name: &str) -> Result<T, RuntimeError> {
        let value = self.params.get(name).ok_or_else(|| RuntimeError::Param {
            node: self.node.clone(),
            name: name.to_string(),
            reason: "missing".into(),
        })?;
        let error = |reason: String| RuntimeError::Param {
            node: self.node.clone(),
            name: name.to_string(),
            reason,
        };
        // serde converts a number beyond f32's range to infinity without a word.
        if std::any::type_name::<T>().contains("f32") && exceeds_f32(value) {
            return Err(error(format!(
                "{value} is beyond a 32-bit float's range (about +-3.4e38)"
            )));
        }
        serde_json::from_value(value.clone())
            .map_err(|e| error(format!("{} (value {value})", plain_type_names(&e.to_string()))))
    }

    /// True when some node of the graph consumes output `port` (a recorder included): a node
    /// may skip computing an output nobody reads.
    pub fn output_is_read(&self, port: &str) -> bool {
        self.outputs
            .iter()
            .any(|o| o.port == port && !o.consumers.is_empty())
    }

    /// Parameter `name` as `T`, or `None` when it is absent or null.
    pub fn param_opt<T: serde::de::DeserializeOwned>(&self, name: &str) -> Result<Option<T>, RuntimeError> {
        match self.params.get(name) {
            None | Some(serde_json::Value::Null) => Ok(None),
            Some(_) => self.param(name).map(Some),
        }
    }
}

/// True when `value` holds a finite number beyond `f32`'s range (anywhere inside it).
fn exceeds_f32(value: &serde_json::Value) -> bool {
    match value {
        serde_json::Value::Number(n) => n
            .as_f64()
            .is_some_and(|x| x.is_finite() && x.abs() > f32::MAX as f64),
        serde_json::Value::Array(a) => a.iter().any(exceeds_f32),
        serde_json::Value::Object(o) => o.values().any(exceeds_f32),
        _ => false,
    }
}

/// serde's message with Rust's integer and float type names said in words, e.g. "expected
/// u16" -> "expected a whole number in 0..=65535 (u16)".
fn plain_type_names(message: &str) -> String {
    const NAMES: [(&str, &str); 10] = [
        ("u8", "a whole number in 0..=255"),
        ("u16", "a whole number in 0..=65535"),
        ("u32", "a whole number in 0..=4294967295"),
        ("u64", "a whole number in 0..=18446744073709551615"),
        ("usize", "a whole number >= 0"),
        ("i32", "a whole number in -2147483648..=2147483647"),
        ("i64", "a whole number"),
        ("f32", "a number"),
        ("f64", "a number"),
        ("bool", "true or false"),
    ];
    for (rust, words) in NAMES {
        let from = format!("expected {rust}");
        // Only the whole word: "expected u16" but not "expected u160".
        if let Some(at) = message.find(&from)
            && !message[at + from.len()..].starts_with(|c: char| c.is_ascii_alphanumeric())
        {
            return message.replacen(&from, &format!("expected {words} ({rust})"), 1);
        }
    }
    message.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parameter_errors_say_the_range_in_words_and_refuse_floats_that_would_be_infinite() {
        let params = |v: serde_json::Value| {
            let mut m = serde_json::Map::new();
            m.insert("x".into(), v);
            NodeConfig::with_params("planar", m)
        };
        let e = params(serde_json::json!(70000))
            .param::<u16>("x")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("node planar: parameter `x`") && e.contains("a whole number in 0..=65535 (u16)"),
            "{e}"
        );
        let e = params(serde_json::json!(1e30))
            .param::<u32>("x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("a whole number in 0..=4294967295 (u32)"), "{e}");
        let e = params(serde_json::json!(1e300))
            .param::<f32>("x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("beyond a 32-bit float's range"), "{e}");
        let e = params(serde_json::json!([1.0, -1e39]))
            .param::<Vec<f32>>("x")
            .unwrap_err()
            .to_string();
        assert!(e.contains("beyond a 32-bit float's range"), "{e}");
        assert_eq!(params(serde_json::json!(1e300)).param::<f64>("x").unwrap(), 1e300);
        assert_eq!(params(serde_json::json!(3e38)).param::<f32>("x").unwrap(), 3e38);
    }

    #[test]
    fn an_output_is_read_only_when_it_has_a_consumer() {
        let mut cfg = NodeConfig::with_params("flow", serde_json::Map::new());
        let output = |port: &str, consumers: Vec<ConsumerRef>| OutputBinding {
            port: port.into(),
            key: format!("i/flow/{port}"),
            schema: "evseg.NormalFlow".into(),
            consumers,
        };
        let reader = ConsumerRef {
            node: "hierarchical".into(),
            port: "egomotion_flow".into(),
            feedback: false,
            ack_key: "i/hierarchical/ack".into(),
        };
        cfg.outputs = vec![output("flow", vec![]), output("wide_flow", vec![reader])];
        assert!(cfg.output_is_read("wide_flow"));
        assert!(!cfg.output_is_read("flow"), "an output without consumers");
        assert!(!cfg.output_is_read("nope"), "an output the node does not have");
    }

    #[test]
    fn malformed_or_missing_config_files_are_named_in_the_error() {
        let dir = std::env::temp_dir().join(format!("evseg-config-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bad = dir.join("bad.json");
        std::fs::write(&bad, b"{\"instance\": 3, ").unwrap();
        let err = NodeConfig::load(&bad).unwrap_err().to_string();
        assert!(
            err.contains("bad.json") && err.contains("invalid node config"),
            "{err}"
        );
        let missing = dir.join("missing.json");
        let err = NodeConfig::load(&missing).unwrap_err().to_string();
        assert!(err.contains("missing.json"), "{err}");
        std::fs::write(&bad, [0xffu8, 0xfe, 0x00]).unwrap();
        assert!(NodeConfig::load(&bad).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
