//! Errors of the node runtime.

use evseg_schemas::CodecError;

/// An error a node's own logic returns; the runtime logs it with the node id and slice.
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// What can go wrong in the runtime.
#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    /// Command line or config file problem.
    #[error("{0}")]
    Config(String),
    /// A parameter is missing or has the wrong type.
    #[error("node {node}: parameter `{name}`: {reason}")]
    Param {
        /// Node id.
        node: String,
        /// Parameter name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// Zenoh failed.
    #[error("zenoh: {0}")]
    Zenoh(String),
    /// A message could not be decoded.
    #[error("node {node}, input `{port}` (key {key}): {source}")]
    Decode {
        /// Node id.
        node: String,
        /// Input port.
        port: String,
        /// Key the message came on.
        key: String,
        /// Codec error (names both schemas on a mismatch).
        source: CodecError,
    },
    /// A message could not be encoded.
    #[error("node {node}, output `{port}`: {source}")]
    Encode {
        /// Node id.
        node: String,
        /// Output port.
        port: String,
        /// Codec error.
        source: CodecError,
    },
    /// The node's code asked for a port it does not have.
    #[error("node {node}: no {direction} port `{port}`")]
    NoPort {
        /// Node id.
        node: String,
        /// "input" or "output".
        direction: &'static str,
        /// Port name.
        port: String,
    },
    /// A consumer disappeared while this node waited for its progress.
    #[error("node {node}: consumer `{consumer}` of output `{port}` is gone")]
    ConsumerGone {
        /// Node id.
        node: String,
        /// Output port.
        port: String,
        /// Consumer node id.
        consumer: String,
    },
    /// The node was asked to stop (signal).
    #[error("stopped by signal")]
    Stopped,
    /// The node's logic failed.
    #[error("node {node}, slice {seq}: {source}")]
    Logic {
        /// Node id.
        node: String,
        /// Sequence number being processed.
        seq: u64,
        /// The logic's error.
        source: BoxError,
    },
}
