//! .rrd files: written with Rerun's framing (magic `RRF2`), holding real content (far larger
//! than a recording with nothing logged, and growing with the points drawn); `view_recording`
//! turns an MCAP recording (written by the evseg recorder) into one, a cut-off MCAP up to its
//! last complete chunk; bad input and bad sinks are clear errors.

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use evseg_recorder::write::{ChannelSpec, McapRecorder, WriterSettings};
use evseg_schemas::Message;
use evseg_viewer::{RunLogger, Sink, ViewError, ViewerParams, log_frame, open, view_recording};

/// The first bytes of every .rrd file Rerun 0.36 writes (`re_log_encoding::rrd::RRD_FOURCC`).
const RRD_MAGIC: &[u8; 4] = b"RRF2";

fn write_rrd(path: &Path, frames: &[(&str, Vec<u8>)], params: ViewerParams) -> evseg_viewer::LogStats {
    let rec = open(&Sink::File(path.to_path_buf()), "test").expect("open file sink");
    let mut logger = RunLogger::new(rec, params).expect("logger");
    for (producer, f) in frames {
        log_frame(&mut logger, producer, f).expect("log");
    }
    logger.finish().expect("finish")
}

fn size(path: &Path) -> u64 {
    std::fs::metadata(path).map(|m| m.len()).unwrap_or(0)
}

fn magic(path: &Path) -> Vec<u8> {
    std::fs::read(path).expect("read rrd")[..4].to_vec()
}

#[test]
fn an_rrd_file_holds_the_logged_points() {
    let dir = tempfile::tempdir().unwrap();
    let params = |max| ViewerParams {
        max_points_per_slice: max,
        ..ViewerParams::default()
    };
    let empty = dir.path().join("empty.rrd");
    write_rrd(&empty, &[], params(2000));
    let frames = common::run(20, 5000, false);
    let small = dir.path().join("nested/small.rrd");
    let stats = write_rrd(&small, &frames, params(500));
    assert_eq!(stats.points_per_layer, 20 * 500);
    let large = dir.path().join("large.rrd");
    let stats = write_rrd(&large, &frames, params(2000));
    assert_eq!(
        (stats.slices, stats.layers, stats.points_per_layer),
        (20, 60, 40_000)
    );
    eprintln!(
        "rrd sizes: nothing logged {} B, 20 slices x 4 layers x 500 points {} B, x 2000 points {} B",
        size(&empty),
        size(&small),
        size(&large)
    );
    for f in [&empty, &small, &large] {
        assert_eq!(magic(f), RRD_MAGIC, "{}", f.display());
    }
    // 20 slices x 4 point layers x 2000 points: at least 1 byte a point compressed (a
    // position on the 64 x 48 sensor holds 11.6 bits; 8 bytes of position and 4 of colour
    // before compression).
    let points = 20 * 4 * 2000;
    assert!(size(&large) > size(&empty) + points, "{} bytes", size(&large));
    // The 1500 more points per slice and layer of the large file take at least a byte each.
    let more = 20 * 4 * 1500;
    assert!(
        size(&large) > size(&small) + more,
        "{} vs {}",
        size(&large),
        size(&small)
    );
}

/// Writes the synthetic run as an MCAP recording the way the recorder node does; returns it.
fn write_mcap(path: &Path, slices: u64, n: usize) {
    let spec = |topic: &str, schema: &str| ChannelSpec {
        topic: topic.into(),
        schema: schema.into(),
        version: evseg_schemas::schema_version(schema).unwrap_or(0),
        metadata: BTreeMap::from([(
            "producer".to_string(),
            topic.split('/').next().unwrap_or("").into(),
        )]),
    };
    let channels = [
        spec("source/truth", evseg_schemas::Truth::SCHEMA),
        spec("slicer/slices", evseg_schemas::Slice::SCHEMA),
        spec("slicer/truth", evseg_schemas::Truth::SCHEMA),
        spec("flow/flow", evseg_schemas::NormalFlow::SCHEMA),
        spec("tracker/tracks", evseg_schemas::Tracks::SCHEMA),
        spec("evaluator/metrics", evseg_schemas::Metrics::SCHEMA),
    ];
    let settings = WriterSettings {
        // Small chunks, so that a cut-off file still has complete ones.
        chunk_bytes: 64 << 10,
        zstd_level: 0,
    };
    let mut w = McapRecorder::create(path, &channels, &settings).expect("create mcap");
    let mut put = |port: usize, f: Vec<u8>| {
        let (env, _) = evseg_schemas::decode_header(&f).expect("header");
        w.write_frame(port, &env, &f).expect("write");
    };
    for k in 0..slices {
        let s = common::slice(k, n);
        // The source's truth comes first and is not aligned with the slices.
        put(0, common::frame(k, &common::truth(&common::slice(k, n / 2), k)));
        put(1, common::frame(k, &s));
        put(2, common::frame(k, &common::truth(&s, k)));
        put(3, common::frame(k, &common::flow(&s, k)));
        put(4, common::frame(k, &common::tracks(&s, k)));
        put(5, common::frame(k, &common::metrics(k)));
    }
    w.finish().expect("finish mcap");
}

#[test]
fn a_recording_becomes_an_rrd() {
    let dir = tempfile::tempdir().unwrap();
    let mcap = dir.path().join("run.mcap");
    write_mcap(&mcap, 10, 2000);
    let rrd = dir.path().join("run.rrd");
    let params = ViewerParams {
        max_points_per_slice: 1000,
        ..ViewerParams::default()
    };
    let s = view_recording(&mcap, &Sink::File(rrd.clone()), &params).expect("view");
    assert!(s.recording.truncated.is_none());
    assert_eq!(s.slices_from.as_deref(), Some("slicer"));
    assert_eq!(s.stats.slices, 10);
    assert_eq!(s.stats.points_per_layer, 10_000);
    // Labels, flow and truth of every slice; the source's truth is not aligned with them.
    assert_eq!(s.stats.layers, 30);
    assert_eq!(s.stats.unaligned_truth, 10);
    assert_eq!(s.stats.boxes, 20);
    assert_eq!(
        (s.stats.unmatched, s.stats.misaligned, s.stats.undecodable),
        (0, 0, 0)
    );
    assert_eq!(magic(&rrd), RRD_MAGIC);
    assert!(size(&rrd) > 2 * 10 * 4 * 1000, "{} bytes", size(&rrd));

    // Read back by Rerun itself: one row per slice on every per-slice entity.
    if let Some(cli) = evseg_tests::rerun_cli() {
        let rows = common::rrd_entities(&cli, &rrd);
        for entity in [
            "events/polarity",
            "segments/tracker/events",
            "segments/tracker/boxes",
            "flow/flow/events",
            "truth/events",
            "metrics/evaluator/iou",
        ] {
            assert_eq!(rows.get(entity), Some(&10), "{entity}: {rows:?}");
        }
        // Plus one static row naming the x, y, z series.
        for entity in [
            "egomotion/tracker/direction",
            "egomotion/tracker/omega",
            "egomotion/truth/direction",
        ] {
            assert_eq!(rows.get(entity), Some(&11), "{entity}: {rows:?}");
        }
        // Slice 0 has no direction error (NaN).
        assert_eq!(
            rows.get("metrics/evaluator/direction_error_deg"),
            Some(&9),
            "{rows:?}"
        );
        // Static: the sensor outline of each 2-D view.
        assert_eq!(rows.get("truth/frame"), Some(&1), "{rows:?}");
        assert!(!rows.keys().any(|e| e.starts_with("segments/source")), "{rows:?}");
    }

    // The first half of the file: the complete chunks are drawn, the rest is reported.
    let bytes = std::fs::read(&mcap).unwrap();
    let cut = dir.path().join("cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let s = view_recording(&cut, &Sink::File(dir.path().join("cut.rrd")), &params).expect("view cut");
    let t = s.recording.truncated.as_ref().expect("truncated");
    assert!(t.offset > 0 && t.offset <= bytes.len() as u64 / 2);
    assert!(
        s.stats.slices >= 2 && s.stats.slices < 10,
        "{} slices",
        s.stats.slices
    );
}

#[test]
fn bad_recordings_and_sinks_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let params = ViewerParams::default();
    let not_mcap = dir.path().join("notes.mcap");
    std::fs::write(&not_mcap, b"hello, not an mcap file").unwrap();
    let out = Sink::File(dir.path().join("x.rrd"));
    let e = view_recording(&not_mcap, &out, &params).expect_err("not mcap");
    assert!(matches!(e, ViewError::Recording(_)), "{e}");
    assert!(
        e.to_string().contains("notes.mcap") && e.to_string().contains("not an MCAP file"),
        "{e}"
    );

    let missing = dir.path().join("missing.mcap");
    let e = view_recording(&missing, &out, &params).expect_err("missing");
    assert!(e.to_string().contains("missing.mcap"), "{e}");

    // An .rrd under a regular file cannot be created.
    let mcap = dir.path().join("run.mcap");
    write_mcap(&mcap, 1, 100);
    let blocked = Sink::File(not_mcap.join("sub/out.rrd"));
    let e = view_recording(&mcap, &blocked, &params).expect_err("blocked");
    assert!(e.to_string().contains("notes.mcap"), "{e}");

    let e = view_recording(&mcap, &Sink::Grpc("not a url".into()), &params).expect_err("bad url");
    assert!(matches!(e, ViewError::Open { .. }), "{e}");
    assert!(e.to_string().contains("not a url"), "{e}");

    let bad = ViewerParams {
        max_points_per_slice: 0,
        ..ViewerParams::default()
    };
    let e = view_recording(&mcap, &out, &bad).expect_err("bad params");
    assert!(e.to_string().contains("max_points_per_slice"), "{e}");
}
