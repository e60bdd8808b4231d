//! Scoring one slice against the ground truth gathered around it.

use evseg_schemas::{Events, Metric, Metrics, Tracks};
use serde::Serialize;

use crate::egomotion::{
    EgomotionScore, InterpolationGap, TrueVelocity, score_egomotion, true_camera_velocity,
};
use crate::error::EvalError;
use crate::history::TruthHistory;
use crate::iou::{self, IouCounts, MaskLookup};
use crate::matching::{ObjectMatch, match_objects};
use crate::objects::{ObjectMotionScore, object_twist, score_object_motion};
use crate::outcome::{Outcome, Skip};
use crate::params::EvalParams;

/// A slice waiting for evaluation: what is needed of its `Slice`, `Truth` and result.
#[derive(Debug, Clone, PartialEq)]
pub struct PendingSlice {
    /// Slice number.
    pub seq: u64,
    /// Window start, seconds.
    pub t_start: f64,
    /// Window end (exclusive), seconds.
    pub t_end: f64,
    /// Sensor width, pixels.
    pub width: u16,
    /// Sensor height, pixels.
    pub height: u16,
    /// Focal lengths `(fx, fy)`, pixels.
    pub focal_px: (f64, f64),
    /// The slice's events.
    pub events: Events,
    /// Ground-truth object id per event (empty when the source has none).
    pub event_object: Vec<u16>,
    /// The result being scored (labels aligned with `events`).
    pub result: Tracks,
}

/// IoU of one slice with its counts.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IouScore {
    /// IoU in [0, 1].
    pub iou: f64,
    /// Event counts.
    pub counts: IouCounts,
}

/// IoU of one slice under the mask protocol.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaskIouScore {
    /// IoU in [0, 1].
    pub iou: f64,
    /// Event counts (over the evaluated events only).
    pub counts: IouCounts,
    /// Time of the mask used, seconds.
    pub mask_t: f64,
    /// Mask period used, seconds (events within half of it of `mask_t` are evaluated).
    pub mask_period_s: f64,
    /// Events evaluated.
    pub events_evaluated: u64,
}

/// Which ground truth the per-object figures used.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectTruth {
    /// Per-event object ids of the source (all events).
    PerEvent,
    /// The nearest mask, events within half a mask period of it.
    Mask,
}

/// Per-object IoU of one slice.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectsScore {
    /// The ground truth used.
    pub truth: ObjectTruth,
    /// One entry per ground-truth object present, in id order.
    pub matches: Vec<ObjectMatch>,
}

/// False alarms of a window whose ground truth has no moving object: how much of the static
/// scene the method calls moving.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StaticScore {
    /// Share of the evaluated events with a non-background label, 0..1.
    pub share_labelled_moving: f64,
    /// Events with ground truth in the window (all of them with per-event ids; those near the
    /// mask with masks).
    pub events_evaluated: u64,
    /// Of those, events with a non-background label.
    pub labelled_moving: u64,
    /// Which ground truth said the window is static.
    pub truth: ObjectTruth,
}

/// Every figure of one slice.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SliceReport {
    /// Slice number.
    pub seq: u64,
    /// Window start, seconds.
    pub t_start: f64,
    /// Window end (exclusive), seconds.
    pub t_end: f64,
    /// Events in the slice.
    pub events: u64,
    /// (a) IoU against per-event ids.
    pub iou_events: Outcome<IouScore>,
    /// (b) IoU against the nearest mask (the paper's protocol).
    pub iou_mask: Outcome<MaskIouScore>,
    /// (c) Per-object IoU after Hungarian matching.
    pub objects: Outcome<ObjectsScore>,
    /// True camera velocity of the window, whether or not the result has an egomotion.
    pub camera_truth: Outcome<TrueVelocity>,
    /// (d) Egomotion.
    pub egomotion: Outcome<EgomotionScore>,
    /// (e) Object image-plane motion, one entry per matched-or-not ground-truth object.
    pub object_motion: Vec<Outcome<ObjectMotionScore>>,
    /// (f) False alarms, in windows whose ground truth has no moving object.
    pub static_scene: Outcome<StaticScore>,
}

/// Ground-truth id per event as used for the frame plot.
pub type TruthIds = Vec<u16>;
/// Marker in [`TruthIds`] for an event without ground truth (outside the mask's time).
pub const UNKNOWN_ID: u16 = u16::MAX;

/// Scores `p` with the ground truth in `history`. Also returns the ground-truth id of every
/// event ([`UNKNOWN_ID`] where there is none) when the window has a moving object.
pub fn evaluate_slice(
    p: &PendingSlice,
    history: &TruthHistory,
    params: &EvalParams,
) -> Result<(SliceReport, Option<TruthIds>), EvalError> {
    let labels = &p.result.label;
    let has_ids = !p.event_object.is_empty();
    let iou_events = if !has_ids {
        Outcome::Skipped(Skip::NoPerEventTruth)
    } else {
        let c = iou::event_iou(p.seq, labels, &p.event_object)?;
        match (c.truth > 0, c.iou()) {
            (true, Some(v)) => Outcome::Scored(IouScore { iou: v, counts: c }),
            _ => Outcome::Skipped(Skip::NoMovingObject),
        }
    };

    let mid = 0.5 * (p.t_start + p.t_end);
    let period = history.mask_period(params.default_mask_period_s);
    let lookup: Result<MaskLookup, Skip> = match iou::nearest_mask(history.masks(), mid) {
        None => Err(Skip::NoMask),
        Some(mask) => {
            let l = iou::mask_lookup(p.seq, &p.events, mask, period)?;
            if l.events.is_empty() {
                Err(Skip::NoEventsNearMask { mask_t: mask.t })
            } else {
                Ok(l)
            }
        }
    };
    let iou_mask = match &lookup {
        Err(s) => Outcome::Skipped(s.clone()),
        Ok(l) => {
            let c = iou::mask_iou(labels, l);
            match (c.truth > 0, c.iou()) {
                (true, Some(v)) => Outcome::Scored(MaskIouScore {
                    iou: v,
                    counts: c,
                    mask_t: l.mask_t,
                    mask_period_s: period,
                    events_evaluated: l.events.len() as u64,
                }),
                _ => Outcome::Skipped(Skip::NoMovingObject),
            }
        }
    };

    // Ground truth per event for the per-object figures and the frame plot.
    let (truth_ids, object_truth): (Option<TruthIds>, Option<ObjectTruth>) = if has_ids {
        (Some(p.event_object.clone()), Some(ObjectTruth::PerEvent))
    } else if let Ok(l) = &lookup {
        let mut ids = vec![UNKNOWN_ID; p.events.len()];
        for (&i, &id) in l.events.iter().zip(&l.ids) {
            ids[i] = id;
        }
        (Some(ids), Some(ObjectTruth::Mask))
    } else {
        (None, None)
    };
    // Why a figure that needs ground truth per event has none for this window.
    let no_truth = || lookup.as_ref().err().cloned().unwrap_or(Skip::NoPerEventTruth);
    let objects = match (&truth_ids, object_truth) {
        (Some(ids), Some(kind)) => {
            let pairs = labels
                .iter()
                .zip(ids)
                .filter(|(_, id)| **id != UNKNOWN_ID)
                .map(|(&l, &id)| (l, id));
            let matches = match_objects(pairs);
            if matches.is_empty() {
                Outcome::Skipped(Skip::NoMovingObject)
            } else {
                Outcome::Scored(ObjectsScore { truth: kind, matches })
            }
        }
        _ => Outcome::Skipped(no_truth()),
    };

    let truth_v = true_camera_velocity(history.camera(), p.t_start, p.t_end, params.max_gap_s);
    let camera_truth: Outcome<TrueVelocity> = truth_v.clone().into();
    let egomotion = score_egomotion(p.seq, &p.result.egomotion, truth_v, params.min_speed_mps)?;

    let mut object_motion = Vec::new();
    if let Outcome::Scored(o) = &objects {
        for m in &o.matches {
            let id = m.object as u32;
            let poses = history.object_poses(id);
            let outcome = match object_twist(poses, p.t_start, p.t_end, params.max_gap_s) {
                Err(InterpolationGap::Missing) => Outcome::Skipped(Skip::NoObjectPoses { id }),
                Err(InterpolationGap::TooFar { t, gap_s }) => Outcome::Skipped(Skip::TruthGap { t, gap_s }),
                Ok(tw) => {
                    let track = m.label.and_then(|l| p.result.tracks.iter().find(|t| t.id == l));
                    score_object_motion(id, m.label, track, &tw, p.focal_px.0, p.focal_px.1).into()
                }
            };
            object_motion.push(outcome);
        }
    }

    let static_scene = match (&truth_ids, object_truth) {
        (Some(ids), Some(kind)) => static_score(labels, ids, kind),
        _ => Outcome::Skipped(no_truth()),
    };

    let moving = iou_events.scored().is_some()
        || iou_mask.scored().is_some()
        || truth_ids
            .as_ref()
            .is_some_and(|ids| ids.iter().any(|&i| i != 0 && i != UNKNOWN_ID));
    let report = SliceReport {
        seq: p.seq,
        t_start: p.t_start,
        t_end: p.t_end,
        events: p.events.len() as u64,
        iou_events,
        iou_mask,
        objects,
        camera_truth,
        egomotion,
        object_motion,
        static_scene,
    };
    Ok((report, truth_ids.filter(|_| moving)))
}

/// [`StaticScore`] of a window from its labels and ground-truth ids ([`UNKNOWN_ID`] = no truth
/// for that event): skipped when an event's truth is a moving object, or none has truth.
fn static_score(labels: &[u32], ids: &[u16], truth: ObjectTruth) -> Outcome<StaticScore> {
    let (mut evaluated, mut moving) = (0u64, 0u64);
    for (&label, &id) in labels.iter().zip(ids) {
        if id == UNKNOWN_ID {
            continue;
        }
        if id != 0 {
            return Outcome::Skipped(Skip::MovingObjectPresent);
        }
        evaluated += 1;
        moving += u64::from(label != 0);
    }
    if evaluated == 0 {
        return Outcome::Skipped(Skip::NoPerEventTruth);
    }
    Outcome::Scored(StaticScore {
        share_labelled_moving: moving as f64 / evaluated as f64,
        events_evaluated: evaluated,
        labelled_moving: moving,
        truth,
    })
}

fn metric(name: &str, value: f64) -> Metric {
    Metric {
        name: name.into(),
        value,
    }
}

impl SliceReport {
    /// True when the ground truth of the window has a moving-object event (either form).
    pub fn has_moving_object(&self) -> bool {
        self.iou_events.scored().is_some() || self.iou_mask.scored().is_some()
    }

    /// The per-slice figures as a `Metrics` message (NaN where a figure was skipped).
    pub fn metrics(&self) -> Metrics {
        let nan = f64::NAN;
        let mut v = vec![
            metric("events", self.events as f64),
            metric("iou_events", self.iou_events.scored().map_or(nan, |s| s.iou)),
            metric("iou_mask", self.iou_mask.scored().map_or(nan, |s| s.iou)),
        ];
        let obj = self.objects.scored().map(|o| {
            let n = o.matches.len() as f64;
            o.matches.iter().map(|m| m.iou).sum::<f64>() / n
        });
        v.push(metric("iou_per_object_mean", obj.unwrap_or(nan)));
        v.push(metric(
            "static_share_labelled_moving",
            self.static_scene
                .scored()
                .map_or(nan, |s| s.share_labelled_moving),
        ));
        let ego = self.egomotion.scored();
        v.push(metric(
            "direction_error_deg",
            ego.and_then(|e| e.direction_error_deg.scored().copied())
                .unwrap_or(nan),
        ));
        v.push(metric("true_speed_mps", ego.map_or(nan, |e| e.true_speed_mps)));
        for (k, axis) in ["x", "y", "z"].iter().enumerate() {
            v.push(metric(
                &format!("true_velocity_{axis}_mps"),
                ego.map_or(nan, |e| e.true_velocity_mps[k]),
            ));
            v.push(metric(
                &format!("scaled_velocity_{axis}_mps"),
                ego.map_or(nan, |e| e.scaled_velocity_mps[k]),
            ));
        }
        let scored: Vec<&ObjectMotionScore> = self
            .object_motion
            .iter()
            .filter_map(|o| o.scored())
            .filter(|s| s.has_prediction())
            .collect();
        for (k, axis) in ["x", "y"].iter().enumerate() {
            let rms = if scored.is_empty() {
                nan
            } else {
                let s: f64 = scored.iter().map(|s| s.translational_flow_error[k].powi(2)).sum();
                (s / scored.len() as f64).sqrt()
            };
            v.push(metric(&format!("object_flow_error_rms_{axis}_norm_per_s"), rms));
        }
        Metrics { values: v }
    }
}
