//! `evseg-normal-flow-learned`: per-event normal flow of each slice by the learned estimator
//! (random-Fourier-feature encoding + MLP, weights loaded at start-up); the same ports and
//! messages as `evseg-normal-flow`. With the optional `truth` input wired, also scores it (per
//! slice in the log, for the run in `normal-flow-score-<node>.json` in the run folder).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use evseg_normal_flow::consensus::{consensus_from_config, consensus_on_slice, describe_consensus};
use evseg_normal_flow::{
    ConsensusParams, LearnedEstimator, LearnedParams, LearnedWeights, NodeScore, Score, WeightsError,
    write_run_score,
};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{NormalFlow, Slice, Truth};
use serde::Serialize;

/// The default weights file, relative to the working folder (the repository root).
const DEFAULT_WEIGHTS: &str = "nodes/normal-flow/weights/learned.bin";

struct LearnedNode {
    node: String,
    run_dir: PathBuf,
    weights_path: PathBuf,
    weights: LearnedWeights,
    params: LearnedParams,
    consensus: ConsensusParams,
    replaced: u64,
    estimator: Option<LearnedEstimator>,
    score: NodeScore,
    slices: u64,
    events: u64,
    valid: u64,
}

/// What the node writes at the end of a run with truth.
#[derive(Serialize)]
struct RunReport<'a> {
    node: &'a str,
    estimator: &'static str,
    weights: String,
    weights_seed: u64,
    d: usize,
    layer_sizes: &'a [usize],
    radius: usize,
    ensemble: usize,
    min_neighbours: usize,
    min_confidence: f32,
    consensus_cell_px: u16,
    consensus_max_deviation: f64,
    /// Estimates whose length the neighbourhood consensus replaced.
    consensus_replaced: u64,
    slices: u64,
    events: u64,
    valid: u64,
    score: Score,
}

impl Stage for LearnedNode {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let (t_start, t_end) = input.span_of("slices").unwrap_or(input.span());
        let rebuild = match &self.estimator {
            Some(e) => e.camera() != &slice.camera,
            None => true,
        };
        if rebuild {
            if self.estimator.is_some() {
                tracing::warn!(seq = input.seq(), "camera changed: estimator tables rebuilt");
            }
            self.estimator = Some(LearnedEstimator::new(
                &slice.camera,
                self.weights.clone(),
                self.params,
            )?);
        }
        let Some(estimator) = self.estimator.as_mut() else {
            return Ok(());
        };
        let mut flow: NormalFlow = estimator.process(&slice.events, t_start, t_end)?;
        self.replaced += consensus_on_slice(&slice, &mut flow, &self.consensus).replaced as u64;
        self.events += flow.confidence.len() as u64;
        self.valid += flow.confidence.iter().filter(|&&c| c > 0.0).count() as u64;
        out.send("flow", input.seq(), t_start, t_end, &flow)?;
        self.slices += 1;
        if let Some(truth) = input.get_opt::<Truth>("truth")? {
            self.score
                .add_slice(&slice.camera, rebuild, input.seq(), &slice.events, &flow, &truth)?;
        }
        Ok(())
    }

    fn finish(&mut self, _out: &mut Outputs) -> Result<(), BoxError> {
        let Some(score) = self.score.summary() else {
            return Ok(());
        };
        let p = &self.params;
        let report = RunReport {
            node: &self.node,
            estimator: "learned",
            weights: self.weights_path.display().to_string(),
            weights_seed: self.weights.seed,
            d: self.weights.d(),
            layer_sizes: &self.weights.sizes,
            radius: self.estimator.as_ref().map(|e| e.radius()).unwrap_or(p.radius),
            ensemble: p.ensemble,
            min_neighbours: p.min_neighbours,
            min_confidence: p.min_confidence,
            consensus_cell_px: self.consensus.cell_px,
            consensus_max_deviation: self.consensus.max_deviation,
            consensus_replaced: self.replaced,
            slices: self.slices,
            events: self.events,
            valid: self.valid,
            score,
        };
        write_run_score(&self.run_dir, &self.node, &report, &report.score)?;
        Ok(())
    }
}

/// The weights file: `param` as given when it exists (relative paths from the working folder);
/// for the default path, the crate's own `weights/learned.bin` when run from elsewhere.
/// The weights the project trained (`weights/learned.bin`), built into the binary so that a node
/// deployed without the source tree (a robot) still starts with the default weights.
const BUILT_IN_WEIGHTS: &[u8] = include_bytes!("../../weights/learned.bin");

/// Where the built-in weights are said to come from in logs and reports.
const BUILT_IN_NAME: &str = "<built-in weights/learned.bin>";

/// The weights named by the `weights` parameter: that file when it exists or when another path
/// was given (a missing file is then an error naming it); for the default path that does not
/// exist from the working folder, the built-in copy.
fn load_weights(param: &str) -> Result<(LearnedWeights, PathBuf), WeightsError> {
    let given = PathBuf::from(param);
    if given.exists() || param != DEFAULT_WEIGHTS {
        return Ok((LearnedWeights::load(&given)?, given));
    }
    let name = PathBuf::from(BUILT_IN_NAME);
    Ok((LearnedWeights::from_bytes(BUILT_IN_WEIGHTS, &name)?, name))
}

fn main() -> ExitCode {
    let d = LearnedParams::default();
    let description = Describe::new(
        "evseg-normal-flow-learned",
        "Per-event normal flow by a learned estimator (random-Fourier-feature encoding of each event's \
         neighbourhood in the slice + bias-free MLP, VecKM_flow style; weights trained on simulator truth)",
    )
    .input::<Slice>("slices", "slices of events (each slice is encoded on its own)")
    .optional_input::<Truth>(
        "truth",
        "ground truth of the slices; when wired, the flow is scored per slice and for the run",
    )
    .output::<NormalFlow>(
        "flow",
        "normal flow per event, normalized units/s, aligned with the slice",
    )
    .param(
        "weights",
        DEFAULT_WEIGHTS,
        "weights file (format in nodes/normal-flow/src/weights.rs), relative to the working folder; the default falls back to the copy built into the binary",
    )
    .param(
        "radius",
        d.radius as u64,
        "neighbourhood half-width, pixels; 0 = the radius the weights were trained with (8)",
    )
    .param(
        "d",
        0u64,
        "expected number of frequency vectors D of the weights file; 0 = any (the file's)",
    )
    .param(
        "ensemble",
        d.ensemble as u64,
        "rotated copies averaged (circular mean), 1..=16; 1 = no ensemble (fastest)",
    )
    .param(
        "min_neighbours",
        d.min_neighbours as u64,
        "fewest events in the window (the event included) for an estimate",
    )
    .param(
        "min_confidence",
        f64::from(d.min_confidence),
        "estimates with confidence (1 - circular spread of the ensemble; 1 without ensemble) at or below this are invalid, [0, 1)",
    )
    .param("threads", d.threads as u64, "worker threads per slice");
    let description = describe_consensus(description, &ConsensusParams::default()).build();
    run_stage(description, |cfg: &NodeConfig| {
        let (weights, path) = load_weights(&cfg.param::<String>("weights")?)?;
        let expected_d = cfg.param::<usize>("d")?;
        if expected_d != 0 && expected_d != weights.d() {
            return Err(format!(
                "weights file {} has D = {}, the graph asks for d = {expected_d}",
                path.display(),
                weights.d()
            )
            .into());
        }
        let params = LearnedParams {
            radius: cfg.param::<usize>("radius")?,
            ensemble: cfg.param::<usize>("ensemble")?,
            min_neighbours: cfg.param::<usize>("min_neighbours")?,
            min_confidence: cfg.param::<f32>("min_confidence")?,
            threads: cfg.param::<usize>("threads")?,
        };
        let consensus = consensus_from_config(cfg)?;
        // Checks the settings once at start-up (any camera will do).
        let probe = evseg_schemas::CameraInfo::pinhole(1, 1, 1.0, "probe");
        LearnedEstimator::new(&probe, weights.clone(), params)
            .with_context(|| format!("weights file {}", path.display()))?;
        tracing::info!(
            weights = %path.display(),
            d = weights.d(),
            seed = weights.seed,
            "learned normal-flow weights loaded"
        );
        Ok(LearnedNode {
            node: cfg.node.clone(),
            run_dir: cfg.run_dir.clone(),
            weights_path: path,
            weights,
            params,
            consensus,
            replaced: 0,
            estimator: None,
            score: NodeScore::default(),
            slices: 0,
            events: 0,
            valid: 0,
        })
    })
}
