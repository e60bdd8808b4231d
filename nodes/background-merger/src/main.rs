//! `evseg-background-merger`: coarse segment merging through temporal consistency (paper
//! section 3.4): warps the previous slice's final segmentation (feedback input), estimates the
//! camera translation direction by the linear SVM, merges the background clusters and keeps the
//! persistent background map.

use std::process::ExitCode;

use evseg_background_merger::{BackgroundMerger, BackgroundParams, SliceInput};
use evseg_geometry::RotationRate;
use evseg_geometry::egomotion_node::{describe_egomotion, egomotion_from_config};
use evseg_geometry::rotation::{SLOPE_DEFAULT, SLOPE_PARAM, SLOPE_PARAM_DOC};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{Clusters, CoarseSegmentation, NormalFlow, Residuals, Slice, Tracks};

struct Node {
    merger: BackgroundMerger,
    /// [`evseg_geometry::rotation::SLOPE_PARAM`].
    rate_slope: bool,
}

impl Stage for Node {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let flow: NormalFlow = input.get("flow")?;
        let clusters: Clusters = input.get("clusters")?;
        let residuals: Residuals = input.get("residuals")?;
        let previous: Option<Tracks> = input.get_opt("previous")?;
        let span = input.span();
        let r = self.merger.merge(&SliceInput {
            camera: &slice.camera,
            events: &slice.events,
            span,
            rate: RotationRate::of_slice(&slice, span, self.rate_slope),
            flow: &flow,
            clusters: &clusters,
            residuals: &residuals,
            previous_labels: previous.as_ref().map(|t| t.label.as_slice()),
        })?;
        tracing::debug!(
            slice = input.seq(),
            warped = r.warped,
            background_clusters = r.clusters.iter().filter(|c| c.background).count(),
            clusters = r.clusters.iter().filter(|c| c.events > 0).count(),
            direction = ?r.coarse.egomotion.direction,
            map_similarity = r.map.similarity,
            "coarse merge"
        );
        out.send("coarse", input.seq(), span.0, span.1, &r.coarse)?;
        Ok(())
    }
}

fn main() -> ExitCode {
    let d = BackgroundParams::default();
    let description = Describe::new(
        "evseg-background-merger",
        "Warps the previous segmentation, SVM egomotion on the background candidates, merges \
         background clusters, persistent background map (paper section 3.4)",
    )
    .input::<Slice>("slices", "event slices (omega: IMU rotation rate, camera frame)")
    .input::<NormalFlow>("flow", "per-event normal flow")
    .input::<Clusters>("clusters", "over-segmentation")
    .input::<Residuals>("residuals", "planar segmenter's background flags")
    .input::<Tracks>(
        "previous",
        "the tracker's output of the previous slice (wire with feedback: true)",
    )
    .output::<CoarseSegmentation>(
        "coarse",
        "group per event (0 = merged background, c+1 = cluster c), residuals under the SVM \
         translation with a depth per cluster, map overlap per group, egomotion",
    )
    .param(
        "min_confidence",
        f64::from(d.min_confidence),
        "flow at or below this confidence is invalid",
    )
    .param("derotate", d.derotate, "subtract the IMU rotational flow")
    .param(SLOPE_PARAM, SLOPE_DEFAULT, SLOPE_PARAM_DOC)
    .param(
        "hypotheses",
        d.hypotheses,
        "choose the background translation among hypotheses by the image area they explain",
    )
    .param(
        "prior_floor",
        d.prior_floor,
        "a cluster's area counts prior_floor + prior in a hypothesis' score",
    )
    .param(
        "hypothesis_refine_iterations",
        d.hypothesis_refine_iterations,
        "most depth-refinement rounds per hypothesis estimate",
    )
    .param(
        "hypothesis_max_samples",
        d.hypothesis_max_samples,
        "most samples per hypothesis estimate (more are subsampled)",
    )
    .param(
        "refine_rounds",
        d.refine_rounds,
        "rounds of SVM on the background -> residuals -> consistent candidates",
    )
    .param(
        "warp_cell_px",
        d.warp_cell_px,
        "cell of the warped previous-segmentation grid, pixels",
    )
    .param(
        "warp_min_hits",
        d.warp_min_hits,
        "fewest events landing on warped previous events for a warp score",
    )
    .param(
        "warp_weight",
        d.warp_weight,
        "weight of the warp score against the planar vote",
    )
    .param(
        "warp_weight_moving",
        d.warp_weight_moving,
        "weight of the warp score where it lands on previous foreground that clearly moved and says more foreground than the planar vote",
    )
    .param(
        "moving_relres",
        d.moving_relres,
        "relative residual at or above which a cluster counts as clearly moving for warp_weight_moving",
    )
    .param(
        "planar_silent_share",
        d.planar_silent_share,
        "planar foreground share of clustered events at or below which the warp score alone is the prior",
    )
    .param(
        "silent_warp_needs_confirmation",
        d.silent_warp_needs_confirmation,
        "with a silent planar vote, the warp score alone is the prior only where it lands on confirmed previous foreground (both votes once said moving)",
    )
    .param(
        "unconfirmed_silent_slices",
        d.unconfirmed_silent_slices,
        "consecutive slices with a silent planar vote during which unconfirmed foreground is still carried by the warp alone",
    )
    .param(
        "confirmed_silent_slices",
        d.confirmed_silent_slices,
        "consecutive slices with a silent planar vote during which confirmed foreground is carried by the warp alone (0 = no limit)",
    )
    .param(
        "candidate_threshold",
        d.candidate_threshold,
        "background prior at or above which a cluster is a background candidate",
    )
    .param(
        "consistency_ratio",
        d.consistency_ratio,
        "mean |residual| / mean |derotated flow| at most this = consistent with the camera motion",
    )
    .param(
        "consistency_floor",
        d.consistency_floor,
        "mean |residual| at most this (normalized units/s) = consistent",
    )
    .param(
        "max_flow_angle_deg",
        d.max_flow_angle_deg,
        "cluster flow within this angle (deg) of the translation's flow direction = consistent; 0 = off",
    )
    .param(
        "flow_direction_min_spread",
        d.flow_direction_min_spread,
        "smallest eigenvalue of sum n0 n0^T per sample for the direction test to apply",
    )
    .param(
        "flow_direction_magnitude_weighting",
        d.flow_direction_magnitude_weighting,
        "weight the direction test's flow fit by 1 / (n^2 + median n^2)",
    )
    .param(
        "map_cell_px",
        d.map_cell_px,
        "cell of the persistent background map, pixels",
    )
    .param(
        "alpha_min",
        d.alpha_min,
        "EMA weight when the slice disagrees with the map",
    )
    .param(
        "alpha_max",
        d.alpha_max,
        "EMA weight when the slice agrees with the map",
    )
    .param(
        "map_threshold",
        f64::from(d.map_threshold),
        "map value meaning background",
    );
    let description = describe_egomotion(description, &d.egomotion).build();
    run_stage(description, |cfg: &NodeConfig| {
        let params = BackgroundParams {
            min_confidence: cfg.param("min_confidence")?,
            derotate: cfg.param("derotate")?,
            egomotion: egomotion_from_config(cfg)?,
            hypotheses: cfg.param("hypotheses")?,
            prior_floor: cfg.param("prior_floor")?,
            hypothesis_max_samples: cfg.param("hypothesis_max_samples")?,
            hypothesis_refine_iterations: cfg.param("hypothesis_refine_iterations")?,
            refine_rounds: cfg.param("refine_rounds")?,
            warp_cell_px: cfg.param("warp_cell_px")?,
            warp_min_hits: cfg.param("warp_min_hits")?,
            warp_weight: cfg.param("warp_weight")?,
            warp_weight_moving: cfg.param("warp_weight_moving")?,
            moving_relres: cfg.param("moving_relres")?,
            planar_silent_share: cfg.param("planar_silent_share")?,
            silent_warp_needs_confirmation: cfg.param("silent_warp_needs_confirmation")?,
            unconfirmed_silent_slices: cfg.param("unconfirmed_silent_slices")?,
            confirmed_silent_slices: cfg.param("confirmed_silent_slices")?,
            candidate_threshold: cfg.param("candidate_threshold")?,
            consistency_ratio: cfg.param("consistency_ratio")?,
            consistency_floor: cfg.param("consistency_floor")?,
            max_flow_angle_deg: cfg.param("max_flow_angle_deg")?,
            flow_direction_min_spread: cfg.param("flow_direction_min_spread")?,
            flow_direction_magnitude_weighting: cfg.param("flow_direction_magnitude_weighting")?,
            map_cell_px: cfg.param("map_cell_px")?,
            alpha_min: cfg.param("alpha_min")?,
            alpha_max: cfg.param("alpha_max")?,
            map_threshold: cfg.param("map_threshold")?,
        };
        Ok(Node {
            merger: BackgroundMerger::new(params)?,
            rate_slope: cfg.param(SLOPE_PARAM)?,
        })
    })
}
