//! Parameters of the visualisation.

use crate::error::ViewError;

/// How much of each slice is drawn and how it is coloured.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewerParams {
    /// Most events drawn per slice and per layer; a larger slice is decimated by keeping every
    /// `n / max`-th event (uniform in the slice's time order, the same events in every layer).
    /// Default 10 000: a 30 ms slice of the default two-objects scene has about 19 000 events,
    /// and at 10 000 the .rrd of the default 1 s run stays near the size given in the README.
    pub max_points_per_slice: usize,
    /// Radius of an event dot, UI points (independent of zoom). Default 1.5: single events stay
    /// visible on a 640 x 480 sensor shown in a ~800-pixel-wide view.
    pub point_radius_ui: f32,
    /// Normal-flow magnitude drawn at full brightness, normalized image units per second;
    /// smaller magnitudes are darker (brightness 0.25 + 0.75 * magnitude / full scale, capped).
    /// Default 1.0: about the flow of an object moving 300 px/s under a 300 px focal length,
    /// the upper end of the simulator's scenes.
    pub flow_full_scale: f32,
    /// Slices whose decimated positions are kept for joining per-event messages (labels, flow,
    /// truth) that arrive after their slice; messages more than this many slices late, or that
    /// wait this many slices for a slice that never comes, are skipped and counted. Default 64:
    /// well above a lock-step window (4) plus the evaluator's look-ahead (a few slices).
    pub cache_slices: usize,
}

impl Default for ViewerParams {
    fn default() -> Self {
        Self {
            max_points_per_slice: 10_000,
            point_radius_ui: 1.5,
            flow_full_scale: 1.0,
            cache_slices: 64,
        }
    }
}

impl ViewerParams {
    /// Checks the ranges: at least one point per slice, a positive finite radius and full
    /// scale, at least one cached slice.
    pub fn validate(&self) -> Result<(), ViewError> {
        let bad = |name: &str, reason: &str| {
            Err(ViewError::Param {
                name: name.into(),
                reason: reason.into(),
            })
        };
        if self.max_points_per_slice == 0 {
            return bad("max_points_per_slice", "must be >= 1");
        }
        if !(self.point_radius_ui.is_finite() && self.point_radius_ui > 0.0) {
            return bad("point_radius_ui", "must be a positive number");
        }
        if !(self.flow_full_scale.is_finite() && self.flow_full_scale > 0.0) {
            return bad("flow_full_scale", "must be a positive number");
        }
        if self.cache_slices == 0 {
            return bad("cache_slices", "must be >= 1");
        }
        Ok(())
    }
}
