//! The `record:` section: checked outputs, default "every output", errors with positions.

mod common;

use common::resolver;
use evseg_graph::{GraphError, RecordSpec, check_str};

const BASE: &str = "name: demo
nodes:
  - id: source
    run: evseg-source
  - id: slicer
    run: evseg-slicer
    inputs: { events: source/events }
";

fn check(text: &str) -> Result<evseg_graph::Graph, GraphError> {
    check_str("g.yaml", text, &resolver)
}

#[test]
fn record_section_is_read_with_checked_outputs() {
    let g = check(&format!(
        "{BASE}record:\n  path: run.mcap\n  outputs: [slicer/slices, source/events, slicer/slices]\n"
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(
        g.record,
        Some(RecordSpec {
            path: "run.mcap".into(),
            outputs: vec!["slicer/slices".into(), "source/events".into()],
            ..Default::default()
        })
    );
    // In the canonical form, and read back.
    let back: evseg_graph::Graph = serde_json::from_str(&g.canonical_json()).unwrap();
    assert_eq!(back.record, g.record);
}

#[test]
fn no_outputs_means_every_output_and_no_section_leaves_the_canonical_form_alone() {
    let g = check(&format!("{BASE}record: {{ path: out/x.mcap }}\n")).unwrap();
    assert_eq!(g.record.unwrap().outputs, Vec::<String>::new());
    let plain = check(BASE).unwrap();
    assert!(plain.record.is_none());
    assert!(!plain.canonical_json().contains("record"));
}

#[test]
fn unknown_outputs_missing_path_and_unknown_keys_are_reported_with_positions() {
    let err = check(&format!(
        "{BASE}record:\n  path: run.mcap\n  outputs: [slicer/slicez, nobody/x]\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("g.yaml:10:13") && err.contains("no output `slicer/slicez`"),
        "{err}"
    );
    assert!(err.contains("did you mean `slicer/slices`"), "{err}");
    assert!(err.contains("no output `nobody/x`"), "{err}");
    let err = check(&format!(
        "{BASE}record:\n  outputs: [slicer/slices]\n  speed: 2\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(err.contains("missing `path`"), "{err}");
    assert!(err.contains("speed"), "{err}");
    let err = check(&format!("{BASE}record: run.mcap\n"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("g.yaml:8:9"), "{err}");
}

#[test]
fn writer_settings_are_read_and_checked_against_their_ranges() {
    let g = check(&format!(
        "{BASE}record:\n  path: run.mcap\n  chunk_bytes: 4194304\n  zstd_level: 19\n"
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    let r = g.record.unwrap();
    assert_eq!((r.chunk_bytes, r.zstd_level), (Some(4_194_304), Some(19)));
    let plain = check(&format!("{BASE}record: {{ path: run.mcap }}\n")).unwrap();
    let r = plain.record.unwrap();
    assert_eq!((r.chunk_bytes, r.zstd_level), (None, None));
    let err = check(&format!(
        "{BASE}record:\n  path: run.mcap\n  chunk_bytes: 0\n  zstd_level: 40\n"
    ))
    .unwrap_err()
    .to_string();
    assert!(
        err.contains("g.yaml:10:16")
            && err.contains("`record.chunk_bytes` must be in 1024..=1073741824, got 0"),
        "{err}"
    );
    assert!(
        err.contains("g.yaml:11:15") && err.contains("`record.zstd_level` must be in 0..=22, got 40"),
        "{err}"
    );
    let err = check(&format!("{BASE}record:\n  path: run.mcap\n  zstd_level: high\n"))
        .unwrap_err()
        .to_string();
    assert!(err.contains("must be an integer in 0..=22"), "{err}");
}
