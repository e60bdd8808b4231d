//! `evseg-oversegmenter`: k-means over-segmentation of each slice (paper section 3.2).

use std::process::ExitCode;

use evseg_oversegmenter::{OversegParams, Oversegmenter};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{Clusters, NormalFlow, Slice};

struct Node(Oversegmenter);

impl Stage for Node {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let flow: NormalFlow = input.get("flow")?;
        let clusters = self.0.segment(&slice.camera, &slice.events, &flow)?;
        let (t0, t1) = input.span();
        out.send("clusters", input.seq(), t0, t1, &clusters)?;
        Ok(())
    }
}

fn main() -> ExitCode {
    let d = OversegParams::default();
    let description = Describe::new(
        "evseg-oversegmenter",
        "Over-segments each slice by k-means on [x, y, lambda * flow] (paper section 3.2)",
    )
    .input::<Slice>("slices", "event slices")
    .input::<NormalFlow>("flow", "per-event normal flow of the same slices")
    .output::<Clusters>("clusters", "cluster id per event (65535 = no valid flow)")
    .param("k", d.k, "number of clusters (paper: 30)")
    .param(
        "lambda",
        d.lambda,
        "weight of flow against position (paper: 0.5); features are normalized x, y and \
         lambda * flow_time_scale_s * normal flow (normalized units/s)",
    )
    .param(
        "flow_time_scale_s",
        d.flow_time_scale_s,
        "seconds turning flow into a distance; 1 s = pixels vs px/s up to the focal length",
    )
    .param(
        "min_confidence",
        f64::from(d.min_confidence),
        "flow with confidence at or below this is not clustered",
    )
    .param("max_iter", d.max_iter, "most Lloyd iterations")
    .param("seed", d.seed, "random seed (same seed, same clusters)")
    .param(
        "max_samples",
        d.max_samples,
        "events used for seeding and iterations (all events are then assigned)",
    )
    .build();
    run_stage(description, |cfg: &NodeConfig| {
        let params = OversegParams {
            k: cfg.param("k")?,
            lambda: cfg.param("lambda")?,
            flow_time_scale_s: cfg.param("flow_time_scale_s")?,
            min_confidence: cfg.param("min_confidence")?,
            max_iter: cfg.param("max_iter")?,
            seed: cfg.param("seed")?,
            max_samples: cfg.param("max_samples")?,
        };
        Ok(Node(Oversegmenter::new(params)?))
    })
}
