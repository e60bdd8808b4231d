//! `report.json`: every figure, per slice and per sequence, with units and conventions.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::params::EvalParams;
use crate::sequence::{SequenceSummary, VELOCITY_SCALING_NOTE};
use crate::slice_eval::SliceReport;

/// What the figures mean and in which units (written at the top of `report.json`).
pub fn units() -> BTreeMap<&'static str, &'static str> {
    BTreeMap::from([
        ("time", "seconds on the sequence clock"),
        ("iou", "fraction in [0, 1] over events (moving = label/id != 0)"),
        ("velocity", "m/s, camera frame (x right, y down, z forward)"),
        (
            "direction_error",
            "degrees between predicted direction and true velocity",
        ),
        (
            "translational_flow",
            "normalized image units per second (focal length 1): (1/Z) A(x) (-v) true, A(x) t_track predicted",
        ),
        (
            "image_velocity",
            "pixels per second (pinhole focal lengths, distortion Jacobian ignored)",
        ),
        (
            "null",
            "not available (skipped or no prediction); never substituted",
        ),
    ])
}

/// The document written to `report.json`.
#[derive(Debug, Serialize)]
pub struct ReportJson<'a> {
    /// Producer.
    pub generator: &'static str,
    /// Units of every figure.
    pub units: BTreeMap<&'static str, &'static str>,
    /// How the m/s egomotion figures are scaled.
    pub velocity_scaling: &'static str,
    /// How predicted labels are matched to objects.
    pub matching: &'static str,
    /// Settings used.
    pub params: &'a EvalParams,
    /// Per-sequence figures.
    pub sequence: &'a SequenceSummary,
    /// Per-slice figures.
    pub slices: &'a [SliceReport],
}

/// `report.json` text (pretty). Non-finite numbers are written as `null`.
pub fn report_json(
    summary: &SequenceSummary,
    slices: &[SliceReport],
    params: &EvalParams,
) -> Result<String, serde_json::Error> {
    serde_json::to_string_pretty(&ReportJson {
        generator: concat!("evseg-evaluator ", env!("CARGO_PKG_VERSION")),
        units: units(),
        velocity_scaling: VELOCITY_SCALING_NOTE,
        matching: "Hungarian: one-to-one assignment of predicted labels to ground-truth objects maximising \
                   summed IoU; pairs with IoU 0 are not matches; an unmatched object scores 0",
        params,
        sequence: summary,
        slices,
    })
}
