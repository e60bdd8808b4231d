//! Replaying a recording (`evseg replay run.mcap --graph G --from slicer`): the nodes
//! downstream of the slicer run live on the recorded slices and truth, and in lock-step mode
//! every frame they publish is bit-identical to the recorded run's (envelope except its
//! wall-clock publish time, and body), unpaced and paced at the recorded speed. A recording
//! without a needed channel, or with one of another schema, is refused before anything starts;
//! a cut-off recording is replayed as far as it was recovered.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use evseg_recorder::write::{ChannelSpec, McapRecorder, WriterSettings};
use evseg_schemas::{Envelope, codec};
use evseg_tests::{Launcher, free_port, sim_graph, write};

fn graph(port: u16) -> String {
    sim_graph("replay", port, "")
}

struct Done {
    ok: bool,
    stdout: String,
    stderr: String,
    seconds: f64,
}

/// Runs `evseg <args>` with a fresh graph file (its own port and instance) in `dir`.
fn evseg(dir: &Path, tag: &str, args: &[&str]) -> (Done, PathBuf) {
    let port = free_port();
    let g = write(dir, &format!("{tag}.yaml"), &graph(port));
    let g = g.to_str().unwrap().to_string();
    let args: Vec<&str> = args
        .iter()
        .map(|a| if *a == "GRAPH" { g.as_str() } else { *a })
        .collect();
    let start = Instant::now();
    let done = Launcher::start(dir, &args, tag).wait(Duration::from_secs(300));
    let d = Done {
        ok: done.status.success(),
        stdout: done.stdout,
        stderr: done.stderr,
        seconds: start.elapsed().as_secs_f64(),
    };
    (d, dir.join(tag))
}

/// Per topic: every message as (envelope with publish time zeroed, body bytes), in file order.
type Frames = BTreeMap<String, Vec<(Envelope, Vec<u8>)>>;

fn frames(path: &Path) -> (Frames, evseg_recorder::read::Recording) {
    let mut out = Frames::new();
    let rec = evseg_recorder::read::read(path, |m| {
        let (mut envelope, used) = codec::decode_header(m.data).expect("recorded frame header");
        envelope.publish_ns = 0;
        out.entry(m.channel.topic.clone())
            .or_default()
            .push((envelope, m.data[used..].to_vec()));
        Ok(())
    })
    .expect("read recording");
    (out, rec)
}

fn counts(f: &Frames) -> BTreeMap<&str, usize> {
    f.iter().map(|(t, v)| (t.as_str(), v.len())).collect()
}

#[test]
fn a_replay_from_the_slicer_is_bit_identical_to_the_recorded_run_at_any_speed() {
    evseg_tests::bin_dir();
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let (orig, orig_dir) = evseg(
        dir,
        "orig",
        &["run", "GRAPH", "--out", "orig", "-q", "--record", "orig.mcap"],
    );
    assert!(orig.ok, "recorded run failed:\n{}", orig.stderr);
    let (want, orig_rec) = frames(&dir.join("orig.mcap"));
    assert_eq!(want["slicer/slices"].len(), 11, "{:?}", counts(&want));
    assert_eq!(want["evaluator/metrics"].len(), 11, "{:?}", counts(&want));
    let (t0, t1) = orig_rec.time_span_ns().unwrap();
    let recorded_span = (t1 - t0) as f64 * 1e-9;
    let report = std::fs::read(orig_dir.join("report/report.json")).unwrap();

    for (tag, speed) in [("fast", None), ("paced", Some("1"))] {
        let mut args = vec!["replay", "orig.mcap", "--graph", "GRAPH", "--from", "slicer"];
        args.extend(["--out", tag, "-q", "--record"]);
        let file = format!("{tag}.mcap");
        args.push(&file);
        if let Some(s) = speed {
            args.extend(["--speed", s]);
        }
        let (run, run_dir) = evseg(dir, tag, &args);
        assert!(run.ok, "replay {tag} failed:\n{}\n{}", run.stdout, run.stderr);
        // Only the downstream nodes ran, next to the replay source.
        let logs: Vec<String> = std::fs::read_dir(run_dir.join("logs"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert!(logs.contains(&"replay.log".to_string()), "{logs:?}");
        assert!(
            !logs.iter().any(|l| l == "source.log" || l == "slicer.log"),
            "{logs:?}"
        );
        // The run folder says what was started: the replay source in place of source and slicer.
        let started: serde_json::Value =
            serde_json::from_slice(&std::fs::read(run_dir.join("graph.started.json")).unwrap()).unwrap();
        let ids: Vec<&str> = started["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .filter_map(|n| n["id"].as_str())
            .collect();
        assert!(ids.contains(&"replay") && !ids.contains(&"slicer"), "{ids:?}");
        let (got, _) = frames(&dir.join(&file));
        assert_eq!(counts(&got), counts(&want), "replay {tag}: messages per channel");
        for (topic, frames) in &want {
            for (i, (w, g)) in frames.iter().zip(&got[topic]).enumerate() {
                assert!(
                    w == g,
                    "replay {tag}: {topic} message {i} differs from the recorded run"
                );
            }
        }
        let replayed_report = std::fs::read(run_dir.join("report/report.json")).unwrap();
        assert!(replayed_report == report, "replay {tag}: report.json differs");
        eprintln!(
            "replay {tag}: {:.2} s for {} recorded frames ({} slices) recorded over {recorded_span:.2} s; recorded run {:.2} s",
            run.seconds,
            want.values().map(Vec::len).sum::<usize>(),
            want["slicer/slices"].len(),
            orig.seconds
        );
        if speed.is_some() {
            assert!(
                run.seconds >= 0.9 * recorded_span,
                "paced at speed 1, the replay took {:.2} s for {recorded_span:.2} s of recording",
                run.seconds
            );
        }
    }

    // A cut-off copy: replayed as far as it was recovered, and said so; what the downstream
    // nodes publish is the start of the recorded run's.
    let bytes = std::fs::read(dir.join("orig.mcap")).unwrap();
    std::fs::write(dir.join("cut.mcap"), &bytes[..bytes.len() * 3 / 5]).unwrap();
    let (run, _) = evseg(
        dir,
        "cut",
        &[
            "replay",
            "cut.mcap",
            "--graph",
            "GRAPH",
            "--from",
            "slicer",
            "--out",
            "cut",
            "-q",
            "--record",
            "cut-replay.mcap",
        ],
    );
    assert!(run.ok, "replay of a cut-off recording failed:\n{}", run.stderr);
    assert!(
        run.stderr.contains("TRUNCATED at byte") && run.stderr.contains("replaying what was recovered"),
        "{}",
        run.stderr
    );
    let (got, _) = frames(&dir.join("cut-replay.mcap"));
    let n = got["evaluator/metrics"].len();
    assert!(n > 0 && n < 11, "{:?}", counts(&got));
    for topic in [
        "slicer/slices",
        "slicer/truth",
        "segmenter/tracks",
        "evaluator/metrics",
    ] {
        assert_eq!(got[topic].len(), n, "{topic}: {:?}", counts(&got));
        assert!(
            got[topic][..] == want[topic][..n],
            "{topic}: not the start of the recorded run"
        );
    }
}

/// A recording with the given channels and no messages.
fn fake_recording(path: &Path, channels: &[(&str, &str)]) {
    let specs: Vec<ChannelSpec> = channels
        .iter()
        .map(|(topic, schema)| ChannelSpec {
            topic: topic.to_string(),
            schema: schema.to_string(),
            version: evseg_schemas::schema_version(schema).unwrap_or(0),
            metadata: BTreeMap::new(),
        })
        .collect();
    McapRecorder::create(path, &specs, &WriterSettings::default())
        .unwrap()
        .finish()
        .unwrap();
}

#[test]
fn a_recording_without_a_needed_channel_or_of_another_schema_is_refused_before_anything_starts() {
    evseg_tests::bin_dir();
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    fake_recording(&dir.join("no-truth.mcap"), &[("slicer/slices", "evseg.Slice")]);
    fake_recording(
        &dir.join("wrong.mcap"),
        &[("slicer/slices", "evseg.Slice"), ("slicer/truth", "evseg.Tracks")],
    );
    std::fs::write(dir.join("text.mcap"), "not a recording").unwrap();
    let cases = [
        (
            "no-truth",
            vec!["no-truth.mcap", "no channel `slicer/truth`", "evaluator.truth"],
        ),
        (
            "wrong",
            vec![
                "wrong.mcap",
                "channel `slicer/truth` holds evseg.Tracks",
                "evseg.Truth",
            ],
        ),
        ("text", vec!["text.mcap", "not an MCAP file"]),
        ("missing", vec!["missing.mcap"]),
    ];
    for (name, expected) in cases {
        let file = format!("{name}.mcap");
        let out = format!("{name}-run");
        let (run, run_dir) = evseg(
            dir,
            &out,
            &[
                "replay", &file, "--graph", "GRAPH", "--from", "slicer", "--out", &out, "-q",
            ],
        );
        assert!(!run.ok, "replay of {file} should fail");
        for e in expected {
            assert!(run.stderr.contains(e), "{name}: `{e}` not in:\n{}", run.stderr);
        }
        assert!(
            !run_dir.exists(),
            "{name}: a run folder was made before the check"
        );
    }
    // An unknown replay point and a bad speed are refused too.
    fake_recording(&dir.join("ok.mcap"), &[("slicer/slices", "evseg.Slice")]);
    let (run, _) = evseg(
        dir,
        "nope",
        &["replay", "ok.mcap", "--graph", "GRAPH", "--from", "nope"],
    );
    assert!(!run.ok && run.stderr.contains("--from `nope`"), "{}", run.stderr);
    let (run, _) = evseg(
        dir,
        "speed",
        &[
            "replay", "ok.mcap", "--graph", "GRAPH", "--from", "slicer", "--speed", "0",
        ],
    );
    assert!(!run.ok && run.stderr.contains("--speed 0"), "{}", run.stderr);
    // So is an override of a replayed node, which would change nothing.
    let (run, _) = evseg(
        dir,
        "set",
        &[
            "replay",
            "ok.mcap",
            "--graph",
            "GRAPH",
            "--from",
            "slicer",
            "--set",
            "slicer.window_ms=20",
        ],
    );
    assert!(
        !run.ok
            && run
                .stderr
                .contains("--set `slicer.window_ms=20`: node `slicer` is replayed from the recording"),
        "{}",
        run.stderr
    );
}

/// A copy of the recording at `from` without the messages of `drop` (`(topic, seq)`): a
/// recording with gaps, as a live run's recorder that could not keep up leaves.
fn copy_without(from: &Path, to: &Path, drop: &[(&str, u64)]) {
    let mut specs: Vec<ChannelSpec> = Vec::new();
    let mut messages: Vec<(usize, Envelope, Vec<u8>)> = Vec::new();
    evseg_recorder::read::read(from, |m| {
        let port = match specs.iter().position(|c| c.topic == m.channel.topic) {
            Some(p) => p,
            None => {
                specs.push(ChannelSpec {
                    topic: m.channel.topic.clone(),
                    schema: m.channel.schema.clone(),
                    version: m.channel.version.unwrap_or(0),
                    metadata: m.channel.metadata.clone(),
                });
                specs.len() - 1
            }
        };
        let (envelope, _) = codec::decode_header(m.data).expect("recorded frame header");
        if !drop.contains(&(m.channel.topic.as_str(), envelope.seq)) {
            messages.push((port, envelope, m.data.to_vec()));
        }
        Ok(())
    })
    .expect("read recording");
    let mut w = McapRecorder::create(to, &specs, &WriterSettings::default()).unwrap();
    for (port, envelope, data) in &messages {
        w.write_frame(*port, envelope, data).unwrap();
    }
    w.finish().unwrap();
}

/// A recording with gaps (a live run's drops) is refused, naming the channel and the way out;
/// with `--skip-gaps` the slices every replayed channel holds are replayed, renumbered, and
/// evaluated with their own sensor times.
#[test]
fn a_recording_with_gaps_replays_the_slices_every_channel_holds_with_skip_gaps() {
    evseg_tests::bin_dir();
    let dir = tempfile::tempdir().unwrap();
    let dir = dir.path();
    let (orig, _) = evseg(
        dir,
        "orig",
        &["run", "GRAPH", "--out", "orig", "-q", "--record", "orig.mcap"],
    );
    assert!(orig.ok, "recorded run failed:\n{}", orig.stderr);
    // Slice 3's truth and slice 6's events lost; slice 10, the last, lost on both.
    copy_without(
        &dir.join("orig.mcap"),
        &dir.join("gaps.mcap"),
        &[
            ("slicer/truth", 3),
            ("slicer/slices", 6),
            ("slicer/slices", 10),
            ("slicer/truth", 10),
        ],
    );
    let base = [
        "replay",
        "gaps.mcap",
        "--graph",
        "GRAPH",
        "--from",
        "slicer",
        "-q",
    ];
    let (run, _) = evseg(dir, "refused", &[&base[..], &["--out", "refused"]].concat());
    assert!(
        !run.ok,
        "a recording with gaps must be refused without --skip-gaps"
    );
    assert!(
        run.stderr.contains("lacks 1 message(s), from sequence") && run.stderr.contains("--skip-gaps"),
        "{}",
        run.stderr
    );
    let (run, run_dir) = evseg(
        dir,
        "skip",
        &[
            &base[..],
            &["--out", "skip", "--skip-gaps", "--record", "skip.mcap"],
        ]
        .concat(),
    );
    assert!(
        run.ok,
        "replay with --skip-gaps failed:\n{}\n{}",
        run.stdout, run.stderr
    );
    assert!(
        run.stderr
            .contains("replaying the 8 slices every replayed channel holds, renumbered 0..8"),
        "{}",
        run.stderr
    );
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(run_dir.join("report/report.json")).unwrap()).unwrap();
    assert_eq!(report["sequence"]["windows"].as_u64(), Some(8), "{report}");
    // The replayed slices are numbered 0..8 and keep their recorded sensor times.
    let (got, _) = frames(&dir.join("skip.mcap"));
    let (want, _) = frames(&dir.join("orig.mcap"));
    let seqs: Vec<u64> = got["slicer/slices"].iter().map(|(e, _)| e.seq).collect();
    assert_eq!(seqs, (0..8).collect::<Vec<u64>>());
    let kept: Vec<u64> = vec![0, 1, 2, 4, 5, 7, 8, 9];
    for (new, old) in kept.iter().enumerate() {
        let (g, w) = (&got["slicer/slices"][new], &want["slicer/slices"][*old as usize]);
        assert_eq!((g.0.t_start, g.0.t_end, &g.1), (w.0.t_start, w.0.t_end, &w.1));
    }
    // `evseg ab --skip-gaps` replays the same slices into both variants (B = A here: every
    // difference is 0).
    let listen = format!("tcp/127.0.0.1:{}", free_port());
    let (run, _) = evseg(
        dir,
        "ab",
        &[
            "ab",
            "GRAPH",
            "--recording",
            "gaps.mcap",
            "--skip-gaps",
            "--work",
            "ab-work",
            "--listen",
            &listen,
        ],
    );
    assert!(run.ok, "ab --skip-gaps failed:\n{}\n{}", run.stdout, run.stderr);
    let rows: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("ab-work/ab.json")).unwrap()).unwrap();
    let iou = rows
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["figure"] == "IoU events (%)")
        .unwrap();
    assert!(iou["a"].is_number() && iou["difference"] == 0.0, "{rows}");
}
