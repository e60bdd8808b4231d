//! Checking a graph as written against the descriptions of its binaries, and building the
//! resolved [`Graph`] when nothing is wrong.

use std::collections::{BTreeMap, HashMap};

use evseg_schemas::describe::NodeDescription;
use evseg_schemas::keys::is_valid_chunk;
use serde_json::{Map, Value as Json};

use crate::cycles::{self, Edge};
use crate::diagnostic::{Problems, Span, did_you_mean, name_list};
use crate::model::{Consumer, Graph, InputSpec, Machine, NodeSpec, OutputSpec, RecordSpec};
use crate::params;
use crate::raw::{RawGraph, RawInput, RawNode, RawRecord};

/// Turns a binary name into its description (the launcher runs `<binary> --describe`).
pub type Resolver<'r> = &'r dyn Fn(&str) -> Result<NodeDescription, String>;

/// What the per-node pass found out about one node.
struct NodeWork<'d> {
    description: Option<&'d NodeDescription>,
    machine: String,
    params: Map<String, Json>,
    param_spans: BTreeMap<String, Span>,
    /// Outputs the node publishes, in description order.
    published: Vec<String>,
    /// Inputs that were wired correctly.
    inputs: Vec<InputSpec>,
}

/// Checks `raw`; returns the resolved graph when no problem was found (in this pass or before).
pub(crate) fn check(raw: &RawGraph<'_>, resolver: Resolver<'_>, p: &mut Problems) -> Option<Graph> {
    if let Some(name) = &raw.name
        && !is_valid_chunk(&name.value)
    {
        p.error(
            name.at,
            format!(
                "invalid instance name `{}`: use ASCII letters, digits, `-` and `_`",
                name.value
            ),
        );
    }
    let machines: Vec<Machine> = if raw.machines.is_empty() {
        vec![Machine::default_local()]
    } else {
        raw.machines
            .iter()
            .map(|m| Machine {
                name: m.name.value.clone(),
                listen: m.listen.clone(),
                connect: m.connect.clone(),
            })
            .collect()
    };
    let index_of = index_ids(&raw.nodes, p);
    let descriptions = describe_all(&raw.nodes, resolver);

    let mut work: Vec<NodeWork<'_>> = raw
        .nodes
        .iter()
        .map(|node| {
            let description = node
                .run
                .as_ref()
                .and_then(|run| match descriptions.get(&run.value)? {
                    Ok(d) => Some(d),
                    Err(message) => {
                        p.error(run.at, message.clone());
                        None
                    }
                });
            check_node(node, description, &machines, p)
        })
        .collect();

    let edges = wire(&raw.nodes, &mut work, &index_of, p);
    let plain_edges: Vec<Edge> = edges.iter().map(|w| w.edge).collect();
    for (i, node) in raw.nodes.iter().enumerate() {
        report_missing_inputs(i, node, &raw.nodes, &work, p);
    }
    for cycle in cycles::find_cycles(raw.nodes.len(), &plain_edges) {
        let closing = &edges[cycle.closing_edge];
        let input = &raw.nodes[closing.edge.to].inputs[closing.input];
        let mut names: Vec<String> = cycle.nodes.iter().map(|&i| node_name(&raw.nodes[i])).collect();
        names.extend(names.first().cloned());
        p.error(
            input.port.at,
            format!(
                "cycle without a feedback edge: {}; mark the edge that goes back as feedback: \
                 `{}: {{ from: {}, feedback: true }}` (it then carries the previous slice's message)",
                names.join(" -> "),
                input.port.value,
                input.from.value
            ),
        );
    }
    let record = raw
        .record
        .as_ref()
        .and_then(|r| check_record(r, &raw.nodes, &work, p));
    if !p.is_empty() {
        return None;
    }
    let name = raw.name.as_ref()?.value.clone();
    let order = cycles::topological_order(raw.nodes.len(), &plain_edges);
    Some(Graph {
        record,
        file: p.file().to_string(),
        name,
        mode: raw.mode,
        window: raw.window,
        queue: raw.queue,
        machines,
        shared_memory: raw.shared_memory,
        nodes: build_nodes(&raw.nodes, work, &order)?,
    })
}

/// Checks the `record:` section: a path, and outputs that exist (`node/output`).
fn check_record(
    record: &RawRecord,
    nodes: &[RawNode<'_>],
    work: &[NodeWork<'_>],
    p: &mut Problems,
) -> Option<RecordSpec> {
    let path = record.path.as_ref()?;
    if path.value.trim().is_empty() {
        p.error(
            path.at,
            "`record.path` is empty; name the MCAP file, e.g. `run.mcap`",
        );
        return None;
    }
    let mut outputs = Vec::new();
    let mut known = Vec::new();
    for (node, w) in nodes.iter().zip(work) {
        let Some(id) = &node.id else { continue };
        for o in &w.published {
            known.push(format!("{}/{o}", id.value));
        }
    }
    for r in record.outputs.iter().flatten() {
        if known.contains(&r.value) {
            if !outputs.contains(&r.value) {
                outputs.push(r.value.clone());
            }
        } else {
            p.error(
                r.at,
                format!(
                    "`record.outputs`: no output `{}` in this graph{}",
                    r.value,
                    did_you_mean(&r.value, &known)
                ),
            );
        }
    }
    if record.outputs.as_ref().is_some_and(|o| o.is_empty()) {
        p.error(
            record.at,
            "`record.outputs` is empty; leave it out to record every output",
        );
    }
    Some(RecordSpec {
        path: path.value.clone(),
        outputs,
        chunk_bytes: record.chunk_bytes,
        zstd_level: record.zstd_level,
    })
}

/// Node ids to their index (the first node with that id), reporting invalid and repeated ids.
fn index_ids<'a>(nodes: &'a [RawNode<'_>], p: &mut Problems) -> HashMap<&'a str, usize> {
    let mut index_of: HashMap<&str, usize> = HashMap::new();
    for (i, node) in nodes.iter().enumerate() {
        let Some(id) = &node.id else { continue };
        if !is_valid_chunk(&id.value) {
            p.error(
                id.at,
                format!(
                    "invalid node id `{}`: use ASCII letters, digits, `-` and `_`",
                    id.value
                ),
            );
        }
        match index_of.get(id.value.as_str()) {
            Some(&first) => {
                let line = nodes[first].anchor().line;
                p.error(
                    id.at,
                    format!("duplicate node id `{}` (first defined at line {line})", id.value),
                );
            }
            None => {
                index_of.insert(&id.value, i);
            }
        }
    }
    index_of
}

/// Each distinct binary's description (asked once), or the message to report at `run:`.
fn describe_all(
    nodes: &[RawNode<'_>],
    resolver: Resolver<'_>,
) -> HashMap<String, Result<NodeDescription, String>> {
    let mut descriptions = HashMap::new();
    for run in nodes.iter().filter_map(|n| n.run.as_ref()) {
        if descriptions.contains_key(&run.value) {
            continue;
        }
        let described = match resolver(&run.value) {
            Ok(d) => match d.outputs.iter().find(|o| !is_valid_chunk(&o.name)) {
                Some(bad) => Err(format!(
                    "binary `{}` describes an output named `{}`, which cannot be a key chunk; fix the binary",
                    run.value, bad.name
                )),
                None => Ok(d),
            },
            Err(message) => Err(format!(
                "cannot get the description of binary `{}`: {message}",
                run.value
            )),
        };
        descriptions.insert(run.value.clone(), described);
    }
    descriptions
}

/// How a node is named in messages: its id, else its position.
fn node_name(node: &RawNode<'_>) -> String {
    node.id.as_ref().map_or_else(
        || format!("(node at line {})", node.at.line),
        |id| id.value.clone(),
    )
}

/// Checks what can be checked on one node alone: machine, parameters, outputs, input ports.
fn check_node<'d>(
    node: &RawNode<'_>,
    description: Option<&'d NodeDescription>,
    machines: &[Machine],
    p: &mut Problems,
) -> NodeWork<'d> {
    let machine = match &node.machine {
        Some(m) if machines.iter().any(|d| d.name == m.value) => m.value.clone(),
        Some(m) => {
            let declared: Vec<&str> = machines.iter().map(|d| d.name.as_str()).collect();
            p.error(
                m.at,
                format!(
                    "machine `{}` is not declared; declared machines: {}{}",
                    m.value,
                    name_list(&declared),
                    did_you_mean(&m.value, &declared)
                ),
            );
            m.value.clone()
        }
        None => machines.first().map(|m| m.name.clone()).unwrap_or_default(),
    };
    let mut work = NodeWork {
        description,
        machine,
        params: Map::new(),
        param_spans: BTreeMap::new(),
        published: Vec::new(),
        inputs: Vec::new(),
    };
    let Some(description) = description else {
        return work;
    };
    (work.params, work.param_spans) =
        params::resolve(node.params, description, &node_name(node), node.anchor(), p);

    let output_names: Vec<&str> = description.outputs.iter().map(|o| o.name.as_str()).collect();
    match &node.outputs {
        None => work.published = output_names.iter().map(|s| s.to_string()).collect(),
        Some(listed) => {
            for (k, item) in listed.iter().enumerate() {
                if description.output(&item.value).is_none() {
                    p.error(
                        item.at,
                        format!(
                            "unknown output `{}` for `{}`; its outputs: {}{}",
                            item.value,
                            description.binary,
                            name_list(&output_names),
                            did_you_mean(&item.value, &output_names)
                        ),
                    );
                } else if let Some(first) = listed[..k].iter().find(|o| o.value == item.value) {
                    p.error(
                        item.at,
                        format!(
                            "output `{}` is listed twice (first at line {})",
                            item.value, first.at.line
                        ),
                    );
                }
            }
            work.published = output_names
                .iter()
                .filter(|name| listed.iter().any(|o| o.value == **name))
                .map(|s| s.to_string())
                .collect();
        }
    }

    let input_names: Vec<&str> = description.inputs.iter().map(|i| i.name.as_str()).collect();
    for input in &node.inputs {
        if description.input(&input.port.value).is_none() {
            p.error(
                input.port.at,
                format!(
                    "unknown input `{}` for `{}`; its inputs: {}{}",
                    input.port.value,
                    description.binary,
                    name_list(&input_names),
                    did_you_mean(&input.port.value, &input_names)
                ),
            );
        }
    }
    work
}

/// A correctly wired edge and which input (index into the consumer's raw inputs) makes it.
struct WiredEdge {
    edge: Edge,
    input: usize,
}

/// Resolves every `inputs:` reference, reporting bad ones; returns the edges that are right
/// (their [`InputSpec`]s are added to the consumers' work).
fn wire(
    nodes: &[RawNode<'_>],
    work: &mut [NodeWork<'_>],
    index_of: &HashMap<&str, usize>,
    p: &mut Problems,
) -> Vec<WiredEdge> {
    let mut edges = Vec::new();
    for (to, node) in nodes.iter().enumerate() {
        for (k, input) in node.inputs.iter().enumerate() {
            let consumer = work[to].description;
            if let Some((from, spec)) = wire_one(node, consumer, input, work, index_of, nodes, p) {
                work[to].inputs.push(spec);
                edges.push(WiredEdge {
                    edge: Edge {
                        from,
                        to,
                        feedback: input.feedback,
                    },
                    input: k,
                });
            }
        }
    }
    edges
}

fn wire_one(
    node: &RawNode<'_>,
    consumer: Option<&NodeDescription>,
    input: &RawInput,
    work: &[NodeWork<'_>],
    index_of: &HashMap<&str, usize>,
    nodes: &[RawNode<'_>],
    p: &mut Problems,
) -> Option<(usize, InputSpec)> {
    let reference = &input.from;
    let Some((producer_id, output)) = reference
        .value
        .split_once('/')
        .filter(|(n, o)| is_valid_chunk(n) && is_valid_chunk(o))
    else {
        p.error(
            reference.at,
            format!(
                "`{}` is not a reference to an output; write `node/output`, e.g. `source/events`",
                reference.value
            ),
        );
        return None;
    };
    let Some(&from) = index_of.get(producer_id) else {
        let ids: Vec<&str> = nodes
            .iter()
            .filter_map(|n| Some(n.id.as_ref()?.value.as_str()))
            .collect();
        p.error(
            reference.at,
            format!(
                "no node `{producer_id}` in this graph; nodes: {}{}",
                name_list(&ids),
                did_you_mean(producer_id, &ids)
            ),
        );
        return None;
    };
    let producer = &work[from];
    let produced = producer.description?;
    let Some(port) = produced.output(output) else {
        let outputs: Vec<&str> = produced.outputs.iter().map(|o| o.name.as_str()).collect();
        p.error(
            reference.at,
            format!(
                "node `{producer_id}` (`{}`) has no output `{output}`; its outputs: {}{}",
                produced.binary,
                name_list(&outputs),
                did_you_mean(output, &outputs)
            ),
        );
        return None;
    };
    if !producer.published.iter().any(|o| o == output) {
        p.error(
            reference.at,
            format!(
                "node `{producer_id}` does not publish `{output}`: add it to the `outputs:` of `{producer_id}` (line {})",
                nodes[from].at.line
            ),
        );
        return None;
    }
    let taken = consumer?.input(&input.port.value)?;
    if taken.schema != port.schema {
        p.error(
            reference.at,
            format!(
                "input `{}` of node `{}` takes `{}`, but `{}` publishes `{}`",
                input.port.value,
                node_name(node),
                taken.schema,
                reference.value,
                port.schema
            ),
        );
        return None;
    }
    Some((
        from,
        InputSpec {
            port: input.port.value.clone(),
            schema: port.schema.clone(),
            from_node: producer_id.to_string(),
            from_output: output.to_string(),
            feedback: input.feedback,
            optional: taken.optional,
            span: input.port.at,
        },
    ))
}

/// Reports each required input of node `i` that `inputs:` does not mention, naming the outputs
/// in the graph that have the right schema.
fn report_missing_inputs(
    i: usize,
    node: &RawNode<'_>,
    nodes: &[RawNode<'_>],
    work: &[NodeWork<'_>],
    p: &mut Problems,
) {
    let (Some(description), Some(named)) = (work[i].description, &node.named_ports) else {
        return;
    };
    for port in description.inputs.iter().filter(|port| !port.optional) {
        if named.contains(&port.name) {
            continue;
        }
        let candidates: Vec<String> = nodes
            .iter()
            .zip(work)
            .filter_map(|(other, w)| Some((other.id.as_ref()?, w)))
            .flat_map(|(id, w)| {
                w.published
                    .iter()
                    .filter(|o| {
                        w.description
                            .and_then(|d| d.output(o))
                            .is_some_and(|o| o.schema == port.schema)
                    })
                    .map(move |o| format!("{}/{o}", id.value))
            })
            .collect();
        let hint = if candidates.is_empty() {
            String::new()
        } else {
            format!("; outputs with that schema: {}", name_list(&candidates))
        };
        p.error(
            node.anchor(),
            format!(
                "node `{}` leaves its input `{}` (`{}`) unconnected; wire it in `inputs:`{hint}",
                node_name(node),
                port.name,
                port.schema
            ),
        );
    }
}

/// The resolved nodes in `order`, with each output's consumers. Only called without problems,
/// so every node has an id, a binary and a description.
fn build_nodes(nodes: &[RawNode<'_>], work: Vec<NodeWork<'_>>, order: &[usize]) -> Option<Vec<NodeSpec>> {
    let mut consumers: HashMap<(String, String), Vec<Consumer>> = HashMap::new();
    for (node, w) in nodes.iter().zip(&work) {
        let id = node.id.as_ref()?;
        for input in &w.inputs {
            consumers
                .entry((input.from_node.clone(), input.from_output.clone()))
                .or_default()
                .push(Consumer {
                    node: id.value.clone(),
                    port: input.port.clone(),
                    feedback: input.feedback,
                });
        }
    }
    let mut specs: Vec<Option<NodeSpec>> = Vec::with_capacity(nodes.len());
    for (node, w) in nodes.iter().zip(work) {
        let id = node.id.as_ref()?.value.clone();
        let description = w.description?;
        let mut inputs = w.inputs;
        inputs.sort_by_key(|i| description.inputs.iter().position(|d| d.name == i.port));
        let outputs = w
            .published
            .iter()
            .filter_map(|name| {
                let port = description.output(name)?;
                let mut readers = consumers.remove(&(id.clone(), name.clone())).unwrap_or_default();
                readers.sort();
                Some(OutputSpec {
                    name: name.clone(),
                    schema: port.schema.clone(),
                    consumers: readers,
                })
            })
            .collect();
        specs.push(Some(NodeSpec {
            id,
            binary: node.run.as_ref()?.value.clone(),
            machine: w.machine,
            params: w.params,
            inputs,
            outputs,
            restart: node.restart,
            pool_mib: node.pool_mib,
            span: node.at,
            param_spans: w.param_spans,
        }));
    }
    order.iter().map(|&i| specs.get_mut(i)?.take()).collect()
}
