//! Progress (acknowledgement) and statistics messages of the runtime itself.
//!
//! These are control messages between nodes and to the launcher, not pipeline data; they are JSON
//! so that a person can read them with any Zenoh tool.

use serde::{Deserialize, Serialize};

/// Count meaning "this port is finished; never wait for it again".
pub const DONE: u64 = u64::MAX;

/// What a node has consumed, published on its progress key after every processed slice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// Node id of the consumer.
    pub node: String,
    /// Per input port: number of messages consumed (sequence numbers `0..count`), or [`DONE`].
    pub consumed: Vec<(String, u64)>,
}

/// Counters a node publishes on its statistics key about twice a second and when it ends.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Stats {
    /// Node id.
    pub node: String,
    /// Data messages received (all inputs).
    pub received: u64,
    /// Data messages received per input port (port name -> count, counted as `received`):
    /// shows which input of a waiting node never arrives. Empty from a node that does not send
    /// it.
    #[serde(default)]
    pub received_by_port: std::collections::BTreeMap<String, u64>,
    /// Data messages published (all outputs).
    pub published: u64,
    /// Joined slices processed (or, for a source, steps taken).
    pub processed: u64,
    /// Inputs dropped (live mode: queue overflow or incomplete joins).
    pub dropped: u64,
    /// Inputs that never arrived (live mode: gaps in an input's sequence numbers, i.e. dropped
    /// by the transport under congestion or already dropped by the producer; see
    /// [`crate::transport::SeqGaps`]). Not part of `dropped`, so a loss is not counted twice
    /// at the same node.
    #[serde(default)]
    pub missed: u64,
    /// Messages refused (wrong schema or version, undecodable).
    pub refused: u64,
    /// Last sequence number processed.
    pub last_seq: Option<u64>,
    /// Seconds spent in the node's own logic.
    pub busy_s: f64,
    /// True once the node has finished.
    pub finished: bool,
    /// Seconds since this process's node started (its subscriptions declared), by its own
    /// clock. Tells a restarted node's first stats from its previous process's last ones (the
    /// launcher's start-up watchdog). 0 from a node that does not send it.
    #[serde(default)]
    pub up_s: f64,
    /// Seconds the node's logic has been inside its current slice (or source step), when it is
    /// and is not waiting for credit; `None` between slices. Published about once a second
    /// while a slice lasts over a second, so the launcher tells a node computing a long slice
    /// from one waiting for input. `None` from a node that does not send it.
    #[serde(default)]
    pub computing_s: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stats from a node built before `up_s` existed (or a foreign node) still parse, with
    /// `up_s` 0; stats of the wrong shape are an error, not a panic.
    #[test]
    fn stats_without_up_s_parse_and_malformed_stats_are_an_error() {
        let old = br#"{"node":"a","received":3,"published":1,"processed":1,"dropped":0,
            "refused":0,"last_seq":0,"busy_s":0.5,"finished":false}"#;
        let s: Stats = serde_json::from_slice(old).unwrap();
        assert_eq!((s.node.as_str(), s.received, s.up_s), ("a", 3, 0.0));
        assert!(s.received_by_port.is_empty());
        let with = br#"{"node":"a","received":0,"published":0,"processed":0,"dropped":0,
            "refused":0,"last_seq":null,"busy_s":0,"finished":false,"up_s":2.5}"#;
        assert_eq!(serde_json::from_slice::<Stats>(with).unwrap().up_s, 2.5);
        for bad in [&br#"{"node":"a","up_s":"soon"}"#[..], b"{", b"[]"] {
            assert!(serde_json::from_slice::<Stats>(bad).is_err());
        }
    }
}
