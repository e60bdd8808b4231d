//! `evseg ab`: two variants of a graph on the same recorded input, their evaluator figures side
//! by side with the differences.
//!
//! Variant A is the graph as written; variant B is the graph with `--swap node=binary` (the node
//! runs another implementation) and `--set-b node.param=value` applied. The swap fits the
//! graph to the new binary where that is safe, with a note for each change
//! (`evseg_graph::swap_adapted`): the old binary's parameters the new one does not have are
//! removed, and optional inputs that read an output the new one does not publish are left
//! unwired. The edited graph is then checked like any graph file, so a required port the new
//! binary lacks, or a port of another type, is refused with variant B's file, line and column.
//! Each recording is replayed from `--from` into both variants (`evseg replay`) at the same
//! time, as two graph instances (`ab-a` and `ab-b`, so no key is shared) on one Zenoh network:
//! variant B's router connects to variant A's. Lock-step replay makes the inputs of both
//! bit-identical. The figures come from each run's `report/report.json`.

use std::path::{Path, PathBuf};

use anyhow::Context;
use serde_json::Value;

use crate::replay::ReplaySpec;
use crate::run::{RunOptions, run};

/// Options of an A/B comparison.
#[derive(Debug, Clone)]
pub struct AbOptions {
    /// Graph file (variant A).
    pub graph: PathBuf,
    /// Recordings to replay (one sequence each).
    pub recordings: Vec<PathBuf>,
    /// Replay point.
    pub from: String,
    /// `node=binary` swaps of variant B.
    pub swap: Vec<String>,
    /// Parameter overrides of both variants.
    pub set: Vec<String>,
    /// Parameter overrides of variant B only.
    pub set_b: Vec<String>,
    /// Working folder (run folders, the edited graph, the reports).
    pub work: PathBuf,
    /// Router listen endpoints of variant A replacing the graph's (default: a free loopback
    /// port). Variant B's router listens on a free loopback port and connects to these.
    pub listen: Vec<String>,
    /// Replay recordings with gaps, keeping the slices every replayed channel holds
    /// (`evseg replay --skip-gaps`); both variants get the same slices.
    pub skip_gaps: bool,
}

/// The figures compared, as (label, JSON pointer into report.json, scale).
const FIGURES: &[(&str, &str, f64)] = &[
    ("IoU mask (%)", "/sequence/iou_mask/mean", 100.0),
    ("IoU events (%)", "/sequence/iou_events/mean", 100.0),
    ("IoU per object (%)", "/sequence/iou_per_object_mean", 100.0),
    ("Vx RMSE (m/s)", "/sequence/egomotion/rmse_mps/0", 1.0),
    ("Vy RMSE (m/s)", "/sequence/egomotion/rmse_mps/1", 1.0),
    ("Vz RMSE (m/s)", "/sequence/egomotion/rmse_mps/2", 1.0),
    (
        "median dir. err (deg)",
        "/sequence/egomotion/direction_error/median_deg",
        1.0,
    ),
    (
        "id switches, worst object",
        "/sequence/id_switches_worst_object",
        1.0,
    ),
    (
        "id switches, worst object, any overlap",
        "/sequence/id_switches_any_overlap_worst_object",
        1.0,
    ),
    (
        "false alarms, static windows (%)",
        "/sequence/static_share_labelled_moving/mean",
        100.0,
    ),
];

/// One figure of one sequence in both variants.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AbFigure {
    /// Sequence (recording file stem, or "overall").
    pub sequence: String,
    /// Figure label with its unit.
    pub figure: String,
    /// Variant A.
    pub a: Option<f64>,
    /// Variant B.
    pub b: Option<f64>,
    /// B - A.
    pub difference: Option<f64>,
}

fn figure(report: &Value, pointer: &str, scale: f64) -> Option<f64> {
    report
        .pointer(pointer)
        .and_then(Value::as_f64)
        .filter(|v| v.is_finite())
        .map(|v| v * scale)
}

fn read_report(dir: &Path) -> anyhow::Result<Value> {
    let path = dir.join("report").join("report.json");
    let text = std::fs::read_to_string(&path).with_context(|| {
        format!(
            "the evaluator wrote no {} (does the graph have one?)",
            path.display()
        )
    })?;
    serde_json::from_str(&text).with_context(|| format!("{}", path.display()))
}

/// Writes variant B's graph file into `work` and returns its path; `resolver` describes the
/// binaries, `replaced` are the nodes `--from` replays (which a swap would not reach).
fn graph_b(
    o: &AbOptions,
    resolver: &crate::resolve::BinaryResolver,
    replaced: &std::collections::BTreeSet<String>,
) -> anyhow::Result<PathBuf> {
    let file = o.graph.display().to_string();
    let mut text = std::fs::read_to_string(&o.graph).with_context(|| format!("cannot read {file}"))?;
    let describe = |b: &str| resolver.describe(b).map(|(_, d)| d);
    let mut swapped: Vec<&str> = Vec::new();
    for s in &o.swap {
        let (node, binary) = s
            .split_once('=')
            .with_context(|| format!("--swap `{s}`: expected node=binary"))?;
        anyhow::ensure!(
            !swapped.contains(&node),
            "--swap `{s}`: node `{node}` is already swapped by an earlier --swap; give one binary per node"
        );
        swapped.push(node);
        anyhow::ensure!(
            !replaced.contains(node),
            "--swap `{s}`: node `{node}` is replayed from the recording, not run (`--from {}` \
             replays it and every node upstream of it), so variant B would not run `{binary}`; \
             replay from a node that does not depend on `{node}`",
            o.from
        );
        let adapted = evseg_graph::swap_adapted(&file, &text, node, binary, &describe)?;
        for note in &adapted.notes {
            eprintln!("note: variant B, {note}");
        }
        text = adapted.text;
    }
    std::fs::create_dir_all(&o.work).with_context(|| format!("cannot create {}", o.work.display()))?;
    let path = o.work.join("graph-b.yaml");
    std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(path)
}

/// Runs both variants on every recording; returns the figures per sequence and overall (mean
/// over sequences).
pub fn ab(o: &AbOptions) -> anyhow::Result<Vec<AbFigure>> {
    anyhow::ensure!(!o.recordings.is_empty(), "give at least one recording");
    // One resolver for the swap and the check, so that each binary is described once.
    let dir = o.graph.parent().map(Path::to_path_buf).unwrap_or_default();
    let resolver = crate::resolve::BinaryResolver::new(&dir);
    // Both variants are checked before anything runs: variant B's graph (a swapped binary with
    // other ports or parameters is reported with variant B's file, line and column), every
    // override with the flag it came from, and that what B changes is run, not replayed.
    let mut a = crate::run::load_graph(&o.graph, &resolver)?;
    let replaced = crate::replay::upstream(&a, &o.from)?;
    let b_graph = graph_b(o, &resolver, &replaced)?;
    crate::run::apply_overrides_of(&mut a, &o.set, "--set")?;
    let mut b = crate::run::load_graph(&b_graph, &resolver)?;
    crate::run::apply_overrides_of(&mut b, &o.set, "--set")?;
    crate::run::apply_overrides_of(&mut b, &o.set_b, "--set-b")?;
    crate::replay::refuse_overrides_of_replayed(&replaced, &o.from, &o.set, "--set")?;
    crate::replay::refuse_overrides_of_replayed(&replaced, &o.from, &o.set_b, "--set-b")?;
    let mut rows = Vec::new();
    for rec in &o.recordings {
        let seq = rec
            .file_stem()
            .map_or_else(|| rec.display().to_string(), |s| s.to_string_lossy().into_owned());
        let a_listen = if o.listen.is_empty() {
            vec![crate::run::free_loopback_endpoint()?]
        } else {
            o.listen.clone()
        };
        let b_listen = vec![crate::run::free_loopback_endpoint()?];
        let b_connect: Vec<String> = a_listen.iter().map(|e| crate::run::local_endpoint(e)).collect();
        let mut options = Vec::new();
        for (variant, graph, extra, listen, connect) in [
            ("a", &o.graph, &[][..], a_listen, Vec::new()),
            ("b", &b_graph, &o.set_b[..], b_listen, b_connect),
        ] {
            let out = o.work.join(&seq).join(variant);
            if out.exists() {
                std::fs::remove_dir_all(&out).with_context(|| format!("cannot clear {}", out.display()))?;
            }
            let mut set = o.set.clone();
            set.extend(extra.iter().cloned());
            options.push((
                variant,
                RunOptions {
                    graph: graph.clone(),
                    instance: Some(format!("ab-{variant}")),
                    out: Some(out),
                    set,
                    listen,
                    connect,
                    quiet: true,
                    replay: Some(ReplaySpec {
                        recording: rec.clone(),
                        from: o.from.clone(),
                        speed: None,
                        skip_gaps: o.skip_gaps,
                    }),
                    ..RunOptions::default()
                },
            ));
        }
        eprintln!("A/B: {seq}, variants a and b side by side on one Zenoh network");
        let outcomes: Vec<anyhow::Result<_>> = std::thread::scope(|scope| {
            let handles: Vec<_> = options
                .iter()
                .map(|(variant, opts)| {
                    scope.spawn(move || {
                        run(opts).with_context(|| format!("variant {variant} on {}", rec.display()))
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(anyhow::anyhow!("a variant's launcher thread panicked")))
                })
                .collect()
        });
        let mut reports = Vec::new();
        for outcome in outcomes {
            reports.push(read_report(&outcome?.dir)?);
        }
        for &(label, pointer, scale) in FIGURES {
            let a = figure(&reports[0], pointer, scale);
            let b = figure(&reports[1], pointer, scale);
            rows.push(AbFigure {
                sequence: seq.clone(),
                figure: label.to_string(),
                a,
                b,
                difference: a.zip(b).map(|(a, b)| b - a),
            });
        }
    }
    if o.recordings.len() > 1 {
        for &(label, _, _) in FIGURES {
            let of = |f: fn(&AbFigure) -> Option<f64>| {
                let v: Vec<f64> = rows.iter().filter(|r| r.figure == label).filter_map(f).collect();
                (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
            };
            let (a, b) = (of(|r| r.a), of(|r| r.b));
            rows.push(AbFigure {
                sequence: "overall".into(),
                figure: label.to_string(),
                a,
                b,
                difference: a.zip(b).map(|(a, b)| b - a),
            });
        }
    }
    Ok(rows)
}

/// The comparison as a Markdown table.
pub fn markdown(rows: &[AbFigure], o: &AbOptions) -> String {
    let num = |v: Option<f64>| v.map_or("n/a".into(), |x| format!("{x:.3}"));
    let mut s = format!(
        "A/B on `{}` from `{}`: A = as written; B = swap {:?}, set {:?} (both: set {:?})\n\n\
         | sequence | figure | A | B | B - A |\n|---|---|---:|---:|---:|\n",
        o.graph.display(),
        o.from,
        o.swap,
        o.set_b,
        o.set
    );
    for r in rows {
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            r.sequence,
            r.figure,
            num(r.a),
            num(r.b),
            num(r.difference)
        ));
    }
    s
}
