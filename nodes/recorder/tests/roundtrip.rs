//! Write a recording, read it back (whole and cut off at every kind of place), export it.

use std::collections::BTreeMap;
use std::path::Path;

use evseg_evimo2::npy;
use evseg_recorder::read::{read, read_bytes};
use evseg_recorder::write::{ChannelSpec, McapRecorder, WriterSettings};
use evseg_recorder::{RecordError, export};
use evseg_schemas::{
    Egomotion, Envelope, FrameKind, Message, Metric, Metrics, NormalFlow, Track, Tracks, codec,
};

fn channel(topic: &str, schema: &str) -> ChannelSpec {
    ChannelSpec {
        topic: topic.into(),
        schema: schema.into(),
        version: evseg_schemas::schema_version(schema).unwrap_or(0),
        metadata: BTreeMap::from([(
            "producer".to_string(),
            topic.split('/').next().unwrap().to_string(),
        )]),
    }
}

fn tracks(seq: u64, n: usize) -> Tracks {
    Tracks {
        // Background, two tracks, and moving events of a track not yet confirmed.
        label: (0..n as u32)
            .map(|i| match (i + seq as u32) % 4 {
                3 => Tracks::UNCONFIRMED,
                l => l,
            })
            .collect(),
        tracks: vec![Track {
            id: 7,
            centroid: [10.0 + seq as f64, 20.0],
            velocity: [1.5, -2.5],
            bbox: [1.0, 2.0, 30.0, 40.0],
            translation: [0.1, 0.2, 0.3],
            age: seq as u32,
            events: 5,
        }],
        egomotion: Egomotion {
            direction: [0.0, 0.0, 1.0],
            omega: [0.01 * seq as f64, 0.0, -0.5],
            valid: seq.is_multiple_of(2),
        },
    }
}

fn flow(n: usize) -> NormalFlow {
    NormalFlow {
        nx: (0..n).map(|i| i as f32 * 0.5).collect(),
        ny: (0..n).map(|i| -(i as f32)).collect(),
        confidence: vec![0.75; n],
    }
}

fn metrics(seq: u64) -> Metrics {
    let mut values = vec![Metric {
        name: "iou".into(),
        value: 0.25 * seq as f64,
    }];
    if seq >= 2 {
        values.push(Metric {
            name: "direction_error_deg".into(),
            value: 3.0,
        });
    }
    Metrics { values }
}

const SLICES: u64 = 5;
const EVENTS_PER_SLICE: usize = 4000;

/// Writes a recording with tracks, flow and metrics channels (and one frame of an unknown schema
/// version) with small chunks, so it has many; returns its bytes.
fn write_recording(path: &Path) -> Vec<u8> {
    write_recording_with(
        path,
        &WriterSettings {
            chunk_bytes: 16 * 1024,
            ..WriterSettings::default()
        },
    )
}

/// [`write_recording`] with the writer's `settings`.
fn write_recording_with(path: &Path, settings: &WriterSettings) -> Vec<u8> {
    let channels = [
        channel("segmenter/tracks", Tracks::SCHEMA),
        channel("flow/flow", NormalFlow::SCHEMA),
        channel("evaluator/metrics", Metrics::SCHEMA),
    ];
    let mut rec = McapRecorder::create(path, &channels, settings).unwrap();
    rec.metadata(
        "evseg.run",
        BTreeMap::from([("graph_hash".to_string(), "abc".to_string())]),
    )
    .unwrap();
    rec.attach("graph.resolved.json", "application/json", b"{\"name\":\"t\"}", 1)
        .unwrap();
    let put = |rec: &mut McapRecorder, port: usize, frame: Vec<u8>| {
        let (env, _) = codec::decode_header(&frame).unwrap();
        rec.write_frame(port, &env, &frame).unwrap();
    };
    for seq in 0..SLICES {
        let (t0, t1) = (seq as f64 * 0.03, (seq + 1) as f64 * 0.03);
        put(
            &mut rec,
            0,
            codec::encode(seq, t0, t1, &tracks(seq, EVENTS_PER_SLICE)).unwrap(),
        );
        put(
            &mut rec,
            1,
            codec::encode(seq, t0, t1, &flow(EVENTS_PER_SLICE)).unwrap(),
        );
        put(&mut rec, 2, codec::encode(seq, t0, t1, &metrics(seq)).unwrap());
    }
    // A frame from a future version of the metrics schema: counted by export, never decoded.
    let env = Envelope {
        schema: Metrics::SCHEMA.into(),
        version: Metrics::VERSION + 1,
        kind: FrameKind::Data,
        seq: SLICES,
        t_start: 0.0,
        t_end: 0.0,
        publish_ns: 5,
    };
    let future = codec::encode_with(&env, Some(&metrics(0))).unwrap();
    rec.write_frame(2, &env, &future).unwrap();
    assert_eq!(rec.counts(), &[SLICES, SLICES, SLICES + 1]);
    rec.finish().unwrap();
    std::fs::read(path).unwrap()
}

#[test]
fn a_complete_recording_reads_back_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let bytes = write_recording(&path);
    let mut frames: Vec<(String, u32, Vec<u8>)> = Vec::new();
    let rec = read(&path, |m| {
        frames.push((m.channel.topic.clone(), m.sequence, m.data.to_vec()));
        Ok(())
    })
    .unwrap();
    assert!(rec.truncated.is_none(), "{}", rec.completeness());
    assert_eq!(rec.messages, 3 * SLICES + 1);
    assert!(rec.chunks >= 3, "small chunks expected, got {}", rec.chunks);
    let by_topic: BTreeMap<&str, u64> = rec
        .channels
        .values()
        .map(|c| (c.topic.as_str(), c.messages))
        .collect();
    assert_eq!(by_topic["segmenter/tracks"], SLICES);
    assert_eq!(by_topic["evaluator/metrics"], SLICES + 1);
    let tracks_channel = rec
        .channels
        .values()
        .find(|c| c.topic == "segmenter/tracks")
        .unwrap();
    assert_eq!(tracks_channel.schema, "evseg.Tracks");
    assert_eq!(tracks_channel.version, Some(1));
    assert_eq!(tracks_channel.message_encoding, "evseg-bincode2");
    assert_eq!(rec.metadata_named("evseg.run").unwrap()["graph_hash"], "abc");
    assert_eq!(rec.attachments[0].name, "graph.resolved.json");
    // The frames are the wire bytes: they decode with the codec, sequence numbers intact.
    let (_, seq, data) = frames
        .iter()
        .find(|(t, s, _)| t == "segmenter/tracks" && *s == 3)
        .unwrap();
    assert_eq!(*seq, 3);
    assert_eq!(
        codec::decode::<Tracks>(data).unwrap().body.unwrap(),
        tracks(3, EVENTS_PER_SLICE)
    );
    assert!(
        bytes.len() < 3 * SLICES as usize * EVENTS_PER_SLICE * 4,
        "compressed"
    );
}

/// Every message of the recording at `path`, in file order: topic, sequence number, the
/// envelope without its publish time (the writer's clock) and the body's bytes.
fn messages(path: &Path) -> Vec<(String, u32, Envelope, Vec<u8>)> {
    let mut frames = Vec::new();
    let rec = read(path, |m| {
        let (mut env, header) = codec::decode_header(m.data).unwrap();
        env.publish_ns = 0;
        frames.push((
            m.channel.topic.clone(),
            m.sequence,
            env,
            m.data[header..].to_vec(),
        ));
        Ok(())
    })
    .unwrap();
    assert!(rec.truncated.is_none(), "{}", rec.completeness());
    frames
}

#[test]
fn writer_settings_change_the_file_not_the_messages_and_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let (small, strong) = (dir.path().join("small.mcap"), dir.path().join("strong.mcap"));
    let small_bytes = write_recording(&small);
    let strong_bytes = write_recording_with(
        &strong,
        &WriterSettings {
            chunk_bytes: 4 << 20,
            zstd_level: 19,
        },
    );
    assert_ne!(small_bytes, strong_bytes, "the settings reach the writer");
    assert_eq!(messages(&small), messages(&strong));
    assert!(
        read(&strong, |_| Ok(())).unwrap().chunks < read(&small, |_| Ok(())).unwrap().chunks,
        "4 MiB chunks are fewer than 16 KiB ones"
    );
    // Out of range: refused naming the setting, and no file is created.
    for (settings, name) in [
        (
            WriterSettings {
                chunk_bytes: 0,
                ..WriterSettings::default()
            },
            "chunk_bytes",
        ),
        (
            WriterSettings {
                chunk_bytes: 1 << 40,
                ..WriterSettings::default()
            },
            "chunk_bytes",
        ),
        (
            WriterSettings {
                zstd_level: 23,
                ..WriterSettings::default()
            },
            "zstd_level",
        ),
    ] {
        let path = dir.path().join("refused.mcap");
        let err = match McapRecorder::create(&path, &[channel("a/b", Tracks::SCHEMA)], &settings) {
            Err(e) => e.to_string(),
            Ok(_) => panic!("{settings:?} accepted"),
        };
        assert!(err.contains(name), "{err}");
        assert!(!path.exists(), "{err}");
    }
}

#[test]
fn a_cut_off_recording_is_read_up_to_its_last_complete_chunk() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let bytes = write_recording(&path);
    let full = read(&path, |_| Ok(())).unwrap();
    let mut last_messages = 0;
    let mut saw_partial = false;
    // Cut everywhere from just after the magic to just before the end.
    for cut in (8..bytes.len()).step_by(97).chain([bytes.len() - 1]) {
        let mut n = 0u64;
        let rec = read_bytes(Path::new("cut.mcap"), &bytes[..cut], &mut |_| {
            n += 1;
            Ok(())
        })
        .unwrap_or_else(|e| panic!("cut at {cut}: {e}"));
        let t = rec
            .truncated
            .as_ref()
            .unwrap_or_else(|| panic!("cut at {cut} not reported"));
        assert!(t.offset <= cut as u64, "cut {cut}: stopped at {}", t.offset);
        assert_eq!(n, rec.messages);
        assert!(rec.messages <= full.messages);
        assert!(
            rec.messages >= last_messages,
            "more data never gives fewer messages"
        );
        last_messages = rec.messages;
        saw_partial |= rec.messages > 0 && rec.messages < full.messages;
        let text = rec.completeness();
        assert!(
            text.contains("cut.mcap") && text.contains("TRUNCATED at byte"),
            "{text}"
        );
    }
    assert!(saw_partial, "some cut must recover part of the messages");
    // Cut inside the summary section: every message is still there.
    assert_eq!(last_messages, full.messages);
}

#[test]
fn a_chunk_whose_writer_was_killed_is_reported_with_its_offset() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let bytes = write_recording(&path);
    // Find the second chunk (opcode 0x06) by walking the records, and give it the placeholder
    // length the writer leaves while a chunk is being written.
    let mut pos = 8;
    let mut chunks = Vec::new();
    while pos + 9 <= bytes.len() {
        let len = u64::from_le_bytes(bytes[pos + 1..pos + 9].try_into().unwrap()) as usize;
        if bytes[pos] == 0x06 {
            chunks.push(pos);
        }
        if bytes[pos] == 0x02 {
            break;
        }
        pos += 9 + len;
    }
    assert!(chunks.len() >= 3, "{} chunks", chunks.len());
    let last = *chunks.last().unwrap();
    let mut broken = bytes[..last + 40].to_vec();
    broken[last + 1..last + 9].copy_from_slice(&u64::MAX.to_le_bytes());
    let rec = read_bytes(Path::new("killed.mcap"), &broken, &mut |_| Ok(())).unwrap();
    let t = rec.truncated.unwrap();
    assert_eq!(t.offset, last as u64);
    assert!(t.reason.contains("never written"), "{}", t.reason);
    assert_eq!(rec.chunks as usize, chunks.len() - 1);
    assert!(rec.messages > 0);
}

#[test]
fn not_an_mcap_file_is_an_error_naming_it() {
    let err = read_bytes(Path::new("x.bin"), b"hello world", &mut |_| Ok(())).unwrap_err();
    assert!(matches!(err, RecordError::NotMcap { .. }));
    assert!(err.to_string().contains("x.bin"), "{err}");
    let missing = read(Path::new("/nonexistent/r.mcap"), |_| Ok(())).unwrap_err();
    assert!(missing.to_string().contains("/nonexistent/r.mcap"), "{missing}");
}

fn load_f64(path: &Path) -> (Vec<usize>, Vec<f64>) {
    let bytes = std::fs::read(path).unwrap();
    let a = npy::parse_bytes(&bytes, &path.display().to_string()).unwrap();
    assert_eq!(a.header.descr, "<f8");
    let v = a
        .data
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    (a.header.shape, v)
}

#[test]
fn export_writes_labels_flow_egomotion_tracks_and_metrics() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    write_recording(&path);
    let out = dir.path().join("export");
    let summary = export::export(&path, &out).unwrap();
    let names: Vec<&str> = summary.files.iter().map(|f| f.file.as_str()).collect();
    assert_eq!(
        names,
        [
            "evaluator.metrics.metrics.npy",
            "flow.flow.flow.npy",
            "segmenter.tracks.egomotion.npy",
            "segmenter.tracks.labels.npy",
            "segmenter.tracks.tracks.npy"
        ]
    );
    // Labels: int64 (N, 2), slice then label, in slice order.
    let bytes = std::fs::read(out.join("segmenter.tracks.labels.npy")).unwrap();
    let a = npy::parse_bytes(&bytes, "labels").unwrap();
    assert_eq!(a.header.descr, "<i8");
    let n = SLICES as usize * EVENTS_PER_SLICE;
    assert_eq!(a.header.shape, [n, 2]);
    let v: Vec<i64> = a
        .data
        .chunks_exact(8)
        .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    let k = 3 * EVENTS_PER_SLICE + 10;
    assert_eq!(
        (v[2 * k], v[2 * k + 1]),
        (3, i64::from(tracks(3, EVENTS_PER_SLICE).label[10]))
    );
    // Unconfirmed events (u32::MAX in the message) are -1, as the other exports' "no id".
    let expected: Vec<i64> = (0..SLICES)
        .flat_map(|s| tracks(s, EVENTS_PER_SLICE).label)
        .map(|l| {
            if l == Tracks::UNCONFIRMED {
                -1
            } else {
                i64::from(l)
            }
        })
        .collect();
    let got: Vec<i64> = v.chunks_exact(2).map(|r| r[1]).collect();
    assert_eq!(got, expected);
    assert!(got.contains(&-1));
    // Flow.
    let (shape, f) = load_f64(&out.join("flow.flow.flow.npy"));
    assert_eq!(shape, [n, 4]);
    assert_eq!(&f[4 * 7..4 * 8], &[0.0, 3.5, -7.0, 0.75]);
    // Egomotion: slice, t_start, t_end, direction, omega, valid.
    let (shape, e) = load_f64(&out.join("segmenter.tracks.egomotion.npy"));
    assert_eq!(shape, [SLICES as usize, 10]);
    assert_eq!(
        &e[10..20],
        &[1.0, 0.03, 0.06, 0.0, 0.0, 1.0, 0.01, 0.0, -0.5, 0.0]
    );
    // Tracks.
    let (shape, t) = load_f64(&out.join("segmenter.tracks.tracks.npy"));
    assert_eq!(shape, [SLICES as usize, 15]);
    assert_eq!(
        &t[15 * 2..15 * 3],
        &[
            2.0, 7.0, 12.0, 20.0, 1.5, -2.5, 1.0, 2.0, 30.0, 40.0, 0.1, 0.2, 0.3, 2.0, 5.0
        ]
    );
    // Metrics: one column per name, NaN where a slice lacks it; the future-version frame is
    // counted, not exported.
    let (shape, m) = load_f64(&out.join("evaluator.metrics.metrics.npy"));
    assert_eq!(shape, [SLICES as usize, 3]);
    assert_eq!(&m[3..5], &[1.0, 0.25]);
    assert!(m[5].is_nan());
    assert_eq!(&m[6..9], &[2.0, 0.5, 3.0]);
    let skipped = &summary.not_exported["evaluator/metrics"];
    assert_eq!(skipped.unknown_schema, 1);
    assert!(skipped.first_problem.as_ref().unwrap().contains("v2"));
    let readme = std::fs::read_to_string(out.join("README.txt")).unwrap();
    assert!(
        readme.contains("direction_x") && readme.contains("rad/s"),
        "{readme}"
    );
    let columns: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("columns.json")).unwrap()).unwrap();
    assert_eq!(columns["files"].as_array().unwrap().len(), 5);
    assert_eq!(columns["complete"], true);
}

#[test]
fn a_truncated_recording_still_exports_what_was_recovered() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("run.mcap");
    let bytes = write_recording(&path);
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let summary = export::export(&cut, &dir.path().join("out")).unwrap();
    assert!(summary.recording.truncated.is_some());
    let labels = summary
        .files
        .iter()
        .find(|f| f.file.ends_with("labels.npy"))
        .unwrap();
    assert!(labels.shape[0] > 0 && labels.shape[0] < SLICES as usize * EVENTS_PER_SLICE);
    assert_eq!(labels.shape[0] % EVENTS_PER_SLICE, 0, "whole messages only");
}

/// Each stage's per-event output is exported, so a user can compare a stage's output between
/// two runs (or against the ground truth) without decoding the wire format.
#[test]
fn export_writes_every_stage_s_per_event_output_and_the_truth() {
    use evseg_schemas::{Clusters, CoarseSegmentation, Residuals, Segment, Segmentation, Truth};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("stages.mcap");
    let channels = [
        channel("overseg/clusters", Clusters::SCHEMA),
        channel("planar/residuals", Residuals::SCHEMA),
        channel("background/coarse", CoarseSegmentation::SCHEMA),
        channel("hierarchical/segments", Segmentation::SCHEMA),
        channel("slicer/truth", Truth::SCHEMA),
    ];
    let mut rec = McapRecorder::create(&path, &channels, &WriterSettings::default()).unwrap();
    let put = |rec: &mut McapRecorder, port: usize, frame: Vec<u8>| {
        let (env, _) = codec::decode_header(&frame).unwrap();
        rec.write_frame(port, &env, &frame).unwrap();
    };
    let ego = Egomotion {
        direction: [0.6, 0.0, 0.8],
        omega: [0.0, 0.1, 0.0],
        valid: true,
    };
    for seq in 0..2u64 {
        let (t0, t1) = (seq as f64 * 0.03, (seq + 1) as f64 * 0.03);
        let clusters = Clusters {
            id: vec![0, u16::MAX, 2],
            count: 3,
        };
        put(&mut rec, 0, codec::encode(seq, t0, t1, &clusters).unwrap());
        let residuals = Residuals {
            residual: vec![0.5, f32::NAN, -0.25],
            background: vec![true, true, false],
            model: vec![],
        };
        put(&mut rec, 1, codec::encode(seq, t0, t1, &residuals).unwrap());
        let coarse = CoarseSegmentation {
            group: vec![0, CoarseSegmentation::UNASSIGNED, 3],
            residual: vec![0.125, f32::NAN, 2.0],
            map_overlap: vec![1.0, f32::NAN, f32::NAN, 0.0],
            egomotion: ego,
        };
        put(&mut rec, 2, codec::encode(seq, t0, t1, &coarse).unwrap());
        let segmentation = Segmentation {
            label: vec![0, 0, 1],
            segments: vec![Segment {
                label: 1,
                translation: [0.1, -0.2, 0.3],
                centroid: [100.0, 50.0],
                bbox: [90.0, 40.0, 110.0, 60.0],
                events: 1,
            }],
            egomotion: ego,
        };
        put(&mut rec, 3, codec::encode(seq, t0, t1, &segmentation).unwrap());
        let truth = Truth {
            event_object: vec![0, 0, 2],
            flow_x: vec![1.0, 2.0, 3.0],
            flow_y: vec![-1.0, -2.0, -3.0],
            ..Truth::default()
        };
        put(&mut rec, 4, codec::encode(seq, t0, t1, &truth).unwrap());
    }
    rec.finish().unwrap();
    let out = dir.path().join("export");
    let summary = export::export(&path, &out).unwrap();
    let names: Vec<&str> = summary.files.iter().map(|f| f.file.as_str()).collect();
    assert_eq!(
        names,
        [
            "background.coarse.egomotion.npy",
            "background.coarse.groups.npy",
            "hierarchical.segments.egomotion.npy",
            "hierarchical.segments.labels.npy",
            "hierarchical.segments.segments.npy",
            "overseg.clusters.clusters.npy",
            "planar.residuals.residuals.npy",
            "slicer.truth.flow.npy",
            "slicer.truth.objects.npy",
        ]
    );
    assert!(summary.not_exported.is_empty(), "{:?}", summary.not_exported);
    let load_i64 = |name: &str| {
        let bytes = std::fs::read(out.join(name)).unwrap();
        let a = npy::parse_bytes(&bytes, name).unwrap();
        assert_eq!(a.header.descr, "<i8");
        let v: Vec<i64> = a
            .data
            .chunks_exact(8)
            .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
            .collect();
        (a.header.shape, v)
    };
    assert_eq!(
        load_i64("overseg.clusters.clusters.npy"),
        (vec![6, 2], vec![0, 0, 0, -1, 0, 2, 1, 0, 1, -1, 1, 2])
    );
    assert_eq!(
        load_i64("slicer.truth.objects.npy"),
        (vec![6, 2], vec![0, 0, 0, 0, 0, 2, 1, 0, 1, 0, 1, 2])
    );
    assert_eq!(
        load_i64("hierarchical.segments.labels.npy").1[6..],
        [1, 0, 1, 0, 1, 1]
    );
    let (shape, r) = load_f64(&out.join("planar.residuals.residuals.npy"));
    assert_eq!(shape, [6, 3]);
    assert_eq!((r[0], r[1], r[2]), (0.0, 0.5, 1.0));
    assert!(r[4].is_nan());
    assert_eq!((r[7], r[8]), (-0.25, 0.0));
    let (shape, g) = load_f64(&out.join("background.coarse.groups.npy"));
    assert_eq!(shape, [6, 3]);
    assert_eq!((g[1], g[2], g[4], g[7], g[8]), (0.0, 0.125, -1.0, 3.0, 2.0));
    let (shape, s) = load_f64(&out.join("hierarchical.segments.segments.npy"));
    assert_eq!(shape, [2, 12]);
    assert_eq!(
        &s[12..],
        &[
            1.0, 1.0, 0.1, -0.2, 0.3, 100.0, 50.0, 90.0, 40.0, 110.0, 60.0, 1.0
        ]
    );
    let (shape, e) = load_f64(&out.join("background.coarse.egomotion.npy"));
    assert_eq!(shape, [2, 10]);
    assert_eq!(&e[10..], &[1.0, 0.03, 0.06, 0.6, 0.0, 0.8, 0.0, 0.1, 0.0, 1.0]);
    let (shape, f) = load_f64(&out.join("slicer.truth.flow.npy"));
    assert_eq!(shape, [6, 3]);
    assert_eq!(&f[6..9], &[0.0, 3.0, -3.0]);
}
