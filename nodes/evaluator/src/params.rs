//! Evaluation settings.

use serde::Serialize;

use crate::error::EvalError;

/// Settings of the evaluation. Every default says where it comes from.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EvalParams {
    /// Mask period assumed before two masks have been seen, seconds. Default 1/60 s: EVIMO2's
    /// ground-truth frames for the event cameras are at 60 Hz (METHOD_NOTES section 4).
    pub default_mask_period_s: f64,
    /// Largest distance between two ground-truth samples (poses, velocities) that may be
    /// interpolated, seconds. Default 0.1 s: 20 Vicon samples at 200 Hz, six mask frames at
    /// 60 Hz; longer gaps are the Vicon dropouts METHOD_NOTES section 4 warns about.
    pub max_gap_s: f64,
    /// How long after a slice's end its evaluation waits for ground truth carried by later
    /// slices (nearest mask, bracketing samples), seconds. Default 0.1 s, which must be at least
    /// `max_gap_s` and half a mask period.
    pub lookahead_s: f64,
    /// Camera speed below which the direction of translation is undefined and its angular error
    /// is skipped, m/s. Default 0.05 m/s: a 1 mm Vicon position noise over a 30 ms window is
    /// already 0.03 m/s of apparent velocity.
    pub min_speed_mps: f64,
    /// IoU above which a matched label counts as the object's identity for the id switches
    /// ([`crate::sequence::ObjectIouSummary::id_switches`]). Default 0.5, as MOTS (Voigtlaender
    /// et al., CVPR 2019): above it a label can match only one object and an object only one
    /// label, so a switch is a change of a confident match; a small piece that the assignment
    /// matches for want of anything better is a miss of the identity, not a new one. 0 counts
    /// every match (the summary's `id_switches_any_overlap` always does).
    pub switch_min_iou: f64,
    /// Frames kept for the report's frame plot. Default 4 (the `frames_in_plot` node parameter).
    pub frames_in_plot: usize,
    /// Largest sensor (width x height, pixels) for which frame snapshots are kept. Default
    /// 4 Mpx: above every event camera in use (EVIMO2's largest is 640 x 480) and 24 MB per kept
    /// frame at most.
    pub max_snapshot_pixels: usize,
}

impl Default for EvalParams {
    fn default() -> Self {
        Self {
            default_mask_period_s: 1.0 / 60.0,
            max_gap_s: 0.1,
            lookahead_s: 0.1,
            min_speed_mps: 0.05,
            switch_min_iou: 0.5,
            frames_in_plot: 4,
            max_snapshot_pixels: 4 << 20,
        }
    }
}

impl EvalParams {
    /// Checks ranges and consistency.
    pub fn validate(&self) -> Result<(), EvalError> {
        // Named as the node's parameters are, in milliseconds (`max_gap_ms=-1`, not `max_gap_s`).
        let pos = |name: &'static str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(EvalError::Param {
                    name,
                    reason: format!("must be a positive number of milliseconds, got {}", v * 1e3),
                })
            }
        };
        pos("default_mask_period_ms", self.default_mask_period_s)?;
        pos("max_gap_ms", self.max_gap_s)?;
        pos("lookahead_ms", self.lookahead_s)?;
        if self.lookahead_s < self.max_gap_s || self.lookahead_s < self.default_mask_period_s / 2.0 {
            return Err(EvalError::Param {
                name: "lookahead_ms",
                reason: format!(
                    "{} ms is shorter than max_gap_ms ({} ms) or half of default_mask_period_ms ({} ms)",
                    self.lookahead_s * 1e3,
                    self.max_gap_s * 1e3,
                    self.default_mask_period_s * 1e3 / 2.0
                ),
            });
        }
        if !(self.min_speed_mps.is_finite() && self.min_speed_mps >= 0.0) {
            return Err(EvalError::Param {
                name: "min_speed_mps",
                reason: format!("must be >= 0 m/s, got {}", self.min_speed_mps),
            });
        }
        if !(0.0..1.0).contains(&self.switch_min_iou) {
            return Err(EvalError::Param {
                name: "switch_min_iou",
                reason: format!("must be in [0, 1), got {}", self.switch_min_iou),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Times are reported as the node's `_ms` parameters, in milliseconds.
    #[test]
    fn time_errors_name_the_node_parameter_in_milliseconds() {
        let d = EvalParams::default();
        let e = EvalParams {
            max_gap_s: -1e-3,
            ..d.clone()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            "parameter max_gap_ms: must be a positive number of milliseconds, got -1"
        );
        let e = EvalParams {
            lookahead_s: 0.05,
            ..d
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(
            e.starts_with("parameter lookahead_ms: 50 ms is shorter than max_gap_ms (100 ms)"),
            "{e}"
        );
    }
}
