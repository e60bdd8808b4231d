//! `evseg replay run.mcap --graph graph.yaml --from slicer`: the nodes downstream of a replay
//! point run live, fed by the recorded outputs of the replay point and the nodes upstream of it.
//!
//! The launcher removes the replay point and every node it depends on (through non-feedback
//! inputs) from the resolved graph, and adds one `evseg-replay` node in their place: one output
//! per removed output that a remaining node consumes, named like the recording's topic
//! (`node/output`) and bound to the original key ([`output_key`]), so the live nodes' inputs
//! keep their keys and credits. Outputs the recorder of this run (`--record`) alone consumes are
//! replayed too when the recording has them. Before anything starts, the recording is read and
//! checked: a missing channel or one of another schema is an error naming the file and the
//! channel, except a missing channel that only optional input ports read (a recording made
//! before those ports were wired): those ports are left unwired, with a note; a cut-off
//! recording is replayed as far as it was recovered, with a warning.

use std::collections::BTreeSet;
use std::path::PathBuf;

use anyhow::{Context, bail};
use evseg_graph::{Consumer, Graph, NodeSpec, OutputSpec, RestartPolicy};
use evseg_recorder::read::Recording;
use evseg_replay::check::{Wanted, check_channels, check_channels_with, check_recording_with};
use evseg_replay::error::ReplayError;
use evseg_replay::keep::{KeptSlices, kept_slices};
use evseg_schemas::keys;

use crate::record::RECORDER_BINARY;

/// Binary of the replay source.
pub const REPLAY_BINARY: &str = "evseg-replay";
/// Node id of the replay source (with `-2`, `-3`, ... when the graph already uses it).
pub const REPLAY_ID: &str = "replay";

/// What `evseg replay` was asked to replay.
#[derive(Debug, Clone)]
pub struct ReplaySpec {
    /// The MCAP recording.
    pub recording: PathBuf,
    /// The replay point: this node and the nodes upstream of it are replayed, not run.
    pub from: String,
    /// Replay a recording with gaps: only the slices every replayed channel holds, renumbered
    /// (`evseg replay --skip-gaps`, see `evseg_replay::keep`); otherwise a gap is refused.
    pub skip_gaps: bool,
    /// Playback speed relative to the recorded publish times; `None` = as fast as lock-step
    /// credits allow.
    pub speed: Option<f64>,
}

/// Refuses overrides (`flag` `node.param=value`, e.g. `--set`) of nodes that `from` replays
/// (the set [`upstream`] gives): such a node is not run, so the value would change nothing,
/// and a comparison or evaluation that seems to include it would silently not.
pub fn refuse_overrides_of_replayed(
    replaced: &BTreeSet<String>,
    from: &str,
    sets: &[String],
    flag: &str,
) -> anyhow::Result<()> {
    for s in sets {
        let node = s.split_once('.').map_or(s.as_str(), |(n, _)| n);
        if replaced.contains(node) {
            bail!(
                "{flag} `{s}`: node `{node}` is replayed from the recording, not run (`--from {from}` \
                 replays it and every node upstream of it), so the value would change nothing; \
                 to run `{node}`, replay from a node that does not depend on it (or use `evseg run`)"
            );
        }
    }
    Ok(())
}

/// The replay point and every node it depends on through non-feedback inputs.
pub fn upstream(graph: &Graph, from: &str) -> anyhow::Result<BTreeSet<String>> {
    if graph.node(from).is_none() {
        let ids: Vec<&str> = graph.nodes.iter().map(|n| n.id.as_str()).collect();
        bail!("--from `{from}`: the graph has no such node (nodes: {ids:?})");
    }
    let mut seen = BTreeSet::new();
    let mut todo = vec![from.to_string()];
    while let Some(id) = todo.pop() {
        if !seen.insert(id.clone()) {
            continue;
        }
        if let Some(n) = graph.node(&id) {
            todo.extend(
                n.inputs
                    .iter()
                    .filter(|i| !i.feedback)
                    .map(|i| i.from_node.clone()),
            );
        }
    }
    Ok(seen)
}

fn is_recorder(graph: &Graph, id: &str) -> bool {
    graph.node(id).is_some_and(|n| n.binary == RECORDER_BINARY)
}

/// A replayed output's topic in the recording and on the replay node, `node/output`.
fn topic(node: &str, output: &str) -> String {
    format!("{node}/{output}")
}

/// A checked replay: the nodes it replaces and the recording it reads.
#[derive(Debug)]
pub struct ReplayPlan {
    spec: ReplaySpec,
    /// Absolute path of the recording.
    file: PathBuf,
    replaced: BTreeSet<String>,
    recording: Recording,
    /// Topics (`node/output`) missing from the recording whose live consumers all take them on
    /// optional ports: not replayed, and those ports left unwired.
    unwired: BTreeSet<String>,
    /// With `skip_gaps`: the slices replayed (renumbered) and the topics they were found on.
    kept: Option<(KeptSlices, BTreeSet<String>)>,
}

/// The outputs of the `replaced` nodes that nodes staying live read, split into those some
/// live node reads on a required port and those read only on optional ports.
fn replayed_outputs(graph: &Graph, replaced: &BTreeSet<String>) -> (Vec<Wanted>, Vec<Wanted>) {
    let (mut required, mut optional) = (Vec::new(), Vec::new());
    for n in graph.nodes.iter().filter(|n| replaced.contains(&n.id)) {
        for o in &n.outputs {
            let live: Vec<&Consumer> = o
                .consumers
                .iter()
                .filter(|c| !replaced.contains(&c.node))
                .collect();
            if live.is_empty() {
                continue;
            }
            let w = Wanted {
                topic: topic(&n.id, &o.name),
                schema: o.schema.clone(),
                needed_by: live
                    .iter()
                    .map(|c| format!("{}.{}", c.node, c.port))
                    .collect::<Vec<_>>()
                    .join(", "),
            };
            let only_optional = live.iter().all(|c| {
                graph
                    .node(&c.node)
                    .and_then(|node| node.input(&c.port))
                    .is_some_and(|i| i.optional)
            });
            if only_optional {
                optional.push(w);
            } else {
                required.push(w);
            }
        }
    }
    (required, optional)
}

/// The topics of `optional` (outputs read only on optional ports) that `recording` does not
/// have. One it has with another schema is still an error.
fn missing_optional(
    recording: &Recording,
    optional: &[Wanted],
    allow_gaps: bool,
) -> Result<BTreeSet<String>, ReplayError> {
    let mut missing = BTreeSet::new();
    for w in optional {
        match check_channels_with(recording, std::slice::from_ref(w), allow_gaps) {
            Ok(()) => {}
            Err(ReplayError::MissingChannel { .. }) => {
                missing.insert(w.topic.clone());
            }
            Err(e) => return Err(e),
        }
    }
    Ok(missing)
}

/// `--skip-gaps`: the slices every one of `topics` holds in the recording `file`, with a note
/// of what is left out; an error when none is.
fn slices_every_channel_holds(file: &std::path::Path, topics: &[String]) -> anyhow::Result<KeptSlices> {
    let report = kept_slices(file, topics).map_err(|e| anyhow::anyhow!("{e}"))?;
    if report.kept.is_empty() {
        bail!(
            "{}: no slice is held by every replayed channel ({topics:?}); nothing to replay",
            file.display()
        );
    }
    let left_out: Vec<String> = report
        .channels
        .iter()
        .filter(|(_, (_, out))| *out > 0)
        .map(|(t, (n, out))| format!("{t}: {out} of {n}"))
        .collect();
    eprintln!(
        "note: --skip-gaps: replaying the {n} slices every replayed channel holds, renumbered \
         0..{n} ({} slice number(s) held by no channel; left out, held by some channels only: {})",
        report.missing_everywhere,
        if left_out.is_empty() {
            "none".to_string()
        } else {
            left_out.join(", ")
        },
        n = report.kept.len(),
    );
    Ok(report.kept)
}

impl ReplayPlan {
    /// Works out what `spec` replaces in `graph` (before any recorder is added) and checks the
    /// recording holds every output a remaining node consumes, and that no override in `sets`
    /// (`--set`) is of a replayed node. Reads the whole recording once.
    pub fn new(graph: &Graph, spec: &ReplaySpec, sets: &[String]) -> anyhow::Result<Self> {
        if let Some(s) = spec.speed
            && !(s.is_finite() && s > 0.0)
        {
            bail!("--speed {s}: must be a number > 0 (leave it out to replay as fast as credits allow)");
        }
        let replaced = upstream(graph, &spec.from)?;
        refuse_overrides_of_replayed(&replaced, &spec.from, sets, "--set")?;
        if graph.nodes.iter().all(|n| replaced.contains(&n.id)) {
            bail!(
                "--from `{}`: no node of the graph runs downstream of it, nothing to replay into",
                spec.from
            );
        }
        let (wanted, optional) = replayed_outputs(graph, &replaced);
        let file = std::path::absolute(&spec.recording)
            .with_context(|| format!("recording {}", spec.recording.display()))?;
        let recording =
            check_recording_with(&file, &wanted, spec.skip_gaps).map_err(|e| anyhow::anyhow!("{e}"))?;
        let unwired =
            missing_optional(&recording, &optional, spec.skip_gaps).map_err(|e| anyhow::anyhow!("{e}"))?;
        let kept = if spec.skip_gaps {
            let topics: Vec<String> = wanted
                .iter()
                .chain(optional.iter().filter(|w| !unwired.contains(&w.topic)))
                .map(|w| w.topic.clone())
                .collect();
            Some((
                slices_every_channel_holds(&file, &topics)?,
                topics.into_iter().collect(),
            ))
        } else {
            None
        };
        for w in optional.iter().filter(|w| unwired.contains(&w.topic)) {
            eprintln!(
                "note: {} has no `{}`; the optional input {} is left unwired",
                file.display(),
                w.topic,
                w.needed_by
            );
        }
        if recording.truncated.is_some() {
            eprintln!(
                "warning: {}; replaying what was recovered",
                recording.completeness()
            );
        }
        let count = |t: &str| {
            recording
                .channels
                .values()
                .find(|c| c.topic == t)
                .map_or(0, |c| c.messages)
        };
        let list: Vec<String> = wanted
            .iter()
            .chain(optional.iter().filter(|w| !unwired.contains(&w.topic)))
            .map(|w| format!("{} ({} messages)", w.topic, count(&w.topic)))
            .collect();
        tracing::info!(from = %spec.from, outputs = ?list, "replay");
        Ok(Self {
            spec: spec.clone(),
            file,
            replaced,
            recording,
            unwired,
            kept,
        })
    }

    /// `graph` (the one given to [`ReplayPlan::new`], possibly with a recorder added) without
    /// the replaced nodes and with a replay source on `machine` publishing their consumed
    /// outputs. Outputs only the recorder consumes are replayed when the recording has them,
    /// else the recorder does not record them.
    pub fn apply(&self, graph: &Graph, machine: &str) -> anyhow::Result<Graph> {
        let mut g = graph.clone();
        let mut id = REPLAY_ID.to_string();
        let mut k = 1;
        while g.node(&id).is_some() {
            k += 1;
            id = format!("{REPLAY_ID}-{k}");
        }
        let mut outputs = Vec::new();
        let mut unrecorded = Vec::new();
        for n in graph.nodes.iter().filter(|n| self.replaced.contains(&n.id)) {
            for o in &n.outputs {
                let live: Vec<Consumer> = o
                    .consumers
                    .iter()
                    .filter(|c| !self.replaced.contains(&c.node))
                    .cloned()
                    .collect();
                if live.is_empty() {
                    continue;
                }
                let t = topic(&n.id, &o.name);
                if self.unwired.contains(&t) {
                    continue;
                }
                let only_recorder = live.iter().all(|c| is_recorder(graph, &c.node));
                // Renumbered slices are matched on the topics they were found on only.
                if only_recorder && self.kept.as_ref().is_some_and(|(_, topics)| !topics.contains(&t)) {
                    unrecorded.push(t);
                    continue;
                }
                if only_recorder {
                    let w = Wanted {
                        topic: t.clone(),
                        schema: o.schema.clone(),
                        needed_by: String::new(),
                    };
                    if check_channels(&self.recording, &[w]).is_err() {
                        unrecorded.push(t);
                        continue;
                    }
                }
                outputs.push(OutputSpec {
                    name: t,
                    schema: o.schema.clone(),
                    consumers: live,
                });
            }
        }
        if !unrecorded.is_empty() {
            eprintln!(
                "note: {} has no {unrecorded:?}; this run's recording leaves them out",
                self.file.display()
            );
        }
        // The replay publishes what the replaced nodes published, so it gets the largest of
        // their shared-memory pools (a replaced slicer's, not the graph's smaller default).
        let shm = &graph.shared_memory;
        let pool_mib = graph
            .nodes
            .iter()
            .filter(|n| self.replaced.contains(&n.id))
            .map(|n| shm.pool_mib_of(n))
            .max()
            .filter(|&mib| mib != shm.pool_mib);
        g.nodes.retain(|n| !self.replaced.contains(&n.id));
        for n in &mut g.nodes {
            // Optional inputs whose channel the recording lacks.
            n.inputs
                .retain(|i| !self.unwired.contains(&topic(&i.from_node, &i.from_output)));
            // Feedback into a replaced node: nobody reads it now.
            for o in &mut n.outputs {
                o.consumers.retain(|c| !self.replaced.contains(&c.node));
            }
            if n.binary == RECORDER_BINARY {
                // Inputs from replaced nodes stay only where the replay publishes them.
                n.inputs.retain(|i| {
                    !self.replaced.contains(&i.from_node) || outputs.iter().any(|o| o.name == i.port)
                });
            }
        }
        let mut params = serde_json::Map::new();
        params.insert("path".into(), self.file.display().to_string().into());
        match &self.kept {
            // The slices every channel holds: a cut-off recording's last slices are left out
            // the same way, so no limits are needed.
            Some((kept, _)) => {
                params.insert("keep".into(), serde_json::to_value(kept)?);
            }
            None => {
                let limits = self.limits(&outputs);
                if !limits.is_empty() {
                    params.insert("limits".into(), serde_json::Value::Object(limits));
                }
            }
        }
        params.insert(
            "speed".into(),
            self.spec
                .speed
                .map_or(serde_json::Value::Null, serde_json::Value::from),
        );
        g.nodes.insert(
            0,
            NodeSpec {
                id,
                binary: REPLAY_BINARY.into(),
                machine: machine.to_string(),
                params,
                inputs: Vec::new(),
                outputs,
                restart: RestartPolicy::default(),
                pool_mib,
                span: Default::default(),
                param_spans: Default::default(),
            },
        );
        Ok(g)
    }
}

impl ReplayPlan {
    /// For a cut-off recording: the outputs of one replaced node that were recovered with
    /// different message counts are all replayed up to the smallest count (a node publishes all
    /// its outputs for a slice together, and a consumer joining two of them by slice would
    /// otherwise see them end at different slices). Empty for a complete recording.
    fn limits(&self, outputs: &[OutputSpec]) -> serde_json::Map<String, serde_json::Value> {
        let mut limits = serde_json::Map::new();
        if self.recording.truncated.is_none() {
            return limits;
        }
        let count = |t: &str| {
            self.recording
                .channels
                .values()
                .find(|c| c.topic == t)
                .map_or(0, |c| c.messages)
        };
        let mut by_node: std::collections::BTreeMap<&str, Vec<(&str, u64)>> = Default::default();
        for o in outputs {
            let node = o.name.split_once('/').map_or(o.name.as_str(), |(n, _)| n);
            by_node.entry(node).or_default().push((&o.name, count(&o.name)));
        }
        for (node, list) in by_node {
            let least = list.iter().map(|(_, n)| *n).min().unwrap_or(0);
            if list.iter().any(|(_, n)| *n != least) {
                eprintln!(
                    "note: the recording is cut off; the outputs of `{node}` are replayed up to {least} messages each (recovered: {list:?})"
                );
                for (topic, _) in list {
                    limits.insert(topic.to_string(), least.into());
                }
            }
        }
        limits
    }
}

/// Key of output `output` of `node` in `instance`: the original producer's key for a replay
/// source's output (named `producer/output`), else the node's own.
pub fn output_key(instance: &str, node: &NodeSpec, output: &str) -> String {
    match output.split_once('/') {
        Some((producer, name)) if node.binary == REPLAY_BINARY => keys::data(instance, producer, name),
        _ => keys::data(instance, &node.id, output),
    }
}

/// Refuses a `--record` file that is the recording being replayed (the recorder would truncate
/// it before the replay reads it).
pub fn check_record_target(
    recording: &std::path::Path,
    record: Option<&std::path::Path>,
) -> anyhow::Result<()> {
    if let Some(record) = record
        && let (Ok(a), Ok(b)) = (recording.canonicalize(), record.canonicalize())
        && a == b
    {
        anyhow::bail!(
            "--record {} is the recording being replayed: recording the replay there would \
             overwrite it; give another file",
            record.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recording_a_replay_onto_its_own_recording_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let rec = dir.path().join("run.mcap");
        std::fs::write(&rec, b"x").unwrap();
        let same = dir.path().join(".").join("run.mcap");
        let e = check_record_target(&rec, Some(&same)).unwrap_err().to_string();
        assert!(e.contains("is the recording being replayed"), "{e}");
        assert!(check_record_target(&rec, Some(&dir.path().join("b.mcap"))).is_ok());
        assert!(check_record_target(&rec, None).is_ok());
    }

    fn graph() -> Graph {
        let node = |id: &str, inputs: serde_json::Value, outputs: serde_json::Value| {
            serde_json::json!({"id": id, "binary": format!("evseg-{id}"), "machine": "local",
                "params": {}, "restart": {"policy": "never", "max": 3},
                "inputs": inputs, "outputs": outputs})
        };
        let input = |port: &str, from: &str, out: &str, feedback: bool| {
            serde_json::json!({"port": port, "schema": "s", "from_node": from, "from_output": out,
                "feedback": feedback})
        };
        let output = |name: &str, consumers: &[(&str, &str, bool)]| {
            let c: Vec<_> = consumers
                .iter()
                .map(|(n, p, f)| serde_json::json!({"node": n, "port": p, "feedback": f}))
                .collect();
            serde_json::json!({"name": name, "schema": "s", "consumers": c})
        };
        serde_json::from_value(serde_json::json!({
            "name": "t", "mode": "lockstep", "window": 4, "queue": 8,
            "machines": [{"name": "local", "listen": ["tcp/127.0.0.1:7447"], "connect": []}],
            "nodes": [
                node("source", serde_json::json!([]), serde_json::json!([
                    output("events", &[("slicer", "events", false)]),
                    output("truth", &[("slicer", "truth", false)])])),
                node("slicer", serde_json::json!([input("events", "source", "events", false),
                        input("truth", "source", "truth", false),
                        input("tracks", "seg", "tracks", true)]),
                    serde_json::json!([output("slices", &[("eval", "slices", false), ("seg", "slices", false)]),
                        output("truth", &[("eval", "truth", false)])])),
                node("seg", serde_json::json!([input("slices", "slicer", "slices", false)]),
                    serde_json::json!([output("tracks", &[("eval", "result", false), ("slicer", "tracks", true)])])),
                node("eval", serde_json::json!([input("slices", "slicer", "slices", false),
                        input("truth", "slicer", "truth", false), input("result", "seg", "tracks", false)]),
                    serde_json::json!([output("metrics", &[])]))
            ]
        }))
        .unwrap()
    }

    #[test]
    fn upstream_follows_inputs_but_not_feedback() {
        let g = graph();
        let up: Vec<String> = upstream(&g, "slicer").unwrap().into_iter().collect();
        assert_eq!(up, ["slicer", "source"]);
        let up: Vec<String> = upstream(&g, "seg").unwrap().into_iter().collect();
        assert_eq!(up, ["seg", "slicer", "source"]);
        let err = upstream(&g, "nope").unwrap_err().to_string();
        assert!(err.contains("nope") && err.contains("slicer"), "{err}");
    }

    fn plan(g: &Graph, topics: &[&str]) -> ReplayPlan {
        let channels = topics
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let c = evseg_recorder::read::ChannelInfo {
                    id: i as u16,
                    topic: t.to_string(),
                    schema: "s".into(),
                    version: None,
                    message_encoding: evseg_recorder::MESSAGE_ENCODING.into(),
                    metadata: Default::default(),
                    messages: 3,
                    bytes: 30,
                    time_ns: Some((1, 2)),
                    gaps: Default::default(),
                };
                (i as u16, c)
            })
            .collect();
        let recording = Recording {
            file: "r.mcap".into(),
            size: 100,
            channels,
            metadata: vec![],
            attachments: vec![],
            chunks: 1,
            messages: 3 * topics.len() as u64,
            orphan_messages: 0,
            truncated: None,
        };
        let spec = ReplaySpec {
            recording: "r.mcap".into(),
            from: "slicer".into(),
            speed: Some(2.0),
            skip_gaps: false,
        };
        let replaced = upstream(g, &spec.from).unwrap();
        let (_, optional) = replayed_outputs(g, &replaced);
        let unwired = missing_optional(&recording, &optional, false).unwrap();
        ReplayPlan {
            replaced,
            file: "/r.mcap".into(),
            spec,
            recording,
            unwired,
            kept: None,
        }
    }

    #[test]
    fn the_replay_node_publishes_what_the_live_nodes_and_the_recorder_read() {
        let g = graph();
        let p = plan(&g, &["slicer/slices", "slicer/truth", "source/truth"]);
        assert!(check_channels(&p.recording, &[]).is_ok());
        // A recorder of every output, as `--record` adds it.
        let (with_rec, rec) = crate::record::add_recorder(
            &g,
            std::path::Path::new("/x.mcap"),
            &evseg_graph::RecordSpec::default(),
            "local",
            Default::default(),
        )
        .unwrap();
        let out = p.apply(&with_rec, "local").unwrap();
        let ids: Vec<&str> = out.nodes.iter().map(|n| n.id.as_str()).collect();
        assert_eq!(ids, ["replay", "seg", "eval", rec.as_str()]);
        let replay = &out.nodes[0];
        assert_eq!(replay.binary, REPLAY_BINARY);
        assert_eq!(replay.params["path"], "/r.mcap");
        assert_eq!(replay.params["speed"], 2.0);
        let names: Vec<&str> = replay.outputs.iter().map(|o| o.name.as_str()).collect();
        // source/events is not in the recording: the recorder leaves it out.
        assert_eq!(names, ["source/truth", "slicer/slices", "slicer/truth"]);
        let slices: Vec<&str> = replay.outputs[1]
            .consumers
            .iter()
            .map(|c| c.node.as_str())
            .collect();
        assert_eq!(slices, ["eval", rec.as_str(), "seg"]);
        let recorder = out.node(&rec).unwrap();
        let ports: Vec<&str> = recorder.inputs.iter().map(|i| i.port.as_str()).collect();
        assert_eq!(
            ports,
            [
                "source/truth",
                "slicer/slices",
                "slicer/truth",
                "seg/tracks",
                "eval/metrics"
            ]
        );
        // The tracker's feedback into the replaced slicer is cut.
        let tracks = out.node("seg").unwrap().output("tracks").unwrap();
        assert!(tracks.consumers.iter().all(|c| c.node != "slicer"));
        // Without a recorder only the live nodes' inputs are replayed.
        let out = p.apply(&g, "local").unwrap();
        let names: Vec<&str> = out.nodes[0].outputs.iter().map(|o| o.name.as_str()).collect();
        assert_eq!(names, ["slicer/slices", "slicer/truth"]);
        // The graph's pools: the replay keeps none of its own.
        assert_eq!(out.nodes[0].pool_mib, None);
    }

    #[test]
    fn a_channel_only_optional_ports_read_may_be_missing_and_leaves_them_unwired() {
        // `seg` also reads the slicer's `hint`, on an optional port.
        let with_hint = |optional: bool| {
            let mut g = graph();
            for n in &mut g.nodes {
                match n.id.as_str() {
                    "slicer" => n.outputs.push(OutputSpec {
                        name: "hint".into(),
                        schema: "s".into(),
                        consumers: vec![Consumer {
                            node: "seg".into(),
                            port: "hint".into(),
                            feedback: false,
                        }],
                    }),
                    "seg" => n.inputs.push(evseg_graph::InputSpec {
                        port: "hint".into(),
                        schema: "s".into(),
                        from_node: "slicer".into(),
                        from_output: "hint".into(),
                        feedback: false,
                        optional,
                        span: Default::default(),
                    }),
                    _ => {}
                }
            }
            g
        };
        let g = with_hint(true);
        let names =
            |g: &Graph| -> Vec<String> { g.nodes[0].outputs.iter().map(|o| o.name.clone()).collect() };
        // A recording made before the port was wired: not replayed, and the port left unwired.
        let p = plan(&g, &["slicer/slices", "slicer/truth"]);
        let out = p.apply(&g, "local").unwrap();
        assert_eq!(names(&out), ["slicer/slices", "slicer/truth"]);
        assert!(out.node("seg").unwrap().input("hint").is_none());
        assert!(out.node("seg").unwrap().input("slices").is_some());
        // A recording with it: replayed and wired.
        let p = plan(&g, &["slicer/slices", "slicer/truth", "slicer/hint"]);
        let out = p.apply(&g, "local").unwrap();
        assert_eq!(names(&out), ["slicer/slices", "slicer/truth", "slicer/hint"]);
        assert!(out.node("seg").unwrap().input("hint").is_some());
        // Present with another schema: still an error.
        let replaced = upstream(&g, "slicer").unwrap();
        let (required, optional) = replayed_outputs(&g, &replaced);
        assert_eq!(optional.len(), 1);
        let mut rec = p.recording.clone();
        for c in rec.channels.values_mut() {
            c.schema = "other".into();
        }
        assert!(matches!(
            missing_optional(&rec, &optional, false),
            Err(ReplayError::WrongSchema { .. })
        ));
        // Read on a required port, the channel is required (a missing one is an error).
        let (required_too, optional) = replayed_outputs(&with_hint(false), &replaced);
        assert!(optional.is_empty());
        assert_eq!(required_too.len(), required.len() + 1);
    }

    #[test]
    fn the_replay_node_gets_the_largest_pool_of_the_nodes_it_replaces() {
        let mut g = graph();
        g.shared_memory.pool_mib = 4;
        for (id, mib) in [("source", 16), ("slicer", 32), ("seg", 64)] {
            if let Some(n) = g.nodes.iter_mut().find(|n| n.id == id) {
                n.pool_mib = Some(mib);
            }
        }
        let p = plan(&g, &["slicer/slices", "slicer/truth"]);
        let out = p.apply(&g, "local").unwrap();
        assert_eq!(out.nodes[0].id, "replay");
        // `seg` stays live with its own pool; the replay takes the slicer's, not 4 MiB.
        assert_eq!(out.nodes[0].pool_mib, Some(32));
        assert_eq!(out.node("seg").and_then(|n| n.pool_mib), Some(64));
    }

    #[test]
    fn a_cut_off_recording_ends_the_outputs_of_one_node_together() {
        let g = graph();
        let mut p = plan(&g, &["slicer/slices", "slicer/truth"]);
        let out = p.apply(&g, "local").unwrap();
        assert!(out.nodes[0].params.get("limits").is_none(), "complete: no limits");
        p.recording.truncated = Some(evseg_recorder::read::Truncation {
            offset: 50,
            reason: "cut".into(),
        });
        let out = p.apply(&g, "local").unwrap();
        assert!(
            out.nodes[0].params.get("limits").is_none(),
            "same counts: no limits"
        );
        if let Some(c) = p.recording.channels.get_mut(&1) {
            c.messages = 2;
        }
        let out = p.apply(&g, "local").unwrap();
        assert_eq!(
            out.nodes[0].params["limits"],
            serde_json::json!({"slicer/slices": 2, "slicer/truth": 2})
        );
    }

    #[test]
    fn replay_outputs_keep_the_original_keys() {
        let mut replay = graph().nodes[0].clone();
        replay.binary = REPLAY_BINARY.into();
        replay.id = "replay".into();
        assert_eq!(
            output_key("i", &replay, "slicer/slices"),
            "evseg/i/data/slicer/slices"
        );
        let seg = &graph().nodes[2];
        assert_eq!(output_key("i", seg, "tracks"), "evseg/i/data/seg/tracks");
    }
}
