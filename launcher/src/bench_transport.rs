//! `evseg bench transport`: what the multi-process graph costs against the same stages called
//! in one process.
//!
//! Both sides run the test-pattern source, the slicer and the stream inspector (the same library
//! code). In-process, the three are called one after the other in a loop. Over Zenoh, they are
//! three processes started by `evseg run` in lock-step mode; throughput there is counted from the
//! source's first publication to the inspector's last arrival (process start-up is reported
//! apart), and the run is checked to have delivered every event exactly once. The graph runs
//! twice: with Zenoh shared memory between the processes (the default for nodes on one
//! machine), and with it switched off, so every slice crosses a loopback socket as it would
//! between two machines.

use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use evseg_inspect::Inspector;
use evseg_slicer::{Slicer, SlicerParams};
use evseg_source::EventSource;
use evseg_source::pattern::{Pattern, PatternParams};

use crate::run::{RunOptions, run};

/// Sensor event rate of the pattern, events per second (a fast sensor's peak rate).
pub const RATE: f64 = 10.0e6;
/// Events pushed through per slice size (at least this many; at least 20 slices).
pub const MIN_EVENTS: u64 = 30_000_000;

/// One row of the benchmark.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Row {
    /// Events per slice.
    pub slice_events: u64,
    /// Events pushed through.
    pub events: u64,
    /// In-process throughput, events per second.
    pub in_process: f64,
    /// Multi-process throughput over Zenoh with shared memory, events per second.
    pub graph: f64,
    /// graph / in_process.
    pub ratio: f64,
    /// Multi-process throughput over Zenoh without shared memory (loopback TCP), events per
    /// second.
    pub graph_socket: f64,
    /// graph_socket / in_process.
    pub ratio_socket: f64,
    /// Seconds from launcher start to the source's first publication.
    pub startup_s: f64,
}

fn in_process(slice_events: u64, seconds: f64) -> anyhow::Result<(u64, f64)> {
    let window = slice_events as f64 / RATE;
    let mut source = Pattern::new(PatternParams {
        rate: RATE,
        seconds,
        width: 640,
        height: 480,
        seed: 5,
    })?;
    let mut slicer = Slicer::new(SlicerParams {
        window_s: window,
        ..SlicerParams::default()
    })?;
    let mut inspector = Inspector::default();
    // The source node keeps a digest of what it publishes; the in-process side does the same work.
    let mut source_digest = evseg_schemas::digest::EventDigest::default();
    let start = Instant::now();
    let mut k = 0u64;
    while let Some(batch) = source.next_batch((k + 1) as f64 * window)? {
        source_digest.add(&batch.events);
        let packet = evseg_schemas::EventPacket {
            camera: source.camera(),
            events: batch.events,
            imu: batch.imu,
        };
        for s in slicer.push(packet, None, (k + 1) as f64 * window)? {
            inspector.add(s.seq, s.t_start, s.t_end, &s.slice);
        }
        k += 1;
    }
    for s in slicer.finish() {
        inspector.add(s.seq, s.t_start, s.t_end, &s.slice);
    }
    let dt = start.elapsed().as_secs_f64();
    let r = inspector.report();
    if r.problem_count != 0 || r.digest != source_digest {
        bail!("in-process run found problems: {:?}", r.problems);
    }
    Ok((r.digest.count, dt))
}

/// Shared-memory pool of the benchmark's nodes, MiB: the lock-step window (4) of its largest
/// slices (1M events, 13 MB), as the graph's documentation asks, so that every row measures
/// shared memory and not the heap path of a full pool (the graphs' default is smaller).
const TRANSPORT_POOL_MIB: u32 = 64;

fn graph_text(slice_events: u64, seconds: f64, port: u16, shared_memory: bool) -> String {
    let window_ms = slice_events as f64 / RATE * 1e3;
    format!(
        r#"name: bench{port}
mode: lockstep
zenoh:
  machines:
    local: {{ listen: ["tcp/127.0.0.1:{port}"] }}
  shared_memory: {{ enabled: {shared_memory}, pool_mib: {TRANSPORT_POOL_MIB} }}
nodes:
  - id: source
    run: evseg-source
    params: {{ kind: pattern, rate: {RATE}, seconds: {seconds}, batch_ms: {window_ms}, seed: 5 }}
    outputs: [events]
  - id: slicer
    run: evseg-slicer
    params: {{ window_ms: {window_ms} }}
    inputs: {{ events: source/events }}
    outputs: [slices]
  - id: inspect
    run: evseg-inspect
    inputs: {{ slices: slicer/slices }}
"#
    )
}

fn over_zenoh(
    slice_events: u64,
    seconds: f64,
    work: &Path,
    shared_memory: bool,
) -> anyhow::Result<(u64, f64, f64)> {
    let port = crate::run::free_loopback_port()?;
    let link = if shared_memory { "shm" } else { "socket" };
    let graph = work.join(format!("transport-{slice_events}-{link}.yaml"));
    std::fs::write(&graph, graph_text(slice_events, seconds, port, shared_memory))?;
    let out = work.join(format!("run-{slice_events}-{link}"));
    let launched = evseg_inspect::now_ns();
    let outcome = run(&RunOptions {
        graph,
        out: Some(out.clone()),
        quiet: true,
        ..RunOptions::default()
    })?;
    if shared_memory && !outcome.shared_memory {
        bail!(
            "shared memory was turned off for the run (the locked-memory limit, see its warning), so the shared-memory column would measure the sockets; raise `ulimit -l` and run again"
        );
    }
    let read = |name: &str| -> anyhow::Result<serde_json::Value> {
        let p = outcome.dir.join(name);
        let text = std::fs::read_to_string(&p).with_context(|| format!("cannot read {}", p.display()))?;
        Ok(serde_json::from_str(&text)?)
    };
    let sent = read("source-source.json")?;
    let seen = read("inspect-inspect.json")?;
    if seen["digest"] != sent["digest"] || seen["problem_count"] != 0 {
        bail!(
            "the graph did not deliver every event exactly once ({})",
            out.display()
        );
    }
    let first = sent["first_publish_ns"].as_u64().context("no first_publish_ns")?;
    let last = seen["last_arrival_ns"].as_u64().context("no last_arrival_ns")?;
    let count = seen["digest"]["count"].as_u64().unwrap_or(0);
    Ok((
        count,
        (last.saturating_sub(first)) as f64 * 1e-9,
        (first.saturating_sub(launched)) as f64 * 1e-9,
    ))
}

/// Runs the benchmark for each slice size; prints and returns the rows.
pub fn bench(sizes: &[u64], work: &Path) -> anyhow::Result<Vec<Row>> {
    std::fs::create_dir_all(work)?;
    let mut rows = Vec::new();
    for &n in sizes {
        let events = MIN_EVENTS.max(20 * n);
        let seconds = events as f64 / RATE;
        let (count_a, dt_a) = in_process(n, seconds)?;
        let (count_b, dt_b, startup) = over_zenoh(n, seconds, work, true)?;
        let (count_c, dt_c, _) = over_zenoh(n, seconds, work, false)?;
        if count_a != count_b || count_a != count_c {
            bail!(
                "in-process saw {count_a} events, the graph {count_b} (shared memory), {count_c} (sockets)"
            );
        }
        let row = Row {
            slice_events: n,
            events: count_a,
            in_process: count_a as f64 / dt_a,
            graph: count_b as f64 / dt_b,
            ratio: (count_b as f64 / dt_b) / (count_a as f64 / dt_a),
            graph_socket: count_c as f64 / dt_c,
            ratio_socket: (count_c as f64 / dt_c) / (count_a as f64 / dt_a),
            startup_s: startup,
        };
        eprintln!(
            "{:>9} events/slice: in-process {:>7.1} M ev/s, graph {:>7.1} M ev/s (ratio {:.2}), without shared memory {:>7.1} M ev/s (ratio {:.2}); start-up {:.2} s",
            n,
            row.in_process / 1e6,
            row.graph / 1e6,
            row.ratio,
            row.graph_socket / 1e6,
            row.ratio_socket,
            row.startup_s
        );
        rows.push(row);
    }
    Ok(rows)
}

/// The rows as a Markdown table.
pub fn markdown(rows: &[Row]) -> String {
    let mut s = String::from(
        "| events per slice | events | in-process (M ev/s) | 3 processes, shared memory (M ev/s) | ratio | 3 processes, loopback TCP (M ev/s) | ratio |\n|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {:.1} | {:.1} | {:.2} | {:.1} | {:.2} |\n",
            r.slice_events,
            r.events,
            r.in_process / 1e6,
            r.graph / 1e6,
            r.ratio,
            r.graph_socket / 1e6,
            r.ratio_socket
        ));
    }
    s
}
