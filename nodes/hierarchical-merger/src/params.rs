//! Settings of the hierarchical merger. `lambda` and `lambda_r` are the paper's (section 3.5);
//! the paper gives no merge threshold, penalty size or minimum segment size, so each default
//! says where it came from.

use evseg_geometry::EgomotionParams;

/// Default weight of the previous slices' cell depths in the final egomotion
/// ([`EgomotionParams::depth_memory`]; graph parameter `depth_memory`). Not in the paper.
/// `method_on_sim` (the fourteen sequences of each set: seven presets x two seeds, 3 s,
/// enter-leave 5 s; mean of the median direction errors, deg) at weights 0 / 0.25 / 0.5 / 1 /
/// 2 / 4: bench seeds 101-107 and 201-207 7.71 / 5.89 / 5.72 / 5.58 / 5.53 / 5.92; unseen
/// seeds 301-307 and 401-407 8.92 / 7.07 / - / 6.89 / 7.99 / -; seeds 501-507 and 601-607
/// 7.90 at 0, 5.94 at 1. IoU unchanged (only the final estimate uses it). 1 is best or within
/// 0.05 deg of it on every set.
pub const DEPTH_MEMORY: f64 = 1.0;

/// Settings of [`crate::HierarchicalMerger`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HierParams {
    /// Flow with confidence at or below this is invalid (default 0: the NormalFlow convention).
    pub min_confidence: f32,
    /// Subtract the IMU rotational flow (default true).
    pub derotate: bool,
    /// Tikhonov regularization of a segment's depth-1 translation, per event (paper: 1e-6).
    pub lambda: f64,
    /// Weight of the residual term of the similarity (paper: 0.5); residuals in normalized
    /// units/s.
    pub lambda_r: f64,
    /// Subtracted from the similarity when exactly one of the two segments lies on the
    /// persistent background map (default 1: as large as the whole range of the motion term for
    /// segments moving at right angles, so such a pair merges only with near-identical motion).
    pub background_penalty: f64,
    /// A segment lies on the map when its mean map value is at least this (default 0.5).
    pub map_threshold: f32,
    /// Pairs merge while their similarity is at least this (default -0.25: the motion term is
    /// -|ti - tj|^2 / (|ti|^2 + |tj|^2), which is -0.2 for the same direction at depths 2:1 and
    /// -1 at right angles; -0.25 merges the same motion at depth ratios up to about 2.3:1).
    pub merge_threshold: f64,
    /// Bounding boxes closer than this count as touching, pixels (default 2: neighbouring
    /// k-means cells share a border, not pixels).
    pub touch_px: f32,
    /// A final object segment with fewer events than this fraction of the slice's events is
    /// labelled background (default 0.002: below that it is flow noise, not an object, at the
    /// event counts of 346-640 px sensors; 0.005 dropped the fragments of objects that did not
    /// merge, IoU 0.136 -> 0.155 on the simulator's one-object scene at 0.002)...
    pub min_segment_fraction: f64,
    /// ...or fewer than this many events (default 20).
    pub min_segment_events: usize,
    /// Cell of the grid that labels events without flow by their labelled neighbours, pixels
    /// (default 4).
    pub fill_cell_px: u16,
    /// How far, in cells, the fill looks for labelled events where the 3x3 cells around an
    /// event without flow hold none: the `(2r + 1) x (2r + 1)` cells for `r` up to this (0 and 1:
    /// only the 3x3 cells, background where they are empty). Default 2 (out to 10 px at 4 px
    /// cells), measured on `evseg bench` (evseg-bench-v3, against 1): IoU mask / events / per
    /// object 73.82 / 83.58 / 78.45 -> 74.24 / 83.98 / 79.30 %, worst object's id switches 3.8
    /// -> 3.2, median direction error 8.4 deg either way, but in windows without a moving object
    /// 1.2-2.3 points more events labelled moving (7.29 / 7.37 / 12.72 / 9.69 -> 9.59 / 8.69 /
    /// 13.94 / 10.82 %); 4 gave 74.44 / 84.13 / 78.70 % (two-objects 202 per object 75 -> 61 %:
    /// one object's label reaches the other's events) with 6.5-14.3 % false alarms. Most of the
    /// object events the 3x3 fill missed had no labelled event at all in their 3x3 cells
    /// (low-contrast 206, first second: 3530 of 4344), where it said background.
    pub fill_reach: u16,
    /// The final egomotion estimate (SVM, then depth refinement; see
    /// `evseg_geometry::egomotion`).
    pub egomotion: EgomotionParams,
    /// Background flow samples at which a slice's direction of translation and the previous
    /// slice's (turned by the gyro's rotation between the two) weigh equally in the direction
    /// published: the slice's weight is `n / (n + direction_prior_samples)` for its `n`
    /// background samples with flow, so a slice with thousands keeps nearly its own estimate
    /// and one with a few hundred leans on the last (0 = off: every slice alone). Not in the
    /// paper. Default 300, from 100 / 300 / 1000 offline on the per-slice estimates
    /// (`method_on_sim` `DIRVEC`; the mean of fourteen median direction errors, deg, and the
    /// RMSE Vx / Vy / Vz relative to off): bench seeds 5.43 -> 5.41 / 5.36 / 5.44, x 0.96 /
    /// 0.99 / 0.98, x 0.93 / 1.00 / 0.95, x 0.90 / 1.04 / 0.88; seeds 301-307 / 401-407 6.11 ->
    /// 6.10 / 6.01 / 6.06, Vz x 0.99 / 0.95 / 0.88; seeds 501-507 / 601-607 5.73 -> 5.73 / 5.71 /
    /// 5.65, Vz x 0.99 / 0.97 / 0.95. A fixed blend (gain 0.25-0.7, session 31) was worse on
    /// every setting: the heading turns about 5.6 deg per 30 ms slice, so only slices with
    /// little evidence should lean on the last. Through the graph at 300 against 0: `evseg
    /// bench` median direction error 5.43 -> 5.36 deg, RMSE 0.034 / 0.036 / 0.050 -> 0.032 /
    /// 0.036 / 0.048 m/s (1000: 5.44 deg, 0.031 / 0.037 / 0.044); seeds 301-307 / 401-407 (3
    /// s) 6.11 -> 6.01 deg, RMSE 0.037 / 0.038 / 0.074 -> 0.036 / 0.037 / 0.071.
    pub direction_prior_samples: f64,
}

impl Default for HierParams {
    fn default() -> Self {
        Self {
            min_confidence: 0.0,
            derotate: true,
            lambda: 1e-6,
            lambda_r: 0.5,
            background_penalty: 1.0,
            map_threshold: 0.5,
            merge_threshold: -0.25,
            touch_px: 2.0,
            min_segment_fraction: 0.002,
            min_segment_events: 20,
            fill_cell_px: 4,
            fill_reach: 2,
            egomotion: EgomotionParams {
                depth_memory: DEPTH_MEMORY,
                ..EgomotionParams::default()
            },
            direction_prior_samples: 300.0,
        }
    }
}

pub use evseg_schemas::params::ParamError;

impl HierParams {
    /// Checks every range.
    pub fn validate(&self) -> Result<(), ParamError> {
        let check = |name, v: f64, ok: bool, why| {
            if ok && v.is_finite() {
                Ok(())
            } else {
                Err(ParamError::new(name, v, why))
            }
        };
        check(
            "lambda",
            self.lambda,
            self.lambda >= 0.0,
            "must be finite and >= 0",
        )?;
        check(
            "lambda_r",
            self.lambda_r,
            self.lambda_r >= 0.0,
            "must be finite and >= 0",
        )?;
        check(
            "background_penalty",
            self.background_penalty,
            self.background_penalty >= 0.0,
            "must be finite and >= 0",
        )?;
        check("merge_threshold", self.merge_threshold, true, "must be finite")?;
        check(
            "depth_memory",
            self.egomotion.depth_memory,
            self.egomotion.depth_memory >= 0.0,
            "must be finite and >= 0",
        )?;
        check(
            "depth_memory_restart_ratio",
            self.egomotion.depth_memory_restart_ratio,
            self.egomotion.depth_memory_restart_ratio >= 0.0,
            "must be finite and >= 0",
        )?;
        check(
            "refine_huber_k",
            self.egomotion.huber_k,
            self.egomotion.huber_k >= 0.0,
            "must be finite and >= 0",
        )?;
        check("touch_px", f64::from(self.touch_px), true, "must be finite")?;
        check(
            "min_segment_fraction",
            self.min_segment_fraction,
            (0.0..=1.0).contains(&self.min_segment_fraction),
            "must be in [0, 1]",
        )?;
        check(
            "map_threshold",
            f64::from(self.map_threshold),
            (0.0..=1.0).contains(&self.map_threshold),
            "must be in [0, 1]",
        )?;
        check(
            "svm_c",
            self.egomotion.svm.c,
            self.egomotion.svm.c > 0.0,
            "must be finite and > 0",
        )?;
        if let Some(problem) = evseg_geometry::min_confidence_problem(self.min_confidence) {
            return Err(ParamError::new("min_confidence", self.min_confidence, problem));
        }
        check(
            "direction_prior_samples",
            self.direction_prior_samples,
            self.direction_prior_samples >= 0.0,
            "must be finite and >= 0",
        )?;
        if self.fill_cell_px == 0 {
            return Err(ParamError::new("fill_cell_px", 0, "must be >= 1"));
        }
        Ok(())
    }
}
