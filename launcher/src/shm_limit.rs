//! Whether Zenoh's shared memory can work for the nodes this launcher starts.
//!
//! Zenoh 1.x locks (`mlock`) the whole of every shared-memory segment it maps: a node's own
//! pool, which it creates at start-up, and the pool of every producer whose frames it reads.
//! Locked memory counts against `RLIMIT_MEMLOCK` (`ulimit -l`, 8 MiB for a normal user on
//! common Linux distributions) unless the process has `CAP_IPC_LOCK`. Where a node cannot
//! create its pool, Zenoh logs an error and the node sends over the socket (it works, slower).
//! Where it created its pool but a consumer cannot map it, Zenoh drops the frames at the
//! consumer without an error, and a lock-step graph stalls for good (measured as a normal user
//! with 4 MiB pools: the slicer never got the source's first packet). So the launcher checks the
//! limit before it starts the nodes and turns shared memory off for all of them when any node
//! would pass it.

use std::path::Path;

use evseg_graph::{NodeSpec, SharedMemory};

/// Bytes Zenoh locks per process whose shared memory a node maps (its own and each producer's)
/// besides the pool itself: its watchdog and metadata segments. Measured with Zenoh 1.10
/// (`VmLck` of the default graph's nodes, as root, pools of 1 and 4 MiB): 1.44 MiB for a node's
/// own, 1.27-1.32 MiB per producer mapped; 1.5 MiB keeps a margin.
pub const ZENOH_SEGMENT_OVERHEAD_BYTES: u64 = 3 << 19;

/// The memory one node would lock with shared memory on.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeLock {
    /// Node id.
    pub node: String,
    /// Its own pool, MiB.
    pub pool_mib: u32,
    /// Distinct producers of its inputs among the nodes started here (their pools it maps).
    pub producers: usize,
    /// Bytes locked: its pool and one pool per such producer, each with
    /// [`ZENOH_SEGMENT_OVERHEAD_BYTES`].
    pub bytes: u64,
}

/// Per node of `nodes` (the nodes this launcher starts), what it would lock with the pool sizes
/// of `shm` (each node's own `pool_mib` or the graph's). A producer started by another
/// machine's launcher is reached over the network, so only producers in `nodes` count.
pub fn locked_per_node(nodes: &[NodeSpec], shm: &SharedMemory) -> Vec<NodeLock> {
    let pool_bytes = |n: &NodeSpec| u64::from(shm.pool_mib_of(n)) << 20;
    nodes
        .iter()
        .map(|n| {
            let mut producers: Vec<&NodeSpec> = n
                .inputs
                .iter()
                .filter(|i| i.from_node != n.id)
                .filter_map(|i| nodes.iter().find(|m| m.id == i.from_node))
                .collect();
            producers.sort_unstable_by(|a, b| a.id.cmp(&b.id));
            producers.dedup_by(|a, b| a.id == b.id);
            let mapped: u64 = producers.iter().map(|m| pool_bytes(m)).sum();
            NodeLock {
                node: n.id.clone(),
                pool_mib: shm.pool_mib_of(n),
                producers: producers.len(),
                bytes: pool_bytes(n) + mapped + ZENOH_SEGMENT_OVERHEAD_BYTES * (1 + producers.len() as u64),
            }
        })
        .collect()
}

/// How much memory this process (and the nodes it starts, which inherit its limits) may lock,
/// bytes; `None` when there is no limit (`RLIMIT_MEMLOCK` infinite, or `CAP_IPC_LOCK` in the
/// effective capabilities, which root has outside containers).
pub fn memlock_allowance() -> Option<u64> {
    if has_cap_ipc_lock() {
        return None;
    }
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit writes into the struct it is given and reads nothing else.
    if unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut lim) } != 0 {
        // Unknown: assume no limit, as before this check (Zenoh then reports what fails).
        return None;
    }
    (lim.rlim_cur != libc::RLIM_INFINITY).then_some(lim.rlim_cur)
}

/// Bit of `CAP_IPC_LOCK` in the capability sets of `/proc/<pid>/status`.
const CAP_IPC_LOCK_BIT: u32 = 14;

fn has_cap_ipc_lock() -> bool {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| cap_eff(&s))
        .is_some_and(|caps| caps >> CAP_IPC_LOCK_BIT & 1 == 1)
}

/// The effective capability set (`CapEff:` line, hexadecimal) of a `/proc/<pid>/status` text.
fn cap_eff(status: &str) -> Option<u64> {
    let line = status.lines().find(|l| l.starts_with("CapEff:"))?;
    u64::from_str_radix(line["CapEff:".len()..].trim(), 16).ok()
}

/// The node that would lock the most, when that is more than `allowance` (`None`: no limit).
pub fn over_allowance(locks: &[NodeLock], allowance: Option<u64>) -> Option<&NodeLock> {
    let limit = allowance?;
    locks.iter().filter(|l| l.bytes > limit).max_by_key(|l| l.bytes)
}

/// Why shared memory as set in `shm` cannot work for `nodes` (the nodes one launcher starts,
/// from the graph file `graph_file`) under this user's locked-memory limit: the node that would
/// lock the most, how much, the limit and how to change it. `None` when it is off or fits.
pub fn over_limit(nodes: &[NodeSpec], shm: &SharedMemory, graph_file: &Path) -> Option<String> {
    if !shm.enabled {
        return None;
    }
    let locks = locked_per_node(nodes, shm);
    let allowance = memlock_allowance();
    let over = over_allowance(&locks, allowance)?;
    let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
    let producers = match over.producers {
        1 => "1 node".to_string(),
        n => format!("{n} nodes"),
    };
    Some(format!(
        "node `{}` would lock {:.1} MiB (its {} MiB pool and those of the {producers} it reads, which Zenoh locks in memory), above this user's locked-memory limit of {:.1} MiB (`ulimit -l`). Raise the limit (`memlock` in /etc/security/limits.conf, or CAP_IPC_LOCK) or lower `zenoh.shared_memory.pool_mib` (or the nodes' own `pool_mib`) in {}",
        over.node,
        mib(over.bytes),
        over.pool_mib,
        mib(allowance.unwrap_or(u64::MAX)),
        graph_file.display()
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(text: &str) -> evseg_graph::Graph {
        let describe = |binary: &str| -> Result<evseg_schemas::describe::NodeDescription, String> {
            let mut d = evseg_runtime::describe::Describe::new(binary, "test");
            d = match binary {
                "src" => d.output::<evseg_schemas::EventPacket>("out", "o"),
                "mid" => d
                    .input::<evseg_schemas::EventPacket>("a", "i")
                    .output::<evseg_schemas::EventPacket>("out", "o"),
                _ => d
                    .input::<evseg_schemas::EventPacket>("a", "i")
                    .input::<evseg_schemas::EventPacket>("b", "i")
                    .input::<evseg_schemas::EventPacket>("c", "i"),
            };
            Ok(d.build())
        };
        evseg_graph::check_str("g.yaml", text, &describe).unwrap()
    }

    #[test]
    fn a_node_locks_its_pool_and_one_pool_per_distinct_local_producer() {
        let g = graph(
            "name: g\nnodes:\n  - { id: s, run: src }\n  - { id: m, run: mid, inputs: { a: s/out } }\n  - { id: k, run: sink, inputs: { a: s/out, b: m/out, c: s/out } }\n",
        );
        let mib = 1u64 << 20;
        let shm = SharedMemory {
            enabled: true,
            pool_mib: 8,
        };
        let locks = locked_per_node(&g.nodes, &shm);
        let by = |id: &str| locks.iter().find(|l| l.node == id).unwrap().clone();
        assert_eq!(by("s").producers, 0);
        assert_eq!(by("s").bytes, 8 * mib + ZENOH_SEGMENT_OVERHEAD_BYTES);
        assert_eq!(by("m").producers, 1);
        // `s` read twice is one segment.
        assert_eq!(by("k").producers, 2);
        assert_eq!(by("k").bytes, 3 * (8 * mib + ZENOH_SEGMENT_OVERHEAD_BYTES));
        // On a machine without `s`, its frames come over the network.
        let here: Vec<_> = g.nodes.iter().filter(|n| n.id != "s").cloned().collect();
        assert_eq!(
            locked_per_node(&here, &shm).iter().map(|l| l.producers).max(),
            Some(1)
        );
        // The node over the limit that locks the most is named; no limit, nothing.
        assert_eq!(
            over_allowance(&locks, Some(16 * mib)).map(|l| l.node.as_str()),
            Some("k")
        );
        assert_eq!(over_allowance(&locks, Some(32 * mib)), None);
        assert_eq!(over_allowance(&locks, None), None);
    }

    #[test]
    fn each_pool_counts_at_its_own_size_in_its_node_and_in_every_consumer() {
        // `s` has a 32 MiB pool of its own, `m` the graph's 2 MiB.
        let g = graph(
            "name: g\nzenoh: { shared_memory: { pool_mib: 2 } }\nnodes:\n  - { id: s, run: src, pool_mib: 32 }\n  - { id: m, run: mid, inputs: { a: s/out } }\n  - { id: k, run: sink, inputs: { a: s/out, b: m/out, c: m/out } }\n",
        );
        assert_eq!(g.node("s").and_then(|n| n.pool_mib), Some(32));
        assert_eq!(g.node("m").and_then(|n| n.pool_mib), None);
        let (mib, o) = (1u64 << 20, ZENOH_SEGMENT_OVERHEAD_BYTES);
        let locks = locked_per_node(&g.nodes, &g.shared_memory);
        let by = |id: &str| locks.iter().find(|l| l.node == id).unwrap().bytes;
        assert_eq!(by("s"), 32 * mib + o);
        assert_eq!(by("m"), 2 * mib + 32 * mib + 2 * o);
        assert_eq!(by("k"), 2 * mib + 32 * mib + 2 * mib + 3 * o);
    }

    #[test]
    fn the_effective_capabilities_are_read_from_the_status_text() {
        let root = "Name:\tevseg\nCapInh:\t0000000000000000\nCapEff:\t000001ffffffffff\n";
        let user = "Name:\tevseg\nCapEff:\t0000000000000000\n";
        assert_eq!(cap_eff(root).map(|c| c >> CAP_IPC_LOCK_BIT & 1), Some(1));
        assert_eq!(cap_eff(user), Some(0));
        assert_eq!(cap_eff("Name:\tx\n"), None);
    }
}
