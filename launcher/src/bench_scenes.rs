//! `evseg bench`: a fixed, versioned set of simulator scenes through a graph, scored by its
//! evaluator, as one table in the paper's form plus mean values; or, with `--sequences`, the
//! EVIMO2 v2 sequence folders a user names ([`bench_sequences`]), one row per sequence.
//!
//! The set (scene presets, seeds, lengths) is [`BENCH_SET`]; change it only together with
//! [`BENCH_VERSION`], so figures stay comparable across commits.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use serde_json::Value;

use crate::resolve::BinaryResolver;
use crate::run::{RunOptions, apply_overrides, load_graph, run};

/// Version of the scene set; part of every report.
///
/// v3 (was v2; same scenes, seeds and events): the simulator's per-event truth gives a moving
/// object the events of pixels it covers in part (its silhouette inside the pixel's edge
/// sub-samples, while the centre sees the background; 2fa0664), which were labelled
/// background: about 10 % more object events, so "IoU events" and "IoU per object" are not
/// comparable with v2; "IoU mask" (masks from pixel centres) and the egomotion figures are.
///
/// v2 (was v1: the first seven rows alone): each preset with two seeds. The method's temporal
/// feedback makes one sequence's score swing by several points, at times tens, with changes
/// as small as 0.1 % of the simulator's events (a slice where the segmentation flips can stay
/// flipped for a second), so one seed per preset ranked variants by chance too often.
pub const BENCH_VERSION: &str = "evseg-bench-v3";

/// The scenes: (preset, seed, seconds of sensor time).
pub const BENCH_SET: &[(&str, u64, f64)] = &[
    ("one-object", 101, 3.0),
    ("two-objects", 102, 3.0),
    ("fast-rotation", 103, 3.0),
    ("enter-leave", 104, 5.0),
    ("camera-only", 105, 3.0),
    ("low-contrast", 106, 3.0),
    ("high-contrast", 107, 3.0),
    ("one-object", 201, 3.0),
    ("two-objects", 202, 3.0),
    ("fast-rotation", 203, 3.0),
    ("enter-leave", 204, 5.0),
    ("camera-only", 205, 3.0),
    ("low-contrast", 206, 3.0),
    ("high-contrast", 207, 3.0),
];

/// One scene's (or sequence's) figures, taken from the evaluator's `report.json`.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SceneRow {
    /// Preset name, or the sequence folder's path below the folder given.
    pub scene: String,
    /// Seed (simulator scenes only).
    pub seed: Option<u64>,
    /// Mean IoU against the nearest mask (the paper's protocol), 0..1; None without moving objects.
    pub iou_mask: Option<f64>,
    /// Mean IoU against per-event ground truth, 0..1.
    pub iou_events: Option<f64>,
    /// Mean per-object IoU after matching, 0..1.
    pub iou_per_object: Option<f64>,
    /// Per-axis translational velocity RMSE, m/s (direction scaled by the true speed).
    pub rmse_mps: Option<[f64; 3]>,
    /// Median egomotion direction error, degrees.
    pub median_direction_error_deg: Option<f64>,
    /// Id switches of the object with the most (issue 5's target: at most one per object per
    /// sequence), counting the matches above the evaluator's `switch_min_iou` (MOTS); None
    /// without moving objects.
    pub max_id_switches: Option<u64>,
    /// The same over every match, whatever its IoU (the evaluator's `id_switches_any_overlap`).
    pub max_id_switches_any_overlap: Option<u64>,
    /// Windows whose ground truth has no moving object.
    pub static_windows: u64,
    /// Mean over those windows of the share of their events labelled moving (false alarms),
    /// 0..1; None without such windows.
    pub static_share_labelled_moving: Option<f64>,
    /// Run folder.
    pub run: PathBuf,
}

fn num(v: &Value) -> Option<f64> {
    v.as_f64()
}

fn row_from_report(scene: &str, seed: Option<u64>, run: &Path, report: &Value) -> SceneRow {
    let s = &report["sequence"];
    let has_moving = s["windows_with_moving_object"].as_u64().unwrap_or(0) > 0;
    let pick = |v: &Value| if has_moving { num(v) } else { None };
    let rmse = s["egomotion"]["rmse_mps"].as_array().and_then(|a| {
        let v: Vec<f64> = a.iter().filter_map(Value::as_f64).collect();
        (v.len() == 3).then(|| [v[0], v[1], v[2]])
    });
    SceneRow {
        scene: scene.to_string(),
        seed,
        iou_mask: pick(&s["iou_mask"]["mean"]),
        iou_events: pick(&s["iou_events"]["mean"]),
        iou_per_object: pick(&s["iou_per_object_mean"]),
        rmse_mps: rmse,
        median_direction_error_deg: num(&s["egomotion"]["direction_error"]["median_deg"]),
        max_id_switches: s["id_switches_worst_object"].as_u64(),
        max_id_switches_any_overlap: s["id_switches_any_overlap_worst_object"].as_u64(),
        static_windows: s["static_share_labelled_moving"]["windows"].as_u64().unwrap_or(0),
        static_share_labelled_moving: num(&s["static_share_labelled_moving"]["mean"]),
        run: run.to_path_buf(),
    }
}

/// Id of the (first) node of `graph` that runs `binary`.
pub fn node_with_binary(graph: &evseg_graph::Graph, binary: &str) -> anyhow::Result<String> {
    graph
        .nodes
        .iter()
        .find(|n| n.binary == binary)
        .map(|n| n.id.clone())
        .with_context(|| format!("the graph has no `{binary}` node"))
}

/// The ids of the source and evaluator nodes of the graph at `graph_path`, after checking the
/// user's `overrides` against it (a bad one fails here, once, not in every run).
fn bench_nodes(graph_path: &Path, overrides: &[String]) -> anyhow::Result<(String, String)> {
    let dir = graph_path.parent().map(Path::to_path_buf).unwrap_or_default();
    let mut graph = load_graph(graph_path, &BinaryResolver::new(&dir))?;
    let source = node_with_binary(&graph, "evseg-source")?;
    let evaluator = node_with_binary(&graph, "evseg-evaluator")?;
    apply_overrides(&mut graph, overrides)?;
    Ok((source, evaluator))
}

/// Runs every scene of the set through `graph_path`; returns the rows.
pub fn bench(
    graph_path: &Path,
    work: &Path,
    overrides: &[String],
    quiet: bool,
) -> anyhow::Result<Vec<SceneRow>> {
    let (source, evaluator) = bench_nodes(graph_path, overrides)?;
    let mut rows = Vec::new();
    for &(scene, seed, seconds) in BENCH_SET {
        let out = work.join(format!("{scene}-{seed}"));
        eprintln!("{BENCH_VERSION}: {scene} (seed {seed}, {seconds} s)");
        let ours = vec![
            format!("{source}.kind=synthetic"),
            format!("{source}.scene={scene}"),
            format!("{source}.seed={seed}"),
            format!("{source}.seconds={seconds}"),
            format!("{evaluator}.sequence={scene}"),
        ];
        let set = with_overrides(overrides, ours)?;
        rows.push(run_and_score(graph_path, &out, set, quiet, scene, Some(seed))?);
    }
    if rows.is_empty() {
        bail!("no scenes");
    }
    Ok(rows)
}

/// The user's parameter overrides (`node.param=value`, `evseg bench --set`) followed by the
/// bench's own (`ours`: the source's input and the evaluator's sequence name); an override of
/// a parameter the bench sets itself is refused, naming it, since the bench's inputs are what
/// make its figures comparable.
fn with_overrides(user: &[String], ours: Vec<String>) -> anyhow::Result<Vec<String>> {
    let key = |s: &str| s.split_once('=').map_or(s.trim(), |(k, _)| k.trim()).to_string();
    for u in user {
        if ours.iter().any(|o| key(o) == key(u)) {
            bail!(
                "--set {u}: `{}` is set by the bench itself for every scene or sequence (its input and name); change the graph's other parameters",
                key(u)
            );
        }
    }
    Ok(user.iter().cloned().chain(ours).collect())
}

/// Runs `graph_path` into run folder `out` with the parameter overrides `set` and reads the
/// evaluator's report into a row named `name`.
fn run_and_score(
    graph_path: &Path,
    out: &Path,
    set: Vec<String>,
    quiet: bool,
    name: &str,
    seed: Option<u64>,
) -> anyhow::Result<SceneRow> {
    if out.exists() {
        std::fs::remove_dir_all(out).with_context(|| format!("cannot clear {}", out.display()))?;
    }
    let outcome = run(&RunOptions {
        graph: graph_path.to_path_buf(),
        out: Some(out.to_path_buf()),
        set,
        quiet,
        // A free port, not the graph's: a benchmark must not collide with a graph running
        // on this machine (or another benchmark) on the default 7447.
        listen: vec![crate::run::free_loopback_endpoint()?],
        ..RunOptions::default()
    })?;
    for line in crate::run::problem_lines(&outcome.dir, false) {
        eprintln!("  {name}: {line}");
    }
    let report_path = outcome.dir.join("report").join("report.json");
    let text = std::fs::read_to_string(&report_path)
        .with_context(|| format!("the evaluator wrote no {}", report_path.display()))?;
    let report: Value = serde_json::from_str(&text).with_context(|| format!("{}", report_path.display()))?;
    Ok(row_from_report(name, seed, &outcome.dir, &report))
}

/// A sequence folder that could not be scored, and why.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SequenceFailure {
    /// The sequence's name in the table.
    pub sequence: String,
    /// The folder.
    pub path: PathBuf,
    /// The run's error, with its causes.
    pub error: String,
}

/// The EVIMO2 v2 sequences named by `roots` (each a sequence folder, or a folder with sequence
/// folders up to four levels below it, as in the dataset's `<camera>/<category>/<split>/`), each
/// with its name in the table: the path below the folder given, or the folder's own name when
/// it was given itself. Fails when a root holds no sequence, naming it.
pub fn sequences_in(roots: &[PathBuf]) -> anyhow::Result<Vec<(String, PathBuf)>> {
    let mut out: Vec<(String, PathBuf)> = Vec::new();
    for root in roots {
        if !root.is_dir() {
            bail!(
                "{}: no such folder (--sequences takes EVIMO2 v2 sequence folders or folders holding them)",
                root.display()
            );
        }
        let (found, complete) = evseg_evimo2::find_sequence_folders(root);
        if found.is_empty() {
            bail!(
                "{}: no EVIMO2 v2 sequence folder (one holding dataset_events_t.npy) in it or up to {} levels below it",
                root.display(),
                evseg_evimo2::reader::SEQUENCE_SEARCH_DEPTH
            );
        }
        if !complete {
            tracing::warn!(
                root = %root.display(),
                found = found.len(),
                "the search for sequence folders stopped after {} folders; pass the sub-folders to bench the rest",
                evseg_evimo2::reader::SEQUENCE_SEARCH_VISITS
            );
        }
        for path in found {
            let name = match path.strip_prefix(root) {
                Ok(rel) if !rel.as_os_str().is_empty() => rel.display().to_string(),
                _ => root
                    .canonicalize()
                    .unwrap_or_else(|_| root.clone())
                    .file_name()
                    .map_or_else(
                        || root.display().to_string(),
                        |n| n.to_string_lossy().into_owned(),
                    ),
            };
            if out.iter().any(|(_, p)| *p == path) {
                continue;
            }
            out.push((name, path));
        }
    }
    Ok(out)
}

/// The name of a sequence's run folder: its table name with every character other than
/// letters, digits, `-` and `_` replaced by `_`, and a number when two names would collide.
fn run_folder_name(name: &str, taken: &mut std::collections::BTreeSet<String>) -> String {
    let base: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let mut candidate = base.clone();
    let mut k = 2;
    while !taken.insert(candidate.clone()) {
        candidate = format!("{base}-{k}");
        k += 1;
    }
    candidate
}

/// The list of the sequences that could not be scored, to follow the table (empty when none).
pub fn failures_markdown(failures: &[SequenceFailure]) -> String {
    if failures.is_empty() {
        return String::new();
    }
    let mut s = String::from("\nNot scored (the run failed):\n\n");
    for f in failures {
        s.push_str(&format!("- {} ({}): {}\n", f.sequence, f.path.display(), f.error));
    }
    s
}

/// `text` without terminal colour codes, on one line: its first line and, when it has more
/// (a failed run's error ends with the node's last log lines), its last one.
fn one_line(text: &str) -> String {
    let mut plain = String::with_capacity(text.len());
    let mut chars = text.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            // A CSI sequence: ESC [ parameters, then a final byte in '@'..='~'.
            if chars.next() == Some('[') {
                for f in chars.by_ref() {
                    if ('@'..='~').contains(&f) {
                        break;
                    }
                }
            }
            continue;
        }
        plain.push(c);
    }
    let lines: Vec<&str> = plain.lines().map(str::trim).filter(|l| !l.is_empty()).collect();
    match lines.as_slice() {
        [] => String::new(),
        [one] => (*one).to_string(),
        [first, .., last] => format!("{first}; {last}"),
    }
}

/// Runs every EVIMO2 v2 sequence of `roots` ([`sequences_in`]) through `graph_path` (its
/// `evseg-source` node is set to `kind: evimo2` and the sequence's `path`), scored by its
/// evaluator. A sequence whose run fails (a corrupt folder, a node that stops) is reported in
/// the failures and the others still run. Returns the rows and the failures.
pub fn bench_sequences(
    graph_path: &Path,
    roots: &[PathBuf],
    work: &Path,
    overrides: &[String],
    quiet: bool,
) -> anyhow::Result<(Vec<SceneRow>, Vec<SequenceFailure>)> {
    let (source, evaluator) = bench_nodes(graph_path, overrides)?;
    let sequences = sequences_in(roots)?;
    let (mut rows, mut failures) = (Vec::new(), Vec::new());
    let mut taken = std::collections::BTreeSet::new();
    for (k, (name, path)) in sequences.iter().enumerate() {
        eprintln!(
            "sequence {} of {}: {name} ({})",
            k + 1,
            sequences.len(),
            path.display()
        );
        let out = work.join(run_folder_name(name, &mut taken));
        let absolute = path.canonicalize().unwrap_or_else(|_| path.clone());
        let ours = vec![
            format!("{source}.kind=evimo2"),
            // A JSON string, so that no path is read as a number or `null`.
            format!("{source}.path={}", Value::String(absolute.display().to_string())),
            format!("{evaluator}.sequence={}", Value::String(name.clone())),
        ];
        let set = with_overrides(overrides, ours)?;
        match run_and_score(graph_path, &out, set, quiet, name, None) {
            Ok(row) => rows.push(row),
            Err(e) => {
                eprintln!("sequence {name} failed: {e:#}");
                let error = one_line(&format!("{e:#}"));
                failures.push(SequenceFailure {
                    sequence: name.clone(),
                    path: path.clone(),
                    error,
                });
            }
        }
    }
    Ok((rows, failures))
}

fn pct(v: Option<f64>) -> String {
    v.map_or("n/a".into(), |x| format!("{:.2}", 100.0 * x))
}

fn mean(vals: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let v: Vec<f64> = vals.flatten().filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// What a table's rows are: the versioned simulator scenes, or EVIMO2 sequence folders.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rows {
    /// [`BENCH_SET`]: a "Scene" and a "Seed" column.
    Scenes,
    /// `--sequences`: a "Sequence" column.
    Sequences,
}

/// The table in the paper's form, one row per scene (or sequence), plus a mean row.
pub fn markdown(rows: &[SceneRow], graph: &Path, kind: Rows, overrides: &[String]) -> String {
    let (title, head, rule) = match kind {
        Rows::Scenes => (BENCH_VERSION, "| Scene | Seed ", "|---|---:"),
        Rows::Sequences => ("EVIMO2 v2 sequences", "| Sequence ", "|---"),
    };
    let with = if overrides.is_empty() {
        String::new()
    } else {
        format!(" with --set {}", overrides.join(" --set "))
    };
    let mut s = format!(
        "{title} on {}{with} (IoU in %, RMSE in m/s with the predicted direction scaled by the true speed)\n\n\
         {head}| IoU mask | IoU events | IoU per object | Vx RMSE | Vy RMSE | Vz RMSE | median dir. err (deg) | id switches, worst object (any overlap) |\n\
         {rule}|---:|---:|---:|---:|---:|---:|---:|---:|\n",
        graph.display()
    );
    let label = |r: &SceneRow| match kind {
        Rows::Scenes => format!("{} | {}", r.scene, r.seed.map_or("n/a".into(), |n| n.to_string())),
        Rows::Sequences => r.scene.clone(),
    };
    let f = |v: Option<f64>, d: usize| v.map_or("n/a".into(), |x| format!("{x:.d$}"));
    for r in rows {
        let rm = |i: usize| r.rmse_mps.map(|a| a[i]);
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            label(r),
            pct(r.iou_mask),
            pct(r.iou_events),
            pct(r.iou_per_object),
            f(rm(0), 3),
            f(rm(1), 3),
            f(rm(2), 3),
            f(r.median_direction_error_deg, 1),
            match (r.max_id_switches, r.max_id_switches_any_overlap) {
                (Some(n), Some(a)) => format!("{n} ({a})"),
                (Some(n), None) => n.to_string(),
                _ => "n/a".into(),
            }
        ));
    }
    let rm_mean = |i: usize| mean(rows.iter().map(|r| r.rmse_mps.map(|a| a[i])));
    let switches = f(mean(rows.iter().map(|r| r.max_id_switches.map(|n| n as f64))), 1);
    let any_overlap = rows
        .iter()
        .map(|r| r.max_id_switches_any_overlap.map(|n| n as f64));
    let blank = match kind {
        Rows::Scenes => " |",
        Rows::Sequences => "",
    };
    s.push_str(&format!(
        "| **mean** |{blank} {} | {} | {} | {} | {} | {} | {} | {switches} ({}) |\n",
        pct(mean(rows.iter().map(|r| r.iou_mask))),
        pct(mean(rows.iter().map(|r| r.iou_events))),
        pct(mean(rows.iter().map(|r| r.iou_per_object))),
        f(rm_mean(0), 3),
        f(rm_mean(1), 3),
        f(rm_mean(2), 3),
        f(mean(rows.iter().map(|r| r.median_direction_error_deg)), 1),
        f(mean(any_overlap), 1)
    ));
    let static_rows: Vec<&SceneRow> = rows.iter().filter(|r| r.static_windows > 0).collect();
    if !static_rows.is_empty() {
        s.push_str(&format!(
            "\nFalse alarms: in the windows whose ground truth has no moving object, the share of \
             their events labelled moving (mean over the windows, %).\n\n\
             {head}| windows | labelled moving |\n{rule}|---:|---:|\n"
        ));
        for r in &static_rows {
            s.push_str(&format!(
                "| {} | {} | {} |\n",
                label(r),
                r.static_windows,
                pct(r.static_share_labelled_moving)
            ));
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_read_the_evaluator_report_and_means_skip_missing_values() {
        let report: Value = serde_json::json!({"sequence": {
            "windows_with_moving_object": 3,
            "iou_mask": {"mean": 0.5}, "iou_events": {"mean": 0.25}, "iou_per_object_mean": 0.75,
            "egomotion": {"rmse_mps": [0.1, 0.2, 0.3], "direction_error": {"median_deg": 4.0}},
            "id_switches_worst_object": 5, "id_switches_any_overlap_worst_object": 7
        }});
        let r = row_from_report("a", Some(1), Path::new("x"), &report);
        assert_eq!((r.static_windows, r.static_share_labelled_moving), (0, None));
        assert_eq!(
            (r.iou_mask, r.iou_events, r.iou_per_object),
            (Some(0.5), Some(0.25), Some(0.75))
        );
        assert_eq!(r.rmse_mps, Some([0.1, 0.2, 0.3]));
        assert_eq!(
            (r.max_id_switches, r.max_id_switches_any_overlap),
            (Some(5), Some(7))
        );
        let empty: Value = serde_json::json!({"sequence": {"windows_with_moving_object": 0,
            "iou_mask": {"mean": 0.0}, "egomotion": {"rmse_mps": null, "direction_error": {"median_deg": null}},
            "static_share_labelled_moving": {"mean": 0.0125, "windows": 100}}});
        let e = row_from_report("b", Some(2), Path::new("y"), &empty);
        assert_eq!(
            (e.static_windows, e.static_share_labelled_moving),
            (100, Some(0.0125))
        );
        assert_eq!(e.iou_mask, None, "a scene without moving objects has no IoU");
        let md = markdown(&[r.clone(), e.clone()], Path::new("g.yaml"), Rows::Scenes, &[]);
        assert!(
            md.contains("| **mean** | | 50.00 | 25.00 | 75.00 | 0.100 | 0.200 | 0.300 | 4.0 | 5.0 (7.0) |"),
            "{md}"
        );
        assert!(md.contains("| 4.0 | 5 (7) |"), "{md}");
        assert!(md.contains("| b | 2 | n/a |"), "{md}");
        assert!(md.contains("| b | 2 | 100 | 1.25 |"), "{md}");
        assert!(!md.contains("| a | 1 | 0 |"), "{md}");

        // The same rows as EVIMO2 sequences: no seed column, in every table.
        let (mut r, mut e) = (r, e);
        (r.scene, r.seed, e.scene, e.seed) = ("imo/eval/scene13".into(), None, "x".into(), None);
        let md = markdown(
            &[r, e],
            Path::new("g.yaml"),
            Rows::Sequences,
            &["tracker.min_hits=1".into()],
        );
        assert!(
            md.starts_with("EVIMO2 v2 sequences on g.yaml with --set tracker.min_hits=1 (IoU"),
            "{md}"
        );
        assert!(md.contains("| Sequence | IoU mask |"), "{md}");
        assert!(md.contains("| imo/eval/scene13 | 50.00 | 25.00 |"), "{md}");
        assert!(md.contains("| **mean** | 50.00 | 25.00 | 75.00 |"), "{md}");
        assert!(
            md.contains("| Sequence | windows | labelled moving |\n|---|---:|---:|"),
            "{md}"
        );
        assert!(md.contains("| x | 100 | 1.25 |"), "{md}");
    }

    #[test]
    fn sequences_are_found_below_the_folders_given_and_named_by_their_path_there() {
        let dir = tempfile::tempdir().unwrap();
        let seq = |rel: &str| {
            let p = dir.path().join(rel);
            std::fs::create_dir_all(&p).unwrap();
            std::fs::write(p.join("dataset_events_t.npy"), b"").unwrap();
            p
        };
        let a = seq("samsung_mono/imo/eval/scene13_dyn_test_00_000000");
        let b = seq("samsung_mono/imo/eval/scene14_dyn_test_03_000000");
        std::fs::create_dir_all(dir.path().join("samsung_mono/imo/train")).unwrap();
        let root = dir.path().join("samsung_mono");
        let found = sequences_in(&[root.clone(), b.clone()]).unwrap();
        assert_eq!(
            found,
            vec![
                ("imo/eval/scene13_dyn_test_00_000000".to_string(), a),
                ("imo/eval/scene14_dyn_test_03_000000".to_string(), b.clone()),
            ],
            "sorted, each once"
        );
        // A sequence folder given itself is named by its own name.
        assert_eq!(
            sequences_in(std::slice::from_ref(&b)).unwrap(),
            vec![("scene14_dyn_test_03_000000".to_string(), b)]
        );
        // A folder without sequences, or no folder: an error naming it.
        let empty = dir.path().join("samsung_mono/imo/train");
        let e = sequences_in(std::slice::from_ref(&empty))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("train") && e.contains("no EVIMO2 v2 sequence folder"),
            "{e}"
        );
        let e = sequences_in(&[dir.path().join("nope")]).unwrap_err().to_string();
        assert!(e.contains("nope") && e.contains("no such folder"), "{e}");
    }

    #[test]
    fn a_failed_run_is_told_on_one_plain_line() {
        let e = "node `source` (g.yaml:22:5) failed with exit code 1\nlast lines of s.log:\n    \u{1b}[2m2026\u{1b}[0m \u{1b}[31mERROR\u{1b}[0m x\n    error: node source: bad.npz: not a zip\n";
        assert_eq!(
            one_line(e),
            "node `source` (g.yaml:22:5) failed with exit code 1; error: node source: bad.npz: not a zip"
        );
        assert_eq!(one_line("just this"), "just this");
        assert_eq!(one_line(""), "");
    }

    #[test]
    fn user_overrides_come_first_and_may_not_change_the_benchs_own() {
        let ours = || vec!["source.seed=101".to_string(), "evaluator.sequence=a".to_string()];
        assert_eq!(
            with_overrides(&["tracker.min_hits=1".into()], ours()).unwrap(),
            ["tracker.min_hits=1", "source.seed=101", "evaluator.sequence=a"]
        );
        let e = with_overrides(&[" source.seed = 7".into()], ours())
            .unwrap_err()
            .to_string();
        assert!(e.contains("`source.seed` is set by the bench itself"), "{e}");
    }

    #[test]
    fn run_folder_names_are_plain_and_distinct() {
        let mut taken = std::collections::BTreeSet::new();
        assert_eq!(
            run_folder_name("imo/eval/scene 13", &mut taken),
            "imo_eval_scene_13"
        );
        assert_eq!(
            run_folder_name("imo/eval/scene_13", &mut taken),
            "imo_eval_scene_13-2"
        );
        assert_eq!(
            run_folder_name("imo_eval_scene_13", &mut taken),
            "imo_eval_scene_13-3"
        );
    }
}
