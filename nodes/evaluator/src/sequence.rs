//! Accumulating slice figures into per-sequence figures.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::matching::ObjectMatch;
use crate::outcome::{Outcome, Skip};
use crate::slice_eval::SliceReport;

/// How the m/s egomotion figures are scaled (written into every report).
pub const VELOCITY_SCALING_NOTE: &str = "Only the direction of translation is observable from normal flow: \
the predicted unit direction is multiplied by the ground-truth speed before the per-axis error is \
taken (the public EVIMO2 egomotion evaluation's convention and the paper's m/s figures). RMSE is over \
slices with a valid prediction and ground truth; the direction error skips slices slower than \
min_speed_mps.";

/// A mean over windows, with the count of windows skipped per reason.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct MeanSummary {
    /// Mean, or `None` when no window was scored.
    pub mean: Option<f64>,
    /// Windows scored.
    pub windows: u64,
    /// Windows skipped, by reason.
    pub skipped: BTreeMap<String, u64>,
}

/// Per-object IoU over a sequence.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectIouSummary {
    /// Ground-truth object id.
    pub object: u32,
    /// Mean IoU over the windows where the object is present (0 counted when unmatched).
    pub mean_iou: f64,
    /// Windows where the object is present.
    pub windows: u64,
    /// Of those, windows where a predicted label was matched to it.
    pub matched_windows: u64,
    /// Times the object's identity changed: the matched label (track id) of a window whose
    /// match has an IoU above the evaluator's `switch_min_iou` (0.5, MOTS) differs from the
    /// label of the previous such window (the "id switches"; windows without such a
    /// match in between do not count as a switch).
    pub id_switches: u64,
    /// Times the matched label changed from one matched window to the next, whatever the
    /// match's IoU (a small piece matched for want of a better one counts): the stricter count
    /// the evaluator reported as `id_switches` before 2026-12-06.
    pub id_switches_any_overlap: u64,
    /// Where the object's events went, over all its windows (shares of its events; the three
    /// shares sum to 1): labelled background.
    pub share_as_background: f64,
    /// Share of the object's events under the label matched to it in their window.
    pub share_in_match: f64,
    /// Share of the object's events under other labels (pieces, or joined to another object).
    pub share_in_other_labels: f64,
}

/// Distribution of the direction error, degrees.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DirectionSummary {
    /// Median, degrees.
    pub median_deg: Option<f64>,
    /// Mean, degrees.
    pub mean_deg: Option<f64>,
    /// Slices with a direction error.
    pub count: u64,
}

/// Egomotion figures over a sequence.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct EgomotionSummary {
    /// Slices scored (valid prediction and ground truth).
    pub windows: u64,
    /// Slices skipped, by reason (`no_prediction` = the method's `valid: false`).
    pub skipped: BTreeMap<String, u64>,
    /// Direction error.
    pub direction_error: DirectionSummary,
    /// Slices whose direction error was skipped, by reason.
    pub direction_skipped: BTreeMap<String, u64>,
    /// Per-axis RMSE of (predicted direction x true speed - true velocity), m/s, camera frame.
    pub rmse_mps: Option<[f64; 3]>,
    /// Mean true speed over the scored slices, m/s.
    pub mean_true_speed_mps: Option<f64>,
    /// How the figures are scaled.
    pub velocity_scaling: String,
}

/// Object image-plane motion figures over a sequence.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ObjectMotionSummary {
    /// (slice, object) pairs with ground-truth motion.
    pub samples: u64,
    /// Of those, pairs with a matched track (a prediction).
    pub with_prediction: u64,
    /// RMSE of the translational image motion in x and y, normalized image units per second.
    pub rmse_translational_flow: Option<[f64; 2]>,
    /// RMSE of the image velocity in x and y, pixels per second.
    pub rmse_image_velocity_px: Option<[f64; 2]>,
    /// Pairs skipped, by reason.
    pub skipped: BTreeMap<String, u64>,
}

/// Every per-sequence figure.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SequenceSummary {
    /// Sequence name (report row).
    pub sequence: String,
    /// Slices evaluated.
    pub windows: u64,
    /// Windows with a moving object in either ground truth.
    pub windows_with_moving_object: u64,
    /// Mean IoU against per-event ids over windows with a moving object.
    pub iou_events: MeanSummary,
    /// Mean IoU against the nearest mask over windows with a moving object (paper's protocol).
    pub iou_mask: MeanSummary,
    /// Per-object IoU after Hungarian matching.
    pub iou_per_object: Vec<ObjectIouSummary>,
    /// Mean of the per-object means.
    pub iou_per_object_mean: Option<f64>,
    /// Id switches of the object with the most ([`ObjectIouSummary::id_switches`], issue 5's
    /// target is at most one), `None` without objects.
    pub id_switches_worst_object: Option<u64>,
    /// The same over any overlap ([`ObjectIouSummary::id_switches_any_overlap`]).
    pub id_switches_any_overlap_worst_object: Option<u64>,
    /// Egomotion.
    pub egomotion: EgomotionSummary,
    /// Object motion.
    pub object_motion: ObjectMotionSummary,
    /// False alarms: the mean over windows whose ground truth has no moving object of the share
    /// of their events labelled moving.
    pub static_share_labelled_moving: MeanSummary,
}

#[derive(Debug, Default)]
struct MeanAcc {
    sum: f64,
    n: u64,
    skipped: BTreeMap<String, u64>,
}

impl MeanAcc {
    fn add<T>(&mut self, o: &Outcome<T>, value: impl Fn(&T) -> f64) {
        match o {
            Outcome::Scored(s) => {
                self.sum += value(s);
                self.n += 1;
            }
            Outcome::Skipped(s) => skip(&mut self.skipped, s),
        }
    }

    fn summary(&self) -> MeanSummary {
        MeanSummary {
            mean: (self.n > 0).then(|| self.sum / self.n as f64),
            windows: self.n,
            skipped: self.skipped.clone(),
        }
    }
}

fn skip(map: &mut BTreeMap<String, u64>, s: &Skip) {
    *map.entry(s.key().to_string()).or_default() += 1;
}

fn rmse<const N: usize>(sq: [f64; N], n: u64) -> Option<[f64; N]> {
    (n > 0).then(|| sq.map(|s| (s / n as f64).sqrt()))
}

/// One ground-truth object's figures so far (see [`ObjectIouSummary`]).
#[derive(Debug, Default)]
struct ObjectAcc {
    iou_sum: f64,
    windows: u64,
    matched_windows: u64,
    /// The label matched in the last matched window.
    last_label: Option<u32>,
    /// The label matched in the last window whose match passed `switch_min_iou`.
    last_identity: Option<u32>,
    id_switches: u64,
    id_switches_any_overlap: u64,
    /// The object's events, and of those: under the matched label, background, other labels.
    events: u64,
    in_match: u64,
    as_background: u64,
    in_other_labels: u64,
}

impl ObjectAcc {
    /// Adds the object's match in one window; a match with an IoU above `switch_min_iou` is
    /// the object's identity.
    fn add(&mut self, m: &ObjectMatch, switch_min_iou: f64) {
        self.iou_sum += m.iou;
        self.windows += 1;
        self.matched_windows += u64::from(m.label.is_some());
        if let Some(l) = m.label {
            if self.last_label.is_some_and(|prev| prev != l) {
                self.id_switches_any_overlap += 1;
            }
            self.last_label = Some(l);
            if m.iou > switch_min_iou {
                if self.last_identity.is_some_and(|prev| prev != l) {
                    self.id_switches += 1;
                }
                self.last_identity = Some(l);
            }
        }
        self.events += m.truth_events;
        self.in_match += m.intersection;
        self.as_background += m.as_background;
        self.in_other_labels += m.in_other_labels;
    }
}

/// Adds slice reports one at a time. Made with [`SequenceAccumulator::new`]; `default()` counts
/// every match as the object's identity (`switch_min_iou` 0).
#[derive(Debug, Default)]
pub struct SequenceAccumulator {
    /// IoU above which a match is the object's identity (`EvalParams::switch_min_iou`).
    switch_min_iou: f64,
    windows: u64,
    moving: u64,
    iou_events: MeanAcc,
    iou_mask: MeanAcc,
    per_object: BTreeMap<u32, ObjectAcc>,
    ego_n: u64,
    ego_skipped: BTreeMap<String, u64>,
    ego_sq: [f64; 3],
    speed_sum: f64,
    directions: Vec<f64>,
    direction_skipped: BTreeMap<String, u64>,
    obj_samples: u64,
    obj_pred: u64,
    obj_sq_flow: [f64; 2],
    obj_sq_img: [f64; 2],
    obj_skipped: BTreeMap<String, u64>,
    static_scene: MeanAcc,
}

impl SequenceAccumulator {
    /// An empty accumulator; a match with an IoU above `switch_min_iou` is the object's identity
    /// for the id switches (`EvalParams::switch_min_iou`).
    pub fn new(switch_min_iou: f64) -> Self {
        Self {
            switch_min_iou,
            ..Self::default()
        }
    }

    /// Adds one slice.
    pub fn add(&mut self, r: &SliceReport) {
        self.windows += 1;
        self.moving += r.has_moving_object() as u64;
        self.iou_events.add(&r.iou_events, |s| s.iou);
        self.iou_mask.add(&r.iou_mask, |s| s.iou);
        self.static_scene
            .add(&r.static_scene, |s| s.share_labelled_moving);
        if let Outcome::Scored(o) = &r.objects {
            for m in &o.matches {
                self.per_object
                    .entry(m.object as u32)
                    .or_default()
                    .add(m, self.switch_min_iou);
            }
        }
        match &r.egomotion {
            Outcome::Scored(e) => {
                self.ego_n += 1;
                self.speed_sum += e.true_speed_mps;
                for k in 0..3 {
                    self.ego_sq[k] += e.scaled_error_mps[k].powi(2);
                }
                match &e.direction_error_deg {
                    Outcome::Scored(d) => self.directions.push(*d),
                    Outcome::Skipped(s) => skip(&mut self.direction_skipped, s),
                }
            }
            Outcome::Skipped(s) => skip(&mut self.ego_skipped, s),
        }
        for o in &r.object_motion {
            match o {
                Outcome::Scored(s) => {
                    self.obj_samples += 1;
                    if s.has_prediction() {
                        self.obj_pred += 1;
                        for k in 0..2 {
                            self.obj_sq_flow[k] += s.translational_flow_error[k].powi(2);
                            self.obj_sq_img[k] += s.image_velocity_error_px[k].powi(2);
                        }
                    }
                }
                Outcome::Skipped(s) => skip(&mut self.obj_skipped, s),
            }
        }
    }

    /// The per-sequence figures, rows named `sequence`.
    pub fn summary(&self, sequence: &str) -> SequenceSummary {
        let iou_per_object: Vec<ObjectIouSummary> = self
            .per_object
            .iter()
            .map(|(&object, a)| {
                let share = |n: u64| {
                    if a.events == 0 {
                        0.0
                    } else {
                        n as f64 / a.events as f64
                    }
                };
                ObjectIouSummary {
                    object,
                    mean_iou: a.iou_sum / a.windows as f64,
                    windows: a.windows,
                    matched_windows: a.matched_windows,
                    id_switches: a.id_switches,
                    id_switches_any_overlap: a.id_switches_any_overlap,
                    share_in_match: share(a.in_match),
                    share_as_background: share(a.as_background),
                    share_in_other_labels: share(a.in_other_labels),
                }
            })
            .collect();
        let iou_per_object_mean = (!iou_per_object.is_empty())
            .then(|| iou_per_object.iter().map(|o| o.mean_iou).sum::<f64>() / iou_per_object.len() as f64);
        let id_switches_worst_object = iou_per_object.iter().map(|o| o.id_switches).max();
        let id_switches_any_overlap_worst_object =
            iou_per_object.iter().map(|o| o.id_switches_any_overlap).max();
        let mut dirs = self.directions.clone();
        dirs.sort_by(f64::total_cmp);
        let median = (!dirs.is_empty()).then(|| {
            let n = dirs.len();
            if n % 2 == 1 {
                dirs[n / 2]
            } else {
                0.5 * (dirs[n / 2 - 1] + dirs[n / 2])
            }
        });
        SequenceSummary {
            sequence: sequence.to_string(),
            windows: self.windows,
            windows_with_moving_object: self.moving,
            iou_events: self.iou_events.summary(),
            iou_mask: self.iou_mask.summary(),
            iou_per_object,
            iou_per_object_mean,
            id_switches_worst_object,
            id_switches_any_overlap_worst_object,
            egomotion: EgomotionSummary {
                windows: self.ego_n,
                skipped: self.ego_skipped.clone(),
                direction_error: DirectionSummary {
                    median_deg: median,
                    mean_deg: (!dirs.is_empty()).then(|| dirs.iter().sum::<f64>() / dirs.len() as f64),
                    count: dirs.len() as u64,
                },
                direction_skipped: self.direction_skipped.clone(),
                rmse_mps: rmse(self.ego_sq, self.ego_n),
                mean_true_speed_mps: (self.ego_n > 0).then(|| self.speed_sum / self.ego_n as f64),
                velocity_scaling: VELOCITY_SCALING_NOTE.to_string(),
            },
            object_motion: ObjectMotionSummary {
                samples: self.obj_samples,
                with_prediction: self.obj_pred,
                rmse_translational_flow: rmse(self.obj_sq_flow, self.obj_pred),
                rmse_image_velocity_px: rmse(self.obj_sq_img, self.obj_pred),
                skipped: self.obj_skipped.clone(),
            },
            static_share_labelled_moving: self.static_scene.summary(),
        }
    }
}
