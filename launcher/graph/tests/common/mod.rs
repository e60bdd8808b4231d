//! A fake resolver with a few node descriptions, and helpers to check graphs from lines.
#![allow(dead_code)]

use evseg_graph::{Diagnostic, Graph, GraphError, check_str};
use evseg_schemas::describe::{InputPort, NodeDescription, OutputPort, Param};
use serde_json::json;

fn input(name: &str, schema: &str, optional: bool) -> InputPort {
    InputPort {
        name: name.into(),
        schema: schema.into(),
        optional,
        doc: String::new(),
    }
}

fn output(name: &str, schema: &str) -> OutputPort {
    OutputPort {
        name: name.into(),
        schema: schema.into(),
        doc: String::new(),
    }
}

/// A parameter; a null default stands for a required one in these fixtures.
fn param(name: &str, default: serde_json::Value) -> Param {
    Param {
        name: name.into(),
        required: default.is_null(),
        default,
        doc: String::new(),
    }
}

/// `evseg-source`, `evseg-slicer`, `evseg-sink`, `evseg-loop`; anything else is "not found".
pub fn resolver(binary: &str) -> Result<NodeDescription, String> {
    let (inputs, outputs, params) = match binary {
        "evseg-source" => (
            vec![],
            vec![
                output("events", "evseg.EventPacket"),
                output("truth", "evseg.Truth"),
            ],
            vec![
                param("kind", json!("synthetic")),
                param("seconds", json!(3)),
                param("seed", json!(7)),
            ],
        ),
        "evseg-slicer" => (
            vec![
                input("events", "evseg.EventPacket", false),
                input("truth", "evseg.Truth", true),
            ],
            vec![output("slices", "evseg.Slice"), output("truth", "evseg.Truth")],
            vec![param("window_ms", json!(30.0)), param("imu", json!(true))],
        ),
        "evseg-sink" => (
            vec![input("slices", "evseg.Slice", false)],
            vec![],
            vec![
                param("path", json!(null)),
                param("tags", json!([])),
                param("format", json!({"csv": true})),
            ],
        ),
        "evseg-loop" => (
            vec![
                input("slices", "evseg.Slice", false),
                input("previous", "evseg.Tracks", false),
            ],
            vec![output("tracks", "evseg.Tracks")],
            vec![],
        ),
        other => return Err(format!("`{other}` not found next to the launcher or on PATH")),
    };
    Ok(NodeDescription {
        binary: binary.into(),
        summary: String::new(),
        inputs,
        outputs,
        params,
    })
}

/// The lines joined with newlines (line i of the slice is line i+1 of the file).
pub fn text(lines: &[&str]) -> String {
    lines.iter().map(|l| format!("{l}\n")).collect()
}

/// Checks the graph made of `lines` as `g.yaml`.
pub fn check(lines: &[&str]) -> Result<Graph, GraphError> {
    check_str("g.yaml", &text(lines), &resolver)
}

/// The diagnostics of a graph that must be refused.
pub fn errors(lines: &[&str]) -> Vec<Diagnostic> {
    match check(lines) {
        Ok(_) => panic!("graph accepted:\n{}", text(lines)),
        Err(GraphError::Invalid(d)) => d,
        Err(e) => panic!("unexpected error {e}"),
    }
}

/// Asserts the graph has exactly one error, at `line`:`column`, whose message contains every
/// word of `words`; returns the message.
pub fn single_error(lines: &[&str], line: usize, column: usize, words: &[&str]) -> String {
    let found = errors(lines);
    assert_eq!(found.len(), 1, "expected one error, got {found:#?}");
    let d = &found[0];
    assert_eq!(
        (d.file.as_str(), d.line, d.column),
        ("g.yaml", line, column),
        "wrong position: {d}"
    );
    for word in words {
        assert!(d.message.contains(word), "message {:?} lacks {word:?}", d.message);
    }
    d.message.clone()
}

/// A valid graph: source -> slicer -> sink and slicer -> tracker, with the tracker feeding back
/// into itself. The sink comes first in the file on purpose (topological order must move it).
pub const VALID: &[&str] = &[
    "name: demo",                                               // 1
    "mode: lockstep",                                           // 2
    "nodes:",                                                   // 3
    "  - id: sink",                                             // 4
    "    run: evseg-sink",                                      // 5
    "    params: { path: out.txt }",                            // 6
    "    inputs: { slices: slicer/slices }",                    // 7
    "  - id: source",                                           // 8
    "    run: evseg-source",                                    // 9
    "    params: { seconds: 5 }",                               // 10
    "  - id: slicer",                                           // 11
    "    run: evseg-slicer",                                    // 12
    "    inputs:",                                              // 13
    "      events: source/events",                              // 14
    "      truth: source/truth",                                // 15
    "    outputs: [slices]",                                    // 16
    "  - id: tracker",                                          // 17
    "    run: evseg-loop",                                      // 18
    "    restart: { policy: on-failure }",                      // 19
    "    inputs:",                                              // 20
    "      slices: slicer/slices",                              // 21
    "      previous: { from: tracker/tracks, feedback: true }", // 22
];

/// `VALID` with line `n` (1-based) replaced by `with`.
pub fn replace(n: usize, with: &str) -> Vec<String> {
    let mut lines: Vec<String> = VALID.iter().map(|s| s.to_string()).collect();
    lines[n - 1] = with.to_string();
    lines
}

/// Borrowed view of owned lines.
pub fn view(lines: &[String]) -> Vec<&str> {
    lines.iter().map(String::as_str).collect()
}
