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

/// The samples of a slice: every event whose flow has confidence above `min_confidence` and a
/// finite non-zero length, derotated with the rotation `rate` at each event's time when given.
///
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
