//! Per-event normal-flow samples in normalized coordinates, derotated with the IMU rate: the one
//! place that turns (camera, events, normal flow, rotation rate) into the quantities every stage
//! of the method fits (paper section 3.3, METHOD_NOTES sections 1 and 3).

use evseg_schemas::align::{AlignError, check_flow};
use evseg_schemas::{Events, NormalFlow};

use crate::camera::UndistortTable;
use crate::motion::{a_matrix, rotational_flow};
use crate::rotation::RotationRate;

/// One event with a valid normal flow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FlowSample {
    /// Index of the event in its slice.
    pub index: usize,
    /// Undistorted normalized coordinates (focal length 1, camera frame).
    pub x: f64,
    /// Undistorted normalized coordinates (focal length 1, camera frame).
    pub y: f64,
    /// Unit normal direction `n0` (normalized image plane).
    pub n0: [f64; 2],
    /// Normal-flow length `n`, normalized units/s (> 0).
    pub n: f64,
    /// Derotated normal flow `n - n0 . (B(x) w)`, normalized units/s (equal to `n` without a
    /// rotation rate).
    pub n_derot: f64,
    /// The estimator's confidence in this flow, 0..1 (`NormalFlow::confidence`).
    pub confidence: f32,
}

impl FlowSample {
    /// `X = n0^T A(x)`: the 3-vector with `n_derot = (X . t) / Z` for a translation `t` and depth
    /// `Z` (METHOD_NOTES section 3).
    pub fn x_row(&self) -> [f64; 3] {
        let a = a_matrix(self.x, self.y);
        [
            self.n0[0] * a[0][0] + self.n0[1] * a[1][0],
            self.n0[0] * a[0][1] + self.n0[1] * a[1][1],
            self.n0[0] * a[0][2] + self.n0[1] * a[1][2],
        ]
    }
}

/// The median normal-flow length `n` of `samples` (normalized units/s; the upper median of an
/// even count), `None` without samples: the scale the magnitude weighting of the egomotion and
/// of the direction test, and the planar segmenter's residual discount, are relative to.
pub fn median_length<'a>(samples: impl IntoIterator<Item = &'a FlowSample>) -> Option<f64> {
    let mut ns: Vec<f64> = samples.into_iter().map(|s| s.n.abs()).collect();
    if ns.is_empty() {
        return None;
    }
    let mid = ns.len() / 2;
    Some(*ns.select_nth_unstable_by(mid, f64::total_cmp).1)
}

/// The samples of a slice: every event whose flow has confidence above `min_confidence` and a
/// finite non-zero length, derotated with the rotation `rate` at each event's time when given.
///
/// The values a stage's `min_confidence` may take: flow counts as valid where its confidence
/// (0..=1; 0 marks no estimate, the `NormalFlow` convention) is above it, so a value below 0
/// would take flow that has no estimate and one of 1 or more would leave no flow at all.
pub const MIN_CONFIDENCE_RANGE: std::ops::Range<f32> = 0.0..1.0;

/// The words of a `min_confidence` outside [`MIN_CONFIDENCE_RANGE`], for stages' parameter
/// errors; `None` when it is inside.
pub fn min_confidence_problem(value: f32) -> Option<&'static str> {
    (!MIN_CONFIDENCE_RANGE.contains(&value))
        .then_some("must be in [0, 1): flow is used where its confidence (0..=1) is above it")
}

/// Errors when the flow does not fit the events or an event lies outside the table's sensor.
pub fn flow_samples(
    table: &UndistortTable,
    events: &Events,
    flow: &NormalFlow,
    rate: Option<&RotationRate>,
    min_confidence: f32,
) -> Result<Vec<FlowSample>, AlignError> {
    check_flow(events, flow)?;
    let mut out = Vec::with_capacity(events.len());
    for i in 0..events.len() {
        table.prefetch_ahead(&events.x, &events.y, i);
        let (u, v) = (events.x[i], events.y[i]);
        let [x, y] = table.event(i, u, v)?;
        let (fx, fy, c) = (f64::from(flow.nx[i]), f64::from(flow.ny[i]), flow.confidence[i]);
        let n = (fx * fx + fy * fy).sqrt(); // not hypot: libm's is several times slower; f32 inputs cannot overflow
        if !(c > min_confidence && n.is_finite() && n > 0.0) {
            continue;
        }
        let n0 = [fx / n, fy / n];
        let (x, y) = (f64::from(x), f64::from(y));
        let n_derot = match rate {
            Some(rate) => {
                let r = rotational_flow(x, y, rate.at(events.t[i]));
                n - (r[0] * n0[0] + r[1] * n0[1])
            }
            None => n,
        };
        out.push(FlowSample {
            index: i,
            x,
            y,
            n0,
            n,
            n_derot,
            confidence: c,
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Camera;
    use evseg_schemas::CameraInfo;

    #[test]
    fn min_confidence_must_leave_some_flow_and_exclude_flow_without_an_estimate() {
        for ok in [0.0, 0.5, 0.999] {
            assert_eq!(min_confidence_problem(ok), None, "{ok}");
        }
        for bad in [-0.1, 1.0, 7.0, f32::NAN, f32::INFINITY] {
            assert!(
                min_confidence_problem(bad).is_some_and(|w| w.contains("[0, 1)")),
                "{bad}"
            );
        }
    }

    #[test]
    fn each_event_is_derotated_with_the_rate_at_its_own_time() {
        let info = CameraInfo::pinhole(64, 48, 50.0, "test");
        let table = Camera::new(&info).undistort_table();
        // Yaw rate 1 rad/s at t = 0.1 s, growing by 5 rad/s^2; two events near the image centre
        // (where the rotational flow along x is about -w_y) 20 ms apart, both seeing a flow of 1
        // along x.
        let rate = RotationRate {
            mean: [0.0, 1.0, 0.0],
            slope: [0.0, 5.0, 0.0],
            t_ref: 0.1,
        };
        let mut events = Events::with_capacity(2);
        events.push(0.09, 32, 24, 1);
        events.push(0.11, 32, 24, 1);
        let flow = NormalFlow {
            nx: vec![1.0; 2],
            ny: vec![0.0; 2],
            confidence: vec![1.0; 2],
        };
        let s = flow_samples(&table, &events, &flow, Some(&rate), 0.0).unwrap();
        let [x, y] = table.get(32, 24).unwrap();
        let expect = |t: f64| 1.0 - rotational_flow(f64::from(x), f64::from(y), rate.at(t))[0];
        assert!((s[0].n_derot - expect(0.09)).abs() < 1e-12, "{}", s[0].n_derot);
        assert!((s[1].n_derot - expect(0.11)).abs() < 1e-12, "{}", s[1].n_derot);
        // 0.95 and 1.05 rad/s: the two events are derotated differently.
        assert!(((s[1].n_derot - s[0].n_derot).abs() - 0.1).abs() < 0.01);
        // A constant rate derotates both alike.
        let constant = RotationRate::from([0.0, 1.0, 0.0]);
        let c = flow_samples(&table, &events, &flow, Some(&constant), 0.0).unwrap();
        assert_eq!(c[0].n_derot, c[1].n_derot);
    }
}
