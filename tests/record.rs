//! Recording a lock-step run into MCAP: nothing dropped (message counts per channel equal what
//! the nodes published), the evaluator's figures unchanged by recording, the file readable by the
//! official Python `mcap` package, a cut-off file recovered up to its last complete chunk, and
//! the NumPy export read back with numpy.
//!
//! The Python checks use `$EVSEG_PYTHON`, else `.venv/bin/python` of the workspace (made by
//! scripts/test), else /work/venv/bin/python, else python3; they are skipped with a message when
//! `mcap` or `numpy` is not importable, except under CI=true where that is a failure.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use evseg_tests::{
    Launcher, SIM_GRAPH_SECONDS, SIM_GRAPH_WINDOW_MS, bin, free_port, read_json, sim_graph, write,
};

/// Simulated seconds of the run and the slicer window: 10 slices.
const SECONDS: f64 = SIM_GRAPH_SECONDS;
const WINDOW_MS: f64 = SIM_GRAPH_WINDOW_MS;

fn graph(port: u16, record: &str) -> String {
    sim_graph("rec", port, record)
}

struct Run {
    out: PathBuf,
    stdout: String,
    seconds: f64,
}

fn run(dir: &Path, tag: &str, record: &str, extra: &[&str]) -> Run {
    let port = free_port();
    let g = write(dir, &format!("{tag}.yaml"), &graph(port, record));
    let out = dir.join(tag);
    let mut args = vec!["run", g.to_str().unwrap(), "--out", out.to_str().unwrap(), "-q"];
    args.extend_from_slice(extra);
    let start = Instant::now();
    let done = Launcher::start(dir, &args, tag).wait(Duration::from_secs(300));
    assert!(done.status.success(), "run {tag} failed:\n{}", done.stderr);
    Run {
        out,
        stdout: done.stdout,
        seconds: start.elapsed().as_secs_f64(),
    }
}

/// `published` per node from the launcher's summary table.
fn published(stdout: &str) -> BTreeMap<String, u64> {
    let mut map = BTreeMap::new();
    let mut in_table = false;
    for line in stdout.lines() {
        let cols: Vec<&str> = line.split_whitespace().collect();
        if cols.first() == Some(&"node") && cols.get(2) == Some(&"published") {
            in_table = true;
            continue;
        }
        if in_table {
            match (cols.len(), cols.get(2).and_then(|v| v.parse::<u64>().ok())) {
                (7, Some(n)) => {
                    map.insert(cols[0].to_string(), n);
                }
                _ => in_table = false,
            }
        }
    }
    map
}

fn evseg(args: &[&str]) -> (bool, String, String) {
    let out = Command::new(bin("evseg")).args(args).output().expect("run evseg");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Python with `mcap` and `numpy`, or `None` (skip) outside CI.
fn python() -> Option<String> {
    evseg_tests::python_with(&["mcap.reader", "numpy"], "Python checks of the recording")
}

fn python_json(py: &str, script: &str, args: &[&str]) -> serde_json::Value {
    serde_json::from_slice(&evseg_tests::run_python(py, script, args)).expect("python printed JSON")
}

/// Lists channels and counts with the official reader, reading every message.
const MCAP_SCRIPT: &str = r#"
import sys, json
from mcap.reader import make_reader
counts, schemas, versions = {}, {}, {}
with open(sys.argv[1], 'rb') as f:
    reader = make_reader(f)
    summary = reader.get_summary()
    for schema, channel, message in reader.iter_messages():
        counts[channel.topic] = counts.get(channel.topic, 0) + 1
        schemas[channel.topic] = schema.name
        versions[channel.topic] = channel.metadata.get('schema_version')
        assert channel.message_encoding == 'evseg-bincode2'
    stats = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    f.seek(0)
    metadata = {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}
    f.seek(0)
    attachments = [a.name for a in make_reader(f).iter_attachments()]
print(json.dumps({'counts': counts, 'schemas': schemas, 'versions': versions, 'stats': stats,
                  'chunks': summary.statistics.chunk_count, 'metadata': metadata,
                  'attachments': attachments}))
"#;

/// Shapes and a few checks of the export, with numpy.
const NUMPY_SCRIPT: &str = r#"
import sys, json
import numpy as np
d = sys.argv[1]
labels = np.load(d + '/segmenter.tracks.labels.npy')
events = np.load(d + '/slicer.slices.events.npy')
ego = np.load(d + '/segmenter.tracks.egomotion.npy')
metrics = np.load(d + '/evaluator.metrics.metrics.npy')
assert labels.dtype == np.int64 and events.dtype == np.float64
assert (np.diff(labels[:, 0]) >= 0).all(), 'slices in order'
assert (labels[:, 0] == events[:, 0]).all(), 'labels aligned with the slice events'
print(json.dumps({'labels': list(labels.shape), 'events': list(events.shape), 'ego': list(ego.shape),
                  'metrics': list(metrics.shape), 'label_max': int(labels[:, 1].max()),
                  'slices': sorted(set(int(s) for s in ego[:, 0])),
                  't_end_last': float(ego[-1, 2])}))
"#;

#[test]
fn a_recorded_lockstep_run_loses_nothing_and_reads_back_everywhere() {
    // Build the binaries first, so the run times printed below are the runs' own.
    evseg_tests::bin_dir();
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let plain = run(dir, "plain", "", &[]);
    let rec_path = dir.join("run.mcap");
    let recorded = run(dir, "recorded", "", &["--record", rec_path.to_str().unwrap()]);
    assert!(recorded.stdout.contains("recorded to"), "{}", recorded.stdout);
    eprintln!(
        "run time: {:.2} s plain, {:.2} s recorded; recording {} bytes",
        plain.seconds,
        recorded.seconds,
        std::fs::metadata(&rec_path).unwrap().len()
    );

    // The evaluator's figures do not change when the run is recorded.
    let a = read_json(&plain.out.join("report/report.json"));
    let b = read_json(&recorded.out.join("report/report.json"));
    assert_eq!(a["sequence"], b["sequence"]);
    assert_eq!(a["slices"], b["slices"]);
    // The evaluator scored every slice: 0.3 s in 30 ms windows (the last one may be partial).
    let slices = b["slices"].as_array().unwrap().len() as u64;
    let full_windows = (SECONDS * 1000.0 / WINDOW_MS).round() as u64;
    assert!(
        (full_windows..=full_windows + 1).contains(&slices),
        "{slices} slices"
    );

    // Message counts per channel equal what each node published (evseg's own reader).
    let pubs = published(&recorded.stdout);
    assert_eq!(pubs, {
        let mut p = published(&plain.stdout);
        p.insert("recorder".into(), 0);
        p
    });
    let mut counts: BTreeMap<String, u64> = BTreeMap::new();
    let rec = evseg_recorder_read(&rec_path, &mut counts);
    assert!(rec.contains("complete"), "{rec}");
    assert_eq!(counts["source/events"] + counts["source/truth"], pubs["source"]);
    assert_eq!(counts["source/events"], counts["source/truth"]);
    assert_eq!(counts["slicer/slices"], slices);
    assert_eq!(counts["slicer/truth"], slices);
    assert_eq!(counts["segmenter/tracks"], pubs["segmenter"]);
    assert_eq!(counts["segmenter/tracks"], slices);
    assert_eq!(counts["evaluator/metrics"], pubs["evaluator"]);
    assert_eq!(counts.len(), 6);

    // The official Python reader agrees.
    let py = python();
    if let Some(py) = &py {
        let v = python_json(py, MCAP_SCRIPT, &[rec_path.to_str().unwrap()]);
        for (topic, n) in &counts {
            assert_eq!(v["counts"][topic], *n, "{topic}: {v}");
            assert_eq!(v["stats"][topic], *n, "{topic}: {v}");
        }
        assert_eq!(v["schemas"]["slicer/slices"], "evseg.Slice");
        assert_eq!(v["versions"]["segmenter/tracks"], "1");
        assert!(v["chunks"].as_u64().unwrap() >= 2, "{v}");
        assert_eq!(
            v["metadata"]["evseg.run"]["instance"],
            format!("rec{}", recorded_port(&recorded.out))
        );
        assert_eq!(v["metadata"]["evseg.run"]["mode"], "lockstep");
        assert!(v["metadata"]["evseg.run"]["graph_hash"].as_str().unwrap().len() == 16);
        assert!(
            v["metadata"]["evseg.params"]["slicer"]
                .as_str()
                .unwrap()
                .contains("window_ms")
        );
        assert!(
            v["attachments"]
                .as_array()
                .unwrap()
                .iter()
                .any(|a| a == "graph.resolved.json")
        );
    }

    // `evseg info` lists the channels; a cut-off copy is read up to its last complete chunk.
    let (ok, info, err) = evseg(&["info", rec_path.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(info.contains("complete") && info.contains("slicer/slices") && info.contains("evseg.Slice"));
    assert!(info.contains("graph_hash"), "{info}");
    let bytes = std::fs::read(&rec_path).unwrap();
    let cut = dir.join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
    let (ok, info, err) = evseg(&["info", cut.to_str().unwrap()]);
    assert!(ok, "{err}");
    assert!(
        info.contains("TRUNCATED at byte") && info.contains("cut.mcap"),
        "{info}"
    );
    let recovered: u64 = info
        .split("recovered ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no recovered count in {info}"));
    let total: u64 = counts.values().sum();
    assert!(
        recovered > 0 && recovered < total,
        "recovered {recovered} of {total}"
    );

    // Export, read back with numpy.
    let exp = dir.join("export");
    let (ok, text, err) = evseg(&[
        "export",
        rec_path.to_str().unwrap(),
        "--out",
        exp.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    assert!(text.contains("labels.npy"), "{text}");
    let (ok, text, err) = evseg(&[
        "export",
        cut.to_str().unwrap(),
        "--out",
        dir.join("cut-export").to_str().unwrap(),
    ]);
    assert!(ok && text.contains("TRUNCATED"), "{text}{err}");
    if let Some(py) = &py {
        let v = python_json(py, NUMPY_SCRIPT, &[exp.to_str().unwrap()]);
        assert_eq!(v["labels"][1], 2);
        assert_eq!(v["labels"][0], v["events"][0]);
        let events = v["events"][0].as_u64().unwrap();
        let sent = read_json(&recorded.out.join("source-source.json"))["digest"]["count"]
            .as_u64()
            .unwrap();
        assert!(
            events > 0 && events <= sent,
            "{events} exported events, {sent} sent"
        );
        assert_eq!(v["ego"], serde_json::json!([slices, 10]));
        assert_eq!(v["metrics"][0], slices);
        assert_eq!(v["label_max"], 0, "the baseline labels everything background");
        assert_eq!(v["slices"].as_array().unwrap().len() as u64, slices);
        // Fixed windows: the last slice ends after `slices` windows.
        let t_end = v["t_end_last"].as_f64().unwrap();
        assert!((t_end - slices as f64 * WINDOW_MS * 1e-3).abs() < 1e-6, "{t_end}");
    }
}

#[test]
fn the_record_section_of_the_graph_selects_outputs_and_writes_into_the_run_folder() {
    let dir = tempfile::tempdir().unwrap();
    let r = run(
        dir.path(),
        "section",
        "record: { path: rec/out.mcap, outputs: [segmenter/tracks, evaluator/metrics], \
         chunk_bytes: 4096, zstd_level: 9 }\n",
        &[],
    );
    // The writer settings reach the recorder as parameters.
    let started = read_json(&r.out.join("graph.started.json"));
    let recorder = started["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|n| n["id"] == "recorder")
        .unwrap();
    assert_eq!(recorder["params"]["chunk_bytes"], 4096, "{recorder}");
    assert_eq!(recorder["params"]["zstd_level"], 9, "{recorder}");
    let file = r.out.join("rec/out.mcap");
    let mut counts = BTreeMap::new();
    let text = evseg_recorder_read(&file, &mut counts);
    assert!(text.contains("complete"), "{text}");
    let slices = read_json(&r.out.join("report/report.json"))["slices"]
        .as_array()
        .unwrap()
        .len() as u64;
    assert!(slices >= 10);
    assert_eq!(
        counts,
        BTreeMap::from([
            ("evaluator/metrics".to_string(), slices),
            ("segmenter/tracks".to_string(), slices)
        ])
    );
}

/// The instance's port, from the run's graph.
fn recorded_port(out: &Path) -> String {
    let g = read_json(&out.join("graph.resolved.json"));
    g["name"].as_str().unwrap().trim_start_matches("rec").to_string()
}

/// Message counts per topic and the completeness line, through `evseg info`.
fn evseg_recorder_read(path: &Path, counts: &mut BTreeMap<String, u64>) -> String {
    let (ok, text, err) = evseg(&["info", path.to_str().unwrap()]);
    assert!(ok, "{err}");
    let mut in_table = false;
    for line in text.lines() {
        let cols: Vec<&str> = line.split_whitespace().collect();
        if cols.first() == Some(&"id") && cols.get(1) == Some(&"topic") {
            in_table = true;
            continue;
        }
        if in_table {
            if cols.len() != 6 {
                break;
            }
            counts.insert(cols[1].to_string(), cols[4].parse().unwrap());
        }
    }
    text
}
