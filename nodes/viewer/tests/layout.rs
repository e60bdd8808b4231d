//! What the logger sends to Rerun, read back from an in-memory sink: the documented entities,
//! one row per slice on the `slice` timeline, decimated points at pixel centres with the
//! colours of their labels / flow / truth, track boxes labelled `id N`, egomotion and metrics
//! series; per-event messages joined with their slice whatever the arrival order; bad input
//! counted, never fatal.

mod common;

use std::collections::BTreeMap;

use evseg_viewer::colour::{flow_colour, label_colour, polarity_colour};
use evseg_viewer::decimate::decimate;
use evseg_viewer::rerun;
use evseg_viewer::{LogStats, RunLogger, ViewerParams, log_frame};
use rerun::components::{Color, Position2D, Scalar, Text};
use rerun::log::{Chunk, LogMsg};

/// One logged row of an entity.
#[derive(Debug, Clone, PartialEq)]
struct Row {
    /// Value on the `slice` timeline (`None` for static rows).
    slice: Option<i64>,
    positions: Vec<[f32; 2]>,
    colours: Vec<[u8; 4]>,
    scalars: Vec<f64>,
    labels: Vec<String>,
}

fn rows_of(msgs: Vec<LogMsg>) -> BTreeMap<String, Vec<Row>> {
    let mut out: BTreeMap<String, Vec<Row>> = BTreeMap::new();
    for m in msgs {
        let LogMsg::ArrowMsg(_, arrow) = m else { continue };
        let chunk = Chunk::from_arrow_msg(&arrow).expect("chunk");
        let entity = chunk
            .entity_path()
            .to_string()
            .trim_start_matches('/')
            .to_string();
        let n = chunk.num_rows();
        let slices: Vec<Option<i64>> = match chunk.timelines().get(&"slice".into()) {
            Some(tc) => tc.times_raw().iter().map(|&t| Some(t)).collect(),
            None => vec![None; n],
        };
        let mut rows: Vec<Row> = slices
            .into_iter()
            .map(|slice| Row {
                slice,
                positions: vec![],
                colours: vec![],
                scalars: vec![],
                labels: vec![],
            })
            .collect();
        let pos = rerun::Points2D::descriptor_positions().component;
        for (r, v) in chunk.iter_component::<Position2D>(pos).enumerate() {
            rows[r].positions = v.iter().map(|p| [p.x(), p.y()]).collect();
        }
        for col in [
            rerun::Points2D::descriptor_colors().component,
            rerun::Boxes2D::descriptor_colors().component,
        ] {
            for (r, v) in chunk.iter_component::<Color>(col).enumerate() {
                if !v.is_empty() {
                    rows[r].colours = v.iter().map(|c| c.to_array()).collect();
                }
            }
        }
        let sc = rerun::Scalars::descriptor_scalars().component;
        for (r, v) in chunk.iter_component::<Scalar>(sc).enumerate() {
            rows[r].scalars = v.iter().map(|s| s.0.0).collect();
        }
        let lb = rerun::Boxes2D::descriptor_labels().component;
        for (r, v) in chunk.iter_component::<Text>(lb).enumerate() {
            rows[r].labels = v.iter().map(|t| t.as_str().to_string()).collect();
        }
        out.entry(entity).or_default().extend(rows);
    }
    for rows in out.values_mut() {
        rows.sort_by_key(|r| r.slice);
    }
    out
}

/// Feeds `frames` to a logger with an in-memory sink; returns the rows and the statistics.
fn log_all(frames: &[(&str, Vec<u8>)], params: ViewerParams) -> (BTreeMap<String, Vec<Row>>, LogStats) {
    let (rec, storage) = rerun::RecordingStreamBuilder::new("evseg-test")
        .memory()
        .expect("memory sink");
    let mut logger = RunLogger::new(rec, params).expect("logger");
    for (producer, f) in frames {
        log_frame(&mut logger, producer, f).expect("log");
    }
    let stats = logger.finish().expect("finish");
    (rows_of(storage.take()), stats)
}

fn params(max_points: usize) -> ViewerParams {
    ViewerParams {
        max_points_per_slice: max_points,
        ..ViewerParams::default()
    }
}

const SLICES: u64 = 5;
const EVENTS: usize = 3000;
const MAX_POINTS: usize = 1000;

#[test]
fn a_run_is_drawn_on_the_documented_entities() {
    let (rows, stats) = log_all(&common::run(SLICES, EVENTS, false), params(MAX_POINTS));
    assert_eq!(stats.slices, SLICES);
    assert_eq!(stats.events, SLICES * EVENTS as u64);
    assert_eq!(stats.points_per_layer, SLICES * MAX_POINTS as u64);
    // Labels, flow and truth of every slice.
    assert_eq!(stats.layers, 3 * SLICES);
    assert_eq!(stats.boxes, 2 * SLICES);
    assert_eq!((stats.unmatched, stats.misaligned, stats.undecodable), (0, 0, 0));

    let pick = decimate(EVENTS, MAX_POINTS);
    for k in 0..SLICES {
        let s = common::slice(k, EVENTS);
        let tr = common::tracks(&s, k);
        let fl = common::flow(&s, k);
        let ids = common::ids(&s, k);
        let at = |entity: &str| -> Row {
            let r = rows[entity].iter().find(|r| r.slice == Some(k as i64));
            r.unwrap_or_else(|| panic!("{entity}: no row for slice {k}"))
                .clone()
        };
        let positions: Vec<[f32; 2]> = pick
            .iter()
            .map(|&i| [f32::from(s.events.x[i]) + 0.5, f32::from(s.events.y[i]) + 0.5])
            .collect();
        let polarity = at("events/polarity");
        assert_eq!(polarity.positions, positions);
        let want: Vec<[u8; 4]> = pick.iter().map(|&i| polarity_colour(s.events.p[i])).collect();
        assert_eq!(polarity.colours, want);

        let seg = at("segments/tracker/events");
        assert_eq!(seg.positions, positions);
        let want: Vec<[u8; 4]> = pick.iter().map(|&i| label_colour(tr.label[i])).collect();
        assert_eq!(seg.colours, want);
        // Both objects and the background are in the drawn subset.
        for id in [0, 11, 12] {
            assert!(
                seg.colours.contains(&label_colour(id)),
                "slice {k}: id {id} not drawn"
            );
        }

        let flow = at("flow/flow/events");
        let want: Vec<[u8; 4]> = pick
            .iter()
            .map(|&i| flow_colour(fl.nx[i], fl.ny[i], fl.confidence[i], 1.0))
            .collect();
        assert_eq!(flow.colours, want);
        assert_eq!(flow.positions, positions);

        let truth = at("truth/events");
        let want: Vec<[u8; 4]> = pick.iter().map(|&i| label_colour(u32::from(ids[i]))).collect();
        assert_eq!(truth.colours, want);

        let boxes = at("segments/tracker/boxes");
        assert_eq!(boxes.labels, ["id 11", "id 12"]);
        assert_eq!(boxes.colours, [label_colour(11), label_colour(12)]);

        assert_eq!(at("egomotion/tracker/direction").scalars, [0.6, 0.0, 0.8]);
        assert_eq!(at("egomotion/tracker/omega").scalars, [0.0, 0.1, 0.0]);
        assert_eq!(at("egomotion/truth/direction").scalars, [0.0, 0.0, 1.0]);
        assert_eq!(at("metrics/evaluator/iou").scalars, [0.5 + 0.01 * k as f64]);
    }
    // The NaN direction error of slice 0 is left out.
    let dir: Vec<Option<i64>> = rows["metrics/evaluator/direction_error_deg"]
        .iter()
        .map(|r| r.slice)
        .collect();
    assert_eq!(dir, (1..SLICES as i64).map(Some).collect::<Vec<_>>());
    // The sensor outline is static, once per 2-D root.
    for root in ["events", "segments/tracker", "flow/flow", "truth"] {
        let frame = &rows[&format!("{root}/frame")];
        assert_eq!(frame.len(), 1, "{root}");
        assert_eq!(frame[0].slice, None);
    }
}

#[test]
fn per_event_messages_before_their_slice_are_drawn_when_it_comes() {
    let (slices_first, a) = log_all(&common::run(SLICES, EVENTS, false), params(MAX_POINTS));
    let (labels_first, b) = log_all(&common::run(SLICES, EVENTS, true), params(MAX_POINTS));
    assert_eq!(a, b);
    assert_eq!(slices_first, labels_first);
}

#[test]
fn small_slices_are_drawn_whole() {
    let (rows, stats) = log_all(&common::run(2, 300, false), params(MAX_POINTS));
    assert_eq!(stats.points_per_layer, 600);
    assert!(
        rows["segments/tracker/events"]
            .iter()
            .all(|r| r.positions.len() == 300)
    );
}

#[test]
fn misaligned_late_and_orphan_messages_are_counted_not_drawn() {
    let mut frames = common::run(3, 200, false);
    // Labels of slice 1 with one value missing.
    let s1 = common::slice(1, 200);
    let mut short = common::tracks(&s1, 1);
    short.label.pop();
    frames.push(("baseline", common::frame(1, &short)));
    // Flow of a slice that never comes.
    frames.push(("flow", common::frame(9, &common::flow(&common::slice(9, 200), 9))));
    // Truth of another node (the source's, aligned with its packets, not the slices).
    frames.push(("source", common::frame(0, &common::truth(&s1, 0))));
    let p = ViewerParams {
        cache_slices: 2,
        ..params(MAX_POINTS)
    };
    // Flow of slice 0, which has left the cache of 2 slices.
    frames.push(("flow", common::frame(0, &common::flow(&common::slice(0, 200), 0))));
    let (rows, stats) = log_all(&frames, p);
    assert_eq!(stats.misaligned, 1);
    assert!(
        stats
            .first_problem
            .as_deref()
            .is_some_and(|t| t.contains("199 per-event values for 200"))
    );
    assert_eq!(stats.unmatched, 2);
    assert_eq!(stats.unaligned_truth, 1);
    assert!(!rows.contains_key("segments/baseline/events"));
    assert_eq!(rows["flow/flow/events"].len(), 3);
}

#[test]
fn garbage_and_unknown_frames_are_counted_not_fatal() {
    let mut frames = common::run(1, 100, false);
    let good = common::frame(0, &common::slice(0, 100));
    frames.push(("slicer", vec![0xFF; 7]));
    frames.push(("slicer", good[..good.len() / 2].to_vec()));
    // A known schema without a drawing.
    let packet = evseg_schemas::EventPacket {
        camera: evseg_schemas::CameraInfo::pinhole(4, 4, 1.0, "t"),
        events: evseg_schemas::Events::default(),
        imu: vec![],
    };
    frames.push(("source", common::frame(0, &packet)));
    // End of stream frames are ignored.
    frames.push((
        "slicer",
        evseg_schemas::encode_end::<evseg_schemas::Slice>(1, 0.03).expect("end"),
    ));
    let (_, stats) = log_all(&frames, params(MAX_POINTS));
    assert_eq!(stats.slices, 1);
    assert_eq!(stats.not_drawn, 3);
    assert_eq!(stats.undecodable, 2);
}

#[test]
fn bad_parameters_are_refused() {
    let rec = rerun::RecordingStreamBuilder::new("t")
        .buffered()
        .expect("stream");
    for p in [
        params(0),
        ViewerParams {
            flow_full_scale: 0.0,
            ..ViewerParams::default()
        },
        ViewerParams {
            point_radius_ui: f32::NAN,
            ..ViewerParams::default()
        },
        ViewerParams {
            cache_slices: 0,
            ..ViewerParams::default()
        },
    ] {
        let e = RunLogger::new(rec.clone(), p).err().expect("refused");
        assert!(e.to_string().starts_with("viewer parameter"), "{e}");
    }
}
