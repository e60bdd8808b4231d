//! Scores a normal-flow estimate against the true optical flow of each event.
//!
//! Notation, everything in normalized units per second: `p` the estimated normal flow, `u` the
//! true optical flow (the simulator's per-event pixel flow converted with the same camera
//! Jacobian as the estimate), `n0 = p / |p|` the estimated normal direction.
//!
//! Only `u` is known, not the true edge direction, so the direction of `p` alone cannot be wrong
//! except in sign: every direction with `u . n0 > 0` is the normal of some edge moving with `u`.
//! The normal flows consistent with `u` are the points `(u . n) n`, which lie on the circle with
//! diameter `u` (centre `u / 2`, radius `|u| / 2`, through the origin and `u`). The metrics:
//!
//! - **sign-correct rate** (primary): share of scored events with `p . u > 0`.
//! - **magnitude error**: `| |p| - u . n0 |`, the difference between the estimated speed across
//!   the edge and the true one along the estimated normal. The end-point error of `p` against the
//!   true normal flow `(u . n0) n0` is `|p - (u . n0) n0| = | |p| - u . n0 |`, the same number,
//!   so it is not reported twice. **relative magnitude error** divides it by `|u|`.
//! - **circle angle error**, degrees: the angle at the origin between `p` and the nearest point
//!   `p*` of the circle of consistent normal flows (`p* = u/2 + (|u|/2) (p - u/2) / |p - u/2|`).
//!   It is 0 exactly when `p` is a normal flow consistent with `u`, does not change when `p` and
//!   `u` are scaled together, stays finite and continuous near `p = u` (unlike the Thales angle
//!   between `p` and `u - p`, which jumps from 90 to 180 degrees when |p| overshoots |u| by 1%),
//!   and grows both with a wrong magnitude for the direction and with a direction impossible for
//!   the magnitude. Where `p*` is the origin (p antiparallel to u) it is 90 degrees.
//!
//! Events are scored when their estimate is valid (confidence > `min_confidence`) and their true
//! flow is non-zero; coverage is the share of events with a valid estimate. Every figure is given
//! for all events, for events at object boundaries (an event whose truth object id differs from
//! that of another event of the slice within `boundary_radius_px`, Chebyshev distance) and for the
//! others.

use evseg_schemas::{CameraInfo, Events, NormalFlow, Truth};
use serde::{Deserialize, Serialize};

use crate::estimator::{check_columns, jacobian_table};

/// Errors of the scorer.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScoreError {
    /// A per-event array has a different length than the events.
    #[error("{what} has {got} entries for {events} events")]
    Length {
        /// Which array.
        what: &'static str,
        /// Its length.
        got: usize,
        /// Number of events.
        events: usize,
    },
    /// Event columns of different lengths.
    #[error(transparent)]
    Events(#[from] crate::estimator::EstimatorError),
}

/// Scorer settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScoreParams {
    /// Chebyshev radius, pixels, of the boundary test. Default 2 (the task's definition).
    pub boundary_radius_px: u16,
    /// Estimates with confidence at or below this are invalid. Default 0 (every estimate the
    /// estimator did not mark invalid).
    pub min_confidence: f32,
}

impl Default for ScoreParams {
    fn default() -> Self {
        Self {
            boundary_radius_px: 2,
            min_confidence: 0.0,
        }
    }
}

/// The metrics of one set of events (see the module docs for the definitions).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct RegionScore {
    /// Events in the set (inside the sensor).
    pub events: u64,
    /// Events with a valid estimate.
    pub valid: u64,
    /// `valid / events` (0 when there is no event).
    pub coverage: f64,
    /// Valid events with a non-zero true flow (the scored ones).
    pub scored: u64,
    /// Share of scored events with `p . u > 0` (NaN when none is scored; serialized as null).
    pub sign_correct_rate: f64,
    /// Median magnitude error, normalized units per second.
    pub magnitude_error_median: f64,
    /// Mean magnitude error, normalized units per second.
    pub magnitude_error_mean: f64,
    /// Median of magnitude error / |u|.
    pub relative_magnitude_error_median: f64,
    /// Median circle angle error, degrees.
    pub circle_angle_error_deg_median: f64,
    /// Mean circle angle error, degrees.
    pub circle_angle_error_deg_mean: f64,
}

impl RegionScore {
    /// The figures on one line, for logs and examples.
    pub fn summary_line(&self) -> String {
        format!(
            "events {:>8}  coverage {:.3}  sign-correct {:.4}  circle angle median {:.2} deg mean {:.2} deg  \
             magnitude error median {:.4} (relative {:.3})",
            self.events,
            self.coverage,
            self.sign_correct_rate,
            self.circle_angle_error_deg_median,
            self.circle_angle_error_deg_mean,
            self.magnitude_error_median,
            self.relative_magnitude_error_median
        )
    }
}

/// Scores of all events and of the boundary / interior split.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Score {
    /// Every event.
    pub all: RegionScore,
    /// Events at object boundaries.
    pub boundary: RegionScore,
    /// The other events.
    pub interior: RegionScore,
    /// Events ignored because they lie outside the sensor.
    pub out_of_sensor: u64,
    /// Events ignored because the truth has no flow for them (truth arrays empty).
    pub no_truth: u64,
}

/// The per-event errors of one valid event with non-zero true flow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EventErrors {
    /// `p . u > 0`.
    pub sign_correct: bool,
    /// `| |p| - u . n0 |`, same units as the inputs.
    pub magnitude_error: f64,
    /// Magnitude error / |u|.
    pub relative_magnitude_error: f64,
    /// Circle angle error, degrees.
    pub circle_angle_error_deg: f64,
}

/// The errors of estimate `p` against true flow `u` (any consistent units); `None` when `p` or
/// `u` is zero or not finite.
pub fn event_errors(p: [f64; 2], u: [f64; 2]) -> Option<EventErrors> {
    let np = p[0].hypot(p[1]);
    let nu = u[0].hypot(u[1]);
    if !(np > 0.0 && nu > 0.0 && np.is_finite() && nu.is_finite()) {
        return None;
    }
    let un = (u[0] * p[0] + u[1] * p[1]) / np;
    let magnitude_error = (np - un).abs();
    let c = [u[0] / 2.0, u[1] / 2.0];
    let d = [p[0] - c[0], p[1] - c[1]];
    let nd = d[0].hypot(d[1]);
    let nearest = if nd > 1e-12 * nu {
        [c[0] + 0.5 * nu * d[0] / nd, c[1] + 0.5 * nu * d[1] / nd]
    } else {
        u
    };
    let nn = nearest[0].hypot(nearest[1]);
    let circle_angle_error_deg = if nn > 1e-9 * nu {
        let dot = p[0] * nearest[0] + p[1] * nearest[1];
        let cross = p[0] * nearest[1] - p[1] * nearest[0];
        cross.abs().atan2(dot).to_degrees()
    } else {
        90.0
    };
    Some(EventErrors {
        sign_correct: un > 0.0,
        magnitude_error,
        relative_magnitude_error: magnitude_error / nu,
        circle_angle_error_deg,
    })
}

#[derive(Debug, Clone, Default)]
struct Accumulator {
    events: u64,
    valid: u64,
    sign_correct: u64,
    magnitude: Vec<f64>,
    relative: Vec<f64>,
    angle: Vec<f64>,
}

impl Accumulator {
    fn add(&mut self, valid: bool, errors: Option<EventErrors>) {
        self.events += 1;
        self.valid += u64::from(valid);
        if let Some(e) = errors {
            self.sign_correct += u64::from(e.sign_correct);
            self.magnitude.push(e.magnitude_error);
            self.relative.push(e.relative_magnitude_error);
            self.angle.push(e.circle_angle_error_deg);
        }
    }

    fn merge(&mut self, other: &Self) {
        self.events += other.events;
        self.valid += other.valid;
        self.sign_correct += other.sign_correct;
        self.magnitude.extend_from_slice(&other.magnitude);
        self.relative.extend_from_slice(&other.relative);
        self.angle.extend_from_slice(&other.angle);
    }

    fn summary(&self) -> RegionScore {
        let scored = self.magnitude.len() as u64;
        RegionScore {
            events: self.events,
            valid: self.valid,
            coverage: if self.events > 0 {
                self.valid as f64 / self.events as f64
            } else {
                0.0
            },
            scored,
            sign_correct_rate: if scored > 0 {
                self.sign_correct as f64 / scored as f64
            } else {
                f64::NAN
            },
            magnitude_error_median: median(&self.magnitude),
            magnitude_error_mean: mean(&self.magnitude),
            relative_magnitude_error_median: median(&self.relative),
            circle_angle_error_deg_median: median(&self.angle),
            circle_angle_error_deg_mean: mean(&self.angle),
        }
    }
}

fn mean(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.iter().sum::<f64>() / v.len() as f64
}

fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    let mid = s.len() / 2;
    let (_, m, _) = s.select_nth_unstable_by(mid, f64::total_cmp);
    let m = *m;
    if s.len() % 2 == 1 {
        m
    } else {
        let lower = s[..mid].iter().copied().fold(f64::NEG_INFINITY, f64::max);
        (lower + m) / 2.0
    }
}

/// Accumulates scores slice by slice; [`Scorer::summary`] gives the whole run's.
#[derive(Debug, Clone)]
pub struct Scorer {
    params: ScoreParams,
    width: usize,
    height: usize,
    jacobian: Vec<[f32; 4]>,
    /// Object id per pixel of the current slice: `EMPTY`, an id, or `MIXED`.
    ids: Vec<u32>,
    /// [all, boundary, interior] over the run.
    run: [Accumulator; 3],
    out_of_sensor: u64,
    no_truth: u64,
}

const EMPTY: u32 = u32::MAX;
const MIXED: u32 = u32::MAX - 1;

impl Scorer {
    /// A scorer for `camera` (true pixel flow converted with its Jacobian).
    pub fn new(camera: &CameraInfo, params: ScoreParams) -> Self {
        let (width, height) = (camera.width as usize, camera.height as usize);
        Self {
            params,
            width,
            height,
            jacobian: jacobian_table(camera),
            ids: vec![EMPTY; width * height],
            run: Default::default(),
            out_of_sensor: 0,
            no_truth: 0,
        }
    }

    /// Scores one slice (`flow` and `truth` aligned with `events`), adds it to the run and
    /// returns the slice's own score. Truth without per-event flow counts every event as
    /// `no_truth`; truth without object ids puts every event in the interior.
    pub fn add_slice(
        &mut self,
        events: &Events,
        flow: &NormalFlow,
        truth: &Truth,
    ) -> Result<Score, ScoreError> {
        check_columns(events)?;
        let n = events.len();
        for (what, got) in [
            ("flow.nx", flow.nx.len()),
            ("flow.ny", flow.ny.len()),
            ("flow.confidence", flow.confidence.len()),
        ] {
            if got != n {
                return Err(ScoreError::Length { what, got, events: n });
            }
        }
        let has_flow = !(truth.flow_x.is_empty() && truth.flow_y.is_empty());
        if has_flow {
            for (what, got) in [
                ("truth.flow_x", truth.flow_x.len()),
                ("truth.flow_y", truth.flow_y.len()),
            ] {
                if got != n {
                    return Err(ScoreError::Length { what, got, events: n });
                }
            }
        }
        let has_ids = !truth.event_object.is_empty();
        if has_ids && truth.event_object.len() != n {
            return Err(ScoreError::Length {
                what: "truth.event_object",
                got: truth.event_object.len(),
                events: n,
            });
        }
        let inside = |i: usize| (events.x[i] as usize) < self.width && (events.y[i] as usize) < self.height;
        if has_ids {
            for i in (0..n).filter(|&i| inside(i)) {
                let idx = events.y[i] as usize * self.width + events.x[i] as usize;
                let id = u32::from(truth.event_object[i]);
                let cell = &mut self.ids[idx];
                *cell = if *cell == EMPTY || *cell == id { id } else { MIXED };
            }
        }
        let mut slice: [Accumulator; 3] = Default::default();
        let mut out_of_sensor = 0;
        let mut no_truth = 0;
        let r = self.params.boundary_radius_px as usize;
        for i in 0..n {
            if !inside(i) {
                out_of_sensor += 1;
                continue;
            }
            if !has_flow {
                no_truth += 1;
                continue;
            }
            let (x, y) = (events.x[i] as usize, events.y[i] as usize);
            let idx = y * self.width + x;
            let boundary = has_ids && self.is_boundary(x, y, u32::from(truth.event_object[i]), r);
            let valid = flow.confidence[i] > self.params.min_confidence;
            let errors = if valid {
                let [j00, j01, j10, j11] = self.jacobian[idx];
                let (fu, fv) = (truth.flow_x[i], truth.flow_y[i]);
                let u = [f64::from(j00 * fu + j01 * fv), f64::from(j10 * fu + j11 * fv)];
                event_errors([f64::from(flow.nx[i]), f64::from(flow.ny[i])], u)
            } else {
                None
            };
            slice[0].add(valid, errors);
            slice[if boundary { 1 } else { 2 }].add(valid, errors);
        }
        if has_ids {
            for i in (0..n).filter(|&i| inside(i)) {
                self.ids[events.y[i] as usize * self.width + events.x[i] as usize] = EMPTY;
            }
        }
        for (run, s) in self.run.iter_mut().zip(&slice) {
            run.merge(s);
        }
        self.out_of_sensor += out_of_sensor;
        self.no_truth += no_truth;
        Ok(Score {
            all: slice[0].summary(),
            boundary: slice[1].summary(),
            interior: slice[2].summary(),
            out_of_sensor,
            no_truth,
        })
    }

    fn is_boundary(&self, x: usize, y: usize, id: u32, r: usize) -> bool {
        let (x0, x1) = (x.saturating_sub(r), (x + r).min(self.width - 1));
        let (y0, y1) = (y.saturating_sub(r), (y + r).min(self.height - 1));
        (y0..=y1).any(|yy| {
            self.ids[yy * self.width + x0..=yy * self.width + x1]
                .iter()
                .any(|&c| c != EMPTY && c != id)
        })
    }

    /// The score of every slice added so far.
    pub fn summary(&self) -> Score {
        Score {
            all: self.run[0].summary(),
            boundary: self.run[1].summary(),
            interior: self.run[2].summary(),
            out_of_sensor: self.out_of_sensor,
            no_truth: self.no_truth,
        }
    }
}
