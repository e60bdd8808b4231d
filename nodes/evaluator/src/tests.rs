//! End-to-end known-answer tests of the streaming evaluator on a constructed sequence.

use evseg_schemas::{CameraInfo, CameraMotion, Distortion, Egomotion, Events, Mask, ObjectPose, Track};

use super::*;
use evseg_geometry::rigid::{mul_mtv, quat_from_axis_angle, quat_to_mat};

const W: u16 = 8;
const H: u16 = 6;
const WINDOW: f64 = 0.03;
/// World velocity of the camera, m/s.
const VW: [f64; 3] = [0.3, 0.0, 0.4];
const YAW_RATE: f64 = 0.2;

fn camera() -> CameraInfo {
    CameraInfo {
        width: W,
        height: H,
        fx: 100.0,
        fy: 100.0,
        cx: 4.0,
        cy: 3.0,
        distortion: Distortion::None,
        imu_to_camera: CameraInfo::IDENTITY,
        imu_time_offset_s: 0.0,
        time_origin_us: 0,
        sensor: "test".into(),
    }
}

fn yaw(t: f64) -> [f64; 4] {
    quat_from_axis_angle([0.0, 1.0, 0.0], YAW_RATE * t)
}

/// Object 1 covers columns 0..3 in every window with k >= 2; windows 0 and 1 have no object.
fn object_at(k: u64, x: u16) -> u16 {
    if k >= 2 && x < 3 { 1 } else { 0 }
}

struct Seq {
    slices: Vec<(u64, f64, f64, Slice, Truth)>,
}

/// `n` windows of 30 ms: 48 events each (every pixel once, spread over the window), masks at
/// 60 Hz, camera poses at 200 Hz (no velocities, like EVIMO2), object poses at 200 Hz.
fn sequence(n: u64, per_event_ids: bool) -> Seq {
    let mut slices = Vec::new();
    for k in 0..n {
        let (t0, t1) = (k as f64 * WINDOW, (k + 1) as f64 * WINDOW);
        let mut events = Events::default();
        let mut ids = Vec::new();
        let total = (W * H) as usize;
        for i in 0..total {
            let (x, y) = ((i % W as usize) as u16, (i / W as usize) as u16);
            events.push(t0 + WINDOW * (i as f64 + 0.5) / total as f64, x, y, 1);
            ids.push(object_at(k, x));
        }
        let mut truth = Truth::default();
        if per_event_ids {
            truth.event_object = ids;
        }
        let mut m = 0;
        loop {
            let t = m as f64 / 60.0;
            m += 1;
            if t >= t1 {
                break;
            }
            if t >= t0 {
                let ids = (0..total)
                    .map(|i| object_at(k, (i % W as usize) as u16))
                    .collect();
                truth.masks.push(Mask {
                    t,
                    width: W,
                    height: H,
                    ids,
                });
            }
        }
        for j in 0..400 {
            let t = j as f64 * 0.005;
            if t >= t0 && t < t1 {
                truth.camera.push(CameraMotion {
                    t,
                    position: [VW[0] * t, VW[1] * t, VW[2] * t],
                    orientation: yaw(t),
                    linear_velocity: None,
                    angular_velocity: None,
                });
                truth.objects.push(ObjectPose {
                    id: 1,
                    t,
                    position: [-0.2 + 0.5 * t, 0.0, 2.0],
                    orientation: [0.0, 0.0, 0.0, 1.0],
                });
            }
        }
        let slice = Slice {
            camera: camera(),
            events,
            imu: vec![],
            omega: None,
        };
        slices.push((k, t0, t1, slice, truth));
    }
    Seq { slices }
}

/// True camera-frame velocity over window `[t0, t1)`: R(t0)^T VW (constant world velocity).
fn true_v(t0: f64) -> [f64; 3] {
    mul_mtv(&quat_to_mat(yaw(t0)), VW)
}

fn rotate_about_y(v: [f64; 3], deg: f64) -> [f64; 3] {
    let (s, c) = deg.to_radians().sin_cos();
    [c * v[0] + s * v[2], v[1], -s * v[0] + c * v[2]]
}

fn run(seq: &Seq, result: impl Fn(u64, f64, &Slice, &Truth) -> Tracks) -> Evaluator {
    let mut ev = Evaluator::new(EvalParams::default()).unwrap();
    let mut n = 0;
    for (k, t0, t1, slice, truth) in &seq.slices {
        let r = result(*k, *t0, slice, truth);
        n += ev
            .push(SliceInput {
                seq: *k,
                t_start: *t0,
                t_end: *t1,
                slice,
                truth,
                result: &r,
            })
            .unwrap()
            .len();
    }
    n += ev.finish().unwrap().len();
    assert_eq!(n, seq.slices.len());
    ev
}

fn perfect(k: u64, t0: f64, slice: &Slice, rotate_deg: f64) -> Tracks {
    let label: Vec<u32> = slice
        .events
        .x
        .iter()
        .map(|&x| object_at(k, x) as u32 * 7)
        .collect();
    let tracks = if k >= 2 {
        vec![Track {
            id: 7,
            centroid: [1.0, 2.5],
            velocity: [0.0; 2],
            bbox: [0.0, 0.0, 2.0, 5.0],
            // Depth-1 camera-equivalent translation of the object: -v / Z.
            translation: [-0.25, 0.0, 0.0],
            age: k as u32,
            events: 18,
        }]
    } else {
        vec![]
    };
    Tracks {
        label,
        tracks,
        egomotion: Egomotion {
            direction: rotate_about_y(true_v(t0), rotate_deg),
            omega: [0.0; 3],
            valid: true,
        },
    }
}

#[test]
fn a_label_that_changes_between_windows_counts_as_id_switches() {
    let seq = sequence(12, true);
    // Label 7 until window 5, then 9, then 7 again from window 9: two switches.
    let ev = run(&seq, |k, t0, s, _| {
        let mut t = perfect(k, t0, s, 0.0);
        if (5..9).contains(&k) {
            t.label.iter_mut().filter(|l| **l == 7).for_each(|l| *l = 9);
        }
        t
    });
    let sum = ev.summary("synthetic");
    assert_eq!(sum.iou_per_object[0].mean_iou, 1.0);
    assert_eq!(sum.iou_per_object[0].id_switches, 2);
    assert_eq!(sum.iou_per_object[0].id_switches_any_overlap, 2);
}

/// A window in which only a small piece of the object is labelled (label 9 on one event in
/// four, IoU 0.25) is matched to that piece but is not the object's identity under the MOTS
/// rule (IoU above 0.5): 7 -> 9 -> 7 counts two switches over any overlap and none as
/// identity. Windows where the object is wholly unconfirmed (moving, no id) match nothing.
#[test]
fn a_small_piece_matched_for_want_of_a_better_one_is_not_an_identity_switch() {
    let seq = sequence(12, true);
    let ev = run(&seq, |k, t0, s, _| {
        let mut t = perfect(k, t0, s, 0.0);
        for (n, l) in t.label.iter_mut().filter(|l| **l == 7).enumerate() {
            if (3..5).contains(&k) {
                *l = if n % 4 == 0 { 9 } else { 0 };
            } else if (6..8).contains(&k) {
                *l = Tracks::UNCONFIRMED;
            }
        }
        t
    });
    let sum = ev.summary("synthetic");
    let o = &sum.iou_per_object[0];
    assert_eq!((o.id_switches, o.id_switches_any_overlap), (0, 2));
    assert_eq!(
        (
            sum.id_switches_worst_object,
            sum.id_switches_any_overlap_worst_object
        ),
        (Some(0), Some(2))
    );
    assert_eq!(o.matched_windows, 8);
    // The unconfirmed windows stay moving for the IoU per event.
    assert_eq!(sum.iou_events.windows, 10);
    assert!(
        sum.iou_events.mean.is_some_and(|m| m > 0.8),
        "{:?}",
        sum.iou_events.mean
    );
}

#[test]
fn perfect_labels_score_one_and_a_ten_degree_direction_error_gives_ten_degrees() {
    let seq = sequence(12, true);
    let ev = run(&seq, |k, t0, s, _| perfect(k, t0, s, 10.0));
    let sum = ev.summary("synthetic");
    assert_eq!(sum.windows, 12);
    assert_eq!(sum.windows_with_moving_object, 10);
    assert_eq!(sum.iou_events.mean, Some(1.0));
    assert_eq!(sum.iou_events.windows, 10);
    assert_eq!(sum.iou_events.skipped.get("no_moving_object"), Some(&2));
    assert_eq!(sum.iou_mask.mean, Some(1.0));
    assert_eq!(sum.iou_mask.windows, 10);
    assert_eq!(sum.iou_per_object.len(), 1);
    assert_eq!(sum.iou_per_object[0].mean_iou, 1.0);
    assert_eq!(sum.iou_per_object[0].matched_windows, 10);
    assert_eq!(sum.iou_per_object[0].id_switches, 0);
    let o = &sum.iou_per_object[0];
    assert_eq!(
        (o.share_in_match, o.share_as_background, o.share_in_other_labels),
        (1.0, 0.0, 0.0)
    );

    let e = &sum.egomotion;
    // The last window's end has no pose after it to interpolate from.
    assert_eq!(e.windows, 11);
    assert_eq!(e.skipped.get("no_camera_truth"), Some(&1));
    assert!(
        (e.direction_error.median_deg.unwrap() - 10.0).abs() < 1e-6,
        "{e:?}"
    );
    assert!((e.direction_error.mean_deg.unwrap() - 10.0).abs() < 1e-6);
    // Expected RMSE: per slice error = rot(v, 10 deg) - v, exactly (poses are exact here up to
    // slerp of a constant-rate yaw, which is exact).
    let mut sq = [0.0; 3];
    for (_, t0, ..) in &seq.slices[..11] {
        let v = true_v(*t0);
        let r = rotate_about_y(v, 10.0);
        for k in 0..3 {
            sq[k] += (r[k] - v[k]).powi(2);
        }
    }
    let want = sq.map(|s| (s / 11.0).sqrt());
    let got = e.rmse_mps.unwrap();
    for k in 0..3 {
        assert!((got[k] - want[k]).abs() < 1e-9, "{got:?} vs {want:?}");
    }
    // The chord: |error| = 2 |v| sin(5 deg), |v| = 0.5 m/s.
    let chord = (got.iter().map(|g| g * g).sum::<f64>()).sqrt();
    assert!((chord - 2.0 * 0.5 * 5f64.to_radians().sin()).abs() < 1e-9);

    // Object motion: object moves +0.5 m/s in x at 2 m -> 0.25 /s; the track predicts it.
    let o = &sum.object_motion;
    // The last window has no object pose after its end: 9 of the 10 windows with the object.
    assert_eq!(o.samples, 9);
    assert_eq!(o.with_prediction, 9);
    assert_eq!(o.skipped.get("no_object_poses"), Some(&1));
    let rm = o.rmse_translational_flow.unwrap();
    assert!(rm[0] < 1e-9 && rm[1] < 1e-9, "{rm:?}");
    // Image velocity: the track claims 0 px/s, truth is 0.25 * 100 = 25 px/s (plus the tiny
    // perspective term of x != 0, which is 0 here since v_z = 0).
    let ri = o.rmse_image_velocity_px.unwrap();
    assert!((ri[0] - 25.0).abs() < 1e-6 && ri[1].abs() < 1e-9, "{ri:?}");
    // Frames were kept for the plot, only from windows with the object.
    let frames = ev.frames(4);
    assert_eq!(frames.len(), 4);
    assert!(frames.iter().all(|f| f.seq >= 2));
}

#[test]
fn all_background_scores_zero_and_invalid_egomotion_is_not_available() {
    let seq = sequence(8, true);
    let ev = run(&seq, |_, _, s, _| Tracks {
        label: vec![0; s.events.len()],
        tracks: vec![],
        egomotion: Egomotion::default(),
    });
    let sum = ev.summary("baseline");
    assert_eq!(sum.iou_events.mean, Some(0.0));
    assert_eq!(sum.iou_mask.mean, Some(0.0));
    assert_eq!(sum.iou_per_object[0].mean_iou, 0.0);
    assert_eq!(sum.iou_per_object[0].matched_windows, 0);
    let o = &sum.iou_per_object[0];
    assert_eq!(
        (o.share_in_match, o.share_as_background, o.share_in_other_labels),
        (0.0, 1.0, 0.0)
    );
    assert_eq!(sum.egomotion.windows, 0);
    assert_eq!(sum.egomotion.skipped.get("no_prediction"), Some(&8));
    assert_eq!(sum.egomotion.skipped.len(), 1);
    assert_eq!(sum.egomotion.rmse_mps, None);
    assert_eq!(sum.egomotion.direction_error.median_deg, None);
    assert_eq!(sum.object_motion.with_prediction, 0);
    assert_eq!(sum.object_motion.rmse_translational_flow, None);
    // The true velocity is still reported (for the plot), without any estimate.
    assert!(ev.reports()[3].camera_truth.scored().is_some());
    assert!(ev.reports()[3].egomotion.scored().is_none());
    // Per-slice metrics carry NaN, never a substitute.
    let m = ev.reports()[3].metrics();
    let get = |n: &str| m.values.iter().find(|v| v.name == n).unwrap().value;
    assert_eq!(get("iou_events"), 0.0);
    assert!(get("direction_error_deg").is_nan());
    assert!(get("scaled_velocity_x_mps").is_nan());
}

#[test]
fn mask_only_source_uses_the_paper_protocol() {
    let seq = sequence(6, false);
    let ev = run(&seq, |k, t0, s, _| perfect(k, t0, s, 0.0));
    let sum = ev.summary("masks");
    assert_eq!(sum.iou_events.mean, None);
    assert_eq!(sum.iou_events.skipped.get("no_per_event_truth"), Some(&6));
    assert_eq!(sum.iou_mask.mean, Some(1.0));
    assert_eq!(sum.iou_mask.windows, 4);
    let r = &ev.reports()[3];
    let m = r.iou_mask.scored().unwrap();
    // Window [0.09, 0.12): midpoint 0.105, nearest mask 6/60 = 0.1; events within 1/120 s.
    assert!((m.mask_t - 0.1).abs() < 1e-12);
    assert!((m.mask_period_s - 1.0 / 60.0).abs() < 1e-9);
    let expected = seq.slices[3]
        .3
        .events
        .t
        .iter()
        .filter(|&&t| (t - 0.1).abs() <= 1.0 / 120.0)
        .count();
    assert_eq!(m.events_evaluated as usize, expected);
    assert!(expected > 0 && expected < 48);
    assert_eq!(
        r.objects.scored().map(|o| o.truth),
        Some(slice_eval::ObjectTruth::Mask)
    );
    assert!((sum.egomotion.direction_error.median_deg.unwrap()).abs() < 1e-6);
}

#[test]
fn scoring_waits_for_lookahead_truth() {
    let seq = sequence(10, true);
    let mut ev = Evaluator::new(EvalParams::default()).unwrap();
    let mut ready = Vec::new();
    for (k, t0, t1, slice, truth) in &seq.slices {
        let r = perfect(*k, *t0, slice, 0.0);
        let out = ev
            .push(SliceInput {
                seq: *k,
                t_start: *t0,
                t_end: *t1,
                slice,
                truth,
                result: &r,
            })
            .unwrap();
        ready.push(out.iter().map(|r| r.seq).collect::<Vec<_>>());
    }
    // 0.1 s look-ahead over 30 ms windows: slice k is scored when slice k + 4 arrives (its end
    // 0.03 (k + 5) >= 0.03 (k + 1) + 0.1 needs 4 more windows, rounding aside).
    assert!(ready[..3].iter().all(|r| r.is_empty()), "{ready:?}");
    assert!(ready.iter().flatten().count() >= 5);
    let rest = ev.finish().unwrap();
    assert_eq!(ready.iter().flatten().count() + rest.len(), 10);
    let seqs: Vec<u64> = ev.reports().iter().map(|r| r.seq).collect();
    assert_eq!(seqs, (0..10).collect::<Vec<_>>());
}

#[test]
fn malformed_input_is_an_error_not_a_panic_and_leaves_the_evaluator_usable() {
    let seq = sequence(3, true);
    let mut ev = Evaluator::new(EvalParams::default()).unwrap();
    let (k, t0, t1, slice, truth) = &seq.slices[0];
    let mut r = perfect(*k, *t0, slice, 0.0);
    r.label.pop();
    let input = |r| SliceInput {
        seq: *k,
        t_start: *t0,
        t_end: *t1,
        slice,
        truth,
        result: r,
    };
    assert_eq!(
        ev.push(input(&r)).unwrap_err(),
        EvalError::LabelLength {
            seq: 0,
            labels: 47,
            events: 48
        }
    );
    let good = perfect(*k, *t0, slice, 0.0);
    let mut bad_truth = truth.clone();
    bad_truth.event_object.push(0);
    let e = ev
        .push(SliceInput {
            truth: &bad_truth,
            ..input(&good)
        })
        .unwrap_err();
    assert!(matches!(
        e,
        EvalError::TruthLength {
            ids: 49,
            events: 48,
            ..
        }
    ));
    let mut bad_dir = good.clone();
    bad_dir.egomotion.direction = [0.0; 3];
    ev.push(input(&bad_dir)).unwrap();
    assert!(matches!(ev.finish(), Err(EvalError::BadDirection { seq: 0, .. })));
    // Reversed window and out-of-order slices.
    let mut ev = Evaluator::new(EvalParams::default()).unwrap();
    assert!(matches!(
        ev.push(SliceInput {
            t_start: *t1,
            t_end: *t0,
            ..input(&good)
        }),
        Err(EvalError::Window { .. })
    ));
    ev.push(input(&good)).unwrap();
    assert!(matches!(ev.push(input(&good)), Err(EvalError::OutOfOrder { .. })));
    // Bad parameters.
    let p = EvalParams {
        lookahead_s: 0.01,
        ..EvalParams::default()
    };
    assert!(matches!(
        Evaluator::new(p),
        Err(EvalError::Param {
            name: "lookahead_ms",
            ..
        })
    ));
    for v in [-0.1, 1.0, f64::NAN] {
        let p = EvalParams {
            switch_min_iou: v,
            ..EvalParams::default()
        };
        let err = Evaluator::new(p).unwrap_err();
        assert!(
            matches!(
                err,
                EvalError::Param {
                    name: "switch_min_iou",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("switch_min_iou"), "{err}");
    }
}

#[test]
fn report_folder_has_every_file_and_figure() {
    let seq = sequence(20, true);
    let ev = run(&seq, |k, t0, s, _| {
        let mut r = perfect(k, t0, s, 10.0);
        // Miss one column of the object in odd slices so the IoU plot is not flat.
        if k % 2 == 1 {
            for (l, &x) in r.label.iter_mut().zip(&s.events.x) {
                if x == 2 {
                    *l = 0;
                }
            }
        }
        r
    });
    let keep = std::env::var_os("EVSEG_KEEP_REPORT").map(std::path::PathBuf::from);
    let tmp = tempfile::tempdir().unwrap();
    let dir = keep.unwrap_or_else(|| tmp.path().join("report"));
    let files = report::write_report(&dir, &ev, "synthetic-01").unwrap();
    let names: Vec<String> = files
        .iter()
        .map(|f| f.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    for n in [
        "iou.png",
        "velocity.png",
        "object_motion.png",
        "frames.png",
        "report.json",
        "report.md",
    ] {
        assert!(names.contains(&n.to_string()), "{n} missing from {names:?}");
    }
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap();
    assert_eq!(json["sequence"]["sequence"], "synthetic-01");
    assert_eq!(json["slices"].as_array().unwrap().len(), 20);
    // Odd windows: 12 of 18 object events -> 2/3; even: 1. Ten windows each from k = 2.
    let mean = json["sequence"]["iou_events"]["mean"].as_f64().unwrap();
    assert!(
        (mean - (9.0 * 1.0 + 9.0 * 2.0 / 3.0) / 18.0).abs() < 1e-12,
        "{mean}"
    );
    assert!(
        json["velocity_scaling"]
            .as_str()
            .unwrap()
            .contains("ground-truth speed")
    );
    // A skipped figure is written as a reason, never as a number.
    assert_eq!(json["slices"][0]["iou_events"]["skipped"], "no_moving_object");
    let md = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(md.contains("| synthetic-01 | 83.33 | 83.33 | 83.33 |"), "{md}");
    assert!(md.contains("![frames.png](frames.png)"));
    for png_name in ["iou.png", "velocity.png", "frames.png"] {
        let bytes = std::fs::read(dir.join(png_name)).unwrap();
        let mut r = png::Decoder::new(std::io::Cursor::new(bytes))
            .read_info()
            .unwrap();
        let mut buf = vec![0; r.output_buffer_size().unwrap()];
        let info = r.next_frame(&mut buf).unwrap();
        assert!(info.width >= 300 && info.height >= 200, "{png_name}");
    }
}

/// Windows whose ground truth has no moving object (windows 0 and 1 of the constructed
/// sequence) score the share of their events labelled moving: one column of eight labelled
/// gives 1/8; the windows with the object are skipped for it; all background gives 0.
#[test]
fn static_windows_score_the_share_labelled_moving() {
    let seq = sequence(6, true);
    let ev = run(&seq, |k, t0, s, _| {
        let mut r = perfect(k, t0, s, 0.0);
        if k < 2 {
            r.label = s.events.x.iter().map(|&x| u32::from(x == 7) * 3).collect();
        }
        r
    });
    let sum = ev.summary("static");
    let st = &sum.static_share_labelled_moving;
    assert_eq!(st.windows, 2);
    assert_eq!(st.mean, Some(0.125));
    assert_eq!(st.skipped.get("moving_object_present"), Some(&4));
    let score = ev.reports()[1].static_scene.scored().unwrap();
    assert_eq!((score.events_evaluated, score.labelled_moving), (48, 6));
    assert_eq!(score.truth, slice_eval::ObjectTruth::PerEvent);
    let m = ev.reports()[1].metrics();
    let get = |n: &str| m.values.iter().find(|v| v.name == n).unwrap().value;
    assert_eq!(get("static_share_labelled_moving"), 0.125);
    // The IoU figures still skip these windows.
    assert_eq!(sum.iou_events.windows, 4);

    let ev = run(&seq, |_, _, s, _| Tracks {
        label: vec![0; s.events.len()],
        tracks: vec![],
        egomotion: Egomotion::default(),
    });
    assert_eq!(ev.summary("bg").static_share_labelled_moving.mean, Some(0.0));

    // With masks only, the events near the window's mask are the ones evaluated.
    let masks = sequence(6, false);
    let ev = run(&masks, |k, t0, s, _| {
        let mut r = perfect(k, t0, s, 0.0);
        if k < 2 {
            r.label = vec![5; s.events.len()];
        }
        r
    });
    let score = ev.reports()[1].static_scene.scored().unwrap();
    assert_eq!(score.truth, slice_eval::ObjectTruth::Mask);
    assert!(score.events_evaluated > 0 && score.events_evaluated < 48);
    assert_eq!(score.share_labelled_moving, 1.0);
}
