//! One test per kind of error, each at an exact line and column.

mod common;

use common::{VALID, errors, replace, single_error, view};

/// `VALID` without line `n` (1-based).
fn without(n: usize) -> Vec<String> {
    let mut lines: Vec<String> = VALID.iter().map(|s| s.to_string()).collect();
    lines.remove(n - 1);
    lines
}

/// `VALID` followed by `more`.
fn plus(more: &[&str]) -> Vec<String> {
    VALID.iter().chain(more).map(|s| s.to_string()).collect()
}

// ---- YAML syntax and types -------------------------------------------------------------------

#[test]
fn yaml_syntax_error_tab_indentation() {
    let lines = replace(5, "\trun: evseg-sink");
    // The parser notices while reading `sink` (4:9); the error points at the tab itself.
    single_error(&view(&lines), 5, 1, &["YAML syntax error", "tab", "use spaces"]);
}

#[test]
fn yaml_syntax_error_unclosed_bracket() {
    // The parser only finds out on the next line (the `:` after `- id`); the message names the
    // bracket left open.
    let lines = replace(16, "    outputs: [slices");
    single_error(
        &view(&lines),
        17,
        7,
        &[
            "YAML syntax error",
            "the `[` opened at line 16, column 14 may lack its `]`",
        ],
    );
}

#[test]
fn wrong_type_for_window() {
    let lines = replace(2, "window: abc");
    single_error(&view(&lines), 2, 9, &["`window`", "integer", "\"abc\""]);
}

#[test]
fn window_out_of_range() {
    let lines = replace(2, "window: 0");
    single_error(&view(&lines), 2, 9, &["`window`", "at least 1", "got 0"]);
}

#[test]
fn nodes_not_a_list() {
    single_error(
        &["name: x", "nodes: 5"],
        2,
        8,
        &["`nodes`", "list", "the integer 5"],
    );
}

#[test]
fn inputs_not_a_mapping_is_not_also_a_missing_input() {
    let lines = replace(7, "    inputs: [slicer/slices]");
    single_error(&view(&lines), 7, 13, &["`inputs`", "mapping", "got a list"]);
}

#[test]
fn bad_mode_and_feedback_type() {
    let lines = replace(2, "mode: fast");
    single_error(
        &view(&lines),
        2,
        7,
        &["unknown mode `fast`", "`lockstep`", "`live`"],
    );
    let lines = replace(22, "      previous: { from: tracker/tracks, feedback: 1 }");
    let found = errors(&view(&lines));
    // `feedback: 1` is refused, so the edge is a plain one and closes a self-loop as well.
    assert_eq!(found.len(), 2, "{found:?}");
    assert_eq!((found[0].line, found[0].column), (22, 7));
    assert!(found[0].message.contains("cycle"));
    assert_eq!((found[1].line, found[1].column), (22, 51));
    assert!(
        found[1].message.contains("`feedback` must be true or false"),
        "{found:?}"
    );
}

#[test]
fn empty_file_and_root_not_a_mapping() {
    single_error(&["# nothing here"], 1, 1, &["holds no graph"]);
    single_error(
        &["- a", "- b"],
        1,
        1,
        &["a graph file must be a mapping", "`nodes`", "got a list"],
    );
    single_error(
        &["nodes:", "  - id: a", "    run: evseg-source"],
        1,
        1,
        &["missing `name`"],
    );
}

#[test]
fn duplicate_yaml_key() {
    let lines = plus(&["name: again"]);
    single_error(&view(&lines), 23, 1, &["duplicate key `name`", "line 1"]);
}

// ---- unknown keys ----------------------------------------------------------------------------

#[test]
fn unknown_top_level_key() {
    let lines = replace(2, "mdoe: lockstep");
    let msg = single_error(
        &view(&lines),
        2,
        1,
        &["unknown key `mdoe`", "allowed keys", "`window`", "`nodes`"],
    );
    assert!(msg.contains("did you mean `mode`?"), "{msg}");
}

#[test]
fn unknown_node_key() {
    let lines = replace(19, "    restart_policy: never");
    single_error(
        &view(&lines),
        19,
        5,
        &["unknown key `restart_policy`", "in a node", "`run`", "`outputs`"],
    );
}

#[test]
fn unknown_zenoh_and_machine_keys() {
    let lines = [
        "name: z",
        "zenoh:",
        "  machnes:",
        "    local: {}",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
    ];
    let msg = single_error(&lines, 3, 3, &["unknown key `machnes`", "`zenoh`", "`machines`"]);
    assert!(msg.contains("did you mean `machines`?"), "{msg}");

    let lines = [
        "name: z",
        "zenoh:",
        "  machines:",
        "    robot: { listen: [\"tcp/127.0.0.1:7447\"], conect: [\"tcp/10.0.0.2:7447\"] }",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
    ];
    single_error(
        &lines,
        4,
        46,
        &["unknown key `conect`", "machine `robot`", "`listen`", "`connect`"],
    );
}

#[test]
fn unknown_input_object_key() {
    let lines = replace(15, "      truth: { from: source/truth, optional: true }");
    single_error(
        &view(&lines),
        15,
        36,
        &["unknown key `optional`", "input `truth`", "`from`", "`feedback`"],
    );
}

#[test]
fn unknown_restart_key() {
    let lines = replace(19, "    restart: { policy: on-failure, tries: 2 }");
    single_error(
        &view(&lines),
        19,
        36,
        &["unknown key `tries`", "`restart`", "`policy`", "`max`"],
    );
}

// ---- ids and names ---------------------------------------------------------------------------

#[test]
fn invalid_node_id() {
    let lines = replace(4, "  - id: \"sink node\"");
    single_error(
        &view(&lines),
        4,
        9,
        &["invalid node id `sink node`", "letters, digits"],
    );
}

#[test]
fn duplicate_node_id_points_at_the_second_and_names_the_first_line() {
    let lines = plus(&["  - id: slicer", "    run: evseg-source"]);
    single_error(
        &view(&lines),
        23,
        9,
        &["duplicate node id `slicer`", "first defined at line 11"],
    );
}

#[test]
fn invalid_instance_name() {
    let lines = replace(1, "name: my demo");
    single_error(&view(&lines), 1, 7, &["invalid instance name `my demo`"]);
}

// ---- binaries and parameters -----------------------------------------------------------------

#[test]
fn unknown_binary_reports_the_resolver_message() {
    let lines = replace(18, "    run: evseg-lop");
    single_error(
        &view(&lines),
        18,
        10,
        &["`evseg-lop`", "not found next to the launcher or on PATH"],
    );
}

#[test]
fn unknown_parameter_lists_valid_names() {
    let lines = replace(10, "    params: { secs: 5 }");
    single_error(
        &view(&lines),
        10,
        15,
        &[
            "unknown parameter `secs`",
            "`evseg-source`",
            "`kind`, `seconds`, `seed`",
        ],
    );
}

#[test]
fn parameter_of_the_wrong_type() {
    let lines = replace(10, "    params: { seconds: five }");
    single_error(
        &view(&lines),
        10,
        24,
        &["parameter `seconds`", "takes a number", "got a string"],
    );
    // An integer where the default is a float is fine (both numbers); a list for a mapping is not.
    let lines = replace(6, "    params: { path: out.txt, format: [csv] }");
    single_error(
        &view(&lines),
        6,
        38,
        &["parameter `format`", "takes a mapping", "got a list"],
    );
}

#[test]
fn missing_required_parameter_at_the_node_id() {
    let lines = replace(6, "    params: { tags: [a] }");
    single_error(
        &view(&lines),
        4,
        9,
        &["node `sink` needs parameter `path`", "`evseg-sink`", "no default"],
    );
    let lines = replace(6, "    params: { path: ~ }");
    single_error(&view(&lines), 6, 21, &["parameter `path` is required", "null"]);
}

#[test]
fn non_finite_parameter() {
    let lines = replace(10, "    params: { seconds: .inf }");
    single_error(&view(&lines), 10, 24, &["JSON has no infinity"]);
}

// ---- ports and wiring ------------------------------------------------------------------------

#[test]
fn unknown_input_port() {
    let lines = replace(15, "      truht: source/truth");
    let msg = single_error(
        &view(&lines),
        15,
        7,
        &["unknown input `truht`", "`evseg-slicer`", "`events`, `truth`"],
    );
    assert!(msg.contains("did you mean `truth`?"), "{msg}");
}

#[test]
fn unknown_output_in_outputs_list() {
    let lines = replace(16, "    outputs: [slices, slice]");
    single_error(
        &view(&lines),
        16,
        23,
        &["unknown output `slice`", "`slices`, `truth`"],
    );
}

#[test]
fn malformed_reference() {
    for bad in ["source.events", "source/events/x", "/events", "source/"] {
        let lines = replace(14, &format!("      events: {bad}"));
        single_error(
            &view(&lines),
            14,
            15,
            &[&format!("`{bad}` is not a reference"), "node/output"],
        );
    }
}

#[test]
fn reference_to_an_unknown_node() {
    let lines = replace(14, "      events: sorce/events");
    let msg = single_error(
        &view(&lines),
        14,
        15,
        &["no node `sorce`", "`sink`, `source`, `slicer`, `tracker`"],
    );
    assert!(msg.contains("did you mean `source`?"), "{msg}");
}

#[test]
fn reference_to_an_output_the_producer_does_not_have() {
    let lines = replace(14, "      events: source/event");
    single_error(
        &view(&lines),
        14,
        15,
        &["node `source`", "has no output `event`", "`events`, `truth`"],
    );
}

#[test]
fn reference_to_an_output_the_producer_does_not_list() {
    let lines = replace(15, "      truth: slicer/truth");
    single_error(
        &view(&lines),
        15,
        14,
        &["node `slicer` does not publish `truth`", "`outputs:`", "line 11"],
    );
}

#[test]
fn schema_mismatch_names_both_schemas_and_ports() {
    let lines = replace(7, "    inputs: { slices: source/events }");
    single_error(
        &view(&lines),
        7,
        23,
        &[
            "input `slices` of node `sink`",
            "takes `evseg.Slice`",
            "`source/events` publishes `evseg.EventPacket`",
        ],
    );
}

#[test]
fn missing_input_at_the_node_id() {
    let lines = without(14);
    single_error(
        &view(&lines),
        11,
        9,
        &[
            "node `slicer`",
            "input `events`",
            "`evseg.EventPacket`",
            "unconnected",
        ],
    );
    // The hint names the outputs that carry that schema.
    assert!(errors(&view(&lines))[0].message.contains("`source/events`"));
}

#[test]
fn undeclared_machine() {
    let lines = replace(10, "    machine: robot");
    single_error(
        &view(&lines),
        10,
        14,
        &["machine `robot` is not declared", "`local`"],
    );
}

#[test]
fn bad_shared_memory_settings() {
    let lines = [
        "name: z",
        "zenoh:",
        "  shared_memory: { enabled: yes-please, pool_mb: 64 }",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
    ];
    let found = errors(&lines);
    assert_eq!(found.len(), 2, "{found:?}");
    let unknown = found.iter().find(|d| d.message.contains("unknown key `pool_mb`"));
    let unknown = unknown.unwrap_or_else(|| panic!("{found:?}"));
    assert!(unknown.message.contains("`pool_mib`"), "{}", unknown.message);
    assert_eq!((unknown.line, unknown.column), (3, 41));
    let enabled = found
        .iter()
        .find(|d| d.message.contains("`zenoh.shared_memory.enabled`"));
    let enabled = enabled.unwrap_or_else(|| panic!("{found:?}"));
    assert_eq!((enabled.line, enabled.column), (3, 29));

    let lines = [
        "name: z",
        "zenoh:",
        "  shared_memory: { pool_mib: 0 }",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
    ];
    single_error(&lines, 3, 30, &["`zenoh.shared_memory.pool_mib`", "at least 1"]);

    // A node's own pool size: an integer of at least 1 MiB, reported where it is written.
    let lines = [
        "name: z",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
        "    pool_mib: 0",
    ];
    single_error(&lines, 5, 15, &["`pool_mib`", "at least 1"]);
    let lines = [
        "name: z",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
        "    pool_mib: lots",
    ];
    single_error(&lines, 5, 15, &["`pool_mib`", "integer"]);
}

#[test]
fn bad_endpoint() {
    let lines = [
        "name: z",
        "zenoh:",
        "  machines:",
        "    robot: { listen: [\"127.0.0.1:7447\"] }",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
    ];
    single_error(&lines, 4, 23, &["not a Zenoh endpoint", "tcp/127.0.0.1:7447"]);
}

// ---- cycles ----------------------------------------------------------------------------------

#[test]
fn self_loop_without_feedback() {
    let lines = replace(22, "      previous: tracker/tracks");
    single_error(
        &view(&lines),
        22,
        7,
        &[
            "cycle without a feedback edge",
            "tracker -> tracker",
            "feedback: true",
        ],
    );
}

#[test]
fn three_node_cycle_lists_its_nodes_in_data_order() {
    let lines = [
        "name: ring",
        "nodes:",
        "  - id: source",
        "    run: evseg-source",
        "  - id: slicer",
        "    run: evseg-slicer",
        "    inputs: { events: source/events }",
        "  - id: a",
        "    run: evseg-loop",
        "    inputs: { slices: slicer/slices, previous: c/tracks }",
        "  - id: b",
        "    run: evseg-loop",
        "    inputs: { slices: slicer/slices, previous: a/tracks }",
        "  - id: c",
        "    run: evseg-loop",
        "    inputs: { slices: slicer/slices, previous: b/tracks }",
    ];
    single_error(
        &lines,
        10,
        38,
        &["a -> b -> c -> a", "previous: { from: c/tracks, feedback: true }"],
    );
}

// ---- everything at once ----------------------------------------------------------------------

#[test]
fn several_errors_are_all_reported_in_file_order() {
    let mut lines: Vec<String> = VALID.iter().map(|s| s.to_string()).collect();
    lines[1] = "window: 0".into(); // 2:9
    lines[4] = "    run: evseg-sink".into();
    lines[5] = "    params: { path: out.txt, colour: red }".into(); // 6:30 unknown parameter
    lines[9] = "    params: { seconds: five }".into(); // 10:24 wrong type
    lines[13] = "      events: sorce/events".into(); // 14:15 unknown node
    lines[18] = "    restart: { policy: sometimes }".into(); // 19:24 bad policy
    lines[21] = "      previous: tracker/tracks".into(); // 22:7 self-loop
    let found = errors(&view(&lines));
    let at: Vec<(usize, usize)> = found.iter().map(|d| (d.line, d.column)).collect();
    assert_eq!(
        at,
        [(2, 9), (6, 30), (10, 24), (14, 15), (19, 24), (22, 7)],
        "{found:#?}"
    );
    assert!(found[1].message.contains("unknown parameter `colour`"));
    assert!(found[4].message.contains("unknown restart policy `sometimes`"));
    assert!(found[5].message.contains("tracker -> tracker"));
    for d in &found {
        assert!(
            d.to_string()
                .starts_with(&format!("g.yaml:{}:{}: error: ", d.line, d.column))
        );
    }
}
