//! One graph split over two launchers ("robot" and "base") joined over Zenoh on loopback, and
//! two instances of one graph side by side on one Zenoh network without crosstalk.

use std::time::Duration;

use evseg_tests::{Launcher, free_port, read_json, write};

#[test]
fn two_launchers_run_one_graph() {
    let dir = tempfile::tempdir().unwrap();
    let (robot, base) = (free_port(), free_port());
    let text = format!(
        r#"name: split{robot}
zenoh:
  machines:
    robot: {{ listen: ["tcp/127.0.0.1:{robot}"] }}
    base: {{ listen: ["tcp/127.0.0.1:{base}"], connect: ["tcp/127.0.0.1:{robot}"] }}
nodes:
  - id: source
    run: evseg-source
    machine: robot
    params: {{ kind: pattern, rate: 200000, seconds: 1, seed: 11 }}
    outputs: [events]
  - id: slicer
    run: evseg-slicer
    machine: robot
    inputs: {{ events: source/events }}
    outputs: [slices]
  - id: inspect
    run: evseg-inspect
    machine: base
    inputs: {{ slices: slicer/slices }}
"#
    );
    let g = write(dir.path(), "graph.yaml", &text);
    let (out_r, out_b) = (dir.path().join("robot"), dir.path().join("base"));
    let base_l = Launcher::start(
        dir.path(),
        &[
            "run",
            g.to_str().unwrap(),
            "--machine",
            "base",
            "--out",
            out_b.to_str().unwrap(),
            "-q",
        ],
        "base",
    );
    let robot_l = Launcher::start(
        dir.path(),
        &[
            "run",
            g.to_str().unwrap(),
            "--machine",
            "robot",
            "--out",
            out_r.to_str().unwrap(),
            "-q",
        ],
        "robot",
    );
    let r = robot_l.wait(Duration::from_secs(120));
    let b = base_l.wait(Duration::from_secs(120));
    assert!(r.status.success(), "robot launcher failed:\n{}", r.stderr);
    assert!(b.status.success(), "base launcher failed:\n{}", b.stderr);
    // Each launcher started only its own nodes.
    assert!(out_r.join("logs/source.log").exists() && !out_r.join("logs/inspect.log").exists());
    assert!(out_b.join("logs/inspect.log").exists() && !out_b.join("logs/source.log").exists());
    let sent = read_json(&out_r.join("source-source.json"))["digest"].clone();
    let seen = read_json(&out_b.join("inspect-inspect.json"));
    assert_eq!(sent["count"], 200_000);
    assert_eq!(seen["digest"], sent);
    assert_eq!(seen["problem_count"], 0);
}

#[test]
fn two_instances_side_by_side_do_not_see_each_other() {
    let dir = tempfile::tempdir().unwrap();
    let (p1, p2) = (free_port(), free_port());
    let text = r#"name: twin
nodes:
  - id: source
    run: evseg-source
    params: { kind: pattern, rate: 200000, seconds: 1, seed: 1 }
    outputs: [events]
  - id: slicer
    run: evseg-slicer
    inputs: { events: source/events }
    outputs: [slices]
  - id: inspect
    run: evseg-inspect
    inputs: { slices: slicer/slices }
"#;
    let g = write(dir.path(), "graph.yaml", text);
    let (out_a, out_b) = (dir.path().join("a"), dir.path().join("b"));
    let ep1 = format!("tcp/127.0.0.1:{p1}");
    let ep2 = format!("tcp/127.0.0.1:{p2}");
    let a = Launcher::start(
        dir.path(),
        &[
            "run",
            g.to_str().unwrap(),
            "--instance",
            "A",
            "--listen",
            &ep1,
            "--out",
            out_a.to_str().unwrap(),
            "-q",
        ],
        "a",
    );
    // Instance B joins A's Zenoh network and sends a different stream (another seed).
    let b = Launcher::start(
        dir.path(),
        &[
            "run",
            g.to_str().unwrap(),
            "--instance",
            "B",
            "--listen",
            &ep2,
            "--connect",
            &ep1,
            "--set",
            "source.seed=2",
            "--out",
            out_b.to_str().unwrap(),
            "-q",
        ],
        "b",
    );
    let ra = a.wait(Duration::from_secs(120));
    let rb = b.wait(Duration::from_secs(120));
    assert!(ra.status.success(), "A failed:\n{}", ra.stderr);
    assert!(rb.status.success(), "B failed:\n{}", rb.stderr);
    for out in [&out_a, &out_b] {
        let sent = read_json(&out.join("source-source.json"))["digest"].clone();
        let seen = read_json(&out.join("inspect-inspect.json"));
        assert_eq!(seen["digest"], sent, "crosstalk or loss in {}", out.display());
        assert_eq!(seen["problem_count"], 0);
    }
    let (sa, sb) = (
        read_json(&out_a.join("source-source.json"))["digest"].clone(),
        read_json(&out_b.join("source-source.json"))["digest"].clone(),
    );
    assert_ne!(
        sa["hash"], sb["hash"],
        "the two instances must carry different streams"
    );
}
