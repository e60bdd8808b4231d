//! The Zenoh key-expression layout. Only the launcher computes keys (and hands them to nodes), so
//! remapping for replay and A/B costs nothing; this module is the one place that spells them.
//!
//! ```text
//! evseg/<instance>/data/<node>/<output>   stage outputs
//! evseg/<instance>/live/<node>            liveliness token of each running node
//! evseg/<instance>/ack/<node>             progress (consumed sequence numbers), for lock-step runs
//! evseg/<instance>/stats/<node>           periodic counters of a node (messages, drops, errors)
//! ```

/// Root of every key.
pub const ROOT: &str = "evseg";

/// Key of output `output` of node `node` in graph instance `instance`.
pub fn data(instance: &str, node: &str, output: &str) -> String {
    format!("{ROOT}/{instance}/data/{node}/{output}")
}

/// Liveliness token key of `node`.
pub fn live(instance: &str, node: &str) -> String {
    format!("{ROOT}/{instance}/live/{node}")
}

/// Wildcard over every liveliness token of an instance.
pub fn live_all(instance: &str) -> String {
    format!("{ROOT}/{instance}/live/*")
}

/// Progress key of `node`.
pub fn ack(instance: &str, node: &str) -> String {
    format!("{ROOT}/{instance}/ack/{node}")
}

/// Wildcard over every progress key of an instance.
pub fn ack_all(instance: &str) -> String {
    format!("{ROOT}/{instance}/ack/*")
}

/// Statistics key of `node`.
pub fn stats(instance: &str, node: &str) -> String {
    format!("{ROOT}/{instance}/stats/{node}")
}

/// Wildcard over every statistics key of an instance.
pub fn stats_all(instance: &str) -> String {
    format!("{ROOT}/{instance}/stats/*")
}

/// True when `name` can be one chunk of a key (node ids, output names, instance names):
/// non-empty, ASCII letters, digits, `-` and `_` only.
pub fn is_valid_chunk(name: &str) -> bool {
    !name.is_empty()
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout() {
        assert_eq!(data("a", "slicer", "slices"), "evseg/a/data/slicer/slices");
        assert_eq!(live("a", "n"), "evseg/a/live/n");
        assert_eq!(ack("b", "n"), "evseg/b/ack/n");
        assert!(is_valid_chunk("normal-flow_2"));
        assert!(!is_valid_chunk("a/b"));
        assert!(!is_valid_chunk("*"));
        assert!(!is_valid_chunk(""));
    }
}
