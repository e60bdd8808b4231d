//! `evseg ab`: two variants of a graph on the same recording. A variant identical to A gives
//! zero differences (lock-step replay feeds both the same frames); a parameter change of B shows
//! in its column; a swap to a binary with other ports is refused before anything runs; a swap
//! to a binary without some of the old one's parameters or optional outputs is fitted with
//! notes.

use std::path::Path;
use std::time::Duration;

use evseg_tests::{Launcher, free_port, read_json, sim_graph, workspace_root, write};

fn graph(port: u16) -> String {
    sim_graph("ab", port, "")
}

fn evseg(dir: &Path, args: &[&str]) -> evseg_tests::Finished {
    Launcher::start(dir, args, "ab").wait(Duration::from_secs(300))
}

#[test]
fn ab_compares_two_variants_on_one_recording() {
    let dir = tempfile::tempdir().unwrap();
    let g = write(dir.path(), "g.yaml", &graph(free_port()));
    let rec = dir.path().join("input.mcap");
    let out = dir.path().join("orig");
    let r = evseg(
        dir.path(),
        &[
            "run",
            g.to_str().unwrap(),
            "--record",
            rec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "-q",
        ],
    );
    assert!(r.status.success(), "recording run failed:\n{}", r.stderr);

    // B = A (the same binary swapped in): every difference is exactly 0.
    let work = dir.path().join("same");
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let r = evseg(
        dir.path(),
        &[
            "ab",
            g.to_str().unwrap(),
            "--recording",
            rec.to_str().unwrap(),
            "--swap",
            "segmenter=evseg-baseline",
            "--work",
            work.to_str().unwrap(),
            "--listen",
            &listen,
        ],
    );
    assert!(r.status.success(), "ab failed:\n{}", r.stderr);
    assert!(r.stdout.contains("| input | IoU mask (%) |"), "{}", r.stdout);
    let rows = read_json(&work.join("ab.json"));
    let rows = rows.as_array().unwrap();
    // IoU mask, events, per object, three RMSE axes, median direction error, the worst
    // object's id switches (MOTS and any overlap), false alarms.
    assert_eq!(rows.len(), 10, "{rows:?}");
    for row in rows {
        assert_eq!(row["a"], row["b"], "{row}");
        if let Some(d) = row["difference"].as_f64() {
            assert_eq!(d, 0.0, "{row}");
        }
    }
    assert!(work.join("ab.md").exists());
    assert!(
        work.join("input")
            .join("a")
            .join("report")
            .join("report.json")
            .exists()
    );
    assert!(
        work.join("input")
            .join("b")
            .join("report")
            .join("report.json")
            .exists()
    );

    // A swap to a binary with other ports is refused before any variant runs, naming B's graph.
    let work = dir.path().join("bad");
    let r = evseg(
        dir.path(),
        &[
            "ab",
            g.to_str().unwrap(),
            "--recording",
            rec.to_str().unwrap(),
            "--swap",
            "segmenter=evseg-slicer",
            "--work",
            work.to_str().unwrap(),
            "--listen",
            &listen,
        ],
    );
    assert!(!r.status.success());
    assert!(r.stderr.contains("graph-b.yaml:"), "{}", r.stderr);
    assert!(!work.join("input").exists(), "nothing may run");
}

#[test]
fn swapping_the_learned_flow_into_the_default_graph_is_fitted_with_notes() {
    // The default graph's flow node sets a plane-fit parameter and feeds the hierarchical
    // merger's optional `egomotion_flow` from the plane fit's `wide_flow`, which the learned
    // estimator has not. Variant B is fitted and passes the check: the run stops only at the
    // recording, which does not exist (so no node starts).
    let dir = tempfile::tempdir().unwrap();
    let graph = workspace_root().join("graph.yaml");
    let work = dir.path().join("w");
    let r = evseg(
        dir.path(),
        &[
            "ab",
            graph.to_str().unwrap(),
            "--recording",
            "missing.mcap",
            "--swap",
            "flow=evseg-normal-flow-learned",
            "--work",
            work.to_str().unwrap(),
        ],
    );
    assert!(!r.status.success());
    assert!(
        r.stderr
            .contains("parameter `max_direction_sd_deg` of node `flow` removed"),
        "{}",
        r.stderr
    );
    assert!(
        r.stderr
            .contains("optional input `egomotion_flow` of node `hierarchical` left unwired"),
        "{}",
        r.stderr
    );
    assert!(r.stderr.contains("missing.mcap"), "{}", r.stderr);
    assert!(
        !r.stderr.contains("graph-b.yaml:"),
        "B must pass the check:\n{}",
        r.stderr
    );
    let b = std::fs::read_to_string(work.join("graph-b.yaml")).unwrap();
    assert!(
        b.contains("run: evseg-normal-flow-learned") && !b.contains("wide_flow"),
        "{b}"
    );
}

#[test]
fn changes_variant_b_could_not_show_are_refused_before_anything_runs() {
    // `--from slicer` replays the source and the slicer: swapping or setting them in B would
    // change nothing, and two swaps of one node would mix two binaries' edits. Each is refused
    // naming the flag and the node, before the (missing) recording is read.
    let dir = tempfile::tempdir().unwrap();
    let graph = workspace_root().join("graph.yaml");
    let work = dir.path().join("w");
    let cases: [(&[&str], &str); 5] = [
        (
            &["--swap", "slicer=evseg-slicer"],
            "--swap `slicer=evseg-slicer`: node `slicer` is replayed from the recording",
        ),
        (
            &[
                "--swap",
                "flow=evseg-normal-flow-learned",
                "--swap",
                "flow=evseg-normal-flow",
            ],
            "node `flow` is already swapped",
        ),
        (
            &["--set-b", "source.seconds=1"],
            "--set-b `source.seconds=1`: node `source` is replayed from the recording",
        ),
        (
            &["--set", "slicer.window_ms=20"],
            "--set `slicer.window_ms=20`: node `slicer` is replayed from the recording",
        ),
        (
            &["--set-b", "flow.no_such_parameter=1"],
            "--set-b `flow.no_such_parameter=1`: node `flow` has no parameter",
        ),
    ];
    for (extra, expected) in cases {
        let mut args = vec![
            "ab",
            graph.to_str().unwrap(),
            "--recording",
            "missing.mcap",
            "--work",
            work.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let r = evseg(dir.path(), &args);
        assert!(!r.status.success(), "{extra:?} must be refused");
        assert!(r.stderr.contains(expected), "{extra:?}:\n{}", r.stderr);
        assert!(
            !r.stderr.contains("missing.mcap"),
            "{extra:?}: checked before the recording:\n{}",
            r.stderr
        );
    }
}
