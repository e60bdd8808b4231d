//! A figure that was either computed or skipped, with the reason it was skipped.

use serde::Serialize;

/// Why a figure was not computed for a slice. Skips are counted per reason in the sequence
/// summary; a skipped figure never contributes a value.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Skip {
    /// The source gives no per-event object ids (EVIMO2 has masks only).
    NoPerEventTruth,
    /// The ground truth of the window contains no moving-object event.
    NoMovingObject,
    /// The ground truth of the window contains a moving-object event (for the figures of
    /// windows without one).
    MovingObjectPresent,
    /// No ground-truth mask has been received near the window.
    NoMask,
    /// No event of the window lies within half a mask period of the nearest mask.
    NoEventsNearMask {
        /// Time of the nearest mask, seconds.
        mask_t: f64,
    },
    /// The method gave no egomotion for this slice (`valid: false`).
    NoPrediction,
    /// No ground-truth camera motion brackets the window.
    NoCameraTruth,
    /// The ground-truth samples around time `t` are further apart than allowed.
    TruthGap {
        /// Time that needed interpolation, seconds.
        t: f64,
        /// Gap between the bracketing samples, seconds.
        gap_s: f64,
    },
    /// The camera moves slower than the threshold: the direction of translation is undefined.
    SlowCamera {
        /// True speed, m/s.
        speed_mps: f64,
    },
    /// No pose of this object brackets the window.
    NoObjectPoses {
        /// Object id.
        id: u32,
    },
    /// The object's origin is not in front of the camera (depth <= 0).
    ObjectBehindCamera {
        /// Object id.
        id: u32,
    },
}

impl Skip {
    /// A short stable key for counting skips by reason.
    pub fn key(&self) -> &'static str {
        match self {
            Skip::NoPerEventTruth => "no_per_event_truth",
            Skip::NoMovingObject => "no_moving_object",
            Skip::MovingObjectPresent => "moving_object_present",
            Skip::NoMask => "no_mask",
            Skip::NoEventsNearMask { .. } => "no_events_near_mask",
            Skip::NoPrediction => "no_prediction",
            Skip::NoCameraTruth => "no_camera_truth",
            Skip::TruthGap { .. } => "truth_gap",
            Skip::SlowCamera { .. } => "slow_camera",
            Skip::NoObjectPoses { .. } => "no_object_poses",
            Skip::ObjectBehindCamera { .. } => "object_behind_camera",
        }
    }
}

/// A computed figure or the reason it was skipped. Serialized as `{"scored": ...}` or
/// `{"skipped": ...}`.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome<T> {
    /// The figure.
    Scored(T),
    /// Why there is none.
    Skipped(Skip),
}

impl<T> Outcome<T> {
    /// The figure, if computed.
    pub fn scored(&self) -> Option<&T> {
        match self {
            Outcome::Scored(v) => Some(v),
            Outcome::Skipped(_) => None,
        }
    }

    /// The skip reason, if skipped.
    pub fn skipped(&self) -> Option<&Skip> {
        match self {
            Outcome::Scored(_) => None,
            Outcome::Skipped(s) => Some(s),
        }
    }
}

impl<T> From<Result<T, Skip>> for Outcome<T> {
    fn from(r: Result<T, Skip>) -> Self {
        match r {
            Ok(v) => Outcome::Scored(v),
            Err(s) => Outcome::Skipped(s),
        }
    }
}
