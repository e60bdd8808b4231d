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
    #[error("node {node}, {}: {source}", slice_label(*seq))]
    Logic {
        /// Node id.
        node: String,
        /// Sequence number being processed; `u64::MAX` while finishing (after the last slice).
        seq: u64,
        /// The logic's error.
        source: BoxError,
    },
}

/// "slice 7", or "at the end of the stream" for [`RuntimeError::Logic`]'s `u64::MAX` (an error
/// of a stage's `finish`, e.g. an evaluator that cannot write its report folder).
fn slice_label(seq: u64) -> String {
    if seq == u64::MAX {
        "at the end of the stream".to_string()
    } else {
        format!("slice {seq}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_logic_error_while_finishing_says_so_instead_of_a_huge_slice_number() {
        let e = |seq| RuntimeError::Logic {
            node: "evaluator".into(),
            seq,
            source: "cannot write report".into(),
        };
        assert_eq!(e(3).to_string(), "node evaluator, slice 3: cannot write report");
        assert_eq!(
            e(u64::MAX).to_string(),
            "node evaluator, at the end of the stream: cannot write report"
        );
    }
}
