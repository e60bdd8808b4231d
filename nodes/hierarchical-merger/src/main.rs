//! `evseg-hierarchical-merger`: hierarchical merging of segments by motion similarity and the
//! final background egomotion (paper section 3.5).

use std::process::ExitCode;

use evseg_geometry::egomotion_node::{describe_egomotion, egomotion_from_config};
use evseg_geometry::rotation::{SLOPE_DEFAULT, SLOPE_PARAM, SLOPE_PARAM_DOC};
use evseg_geometry::{EgomotionParams, RotationRate};
use evseg_hierarchical_merger::{HierParams, HierarchicalMerger};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{CoarseSegmentation, NormalFlow, Segmentation, Slice};

struct Node {
    merger: HierarchicalMerger,
    /// [`evseg_geometry::rotation::SLOPE_PARAM`].
    rate_slope: bool,
}

impl Stage for Node {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let flow: NormalFlow = input.get("flow")?;
        let coarse: CoarseSegmentation = input.get("coarse")?;
        let egomotion_flow: Option<NormalFlow> = input.get_opt("egomotion_flow")?;
        let rate = RotationRate::of_slice(&slice, input.span(), self.rate_slope);
        let r = self.merger.merge_with_egomotion_flow(
            &slice.camera,
            &slice.events,
            &flow,
            egomotion_flow.as_ref(),
            rate,
            &coarse,
        )?;
        tracing::debug!(
            slice = input.seq(),
            initial = r.initial_segments,
            merges = r.merges,
            dropped_small = r.dropped_small,
            segments = r.segmentation.segments.len(),
            "hierarchical merge"
        );
        let (t0, t1) = input.span();
        out.send("segments", input.seq(), t0, t1, &r.segmentation)?;
        Ok(())
    }
}

fn main() -> ExitCode {
    let d = HierParams::default();
    let description = Describe::new(
        "evseg-hierarchical-merger",
        "Per-segment depth-1 translation, similarity merging of touching segments with the \
         background penalty, final background egomotion by the SVM (paper section 3.5)",
    )
    .input::<Slice>("slices", "event slices (omega: IMU rotation rate, camera frame)")
    .input::<NormalFlow>("flow", "per-event normal flow")
    .input::<CoarseSegmentation>("coarse", "the background merger's groups")
    .optional_input::<NormalFlow>(
        "egomotion_flow",
        "per-event normal flow for the final egomotion only (the normal-flow node's wide_flow); without it the final egomotion uses flow",
    )
    .output::<Segmentation>(
        "segments",
        "label per event (0 = background), segments with translation (depth 1), egomotion",
    )
    .param(
        "min_confidence",
        f64::from(d.min_confidence),
        "flow at or below this confidence is invalid",
    )
    .param("derotate", d.derotate, "subtract the IMU rotational flow")
    .param(SLOPE_PARAM, SLOPE_DEFAULT, SLOPE_PARAM_DOC)
    .param(
        "lambda",
        d.lambda,
        "Tikhonov regularization per event (paper: 1e-6)",
    )
    .param("lambda_r", d.lambda_r, "weight of the residual term (paper: 0.5)")
    .param(
        "background_penalty",
        d.background_penalty,
        "similarity penalty when only one segment lies on the background map",
    )
    .param(
        "map_threshold",
        f64::from(d.map_threshold),
        "map value meaning background",
    )
    .param(
        "merge_threshold",
        d.merge_threshold,
        "pairs merge while their similarity is at least this",
    )
    .param(
        "touch_px",
        f64::from(d.touch_px),
        "bounding boxes this close touch, pixels",
    )
    .param(
        "min_segment_fraction",
        d.min_segment_fraction,
        "smaller object segments (fraction of the slice's events) become background",
    )
    .param(
        "min_segment_events",
        d.min_segment_events,
        "object segments with fewer events become background",
    )
    .param(
        "fill_cell_px",
        d.fill_cell_px,
        "grid cell labelling events without flow, pixels",
    )
    .param(
        "fill_reach",
        d.fill_reach,
        "cells the fill looks out to where the 3x3 cells around an event without flow hold no labelled event",
    )
    .param(
        "direction_prior_samples",
        d.direction_prior_samples,
        "background samples at which the slice's direction and the previous one (turned by the gyro) weigh equally in the published direction (0 = off)",
    )
    .param(
        "depth_memory",
        d.egomotion.depth_memory,
        "weight of the previous slices' cell depths as a prior in the final egomotion's depth refinement (0 = off)",
    )
    .param(
        "depth_memory_ramp_slices",
        d.egomotion.depth_memory_ramp_slices,
        "slices over which depth_memory's weight grows to its full value from the start (0 = at once)",
    )
    .param(
        "depth_memory_restart_ratio",
        d.egomotion.depth_memory_restart_ratio,
        "while depth_memory ramps up: restart it when its direction fits the slice's samples worse than the slice's own direction by more than this fraction of the robust cost (0 = never)",
    );
    let description = describe_egomotion(description, &d.egomotion).build();
    run_stage(description, |cfg: &NodeConfig| {
        let params = HierParams {
            min_confidence: cfg.param("min_confidence")?,
            derotate: cfg.param("derotate")?,
            lambda: cfg.param("lambda")?,
            lambda_r: cfg.param("lambda_r")?,
            background_penalty: cfg.param("background_penalty")?,
            map_threshold: cfg.param("map_threshold")?,
            merge_threshold: cfg.param("merge_threshold")?,
            touch_px: cfg.param("touch_px")?,
            min_segment_fraction: cfg.param("min_segment_fraction")?,
            min_segment_events: cfg.param("min_segment_events")?,
            fill_cell_px: cfg.param("fill_cell_px")?,
            fill_reach: cfg.param("fill_reach")?,
            direction_prior_samples: cfg.param("direction_prior_samples")?,
            egomotion: EgomotionParams {
                depth_memory: cfg.param("depth_memory")?,
                depth_memory_ramp_slices: cfg.param("depth_memory_ramp_slices")?,
                depth_memory_restart_ratio: cfg.param("depth_memory_restart_ratio")?,
                ..egomotion_from_config(cfg)?
            },
        };
        Ok(Node {
            merger: HierarchicalMerger::new(params)?,
            rate_slope: cfg.param(SLOPE_PARAM)?,
        })
    })
}
