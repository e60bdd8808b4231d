//! The viewer in a real graph: `evseg run` of a small simulator graph with an `evseg-viewer`
//! node and `--record`, then `evseg view` of the recording. Both .rrd files are Rerun files
//! holding every slice; `evseg view` says what it drew. Uses the workspace's whole-graph test
//! helpers (loopback router on a free port, binaries of the same profile, children killed on
//! failure).

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use evseg_tests::{Launcher, bin, free_port, sim_graph, write};

/// The shared test graph makes 10 full slices (0.3 s of 30 ms windows).
const SLICES: u64 = 10;

fn graph(port: u16) -> String {
    sim_graph(
        "view",
        port,
        r#"  - id: viewer
    run: evseg-viewer
    params: { max_points_per_slice: 2000 }
    inputs:
      slices: slicer/slices
      tracks: segmenter/tracks
      truth: slicer/truth
      metrics: evaluator/metrics
"#,
    )
}

/// Size of the file and whether it starts with Rerun's `RRF2`.
fn rrd(path: &Path) -> (u64, bool) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (bytes.len() as u64, bytes.starts_with(b"RRF2"))
}

#[test]
fn a_run_with_a_viewer_node_and_its_recording_give_rrd_files() {
    evseg_tests::bin_dir();
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let port = free_port();
    let g = write(dir, "view.yaml", &graph(port));
    let out = dir.join("run");
    let mcap = dir.join("run.mcap");
    let args = [
        "run",
        g.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
        "--record",
        mcap.to_str().unwrap(),
    ];
    let done = Launcher::start(dir, &args, "run").wait(Duration::from_secs(300));
    assert!(
        done.status.success(),
        "run failed:\n{}\n{}",
        done.stdout,
        done.stderr
    );

    // The live node's file, in the run folder. 10 slices x 3 layers (polarity, tracks, truth)
    // of up to 2000 points: at least 2 bytes a point even compressed.
    let (live_size, live_magic) = rrd(&out.join("viewer.rrd"));
    assert!(live_magic, "viewer.rrd is not a Rerun file");
    assert!(live_size > 2 * SLICES * 3 * 2000, "viewer.rrd: {live_size} bytes");

    // The recording, converted.
    let view_rrd = dir.join("view.rrd");
    let o = Command::new(bin("evseg"))
        .args([
            "view",
            mcap.to_str().unwrap(),
            "--out",
            view_rrd.to_str().unwrap(),
        ])
        .output()
        .expect("run evseg view");
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "evseg view failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    assert!(stdout.contains(": complete"), "{stdout}");
    // Every recorded slice is drawn, with its labels and its truth.
    let mut recorded = 0u64;
    evseg_recorder::read::read(&mcap, |m| {
        recorded += u64::from(m.channel.topic == "slicer/slices");
        Ok(())
    })
    .expect("read the recording");
    assert!(recorded >= SLICES, "{recorded} slices recorded");
    assert!(
        stdout.contains(&format!("{recorded} slices of `slicer`")),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!(" {} per-event layers", 2 * recorded)),
        "{stdout}"
    );
    // The source's truth is aligned with its packets, not the slices: skipped and said so.
    assert!(
        stdout.contains("truth messages of a node other than the slices'"),
        "{stdout}"
    );
    assert!(!stdout.contains("undecodable"), "{stdout}");
    assert!(!stdout.contains("without their slice"), "{stdout}");
    let (size, magic) = rrd(&view_rrd);
    assert!(magic, "view.rrd is not a Rerun file");
    // Every slice: polarity, segmenter labels, truth; the default 10000 points would be more.
    assert!(size > 2 * SLICES * 3 * 2000, "view.rrd: {size} bytes");
    eprintln!("rrd sizes: live node {live_size} B, evseg view {size} B");

    // A file that is not a recording: a clear error naming it, no .rrd.
    let bogus = write(dir, "bogus.mcap", "not mcap");
    let o = Command::new(bin("evseg"))
        .args(["view", bogus.to_str().unwrap()])
        .output()
        .expect("run evseg view");
    assert!(!o.status.success());
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(
        stderr.contains("bogus.mcap") && stderr.contains("not an MCAP file"),
        "{stderr}"
    );
    assert!(!dir.join("bogus.rrd").exists());
}
