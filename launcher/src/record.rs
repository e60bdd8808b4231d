//! Recording a run: the launcher adds an `evseg-recorder` node to the resolved graph, with one
//! input per recorded output (port name = `node/output`), and lists it as a consumer of each of
//! those outputs, so in lock-step mode the producers wait for it like for any consumer.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use evseg_graph::{Consumer, Graph, InputSpec, NodeSpec, RecordSpec, RestartPolicy};

/// Binary of the recorder node.
pub const RECORDER_BINARY: &str = "evseg-recorder";
/// Node id of the recorder (with `-2`, `-3`, ... when the graph already uses it).
pub const RECORDER_ID: &str = "recorder";

/// 64-bit FNV-1a of `text`, as 16 hex digits: the graph hash stored in recordings (of the
/// canonical resolved graph, without the recorder, so a recorded and an unrecorded run of one
/// graph have the same hash).
pub fn graph_hash(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

/// Where a run's recording goes: `--record` (relative to the working folder) wins over the
/// graph's `record.path` (relative to the run folder). `None`: not recorded.
pub fn recording_path(cli: Option<&Path>, graph: &Graph, run_dir: &Path) -> anyhow::Result<Option<PathBuf>> {
    let path = match (cli, &graph.record) {
        (Some(p), _) => std::path::absolute(p).with_context(|| format!("--record {}", p.display()))?,
        (None, Some(r)) => run_dir.join(&r.path),
        (None, None) => return Ok(None),
    };
    Ok(Some(path))
}

/// `graph` with a recorder node on `machine` writing `path`, consuming `record.outputs`
/// (`node/output`; empty = every published output), with `record`'s writer settings (chunk
/// size, zstd level) as its parameters where given (`record.path` is not used: `path` is the
/// file). `metadata` is stored in the recording as the run's facts. Returns the new graph and
/// the recorder's node id.
pub fn add_recorder(
    graph: &Graph,
    path: &Path,
    record: &RecordSpec,
    machine: &str,
    metadata: serde_json::Map<String, serde_json::Value>,
) -> anyhow::Result<(Graph, String)> {
    let outputs = &record.outputs;
    let mut g = graph.clone();
    let mut id = RECORDER_ID.to_string();
    let mut k = 1;
    while g.node(&id).is_some() {
        k += 1;
        id = format!("{RECORDER_ID}-{k}");
    }
    let selected: Vec<(String, String)> = if outputs.is_empty() {
        g.nodes
            .iter()
            .flat_map(|n| n.outputs.iter().map(move |o| (n.id.clone(), o.name.clone())))
            .collect()
    } else {
        outputs
            .iter()
            .map(|r| {
                r.split_once('/')
                    .map(|(n, o)| (n.to_string(), o.to_string()))
                    .with_context(|| format!("recorded output `{r}`: expected node/output"))
            })
            .collect::<anyhow::Result<_>>()?
    };
    if selected.is_empty() {
        bail!("nothing to record: the graph publishes no output");
    }
    let mut inputs = Vec::new();
    for (node, output) in &selected {
        let topic = format!("{node}/{output}");
        let spec = g
            .nodes
            .iter_mut()
            .find(|n| n.id == *node)
            .and_then(|n| n.outputs.iter_mut().find(|o| o.name == *output))
            .with_context(|| format!("recorded output `{topic}` is not published by this graph"))?;
        spec.consumers.push(Consumer {
            node: id.clone(),
            port: topic.clone(),
            feedback: false,
        });
        spec.consumers.sort();
        inputs.push(InputSpec {
            port: topic,
            schema: spec.schema.clone(),
            from_node: node.clone(),
            from_output: output.clone(),
            feedback: false,
            optional: false,
            span: Default::default(),
        });
    }
    let mut params = serde_json::Map::new();
    params.insert("path".into(), path.display().to_string().into());
    params.insert("metadata".into(), serde_json::Value::Object(metadata));
    if let Some(b) = record.chunk_bytes {
        params.insert("chunk_bytes".into(), b.into());
    }
    if let Some(z) = record.zstd_level {
        params.insert("zstd_level".into(), z.into());
    }
    g.nodes.push(NodeSpec {
        id: id.clone(),
        binary: RECORDER_BINARY.into(),
        machine: machine.to_string(),
        params,
        inputs,
        outputs: Vec::new(),
        restart: RestartPolicy::default(),
        pool_mib: None,
        span: Default::default(),
        param_spans: Default::default(),
    });
    Ok((g, id))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph() -> Graph {
        serde_json::from_value(serde_json::json!({
            "name": "t", "mode": "lockstep", "window": 4, "queue": 8,
            "machines": [{"name": "local", "listen": ["tcp/127.0.0.1:7447"], "connect": []}],
            "nodes": [
                {"id": "source", "binary": "evseg-source", "machine": "local", "params": {},
                 "inputs": [], "restart": {"policy": "never", "max": 3},
                 "outputs": [{"name": "events", "schema": "evseg.EventPacket",
                              "consumers": [{"node": "slicer", "port": "events", "feedback": false}]}]},
                {"id": "slicer", "binary": "evseg-slicer", "machine": "local", "params": {},
                 "restart": {"policy": "never", "max": 3},
                 "inputs": [{"port": "events", "schema": "evseg.EventPacket", "from_node": "source",
                             "from_output": "events", "feedback": false}],
                 "outputs": [{"name": "slices", "schema": "evseg.Slice", "consumers": []}]},
                {"id": "recorder", "binary": "evseg-x", "machine": "local", "params": {},
                 "restart": {"policy": "never", "max": 3}, "inputs": [], "outputs": []}
            ]
        }))
        .unwrap()
    }

    #[test]
    fn every_output_gets_the_recorder_as_a_consumer() {
        let (g, id) = add_recorder(
            &graph(),
            Path::new("/tmp/r.mcap"),
            &RecordSpec::default(),
            "local",
            Default::default(),
        )
        .unwrap();
        assert_eq!(id, "recorder-2", "the graph already has a `recorder`");
        let rec = g.node(&id).unwrap();
        let ports: Vec<&str> = rec.inputs.iter().map(|i| i.port.as_str()).collect();
        assert_eq!(ports, ["source/events", "slicer/slices"]);
        assert_eq!(rec.inputs[1].schema, "evseg.Slice");
        assert_eq!(rec.params["path"], "/tmp/r.mcap");
        let events = g.node("source").unwrap().output("events").unwrap();
        assert_eq!(events.consumers.len(), 2);
        assert!(
            events
                .consumers
                .iter()
                .any(|c| c.node == id && c.port == "source/events")
        );
        assert_eq!(g.node("slicer").unwrap().outputs[0].consumers[0].node, id);
    }

    #[test]
    fn a_selection_records_only_those_and_unknown_outputs_fail() {
        let (g, id) = add_recorder(
            &graph(),
            Path::new("r.mcap"),
            &RecordSpec {
                outputs: vec!["slicer/slices".into()],
                zstd_level: Some(9),
                ..Default::default()
            },
            "local",
            Default::default(),
        )
        .unwrap();
        assert_eq!(g.node(&id).unwrap().inputs.len(), 1);
        // The writer settings given, and only those, become the recorder's parameters.
        assert_eq!(g.node(&id).unwrap().params["zstd_level"], 9);
        assert!(!g.node(&id).unwrap().params.contains_key("chunk_bytes"));
        assert_eq!(g.node("source").unwrap().outputs[0].consumers.len(), 1);
        let err = add_recorder(
            &graph(),
            Path::new("r"),
            &RecordSpec {
                outputs: vec!["slicer/nope".into()],
                ..Default::default()
            },
            "local",
            Default::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(err.contains("slicer/nope"), "{err}");
    }

    #[test]
    fn graph_hash_is_fnv1a() {
        // FNV-1a 64 test vectors.
        assert_eq!(graph_hash(""), "cbf29ce484222325");
        assert_eq!(graph_hash("a"), "af63dc4c8601ec8c");
    }
}
