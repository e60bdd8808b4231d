//! `evseg-hierarchical-merger`: hierarchical merging of segments by motion similarity and the
//! final background egomotion (paper section 3.5).

use std::process::ExitCode;

use evseg_geometry::{EgomotionParams, SvmParams};
use evseg_hierarchical_merger::{HierParams, HierarchicalMerger};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{CoarseSegmentation, NormalFlow, Segmentation, Slice};

struct Node(HierarchicalMerger);

impl Stage for Node {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let flow: NormalFlow = input.get("flow")?;
        let coarse: CoarseSegmentation = input.get("coarse")?;
        let r = self
            .0
            .merge(&slice.camera, &slice.events, &flow, slice.omega, &coarse)?;
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
    .param("svm_c", d.egomotion.svm.c, "SVM cost C (squared hinge)")
    .param(
        "egomotion_min_confidence",
        f64::from(d.egomotion.min_confidence),
        "only flow above this confidence takes part in the egomotion",
    )
    .param(
        "egomotion_min_samples",
        d.egomotion.min_samples,
        "fewest background events for an egomotion estimate",
    )
    .param(
        "refine_iterations",
        d.egomotion.refine_iterations,
        "rounds of depth refinement after the SVM (0 = the SVM alone, as in the paper)",
    )
    .param(
        "depth_grid_cols",
        d.egomotion.grid_cols,
        "columns of the grid of constant-depth cells of the refinement",
    )
    .param(
        "min_cell_samples",
        d.egomotion.min_cell_samples,
        "cells with fewer samples are left out of the refinement",
    )
    .param(
        "egomotion_density_cell_px",
        d.egomotion.density_cell_px,
        "cells over which the egomotion samples are density-normalized, pixels (0 = off)",
    )
    .param(
        "refine_huber_k",
        d.egomotion.huber_k,
        "Huber constant of the egomotion's depth refinement, in robust residual scales (0 = plain least squares)",
    )
    .param(
        "egomotion_magnitude_weighting",
        d.egomotion.magnitude_weighting,
        "weight egomotion samples by 1 / (n^2 + median n^2) (normal-flow error grows with its length)",
    )
    .build();
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
            egomotion: EgomotionParams {
                svm: SvmParams {
                    c: cfg.param("svm_c")?,
                    ..SvmParams::default()
                },
                min_confidence: cfg.param("egomotion_min_confidence")?,
                min_samples: cfg.param("egomotion_min_samples")?,
                refine_iterations: cfg.param("refine_iterations")?,
                grid_cols: cfg.param("depth_grid_cols")?,
                min_cell_samples: cfg.param("min_cell_samples")?,
                density_cell_px: cfg.param("egomotion_density_cell_px")?,
                huber_k: cfg.param("refine_huber_k")?,
                magnitude_weighting: cfg.param("egomotion_magnitude_weighting")?,
            },
        };
        Ok(Node(HierarchicalMerger::new(params)?))
    })
}
