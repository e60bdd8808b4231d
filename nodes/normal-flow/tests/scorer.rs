//! Scorer known answers on constructed estimates `p` and true flows `u`.

use evseg_normal_flow::score::{ScoreError, event_errors};
use evseg_normal_flow::{ScoreParams, Scorer};
use evseg_schemas::{CameraInfo, Events, NormalFlow, Truth};

const S: f64 = std::f64::consts::FRAC_1_SQRT_2;

#[test]
fn true_normal_flows_have_no_error() {
    let u = [1.0, 0.0];
    for p in [[1.0, 0.0], [0.5, 0.5], [0.5, -0.5], [0.25, 0.25 * 3f64.sqrt()]] {
        let e = event_errors(p, u).expect("defined");
        assert!(e.sign_correct);
        assert!(e.magnitude_error < 1e-12, "{p:?}: {}", e.magnitude_error);
        assert!(
            e.circle_angle_error_deg < 1e-6,
            "{p:?}: {}",
            e.circle_angle_error_deg
        );
    }
}

#[test]
fn wrong_sign_and_wrong_magnitude() {
    let u = [1.0, 0.0];
    // Opposite of a true normal flow at 45 degrees: |p| = 0.707, u . n0 = -0.707.
    let e = event_errors([-0.5, -0.5], u).expect("defined");
    assert!(!e.sign_correct);
    assert!((e.magnitude_error - 2.0 * S).abs() < 1e-12);
    // Twice the true normal flow at 45 degrees: |p| = 1.414, u . n0 = 0.707.
    let e = event_errors([1.0, 1.0], u).expect("defined");
    assert!(e.sign_correct);
    assert!((e.magnitude_error - S).abs() < 1e-12);
    assert!((e.relative_magnitude_error - S).abs() < 1e-12);
    // Nearest circle point (0.5 + 0.5/sqrt5, 1/sqrt5) at atan(0.618034) = 31.7175 deg vs 45 deg.
    assert!(
        (e.circle_angle_error_deg - 13.2825).abs() < 1e-3,
        "{}",
        e.circle_angle_error_deg
    );
    // 5% too long along u itself: magnitude error 0.05, nearest circle point u, angle 0.
    let e = event_errors([1.05, 0.0], u).expect("defined");
    assert!((e.magnitude_error - 0.05).abs() < 1e-12 && e.circle_angle_error_deg < 1e-9);
    // Antiparallel: the nearest consistent normal flow is the origin, 90 degrees by definition.
    let e = event_errors([-1.0, 0.0], u).expect("defined");
    assert!(!e.sign_correct && (e.circle_angle_error_deg - 90.0).abs() < 1e-9);
    // Scale invariance.
    let a = event_errors([0.3, 0.7], [1.0, 0.2]).expect("defined");
    let b = event_errors([30.0, 70.0], [100.0, 20.0]).expect("defined");
    assert!((a.circle_angle_error_deg - b.circle_angle_error_deg).abs() < 1e-9);
    assert!((a.relative_magnitude_error - b.relative_magnitude_error).abs() < 1e-12);
    assert!(event_errors([0.0, 0.0], u).is_none());
    assert!(event_errors([1.0, 0.0], [0.0, 0.0]).is_none());
    assert!(event_errors([f64::NAN, 0.0], u).is_none());
}

/// (x, y, object, true flow px/s, estimate normalized/s, confidence)
type Row = (u16, u16, u16, [f32; 2], [f32; 2], f32);

fn slice() -> (CameraInfo, Events, NormalFlow, Truth) {
    let camera = CameraInfo::pinhole(64, 48, 100.0, "t");
    let mut ev = Events::default();
    let mut flow = NormalFlow::default();
    let mut truth = Truth::default();
    // (x, y, object, true flow px/s, estimate normalized/s, confidence)
    let rows: [Row; 6] = [
        (10, 10, 1, [100.0, 0.0], [1.0, 0.0], 0.9), // boundary (object 2 at x = 12), exact
        (12, 10, 2, [0.0, 100.0], [0.0, -1.0], 0.8), // boundary, wrong sign
        (40, 30, 1, [100.0, 0.0], [0.5, 0.5], 0.7), // interior, true normal flow at 45 deg
        (41, 30, 1, [100.0, 0.0], [2.0, 0.0], 0.0), // interior, invalid
        (42, 30, 1, [0.0, 0.0], [1.0, 0.0], 0.5),   // interior, valid but no true motion
        (70, 30, 1, [100.0, 0.0], [1.0, 0.0], 0.5), // outside the sensor
    ];
    for (i, (x, y, id, u, p, c)) in rows.into_iter().enumerate() {
        ev.push(i as f64 * 1e-3, x, y, 1);
        truth.event_object.push(id);
        truth.flow_x.push(u[0]);
        truth.flow_y.push(u[1]);
        flow.nx.push(p[0]);
        flow.ny.push(p[1]);
        flow.confidence.push(c);
    }
    (camera, ev, flow, truth)
}

#[test]
fn slice_score_splits_boundary_and_interior() {
    let (camera, ev, flow, truth) = slice();
    let mut scorer = Scorer::new(&camera, ScoreParams::default());
    let s = scorer.add_slice(&ev, &flow, &truth).expect("aligned");
    assert_eq!(s.out_of_sensor, 1);
    assert_eq!((s.all.events, s.all.valid, s.all.scored), (5, 4, 3));
    assert!((s.all.coverage - 0.8).abs() < 1e-12);
    assert!((s.all.sign_correct_rate - 2.0 / 3.0).abs() < 1e-12);
    assert_eq!((s.boundary.events, s.boundary.scored), (2, 2));
    assert!((s.boundary.sign_correct_rate - 0.5).abs() < 1e-12);
    assert_eq!(
        (s.interior.events, s.interior.valid, s.interior.scored),
        (3, 2, 1)
    );
    assert!((s.interior.sign_correct_rate - 1.0).abs() < 1e-12);
    assert!(s.interior.magnitude_error_median < 1e-6);
    // Boundary: errors 0 (exact) and 2 (|p| = 1, u . n0 = -1) in normalized units: median 1.
    assert!((s.boundary.magnitude_error_median - 1.0).abs() < 1e-6);
    // The run summary equals the slice after one slice, and doubles its counts after two.
    assert_eq!(scorer.summary(), s);
    scorer.add_slice(&ev, &flow, &truth).expect("aligned");
    let run = scorer.summary();
    assert_eq!((run.all.events, run.all.scored, run.out_of_sensor), (10, 6, 2));
    assert!((run.all.sign_correct_rate - 2.0 / 3.0).abs() < 1e-12);
}

#[test]
fn boundary_needs_another_object_within_two_pixels() {
    let (camera, mut ev, flow, truth) = slice();
    ev.x[1] = 13; // 3 px away from the object-1 event: both interior now
    let mut scorer = Scorer::new(&camera, ScoreParams::default());
    let s = scorer.add_slice(&ev, &flow, &truth).expect("aligned");
    assert_eq!(s.boundary.events, 0);
    assert!(s.boundary.sign_correct_rate.is_nan());
    assert_eq!(s.interior.events, 5);
}

#[test]
fn misaligned_inputs_are_errors() {
    let (camera, ev, flow, truth) = slice();
    let mut scorer = Scorer::new(&camera, ScoreParams::default());
    let mut short = flow.clone();
    short.confidence.pop();
    assert!(matches!(
        scorer.add_slice(&ev, &short, &truth),
        Err(ScoreError::Length {
            what: "flow.confidence",
            ..
        })
    ));
    let mut t = truth.clone();
    t.flow_y.push(0.0);
    assert!(scorer.add_slice(&ev, &flow, &t).is_err());
    let mut t = truth.clone();
    t.event_object.pop();
    assert!(scorer.add_slice(&ev, &flow, &t).is_err());
    // Truth without per-event flow: nothing is scored, every event counted as no_truth.
    let s = scorer.add_slice(&ev, &flow, &Truth::default()).expect("aligned");
    assert_eq!((s.no_truth, s.all.events), (5, 0));
    // Nothing above changed the run.
    assert_eq!(scorer.summary().all.events, 0);
}
