//! Valid graphs: defaults, consumers, order, keys, canonical form.

mod common;

use common::{VALID, check, text};
use evseg_graph::{Consumer, GraphError, Machine, Mode, Restart, SharedMemory, Span, check_str};
use serde_json::json;

#[test]
fn valid_graph_resolves_with_defaults_consumers_and_order() {
    let graph = check(VALID).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(graph.file, "g.yaml");
    assert_eq!(graph.name, "demo");
    assert_eq!(graph.mode, Mode::Lockstep);
    assert_eq!((graph.window, graph.queue), (4, 8));
    assert_eq!(graph.machines, [Machine::default_local()]);
    assert_eq!(graph.machines[0].listen, ["tcp/127.0.0.1:7447"]);

    let ids: Vec<&str> = graph.nodes.iter().map(|n| n.id.as_str()).collect();
    assert_eq!(ids, ["source", "slicer", "sink", "tracker"]);

    let source = graph.node("source").unwrap();
    assert_eq!(source.binary, "evseg-source");
    assert_eq!(source.machine, "local");
    assert_eq!(
        json!(source.params),
        json!({ "kind": "synthetic", "seconds": 5, "seed": 7 })
    );
    assert_eq!(source.span, Span::new(8, 5));
    assert_eq!(source.param_spans["seconds"], Span::new(10, 15));
    let events = source.output("events").unwrap();
    assert_eq!(events.schema, "evseg.EventPacket");
    assert_eq!(
        events.consumers,
        [Consumer {
            node: "slicer".into(),
            port: "events".into(),
            feedback: false
        }]
    );
    assert_eq!(source.output("truth").unwrap().consumers[0].port, "truth");

    let slicer = graph.node("slicer").unwrap();
    // Only the listed output is published; the slicer's own `truth` is not.
    assert_eq!(slicer.outputs.len(), 1);
    assert_eq!(
        slicer.outputs[0].consumers,
        [
            Consumer {
                node: "sink".into(),
                port: "slices".into(),
                feedback: false
            },
            Consumer {
                node: "tracker".into(),
                port: "slices".into(),
                feedback: false
            },
        ]
    );
    assert_eq!(json!(slicer.params), json!({ "window_ms": 30.0, "imu": true }));
    assert_eq!(
        slicer.inputs.iter().map(|i| i.port.as_str()).collect::<Vec<_>>(),
        ["events", "truth"]
    );
    assert_eq!(slicer.inputs[0].span, Span::new(14, 7));

    let sink = graph.node("sink").unwrap();
    assert_eq!(
        json!(sink.params),
        json!({ "path": "out.txt", "tags": [], "format": { "csv": true } })
    );
    assert!(sink.outputs.is_empty());
    assert_eq!(sink.restart.policy, Restart::Never);

    let tracker = graph.node("tracker").unwrap();
    let previous = tracker.input("previous").unwrap();
    assert!(previous.feedback);
    assert_eq!(
        (previous.from_node.as_str(), previous.from_output.as_str()),
        ("tracker", "tracks")
    );
    assert_eq!(previous.schema, "evseg.Tracks");
    assert_eq!(
        tracker.output("tracks").unwrap().consumers,
        [Consumer {
            node: "tracker".into(),
            port: "previous".into(),
            feedback: true
        }]
    );
    assert_eq!(tracker.restart.policy, Restart::OnFailure);
    assert_eq!(tracker.restart.max, 3);
    assert!(tracker.restart.allows_restart(2));
    assert!(!tracker.restart.allows_restart(3));
}

#[test]
fn keys_machines_and_instance() {
    let graph = check(VALID).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        graph.data_key("slicer", "slices").as_deref(),
        Some("evseg/demo/data/slicer/slices")
    );
    assert_eq!(graph.data_key("slicer", "truth"), None, "not published");
    assert_eq!(graph.data_key("nobody", "x"), None);
    let keys = graph.node_keys("tracker").unwrap();
    assert_eq!(keys.inputs[0].key, "evseg/demo/data/slicer/slices");
    assert_eq!(keys.inputs[1].key, "evseg/demo/data/tracker/tracks");
    assert!(keys.inputs[1].feedback);
    assert_eq!(keys.outputs[0].key, "evseg/demo/data/tracker/tracks");
    assert_eq!(graph.data_keys().len(), 4);
    assert_eq!(graph.nodes_on("local").len(), 4);
    assert!(graph.nodes_on("base").is_empty());

    let b = graph.clone().with_instance("demo-b").unwrap();
    assert_eq!(
        b.data_key("source", "events").as_deref(),
        Some("evseg/demo-b/data/source/events")
    );
    match graph.with_instance("a/b") {
        Err(GraphError::InvalidInstance { name }) => assert_eq!(name, "a/b"),
        other => panic!("accepted a bad instance name: {other:?}"),
    }
}

#[test]
fn machines_in_declaration_order_and_default_first_machine() {
    let lines = [
        "name: robot-run",
        "mode: live",
        "queue: 2",
        "zenoh:",
        "  machines:",
        "    robot: { listen: [\"tcp/127.0.0.1:7447\"] }",
        "    base:  { listen: [\"tcp/127.0.0.1:7448\"], connect: [\"tcp/127.0.0.1:7447\"] }",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
        "  - id: slicer",
        "    run: evseg-slicer",
        "    machine: base",
        "    inputs: { events: source/events }",
    ];
    let graph = check(&lines).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(graph.mode, Mode::Live);
    assert_eq!(graph.queue, 2);
    let names: Vec<&str> = graph.machines.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["robot", "base"]);
    assert_eq!(graph.machine("base").unwrap().connect, ["tcp/127.0.0.1:7447"]);
    assert_eq!(graph.node("source").unwrap().machine, "robot");
    let on_base: Vec<&str> = graph.nodes_on("base").iter().map(|n| n.id.as_str()).collect();
    assert_eq!(on_base, ["slicer"]);
}

#[test]
fn shared_memory_defaults_and_settings() {
    let graph = check(VALID).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(graph.shared_memory, SharedMemory::default());
    assert!(graph.shared_memory.enabled);
    // Defaults stay out of the canonical form, so older graphs hash as before.
    let json = serde_json::to_value(&graph).unwrap();
    assert!(json.get("shared_memory").is_none(), "{json}");

    let lines = [
        "name: z",
        "zenoh:",
        "  shared_memory: { enabled: false }",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
    ];
    let graph = check(&lines).unwrap_or_else(|e| panic!("{e}"));
    assert!(!graph.shared_memory.enabled);
    assert_eq!(graph.shared_memory.pool_mib, SharedMemory::DEFAULT_POOL_MIB);
    assert_eq!(graph.machines, [Machine::default_local()]);
    let json = serde_json::to_value(&graph).unwrap();
    assert_eq!(json["shared_memory"], json!({"enabled": false, "pool_mib": 32}));

    let lines = [
        "name: z",
        "zenoh:",
        "  shared_memory:",
        "    pool_mib: 256",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
    ];
    let graph = check(&lines).unwrap_or_else(|e| panic!("{e}"));
    assert!(graph.shared_memory.enabled);
    assert_eq!(graph.shared_memory.pool_mib, 256);
}

#[test]
fn canonical_json_ignores_layout_and_key_order() {
    let a = check(VALID).unwrap_or_else(|e| panic!("{e}"));
    // Same graph: keys reordered, flow style changed, comments added, params given in another
    // order, nested mapping keys in another order.
    let b_lines = [
        "# a comment that shifts every line",
        "nodes:",
        "  - run: evseg-sink",
        "    id: sink",
        "    inputs:",
        "      slices: slicer/slices",
        "    params:",
        "      path: out.txt",
        "  - { id: source, params: { seconds: 5 }, run: evseg-source }",
        "  - id: slicer",
        "    outputs: [slices]",
        "    run: evseg-slicer",
        "    inputs: { truth: source/truth, events: source/events }",
        "  - id: tracker",
        "    inputs:",
        "      previous: { feedback: true, from: tracker/tracks }",
        "      slices: slicer/slices",
        "    run: evseg-loop",
        "    restart: { max: 3, policy: on-failure }",
        "mode: lockstep",
        "name: demo",
    ];
    let b = check(&b_lines).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(a.canonical_json(), b.canonical_json());
    assert_ne!(a.node("source").unwrap().span, b.node("source").unwrap().span);
    let dump: serde_json::Value = serde_json::from_str(&a.canonical_json()).unwrap();
    assert_eq!(dump["nodes"][0]["id"], "source");
    assert_eq!(
        dump["nodes"][3]["restart"],
        json!({ "policy": "on-failure", "max": 3 })
    );
    assert_eq!(dump["mode"], "lockstep");
    assert!(dump["nodes"][0].get("span").is_none());
    assert!(dump.get("file").is_none());
}

#[test]
fn feedback_cycle_accepted_and_the_same_cycle_unmarked_refused() {
    // Two loop nodes feeding each other's `previous`; one edge marked.
    let marked = [
        "name: loop",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
        "  - id: slicer",
        "    run: evseg-slicer",
        "    inputs: { events: source/events }",
        "  - id: a",
        "    run: evseg-loop",
        "    inputs:",
        "      slices: slicer/slices",
        "      previous: { from: b/tracks, feedback: true }",
        "  - id: b",
        "    run: evseg-loop",
        "    inputs:",
        "      slices: slicer/slices",
        "      previous: a/tracks",
    ];
    let graph = check(&marked).unwrap_or_else(|e| panic!("{e}"));
    let ids: Vec<&str> = graph.nodes.iter().map(|n| n.id.as_str()).collect();
    assert_eq!(ids, ["source", "slicer", "a", "b"]);

    let mut unmarked = marked.to_vec();
    unmarked[11] = "      previous: b/tracks";
    common::single_error(
        &unmarked,
        12,
        7,
        &[
            "cycle",
            "a -> b -> a",
            "feedback: true",
            "previous: { from: b/tracks, feedback: true }",
        ],
    );
}

#[test]
fn load_reads_files_and_reports_io_and_encoding_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("graph.yaml");
    std::fs::write(&path, text(VALID)).unwrap();
    let graph = evseg_graph::load(&path, &common::resolver).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(graph.file, path.display().to_string());

    match evseg_graph::load(&dir.path().join("missing.yaml"), &common::resolver) {
        Err(e @ GraphError::Io { .. }) => assert!(e.to_string().contains("missing.yaml"), "{e}"),
        other => panic!("{other:?}"),
    }

    // A binary blob: valid first line, then bytes that are not UTF-8.
    std::fs::write(&path, b"name: x\nn\xc3\xa9: \xff\xfe\x00\x01").unwrap();
    match evseg_graph::load(&path, &common::resolver) {
        Err(GraphError::Invalid(d)) => {
            assert_eq!((d.len(), d[0].line, d[0].column), (1, 2, 5), "{d:?}");
            assert!(
                d[0].message.contains("not UTF-8") && d[0].message.contains("byte offset 13"),
                "{d:?}"
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn error_display_lists_every_diagnostic() {
    let err = check_str("x.yaml", "name: [\n", &common::resolver).unwrap_err();
    let shown = err.to_string();
    assert!(
        shown.starts_with("x.yaml:2:1: error: YAML syntax error"),
        "{shown}"
    );
}

#[test]
fn canonical_json_reads_back() {
    let graph = check(VALID).unwrap_or_else(|e| panic!("{e}"));
    let back: evseg_graph::Graph = serde_json::from_str(&graph.canonical_json()).unwrap();
    assert_eq!(back.canonical_json(), graph.canonical_json());
    assert_eq!(back.nodes[0].span, Span::default());
}
