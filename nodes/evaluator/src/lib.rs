//! Scoring a segmentation / tracking result against ground truth, and the report folder.
//!
//! Per slice (see [`slice_eval::SliceReport`]):
//! - (a) **IoU per event** against the source's per-event object ids (simulator): predicted
//!   moving = label != 0, truly moving = id != 0; only windows with a moving object count.
//! - (b) **IoU against the nearest mask** (the paper's protocol, all that EVIMO2 offers): the
//!   mask nearest to the window's midpoint; events within half a mask period of its time are
//!   looked up at their pixel.
//! - (c) **Per-object IoU** after Hungarian matching of predicted labels to ground-truth objects
//!   (per-event ids when present, else the mask form).
//! - (d) **Egomotion**: true camera velocity (camera frame, m/s) from velocity samples or poses;
//!   direction error in degrees; per-axis error of the direction scaled by the true speed
//!   ([`sequence::VELOCITY_SCALING_NOTE`]).
//! - (e) **Object image-plane motion** at the object's origin from its relative twist, against
//!   the matched track ([`objects`] documents units and conventions).
//!
//! Per sequence ([`sequence::SequenceSummary`]): means, per-object IoU, median and mean
//! direction error, per-axis RMSE, counts of windows evaluated and skipped by reason.
//!
//! [`Evaluator`] takes slices in time order. Because a slice's `Truth` carries only the items
//! stamped inside its own window, a slice is scored once ground truth up to `lookahead_s` past its
//! end has arrived (or at [`Evaluator::finish`]).

#![deny(missing_docs)]

pub mod egomotion;
pub mod error;
pub mod frames;
pub mod history;
pub mod iou;
pub mod matching;
pub mod objects;
pub mod outcome;
pub mod params;
pub mod report;
pub mod sequence;
pub mod slice_eval;

use std::collections::VecDeque;

use evseg_schemas::{Slice, Tracks, Truth};

pub use error::EvalError;
pub use frames::{FrameReservoir, FrameSnapshot};
pub use outcome::{Outcome, Skip};
pub use params::EvalParams;
pub use sequence::{SequenceAccumulator, SequenceSummary};
pub use slice_eval::{PendingSlice, SliceReport, evaluate_slice};

/// One slice to score: the slice, its ground truth and the result, with the window from the
/// slice's envelope.
#[derive(Debug, Clone, Copy)]
pub struct SliceInput<'a> {
    /// Slice number.
    pub seq: u64,
    /// Window start, seconds.
    pub t_start: f64,
    /// Window end (exclusive), seconds.
    pub t_end: f64,
    /// The slice (events, camera).
    pub slice: &'a Slice,
    /// Its ground truth.
    pub truth: &'a Truth,
    /// The result to score (labels aligned with the slice's events).
    pub result: &'a Tracks,
}

/// Scores a stream of slices of one sequence.
#[derive(Debug)]
pub struct Evaluator {
    params: EvalParams,
    history: history::TruthHistory,
    pending: VecDeque<PendingSlice>,
    last_end: Option<f64>,
    accumulator: SequenceAccumulator,
    frames: FrameReservoir,
    reports: Vec<SliceReport>,
}

impl Evaluator {
    /// An evaluator with `params` (checked).
    pub fn new(params: EvalParams) -> Result<Self, EvalError> {
        params.validate()?;
        Ok(Self {
            frames: FrameReservoir::new(params.frames_in_plot),
            accumulator: SequenceAccumulator::new(params.switch_min_iou),
            params,
            history: Default::default(),
            pending: VecDeque::new(),
            last_end: None,
            reports: Vec::new(),
        })
    }

    /// Adds a slice; returns the reports of every slice that could be scored now (earlier
    /// slices whose look-ahead is covered), in order. Malformed input is an error and leaves
    /// the evaluator unchanged.
    pub fn push(&mut self, input: SliceInput<'_>) -> Result<Vec<SliceReport>, EvalError> {
        let SliceInput {
            seq,
            t_start,
            t_end,
            slice,
            truth,
            result,
        } = input;
        if !(t_start.is_finite() && t_end.is_finite() && t_end > t_start) {
            return Err(EvalError::Window { seq, t_start, t_end });
        }
        if let Some(prev_end) = self.last_end
            && t_start < prev_end - 1e-9
        {
            return Err(EvalError::OutOfOrder {
                seq,
                t_start,
                prev_end,
            });
        }
        let n = slice.events.len();
        if !slice.events.is_consistent() {
            return Err(EvalError::EventColumns { seq });
        }
        if result.label.len() != n {
            return Err(EvalError::LabelLength {
                seq,
                labels: result.label.len(),
                events: n,
            });
        }
        if !truth.event_object.is_empty() && truth.event_object.len() != n {
            return Err(EvalError::TruthLength {
                seq,
                ids: truth.event_object.len(),
                events: n,
            });
        }
        self.history.add(seq, truth)?;
        self.last_end = Some(t_end);
        self.pending.push_back(PendingSlice {
            seq,
            t_start,
            t_end,
            width: slice.camera.width,
            height: slice.camera.height,
            focal_px: (slice.camera.fx, slice.camera.fy),
            events: slice.events.clone(),
            event_object: truth.event_object.clone(),
            result: result.clone(),
        });
        let mut out = Vec::new();
        while self
            .pending
            .front()
            .is_some_and(|p| p.t_end + self.params.lookahead_s <= t_end)
        {
            if let Some(p) = self.pending.pop_front() {
                out.push(self.score(&p)?);
            }
        }
        let oldest = self.pending.front().map_or(t_end, |p| p.t_start);
        self.history.prune_before(oldest - self.params.lookahead_s);
        Ok(out)
    }

    /// Scores every slice still waiting (end of the stream) and returns their reports.
    pub fn finish(&mut self) -> Result<Vec<SliceReport>, EvalError> {
        let mut out = Vec::new();
        while let Some(p) = self.pending.pop_front() {
            out.push(self.score(&p)?);
        }
        Ok(out)
    }

    fn score(&mut self, p: &PendingSlice) -> Result<SliceReport, EvalError> {
        let (report, truth_ids) = evaluate_slice(p, &self.history, &self.params)?;
        if let Some(ids) = truth_ids {
            let pixels = p.width as usize * p.height as usize;
            let snap = (self.frames.wants_next() && pixels > 0 && pixels <= self.params.max_snapshot_pixels)
                .then(|| {
                    let iou = report
                        .iou_events
                        .scored()
                        .map(|s| s.iou)
                        .or(report.iou_mask.scored().map(|s| s.iou));
                    let mut s = FrameSnapshot::new(
                        p.seq,
                        (p.t_start, p.t_end),
                        (p.width, p.height),
                        (&p.events.x, &p.events.y),
                        &p.result.label,
                        &ids,
                        iou,
                    );
                    if let Some(o) = report.objects.scored() {
                        s.matches = o
                            .matches
                            .iter()
                            .filter_map(|m| m.label.map(|l| (l, m.object)))
                            .collect();
                    }
                    s
                });
            self.frames.offer(snap);
        }
        self.accumulator.add(&report);
        self.reports.push(report.clone());
        Ok(report)
    }

    /// Reports of every slice scored so far, in order.
    pub fn reports(&self) -> &[SliceReport] {
        &self.reports
    }

    /// The per-sequence figures so far, with rows named `sequence`.
    pub fn summary(&self, sequence: &str) -> SequenceSummary {
        self.accumulator.summary(sequence)
    }

    /// Up to `n` kept frame snapshots, evenly spread over the slices with a moving object.
    pub fn frames(&self, n: usize) -> Vec<&FrameSnapshot> {
        self.frames.select(n)
    }

    /// The settings.
    pub fn params(&self) -> &EvalParams {
        &self.params
    }
}

#[cfg(test)]
mod tests;
