//! Telling the user when the other machines of a graph stay silent.
//!
//! A launcher started with `--machine NAME` runs that machine's nodes and a Zenoh router that
//! keeps trying to reach the graph's other routers (another launcher may start later), so an
//! unreachable peer (wrong address, a firewall, the other launcher never started) used to
//! leave the run waiting without a word. After [`PEER_WARN_AFTER`] the launcher says which
//! machines no node has been heard from, whether any router is connected at all, and the
//! endpoints it listens on and connects to. The same holds for `--connect` endpoints of a run
//! on one machine that no router answers. It warns once per run and does not stop it: the
//! other launcher may still come.

use std::collections::BTreeMap;
use std::time::Duration;

use evseg_graph::Graph;
use evseg_runtime::progress::Stats;

/// How long a run waits for the other machines before it says they are silent.
pub const PEER_WARN_AFTER: Duration = Duration::from_secs(20);

/// What the launcher watches for: the graph's other machines that run nodes, and its own
/// endpoints.
#[derive(Debug, Clone)]
pub struct PeerWatch {
    /// (machine, its nodes) of every other machine with nodes.
    others: Vec<(String, Vec<String>)>,
    listen: Vec<String>,
    connect: Vec<String>,
    /// The graph file, as the user gave it (for the command in the hint).
    graph_file: String,
    /// Checked once after [`PEER_WARN_AFTER`] (warned or found well): nothing more to do.
    done: bool,
}

impl PeerWatch {
    /// For a launcher running `here`'s nodes of `graph` (read from `graph_file`; `here` `None`:
    /// every node runs here) with its router's `listen` and `connect` endpoints.
    pub fn new(
        graph: &Graph,
        graph_file: &str,
        here: Option<&str>,
        listen: &[String],
        connect: &[String],
    ) -> Self {
        let others = match here {
            None => Vec::new(),
            Some(here) => graph
                .machines
                .iter()
                .filter(|m| m.name != here)
                .map(|m| {
                    let nodes = graph.nodes_on(&m.name).iter().map(|n| n.id.clone()).collect();
                    (m.name.clone(), nodes)
                })
                .filter(|(_, nodes): &(String, Vec<String>)| !nodes.is_empty())
                .collect(),
        };
        Self {
            others,
            listen: listen.to_vec(),
            connect: connect.to_vec(),
            graph_file: graph_file.to_string(),
            done: false,
        }
    }

    /// True while there is something to watch that has not been checked (the caller may skip
    /// asking Zenoh for its routers otherwise).
    pub fn pending(&self) -> bool {
        !self.done && (!self.others.is_empty() || !self.connect.is_empty())
    }

    /// The warning to give now, `elapsed` into the run with `routers` other routers connected
    /// to this one and the nodes' latest `stats`; `None` when too early, when all is well, or
    /// once checked (the run is checked once, at the first call after [`PEER_WARN_AFTER`]).
    pub fn check(
        &mut self,
        elapsed: Duration,
        routers: usize,
        stats: &BTreeMap<String, Stats>,
    ) -> Option<String> {
        if self.done || elapsed < PEER_WARN_AFTER {
            return None;
        }
        self.done = true;
        let silent: Vec<&(String, Vec<String>)> = self
            .others
            .iter()
            .filter(|(_, nodes)| !nodes.iter().any(|n| stats.contains_key(n)))
            .collect();
        let unanswered = !self.connect.is_empty() && routers == 0;
        if silent.is_empty() && !unanswered {
            return None;
        }
        let secs = elapsed.as_secs();
        let endpoints = format!(
            "this launcher's router listens on {:?} and connects to {:?}",
            self.listen, self.connect
        );
        let routers_said = match routers {
            0 => "no other router is connected to this one".to_string(),
            1 => "1 other router is connected".to_string(),
            n => format!("{n} other routers are connected"),
        };
        if silent.is_empty() {
            return Some(format!(
                "warning: after {secs} s no router answers at {:?} ({endpoints}); is the address \
                 right and reachable from here?",
                self.connect
            ));
        }
        let list: Vec<String> = silent
            .iter()
            .map(|(m, nodes)| format!("`{m}` (nodes {})", nodes.join(", ")))
            .collect();
        let hint = if routers == 0 {
            let commands: Vec<String> = silent
                .iter()
                .map(|(m, _)| format!("`evseg run {} --machine {m}`", self.graph_file))
                .collect();
            format!(
                "start {} there, and check that the endpoints are reachable (address, port, \
                 firewall)",
                commands.join(", ")
            )
        } else {
            "is its launcher running this graph with the same instance name?".to_string()
        };
        Some(format!(
            "warning: after {secs} s nothing has been heard from machine {}: {routers_said} \
             ({endpoints}); {hint}. The run goes on waiting for it.",
            list.join(", ")
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph() -> Graph {
        let describe = |binary: &str| -> Result<evseg_schemas::describe::NodeDescription, String> {
            Ok(evseg_runtime::describe::Describe::new(binary, "test").build())
        };
        let yaml = r#"
name: two
zenoh:
  machines:
    robot: { listen: ["tcp/127.0.0.1:17447"] }
    base: { listen: ["tcp/127.0.0.1:17448"], connect: ["tcp/127.0.0.1:17447"] }
    idle: { listen: ["tcp/127.0.0.1:17449"] }
nodes:
  - id: a
    run: x
    machine: robot
  - id: b
    run: x
    machine: base
"#;
        evseg_graph::check_str("two.yaml", yaml, &describe).expect("test graph")
    }

    fn heard(ids: &[&str]) -> BTreeMap<String, Stats> {
        ids.iter().map(|id| (id.to_string(), Stats::default())).collect()
    }

    #[test]
    fn a_silent_machine_is_named_once_after_the_wait() {
        let g = graph();
        let listen = vec!["tcp/127.0.0.1:17448".to_string()];
        let connect = vec!["tcp/127.0.0.1:17447".to_string()];
        let mut w = PeerWatch::new(&g, "two.yaml", Some("base"), &listen, &connect);
        let late = PEER_WARN_AFTER + Duration::from_secs(1);
        assert_eq!(w.check(Duration::from_secs(5), 0, &heard(&["b"])), None);
        let m = w.check(late, 0, &heard(&["b"])).expect("a warning");
        assert!(m.contains("machine `robot` (nodes a)"), "{m}");
        assert!(m.contains("no other router is connected"), "{m}");
        assert!(
            m.contains("start `evseg run two.yaml --machine robot` there"),
            "{m}"
        );
        assert!(m.contains("tcp/127.0.0.1:17447"), "{m}");
        // The machine without nodes is not waited for; the warning is given once.
        assert!(!m.contains("idle"), "{m}");
        assert_eq!(w.check(late * 2, 0, &heard(&["b"])), None);
        // Heard from: nothing to say, and nothing more to watch.
        let mut w = PeerWatch::new(&g, "two.yaml", Some("base"), &listen, &connect);
        assert!(w.pending());
        assert_eq!(w.check(late, 1, &heard(&["a", "b"])), None);
        assert!(!w.pending());
        // Connected but silent: another instance or graph.
        let mut w = PeerWatch::new(&g, "two.yaml", Some("base"), &listen, &connect);
        let m = w.check(late, 1, &heard(&["b"])).expect("a warning");
        assert!(
            m.contains("1 other router is connected") && m.contains("instance"),
            "{m}"
        );
    }

    #[test]
    fn a_connect_endpoint_nobody_answers_is_named_on_one_machine() {
        let g = graph();
        let listen = vec!["tcp/127.0.0.1:17447".to_string()];
        let late = PEER_WARN_AFTER + Duration::from_secs(1);
        let mut w = PeerWatch::new(&g, "two.yaml", None, &listen, &["tcp/127.0.0.1:9".to_string()]);
        let m = w.check(late, 0, &heard(&["a", "b"])).expect("a warning");
        assert!(m.contains("no router answers at [\"tcp/127.0.0.1:9\"]"), "{m}");
        let mut w = PeerWatch::new(&g, "two.yaml", None, &listen, &[]);
        assert_eq!(w.check(late, 0, &heard(&[])), None);
    }
}
