//! `evseg bench pipeline`: end-to-end speed of a whole graph in lock-step mode.
//!
//! A simulator scene is first written as an EVIMO2 v2 folder (not timed: the simulator is slower
//! than the pipeline and would be what is measured), then the graph (default
//! `graphs/evimo2.yaml`, the method's stages) reads it. Reported: events per second over the
//! run's wall time (from the nodes' spawn, so process start-up included; the start-up before
//! the source's first packet and the rate after it are given too) and each stage's share of the
//! busy time its node reported (seconds inside its own logic).

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::Value;

use crate::run::{RunOptions, run};
use crate::spread::median_and_range;

/// One stage's busy time.
#[derive(Debug, Clone, serde::Serialize)]
pub struct StageTime {
    /// Node id.
    pub node: String,
    /// Seconds in the node's own logic.
    pub busy_s: f64,
    /// Slices (or source steps) processed.
    pub processed: u64,
}

/// The figures of one pipeline run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct PipelineRow {
    /// Scene, seed, seconds of sensor time.
    pub scene: String,
    /// Seed of the scene.
    pub seed: u64,
    /// Events in the sequence.
    pub events: u64,
    /// Wall time of the run, seconds.
    pub wall_s: f64,
    /// Events per second over the wall time.
    pub events_per_s: f64,
    /// Seconds from the nodes' spawn (the start of `wall_s`) to the source's first packet:
    /// process start-up, the sessions' connection and the first read, paid once per run
    /// whatever its length (`None` when the source's summary lacks its first publication).
    pub start_up_s: Option<f64>,
    /// Events per second from the source's first packet to the end of the run (`None` as
    /// above): the throughput a long run approaches.
    pub events_per_s_after_start_up: Option<f64>,
    /// Per node, in graph order of the statistics.
    pub stages: Vec<StageTime>,
    /// Restarts during the run ([`crate::run::RunOutcome::restarts`]): its rate includes
    /// their waits, so it says little of the pipeline's speed.
    pub restarts: Vec<String>,
}

/// Options of the pipeline benchmark.
#[derive(Debug, Clone)]
pub struct PipelineOptions {
    /// Graph to run; its `evseg-source` node gets `kind=evimo2` and the folder's path.
    pub graph: PathBuf,
    /// Simulator preset.
    pub scene: String,
    /// Seed.
    pub seed: u64,
    /// Seconds of sensor time.
    pub seconds: f64,
    /// Working folder (the sequence and the run folder).
    pub work: PathBuf,
}

/// Writes the sequence (unless already there) and runs the graph on it.
pub fn bench(o: &PipelineOptions) -> anyhow::Result<PipelineRow> {
    let seq = o.work.join(format!("{}-seed{}-{}s", o.scene, o.seed, o.seconds));
    if !seq.join("dataset_events_t.npy").exists() {
        eprintln!("writing {} (not timed)", seq.display());
        evseg_source::synthetic::write_evimo2(&o.scene, o.seed, Some(o.seconds), 1.0, &seq)
            .with_context(|| format!("cannot write the sequence to {}", seq.display()))?;
    }
    let dir = o.graph.parent().map(Path::to_path_buf).unwrap_or_default();
    let graph = crate::run::load_graph(&o.graph, &crate::resolve::BinaryResolver::new(&dir))?;
    let source = crate::bench_scenes::node_with_binary(&graph, "evseg-source")?;
    let out = o.work.join("run");
    if out.exists() {
        std::fs::remove_dir_all(&out).with_context(|| format!("cannot clear {}", out.display()))?;
    }
    let outcome = run(&RunOptions {
        graph: o.graph.clone(),
        out: Some(out),
        set: vec![
            format!("{source}.kind=evimo2"),
            format!("{source}.path={}", seq.display()),
        ],
        quiet: true,
        // A free port, not the graph's (as `evseg bench`): it runs beside other graphs.
        listen: vec![crate::run::free_loopback_endpoint()?],
        ..RunOptions::default()
    })?;
    let digest_path = outcome.dir.join(format!("source-{source}.json"));
    let digest: Value = serde_json::from_str(
        &std::fs::read_to_string(&digest_path).with_context(|| format!("{}", digest_path.display()))?,
    )
    .with_context(|| format!("{}", digest_path.display()))?;
    let events = digest["digest"]["count"]
        .as_u64()
        .with_context(|| format!("{}: no digest.count", digest_path.display()))?;
    let start_up_s = digest["first_publish_ns"]
        .as_u64()
        .map(|first| first.saturating_sub(outcome.started_unix_ns) as f64 * 1e-9);
    let events_per_s_after_start_up = start_up_s
        .map(|s| outcome.seconds - s)
        .filter(|&after| after > 0.0)
        .map(|after| events as f64 / after);
    let stages = outcome
        .stats
        .values()
        .map(|s| StageTime {
            node: s.node.clone(),
            busy_s: s.busy_s,
            processed: s.processed,
        })
        .collect();
    Ok(PipelineRow {
        scene: o.scene.clone(),
        seed: o.seed,
        events,
        wall_s: outcome.seconds,
        events_per_s: events as f64 / outcome.seconds.max(1e-9),
        start_up_s,
        events_per_s_after_start_up,
        stages,
        restarts: outcome.restarts,
    })
}

/// The row as Markdown: the headline, then the per-stage shares.
pub fn markdown(r: &PipelineRow, graph: &Path) -> String {
    let total: f64 = r.stages.iter().map(|s| s.busy_s).sum();
    let after = match (r.start_up_s, r.events_per_s_after_start_up) {
        (Some(s), Some(rate)) => format!(
            " ({s:.2} s of start-up before the first packet; {:.2} M events/s after it)",
            rate / 1e6
        ),
        _ => String::new(),
    };
    let mut s = format!(
        "{} on `{}` (seed {}): {} events in {:.2} s wall = **{:.2} M events/s** end to end, lock-step{after}\n\n\
         | node | busy s | share of busy time | slices |\n|---|---:|---:|---:|\n",
        graph.display(),
        r.scene,
        r.seed,
        r.events,
        r.wall_s,
        r.events_per_s / 1e6
    );
    for st in &r.stages {
        s.push_str(&format!(
            "| {} | {:.2} | {:.1} % | {} |\n",
            st.node,
            st.busy_s,
            100.0 * st.busy_s / total.max(1e-12),
            st.processed
        ));
    }
    if !r.restarts.is_empty() {
        s.push_str(&format!(
            "\n**This run restarted {} node(s)**, and its wall time includes the wait: {}\n",
            r.restarts.len(),
            r.restarts.join("; ")
        ));
    }
    s
}

/// Runs the benchmark `runs` times, prints each run's table and (with two runs or more) the
/// [`summary`], and writes them to `pipeline.md` and the rows to `pipeline.json` in the
/// working folder (one run: its row; several: the list).
pub fn run_and_write(options: &PipelineOptions, runs: u32) -> anyhow::Result<()> {
    let mut rows = Vec::new();
    let mut md = String::new();
    for _ in 0..runs {
        let row = bench(options)?;
        let run_md = markdown(&row, &options.graph);
        println!("{run_md}");
        md.push_str(&run_md);
        md.push('\n');
        rows.push(row);
    }
    if let Some(summary) = summary(&rows) {
        println!("{summary}");
        md.push_str(&summary);
        md.push('\n');
    }
    std::fs::write(options.work.join("pipeline.md"), &md)?;
    let json = match rows.as_slice() {
        [one] => serde_json::to_string_pretty(one)?,
        all => serde_json::to_string_pretty(all)?,
    };
    std::fs::write(options.work.join("pipeline.json"), json)?;
    Ok(())
}

/// With two runs or more, a line with the median, lowest and highest end-to-end rate (M
/// events/s) and the median start-up; `None` for a single run.
pub fn summary(rows: &[PipelineRow]) -> Option<String> {
    if rows.len() < 2 {
        return None;
    }
    let rates: Vec<f64> = rows.iter().map(|r| r.events_per_s / 1e6).collect();
    let (median_rate, lo, hi) = median_and_range(&rates)?;
    let start_ups: Vec<f64> = rows.iter().filter_map(|r| r.start_up_s).collect();
    let start_up = match median_and_range(&start_ups) {
        Some((m, _, _)) => format!("; median start-up {m:.2} s"),
        None => String::new(),
    };
    let restarted = rows.iter().filter(|r| !r.restarts.is_empty()).count();
    let restarted = if restarted == 0 {
        String::new()
    } else {
        format!("; {restarted} run(s) restarted a node (their rates count the wait)")
    };
    Some(format!(
        "{} runs: median **{:.2} M events/s** end to end (lowest {lo:.2}, highest {hi:.2}){start_up}{restarted}",
        rows.len(),
        median_rate
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(rate: f64, start_up: Option<f64>) -> PipelineRow {
        PipelineRow {
            scene: "two-objects".into(),
            seed: 7,
            events: 1,
            wall_s: 1.0,
            events_per_s: rate * 1e6,
            start_up_s: start_up,
            events_per_s_after_start_up: None,
            stages: vec![],
            restarts: vec![],
        }
    }

    #[test]
    fn the_summary_gives_the_median_and_the_range_of_several_runs() {
        assert_eq!(summary(&[row(1.0, Some(0.3))]), None);
        let s = summary(&[row(0.9, Some(0.3)), row(1.1, Some(0.2)), row(0.8, None)]);
        assert_eq!(
            s.as_deref(),
            Some(
                "3 runs: median **0.90 M events/s** end to end (lowest 0.80, highest 1.10); median start-up 0.25 s"
            )
        );
        let even = summary(&[row(0.9, None), row(1.0, None)]).unwrap_or_default();
        assert!(even.contains("median **0.95 M events/s**"), "{even}");
        assert!(!even.contains("restarted"), "{even}");
    }

    /// A run in which the launcher restarted a node is no measure of the pipeline's speed: its
    /// table and the summary say so.
    #[test]
    fn a_run_that_restarted_a_node_is_marked() {
        let mut slow = row(0.1, None);
        slow.restarts = vec!["node `evaluator` processed nothing in 40 s".into()];
        let md = markdown(&slow, Path::new("graphs/evimo2.yaml"));
        assert!(
            md.contains("restarted 1 node(s)") && md.contains("`evaluator`"),
            "{md}"
        );
        let s = summary(&[row(1.0, None), slow, row(1.1, None)]).unwrap_or_default();
        assert!(
            s.ends_with("; 1 run(s) restarted a node (their rates count the wait)"),
            "{s}"
        );
    }
}
