//! Settings of the background merger. The paper (section 3.4) gives the steps but none of these
//! numbers; each default says where it came from.

use evseg_geometry::EgomotionParams;

/// Settings of [`crate::BackgroundMerger`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BackgroundParams {
    /// Flow with confidence at or below this is invalid (default 0: the NormalFlow convention
    /// "0 = no estimate").
    pub min_confidence: f32,
    /// Subtract the IMU rotational flow (default true; the SVM step needs derotated flow).
    pub derotate: bool,
    /// The egomotion estimate (SVM, then depth refinement; see `evseg_geometry::egomotion`).
    pub egomotion: EgomotionParams,
    /// Choose the background translation among several hypotheses by the image area they
    /// explain (default true; see `select_hypothesis` in the crate source). Off: the estimate
    /// from the background candidates alone, as the paper describes. On the simulator a densely
    /// textured object that the planar vote calls background otherwise captures the estimate.
    pub hypotheses: bool,
    /// Weight of a cluster's area in a hypothesis' score is `prior_floor + prior` (default 0.5:
    /// a cluster the planar and warp votes call foreground still counts a third as much as one
    /// they call background). At 0.2 `evseg bench` (evseg-bench-v3, 0559795) gives the same
    /// IoU mask / events and egomotion to the digit (per object 77.70 -> 77.73 %).
    pub prior_floor: f64,
    /// Most samples per hypothesis estimate; more are subsampled regularly (default 600, 200
    /// per parameter of the direction; was 3000). A hypothesis only has to say which clusters
    /// it explains, and the winner is re-estimated from all its samples, so its precision hardly
    /// matters: with 600 samples and `hypothesis_refine_iterations` 3 instead of 3000 and 10,
    /// `method_on_sim` gave the same mean IoU and direction error on the fourteen bench
    /// sequences (0.8437 -> 0.8438, 7.64 deg; two slices of one sequence differ), on seeds
    /// 301-407 (0.8635, 8.81 deg, identical) and 501-607 (0.8353 -> 0.8363, 8.38 -> 8.33 deg),
    /// and on seeds 11-12 with the presets, contrast 0.3 and 2 Hz noise (identical), while the
    /// stage's busy time in `evseg bench pipeline` fell from 1.85-2.16 s to 1.56-1.82 s.
    pub hypothesis_max_samples: usize,
    /// Most rounds of the depth refinement per hypothesis estimate (the egomotion's
    /// `refine_iterations` when smaller). Default 3 (was 10; see `hypothesis_max_samples`): the
    /// hypotheses only need to be roughly right, the winner is re-estimated with every round;
    /// the ten hypotheses' refinements were the largest part of the stage's time (`evseg bench
    /// pipeline`, `perf`).
    pub hypothesis_refine_iterations: usize,
    /// Rounds of "SVM on the background, residuals, background = consistent candidates"
    /// (default 2: the second round drops the candidates the first translation does not explain,
    /// such as an object the planar vote missed, from the SVM; a third changed nothing on the
    /// test scenes).
    pub refine_rounds: usize,
    /// Cell of the warped previous-background occupancy grid, pixels (default 4: the warp's
    /// accuracy at 30 ms slices is a few pixels).
    pub warp_cell_px: u16,
    /// Fewest events of a cluster that must land on warped previous events for its warp score
    /// to count (default 10: below that the score is noise).
    pub warp_min_hits: usize,
    /// Weight of the warp score against the planar-residual vote in a cluster's background prior
    /// (default 0.25; the paper uses both without weights). The warp repeats the previous
    /// slice's mistakes: measured with `examples/method_on_sim.rs` of the hierarchical merger
    /// (seed 1, 1.5 s, estimated flow), final IoU one-object / two-objects / fast-rotation
    /// 0.097 / 0.111 / - at 0.5, 0.127 / 0.125 / 0.113 at 0.25, 0.136 / 0.120 / 0.123 at 0.
    /// Re-measured at 0559795 on `evseg bench` (evseg-bench-v3): IoU mask / events / per object
    /// 73.18 / 82.74 / 77.70 % at 0.25, 65.01 / 72.63 / 68.76 % at 0.5. The object episodes
    /// that are lost for 5-15 slices (two-objects 102 slices 52-57, low-contrast 106 slices
    /// 52-63, one-object 101 slices 30-38: the planar vote calls the object's clusters
    /// background while their warp score says foreground, prior 0.75) suggested weighting the
    /// warp more only where it says *more* foreground than the planar vote; at 0.5 for that
    /// case (measured, not kept) the in-process `method_on_sim` mean IoU rose 0.827 -> 0.834 on
    /// the bench's fourteen sequences and 0.860 -> 0.864 on the unseen seeds 11-14 (2 s, eight
    /// presets), but the false alarms of static windows rose 0.102 -> 0.135: the same
    /// persistence that keeps an object also keeps the start-up phantoms. Restricted to
    /// previous foreground that clearly moved, it is kept:
    /// [`BackgroundParams::warp_weight_moving`].
    pub warp_weight: f64,
    /// Weight of the warp score instead of [`BackgroundParams::warp_weight`] for a cluster
    /// that lands mostly on warped previous foreground which *clearly moved* (its cluster's
    /// relative residual under the previous slice's translation was at least
    /// [`BackgroundParams::moving_relres`]), where the warp says more foreground than the
    /// planar vote. Default 0.6: above one half, so that such a warp outvotes even a unanimous
    /// planar vote (a prior of 0.4). An object that moved unmistakably a slice ago rarely
    /// stops being one, but its flow can match the background plane for a few slices (a
    /// swinging object at its turning point, or one that fires most of the events and takes
    /// the plane fit), and the object was then lost for 5-15 slices (see
    /// [`BackgroundParams::warp_weight`]). A previous foreground that was explained by the
    /// camera's motion (a false alarm) keeps the ordinary weight, so the start-up phantoms are
    /// not carried along. Measured (in-process `method_on_sim`, mean per-event IoU; false
    /// alarms of static windows): the bench's fourteen sequences 0.827 -> 0.836 (0.832 at 0.5,
    /// where a unanimous planar vote still ties; 0.834 at 0.75), false alarms 0.074 / 0.094 /
    /// 0.074 / 0.121 -> 0.074 / 0.097 / 0.074 / 0.127; unseen seeds 11-14 (2 s, eight presets)
    /// 0.860 -> 0.868, false alarms 0.102 -> 0.106, median direction error 10.1 -> 9.9 deg
    /// (largest changes low-contrast 12 0.719 -> 0.842, two-objects 14 0.793 -> 0.850,
    /// fast-rotation 13 0.775 -> 0.816, enter-leave 14 0.917 -> 0.895, high-contrast 14
    /// 0.662 -> 0.643, high-contrast 11 0.912 -> 0.898). Set it equal to `warp_weight` to
    /// turn the rule off.
    pub warp_weight_moving: f64,
    /// A cluster whose mean absolute residual after its own best non-negative inverse depth
    /// under the estimated translation is at least this fraction of its mean absolute
    /// derotated flow counts as clearly moving for [`BackgroundParams::warp_weight_moving`]
    /// (default 0.8: its best depth explains less than a fifth of its flow; a cluster that
    /// no positive depth explains has 1). Chosen without tuning.
    pub moving_relres: f64,
    /// When the planar segmenter called at most this share of the clustered events foreground,
    /// its vote is taken to carry no information this slice and a cluster's prior is its warp
    /// score alone (where it has one). A 2-means split that separated (almost) nothing happens
    /// when no object moves, but also when an object fills so much of the slice that the plane
    /// fit follows it; the planar vote then calls the object background, and at weight
    /// [`BackgroundParams::warp_weight`] the warp could not overrule it. 0 = off (the planar
    /// vote always counts, as before). Default 0.02 (a fiftieth; chosen as the smallest clear
    /// share, not tuned to a scene). `examples/method_on_sim.rs` of the hierarchical merger,
    /// mean IoU with 0 -> 0.02 (0.05, 0.1 about the same): seed 101 (3 s) one-object 0.465 ->
    /// 0.484, two-objects 0.467 -> 0.514, fast-rotation 0.350 -> 0.462, enter-leave 0.645 ->
    /// 0.693, low-contrast 0.339 -> 0.369, high-contrast 0.491 -> 0.498; on seeds the bench does
    /// not use (11 and 12, 2 s) every object scene gained or held (fast-rotation 0.40 -> 0.50 and
    /// 0.29 -> 0.45). Letting the warp also *invert* a split it contradicts was tried and lost
    /// (high-contrast 0.50 -> 0.40).
    pub planar_silent_share: f64,
    /// When the planar vote is silent ([`BackgroundParams::planar_silent_share`]), the warp
    /// score alone is the prior only for a cluster that lands mostly on *confirmed* previous
    /// foreground; any other cluster mixes the warp with the (unanimous) planar vote at
    /// [`BackgroundParams::warp_weight`]. A cluster is confirmed when, in one slice, both
    /// independent votes call it moving (planar background share and warp score below
    /// [`BackgroundParams::candidate_threshold`], planar vote not silent), or when it lands
    /// mostly on confirmed previous foreground (the status is carried by the warp). Off: every
    /// cluster takes the warp alone. With it off, a phantom of the first slice (which has no
    /// warp, so only the planar vote made it) is carried forward by the warp alone for as long
    /// as the planar vote stays silent, since nothing else can outvote it.
    pub silent_warp_needs_confirmation: bool,
    /// Grace for [`BackgroundParams::silent_warp_needs_confirmation`]: unconfirmed foreground is
    /// still carried by the warp alone during the first this many consecutive slices with a
    /// silent planar vote (a real object the first slice found, before any warp could confirm
    /// it, survives a short silence; a first-slice phantom does not survive a long one). 0 =
    /// no grace.
    pub unconfirmed_silent_slices: u32,
    /// Confirmed foreground is carried by the warp alone for at most this many consecutive
    /// slices with a silent planar vote (0 = no limit); after that its warp score is mixed with
    /// the planar vote like any other. Default 3 (90 ms at 30 ms slices). A phantom that two
    /// slices of the planar vote happened to agree on (a near box's silhouette against a far
    /// wall in camera-only 205) was otherwise carried for 30 slices; on the simulator no real
    /// object needed more than 2 (the limit changed no IoU at 2, 3, 5 or 10; 1 cost
    /// fast-rotation 203 0.6 points). An object the planar vote cannot see for longer (one
    /// moving along the camera's translation) is then given up until it is seen again.
    pub confirmed_silent_slices: u32,
    /// A cluster whose background prior (weighted mean of the fraction of its events the planar
    /// segmenter called background and its warp score) is at least this is a background
    /// candidate (default 0.5: the majority).
    pub candidate_threshold: f64,
    /// A cluster whose 2-D flow the direction test cannot determine (nearly parallel edges) is
    /// consistent with the estimated camera translation when the mean absolute residual of its
    /// events (after fitting the cluster's own inverse depth) is at most this fraction of their
    /// mean absolute derotated flow. Default 10, i.e. such clusters keep the prior's verdict
    /// (was 0.5). Along parallel edges one inverse depth leaves the depth variation and the
    /// estimator's noise as residual, not only independent motion, and with the repaired
    /// normal flow (normal-flow consensus, `dt_max` 100 ms) this fallback demoted more
    /// background than objects: `evseg bench` (evseg-bench-v1, means; IoU mask %, per-object %,
    /// median direction error deg) 42.93 / 39.79 / 22.4 at 0.5 (angle 20), 44.66 / 34.95 /
    /// 15.2 at 10 (angle 20), 46.16 / 36.98 / 14.5 at 10 with angle 45 (the defaults), 46.58 /
    /// 34.17 / 15.1 at 10 with angle 90, 46.96 / 36.49 / 15.1 with both tests off (angle 0: the
    /// translation hypotheses then all tie). With the normal flow of before the consensus, 10
    /// had lost 8 points (21.78 against 29.85 %, 3e0e0a2). On seeds the bench does not use
    /// (`method_on_sim`, seeds 11 and 12, 2 s, six object presets) 10 with angle 45 raised the
    /// mean IoU 0.524 -> 0.589 and 0.430 -> 0.501 and lowered the direction error on 10 of the 12.
    pub consistency_ratio: f64,
    /// ...or at most this absolute mean residual, normalized units/s (default 0.02: about
    /// 10 px/s at f = 500 px, the noise floor of estimated normal flow; covers a camera that
    /// barely translates).
    pub consistency_floor: f64,
    /// A cluster whose derotated 2-D flow (fitted to its normal flows) is at most this many
    /// degrees from the direction of the translational flow `A(x) t` is consistent with the
    /// translation, whatever its depth (`evseg_geometry::direction`); 0 turns the test off (the
    /// residual ratio above alone). Default 45 (was 20, the best of 10/15/20/30/45 in the
    /// hierarchical merger's `examples/oracle_ladder.rs`, rung R5, with the *true* camera
    /// motion): with the estimated translation, 10-25 deg off, a tight angle demoted
    /// background; `evseg bench` with `consistency_ratio` 0.5: 42.93 % IoU mask at 20, 43.90 %
    /// at 45; see `consistency_ratio` for the pair. Re-measured at 0559795 (evseg-bench-v3):
    /// IoU mask / events / per object 73.18 / 82.74 / 77.70 % at 45, 72.87 / 82.42 / 77.31 %
    /// at 30.
    pub max_flow_angle_deg: f64,
    /// The direction test applies only when the smaller eigenvalue of `sum n0 n0^T` is at least
    /// this fraction of the cluster's samples (default 0.1: chosen without tuning; below it the
    /// edges are nearly parallel and the flow along them is unobserved, so the residual ratio
    /// decides).
    pub flow_direction_min_spread: f64,
    /// Weight the direction test's flow fit by `1 / (n^2 + n_med^2)` per sample, as the egomotion
    /// does (default true; `examples/oracle_ladder.rs` rung R5 at 20 deg, true camera motion,
    /// estimated flow: IoU 0.497 / 0.516 unweighted, 0.523 / 0.529 weighted, one-object /
    /// two-objects).
    pub flow_direction_magnitude_weighting: bool,
    /// Cell of the persistent background map, pixels (default 8: coarse enough to span the
    /// camera's motion over a few slices).
    pub map_cell_px: u16,
    /// EMA weight of the current slice when it disagrees completely with the map (default 0.05).
    pub alpha_min: f64,
    /// EMA weight of the current slice when it agrees completely with the map (default 0.5).
    /// The weight grows linearly with the similarity (IoU of background cells) between them, so a
    /// slice whose separation failed barely changes the map (paper: "adaptive alpha based on
    /// similarity").
    pub alpha_max: f64,
    /// A map cell is background when its value is at least this (default 0.5).
    pub map_threshold: f32,
}

impl Default for BackgroundParams {
    fn default() -> Self {
        Self {
            min_confidence: 0.0,
            derotate: true,
            egomotion: EgomotionParams::default(),
            hypotheses: true,
            prior_floor: 0.5,
            hypothesis_max_samples: 600,
            hypothesis_refine_iterations: 3,
            refine_rounds: 2,
            warp_cell_px: 4,
            warp_min_hits: 10,
            warp_weight: 0.25,
            warp_weight_moving: 0.6,
            moving_relres: 0.8,
            planar_silent_share: 0.02,
            silent_warp_needs_confirmation: true,
            unconfirmed_silent_slices: 1,
            confirmed_silent_slices: 3,
            candidate_threshold: 0.5,
            consistency_ratio: 10.0,
            consistency_floor: 0.02,
            max_flow_angle_deg: 45.0,
            flow_direction_min_spread: 0.1,
            flow_direction_magnitude_weighting: true,
            map_cell_px: 8,
            alpha_min: 0.05,
            alpha_max: 0.5,
            map_threshold: 0.5,
        }
    }
}

pub use evseg_schemas::params::ParamError;

impl BackgroundParams {
    /// Checks every range.
    pub fn validate(&self) -> Result<(), ParamError> {
        use evseg_schemas::params::{finite_non_negative as nonneg, unit};
        unit("warp_weight", self.warp_weight)?;
        unit("warp_weight_moving", self.warp_weight_moving)?;
        nonneg("moving_relres", self.moving_relres)?;
        unit("candidate_threshold", self.candidate_threshold)?;
        unit("planar_silent_share", self.planar_silent_share)?;
        unit("alpha_min", self.alpha_min)?;
        unit("alpha_max", self.alpha_max)?;
        unit("map_threshold", f64::from(self.map_threshold))?;
        nonneg("consistency_ratio", self.consistency_ratio)?;
        nonneg("consistency_floor", self.consistency_floor)?;
        nonneg("prior_floor", self.prior_floor)?;
        nonneg("max_flow_angle_deg", self.max_flow_angle_deg)?;
        unit("flow_direction_min_spread", self.flow_direction_min_spread)?;
        nonneg("svm_c", self.egomotion.svm.c)?;
        nonneg("refine_huber_k", self.egomotion.huber_k)?;
        if let Some(problem) = evseg_geometry::min_confidence_problem(self.min_confidence) {
            return Err(ParamError::new("min_confidence", self.min_confidence, problem));
        }
        if self.warp_cell_px == 0 || self.map_cell_px == 0 {
            return Err(ParamError::new("warp_cell_px/map_cell_px", 0, "must be >= 1"));
        }
        if self.alpha_min > self.alpha_max {
            return Err(ParamError::new(
                "alpha_min",
                self.alpha_min,
                "must not exceed alpha_max",
            ));
        }
        Ok(())
    }
}
