//! `evseg check` on graphs with each kind of error: the message names file, line and column, and
//! nothing is started.

use std::path::Path;
use std::process::Command;

use evseg_tests::{bin, write};

const GOOD: &str = r#"name: checked
nodes:
  - id: source
    run: evseg-source
    params: { kind: pattern }
  - id: slicer
    run: evseg-slicer
    inputs: { events: source/events }
  - id: inspect
    run: evseg-inspect
    inputs: { slices: slicer/slices }
"#;

fn check(dir: &Path, text: &str) -> (bool, String) {
    let g = write(dir, "graph.yaml", text);
    let out = Command::new(bin("evseg"))
        .args(["check", g.to_str().unwrap()])
        .output()
        .unwrap();
    let all = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), all)
}

fn expect_error(text: &str, line: usize, column: usize, words: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let (ok, out) = check(dir.path(), text);
    assert!(!ok, "check accepted a bad graph:\n{text}");
    let at = format!("graph.yaml:{line}:{column}: error:");
    assert!(out.contains(&at), "expected an error at {at} in:\n{out}");
    for w in words {
        assert!(out.contains(w), "expected `{w}` in:\n{out}");
    }
}

#[test]
fn a_good_graph_passes() {
    let dir = tempfile::tempdir().unwrap();
    let (ok, out) = check(dir.path(), GOOD);
    assert!(ok, "{out}");
    assert!(out.contains("3 nodes"), "{out}");
}

#[test]
fn unknown_keys() {
    expect_error(
        &GOOD.replace("name: checked", "name: checked\nmdoe: live"),
        2,
        1,
        &["mdoe", "mode"],
    );
    expect_error(
        &GOOD.replace("    run: evseg-slicer", "    run: evseg-slicer\n    colour: red"),
        8,
        5,
        &["colour"],
    );
}

#[test]
fn unknown_binary() {
    expect_error(
        &GOOD.replace("run: evseg-slicer", "run: evseg-no-such-node"),
        7,
        10,
        &["evseg-no-such-node", "not found"],
    );
}

#[test]
fn unknown_parameter() {
    expect_error(
        &GOOD.replace("params: { kind: pattern }", "params: { kind: pattern, rrate: 5 }"),
        5,
        30,
        &["rrate", "rate"],
    );
}

#[test]
fn wrong_parameter_type() {
    expect_error(
        &GOOD.replace(
            "params: { kind: pattern }",
            "params: { kind: pattern, rate: fast }",
        ),
        5,
        36,
        &["rate"],
    );
}

#[test]
fn input_wired_to_another_message_type() {
    // The inspector wants slices; the source's events are event packets.
    expect_error(
        &GOOD.replace("slices: slicer/slices", "slices: source/events"),
        11,
        23,
        &["evseg.Slice", "evseg.EventPacket"],
    );
}

#[test]
fn missing_input() {
    expect_error(
        &GOOD.replace("    inputs: { slices: slicer/slices }\n", ""),
        9,
        9,
        &["slices"],
    );
}

#[test]
fn unknown_node_in_a_reference() {
    expect_error(
        &GOOD.replace("events: source/events", "events: sauce/events"),
        8,
        23,
        &["sauce"],
    );
}

#[test]
fn cycle_without_feedback_mark_and_with_it() {
    // A node type whose output feeds its own kind of input: a relay, described by a script.
    let dir = tempfile::tempdir().unwrap();
    let relay = r#"#!/bin/sh
cat <<'JSON'
{"binary":"relay","summary":"test relay","inputs":[{"name":"in","schema":"evseg.Slice"},{"name":"back","schema":"evseg.Slice","optional":true}],"outputs":[{"name":"out","schema":"evseg.Slice"}],"params":[]}
JSON
"#;
    let script = write(dir.path(), "relay.sh", relay);
    std::fs::set_permissions(&script, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let cyc = r#"name: cyc
nodes:
  - id: source
    run: evseg-source
    params: { kind: pattern }
  - id: slicer
    run: evseg-slicer
    inputs: { events: source/events }
  - id: a
    run: ./relay.sh
    inputs: { in: slicer/slices, back: b/out }
  - id: b
    run: ./relay.sh
    inputs: { in: a/out }
"#;
    let (ok, out) = check(dir.path(), cyc);
    assert!(!ok);
    assert!(out.contains("graph.yaml:11:34:"), "{out}");
    assert!(out.contains("cycle") && out.contains("feedback: true"), "{out}");
    let marked = cyc.replace("back: b/out", "back: { from: b/out, feedback: true }");
    let (ok, out) = check(dir.path(), &marked);
    assert!(ok, "a feedback-marked cycle must pass:\n{out}");
}

#[test]
fn several_errors_are_all_reported() {
    let bad = GOOD
        .replace("name: checked", "name: checked\nmdoe: live")
        .replace("run: evseg-slicer", "run: nope");
    let dir = tempfile::tempdir().unwrap();
    let (ok, out) = check(dir.path(), &bad);
    assert!(!ok);
    assert_eq!(out.matches(": error:").count(), 2, "{out}");
}

#[test]
fn malformed_yaml_is_an_error_not_a_crash() {
    for text in [
        "name: [unclosed\nnodes: []\n",
        "\tname: x\n",
        "nodes: {a: [}\n",
        "\u{0}\u{1}binary",
    ] {
        let dir = tempfile::tempdir().unwrap();
        let (ok, out) = check(dir.path(), text);
        assert!(!ok);
        assert!(out.contains("graph.yaml:"), "{out}");
        assert!(!out.contains("panicked"), "{out}");
    }
}

#[test]
fn a_reader_that_closes_the_output_early_ends_check_quietly() {
    // `evseg check graph.yaml | true`: the reader is gone before the first print.
    let dir = tempfile::tempdir().unwrap();
    let g = write(dir.path(), "graph.yaml", GOOD);
    let mut child = Command::new(bin("evseg"))
        .args(["check", g.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_ne!(out.status.code(), Some(101), "{stderr}");
}

#[test]
fn a_missing_file_is_named() {
    let out = Command::new(bin("evseg"))
        .args(["check", "/nonexistent/graph.yaml"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nonexistent/graph.yaml"));
}
