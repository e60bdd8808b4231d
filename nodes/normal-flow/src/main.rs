//! `evseg-normal-flow`: per-event normal flow of each slice by local plane fits; with the
//! optional `truth` input wired, also scores it (per slice in the log, for the run in
//! `normal-flow-score-<node>.json` in the run folder). With the `wide_flow` output read by
//! some node of the graph, also sends the wide flow (a 7 x 7 refit of the fast estimates,
//! [`evseg_normal_flow::WideFitParams`]) for the final egomotion.

use std::path::PathBuf;
use std::process::ExitCode;

use evseg_normal_flow::consensus::{consensus_from_config, consensus_on_slice, describe_consensus};
use evseg_normal_flow::{
    ConsensusParams, NodeScore, PlaneFitEstimator, PlaneFitParams, Score, WideFitParams, write_run_score,
};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, Mode, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{Events, NormalFlow, Slice, Truth};
use serde::Serialize;

struct NormalFlowNode {
    node: String,
    run_dir: PathBuf,
    params: PlaneFitParams,
    consensus: ConsensusParams,
    replaced: u64,
    /// The wide fit's settings when some node reads `wide_flow` (else it is not computed).
    wide: Option<WideFitParams>,
    /// Wide-flow lengths the consensus replaced.
    wide_replaced: u64,
    estimator: Option<PlaneFitEstimator>,
    score: NodeScore,
    slices: u64,
    /// Whether each slice waits for the next one ([`PlaneFitParams::lookahead_across_slices`],
    /// off when the lock-step window is too small for it).
    across_slices: bool,
    /// The slice waiting for the next one's first events.
    held: Option<Held>,
}

/// A slice the node has received but not yet fitted: it waits for the next slice, whose first
/// events its look-ahead reads.
struct Held {
    seq: u64,
    span: (f64, f64),
    slice: Slice,
    truth: Option<Truth>,
}

/// What the node writes at the end of a run with truth.
#[derive(Serialize)]
struct RunReport<'a> {
    node: &'a str,
    /// Which estimator wrote the file (the learned node writes "learned").
    estimator: &'static str,
    slices: u64,
    radius: usize,
    dt_min_ms: f64,
    dt_max_ms: f64,
    min_points: usize,
    outlier_ms: f64,
    max_speed_px_s: f64,
    min_confidence: f64,
    check_radius: usize,
    check_max_angle_deg: f64,
    check_max_speed_diff: f64,
    consensus_cell_px: u16,
    consensus_max_deviation: f64,
    /// Estimates whose length the neighbourhood consensus replaced.
    consensus_replaced: u64,
    events: u64,
    valid: u64,
    out_of_sensor: u64,
    bad_time: u64,
    out_of_order: u64,
    /// Fits the larger window's plane disagreed with (left invalid).
    disagreed: u64,
    /// The wide flow's window and check half-widths and speed threshold (pixels, px/s; all 0
    /// when `wide_flow` is not read), its fits and valid ones, and the lengths its consensus
    /// replaced.
    wide_radius: usize,
    wide_check_radius: usize,
    wide_min_speed_px_s: f64,
    wide_fits: u64,
    wide_valid: u64,
    wide_consensus_replaced: u64,
    score: Score,
}

impl NormalFlowNode {
    /// Fits `held`, with the look-ahead reaching into `next` when given, and sends its flow.
    fn fit_and_send(&mut self, held: Held, next: Option<&Events>, out: &mut Outputs) -> Result<(), BoxError> {
        let Held {
            seq,
            span: (t_start, t_end),
            slice,
            truth,
        } = held;
        let rebuild = match &self.estimator {
            Some(e) => e.camera() != &slice.camera,
            None => true,
        };
        if rebuild {
            if self.estimator.is_some() {
                tracing::warn!(seq, "camera changed: surfaces of active events restarted");
            }
            let estimator = PlaneFitEstimator::new(&slice.camera, self.params)?;
            self.estimator = Some(match self.wide {
                Some(wide) => estimator.with_wide_fit(wide)?,
                None => estimator,
            });
        }
        let Some(estimator) = self.estimator.as_mut() else {
            return Ok(());
        };
        let before = estimator.stats();
        let mut flow = NormalFlow::default();
        let mut wide = self.wide.map(|_| NormalFlow::default());
        // Named by its own sequence number: a held slice is fitted while the next one is the
        // runtime's current slice.
        estimator
            .process_wide_into(&slice.events, next, &mut flow, wide.as_mut())
            .map_err(|e| format!("slice {seq}: {e}"))?;
        let after = estimator.stats();
        self.replaced += consensus_on_slice(&slice, &mut flow, &self.consensus).replaced as u64;
        if let Some(wide) = wide.as_mut() {
            self.wide_replaced += consensus_on_slice(&slice, wide, &self.consensus).replaced as u64;
        }
        let ignored = (after.out_of_sensor - before.out_of_sensor) + (after.bad_time - before.bad_time);
        if ignored > 0 {
            tracing::warn!(
                seq,
                ignored,
                "events outside the sensor or with a bad time ignored"
            );
        }
        out.send("flow", seq, t_start, t_end, &flow)?;
        if let Some(wide) = &wide {
            out.send("wide_flow", seq, t_start, t_end, wide)?;
        }
        self.slices += 1;
        if let Some(truth) = truth {
            self.score
                .add_slice(&slice.camera, rebuild, seq, &slice.events, &flow, &truth)?;
        }
        Ok(())
    }
}

impl Stage for NormalFlowNode {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let current = Held {
            seq: input.seq(),
            span: input.span_of("slices").unwrap_or(input.span()),
            truth: input.get_opt::<Truth>("truth")?,
            slice,
        };
        if !self.across_slices {
            return self.fit_and_send(current, None, out);
        }
        let result = match self.held.take() {
            Some(held) => {
                // The next slice's events only help a slice of the same camera, and only when
                // their columns agree (if not, that slice's own fit reports it).
                let usable =
                    held.slice.camera == current.slice.camera && current.slice.events.is_consistent();
                self.fit_and_send(held, usable.then_some(&current.slice.events), out)
            }
            None => Ok(()),
        };
        // Held whatever became of the previous slice, so that one bad slice costs only itself.
        self.held = Some(current);
        result
    }

    fn finish(&mut self, out: &mut Outputs) -> Result<(), BoxError> {
        // The last slice has no next one to look into.
        if let Some(held) = self.held.take() {
            self.fit_and_send(held, None, out)?;
        }
        let Some(score) = self.score.summary() else {
            return Ok(());
        };
        let stats = self.estimator.as_ref().map(|e| e.stats()).unwrap_or_default();
        let p = &self.params;
        let report = RunReport {
            node: &self.node,
            estimator: "plane-fit",
            slices: self.slices,
            radius: p.radius,
            dt_min_ms: p.dt_min_s * 1e3,
            dt_max_ms: p.dt_max_s * 1e3,
            min_points: p.min_points,
            outlier_ms: p.outlier_s * 1e3,
            max_speed_px_s: p.max_speed_px_s,
            min_confidence: p.min_confidence,
            check_radius: p.check_radius,
            check_max_angle_deg: p.check_max_angle_rad.to_degrees(),
            check_max_speed_diff: p.check_max_speed_diff,
            consensus_cell_px: self.consensus.cell_px,
            consensus_max_deviation: self.consensus.max_deviation,
            consensus_replaced: self.replaced,
            events: stats.events,
            valid: stats.valid,
            out_of_sensor: stats.out_of_sensor,
            bad_time: stats.bad_time,
            out_of_order: stats.out_of_order,
            disagreed: stats.disagreed,
            wide_radius: self.wide.map_or(0, |w| w.radius),
            wide_check_radius: self.wide.map_or(0, |w| w.check_radius),
            wide_min_speed_px_s: self.wide.map_or(0.0, |w| w.min_speed_px_s),
            wide_fits: stats.wide_fits,
            wide_valid: stats.wide_valid,
            wide_consensus_replaced: self.wide_replaced,
            score,
        };
        write_run_score(&self.run_dir, &self.node, &report, &report.score)?;
        Ok(())
    }
}

fn main() -> ExitCode {
    let d = PlaneFitParams::default();
    let dw = WideFitParams::default();
    let dc = ConsensusParams::default();
    let description = Describe::new(
        "evseg-normal-flow",
        "Per-event normal flow by local plane fits on the surface of active events (Benosman et al. 2014)",
    )
    .input::<Slice>(
        "slices",
        "slices of events, in order (the surfaces persist across slices)",
    )
    .optional_input::<Truth>(
        "truth",
        "ground truth of the slices; when wired, the flow is scored per slice and for the run",
    )
    .output::<NormalFlow>(
        "flow",
        "normal flow per event, normalized units/s, aligned with the slice",
    )
    .output::<NormalFlow>(
        "wide_flow",
        "as flow, with the estimates faster than wide_min_speed_px_s refitted on the wide window (for the final egomotion); computed and sent only when a node of the graph reads it",
    )
    .param(
        "radius",
        d.radius as u64,
        "window half-width, pixels (2 = 5x5, 1 = 3x3)",
    )
    .param(
        "dt_min_ms",
        d.dt_min_s * 1e3,
        "neighbours younger than this are left out, ms",
    )
    .param(
        "dt_max_ms",
        d.dt_max_s * 1e3,
        "neighbours older than this are left out, ms",
    )
    .param("min_points", d.min_points as u64, "fewest points of a plane fit")
    .param(
        "outlier_ms",
        d.outlier_s * 1e3,
        "points with a larger time residual are rejected, ms",
    )
    .param(
        "max_refits",
        d.max_refits as u64,
        "refits after outlier rejection, at most",
    )
    .param(
        "max_speed_px_s",
        d.max_speed_px_s,
        "faster fits are invalid, pixels/s",
    )
    .param(
        "lookahead_ms",
        d.lookahead_s * 1e3,
        "non-causal fit: neighbours up to this after the event (within the slice, or into the next one with lookahead_across_slices), ms; 0 = causal",
    )
    .param(
        "lookahead_across_slices",
        d.lookahead_across_slices,
        "the look-ahead reaches into the next slice: each slice's flow is sent when the next slice arrives (one slice of latency; needs a lock-step window of at least 2)",
    )
    .param(
        "max_direction_sd_deg",
        if d.max_direction_sd_rad.is_finite() {
            serde_json::Value::from(d.max_direction_sd_rad.to_degrees())
        } else {
            serde_json::Value::Null
        },
        "fits whose gradient direction standard deviation reaches this are invalid, degrees (null = no test)",
    )
    .param(
        "min_confidence",
        d.min_confidence,
        "fits with a confidence at or below this are invalid, [0, 1)",
    )
    .param(
        "check_radius",
        d.check_radius as u64,
        "half-width of a larger window whose plane must agree with the fit's, pixels (0 = no check; else radius+1..=4)",
    )
    .param(
        "check_max_angle_deg",
        d.check_max_angle_rad.to_degrees(),
        "largest angle between the two windows' normal flows, degrees",
    )
    .param(
        "check_max_speed_diff",
        d.check_max_speed_diff,
        "largest relative difference of the two windows' speeds",
    )
    .param(
        "check_skip_confidence",
        d.check_skip_confidence,
        "fits at least this confident (and within check_skip_direction_sd_deg) skip the check",
    )
    .param(
        "check_skip_direction_sd_deg",
        d.check_skip_direction_sd_rad.to_degrees(),
        "fits this certain of their direction, degrees (and within check_skip_confidence) skip the check",
    )
    .param(
        "wide_radius",
        dw.radius as u64,
        "wide_flow: half-width of the wide window, pixels (radius+1..=4)",
    )
    .param(
        "wide_check_radius",
        dw.check_radius as u64,
        "wide_flow: half-width of the wide fit's scale check, pixels (0 = no check; else wide_radius+1..=4)",
    )
    .param(
        "wide_min_speed_px_s",
        dw.min_speed_px_s,
        "wide_flow: estimates faster than this are refitted on the wide window, pixels/s",
    )
    .param(
        "wide_max_refits",
        dw.max_refits as u64,
        "wide_flow: refits of the wide fit after outlier rejection, at most",
    );
    let description = describe_consensus(description, &dc).build();
    run_stage(description, |cfg: &NodeConfig| {
        let params = PlaneFitParams {
            radius: cfg.param::<usize>("radius")?,
            dt_min_s: cfg.param::<f64>("dt_min_ms")? * 1e-3,
            dt_max_s: cfg.param::<f64>("dt_max_ms")? * 1e-3,
            min_points: cfg.param::<usize>("min_points")?,
            outlier_s: cfg.param::<f64>("outlier_ms")? * 1e-3,
            max_refits: cfg.param::<usize>("max_refits")?,
            max_speed_px_s: cfg.param::<f64>("max_speed_px_s")?,
            min_confidence: cfg.param::<f64>("min_confidence")?,
            lookahead_s: cfg.param::<f64>("lookahead_ms")? * 1e-3,
            lookahead_across_slices: cfg.param::<bool>("lookahead_across_slices")?,
            max_direction_sd_rad: cfg
                .param_opt::<f64>("max_direction_sd_deg")?
                .map_or(f64::INFINITY, f64::to_radians),
            check_radius: cfg.param::<usize>("check_radius")?,
            check_max_angle_rad: cfg.param::<f64>("check_max_angle_deg")?.to_radians(),
            check_max_speed_diff: cfg.param::<f64>("check_max_speed_diff")?,
            check_skip_confidence: cfg.param::<f64>("check_skip_confidence")?,
            check_skip_direction_sd_rad: cfg.param::<f64>("check_skip_direction_sd_deg")?.to_radians(),
        };
        params.validate()?;
        let wide = WideFitParams {
            radius: cfg.param::<usize>("wide_radius")?,
            check_radius: cfg.param::<usize>("wide_check_radius")?,
            min_speed_px_s: cfg.param::<f64>("wide_min_speed_px_s")?,
            max_refits: cfg.param::<usize>("wide_max_refits")?,
        };
        wide.validate(&params)?;
        // The wide fit costs time; it runs only for a graph that reads its output.
        let wide_read = cfg.output_is_read("wide_flow");
        // In lock-step mode a held slice is sent only when the next one arrives, and the
        // slicer sends the next one only while fewer than `window` slices wait for their
        // consumers, some of which wait for this node's flow: a window of 1 would stall.
        let wanted = params.lookahead_across_slices && params.lookahead_s > 0.0;
        let window_allows = !(cfg.mode == Mode::Lockstep && cfg.window < 2);
        let across_slices = wanted && window_allows;
        if wanted && !window_allows {
            tracing::warn!(
                node = %cfg.node,
                window = cfg.window,
                "lookahead_across_slices needs a lock-step window of at least 2; each slice is fitted on its own"
            );
        }
        let consensus = consensus_from_config(cfg)?;
        Ok(NormalFlowNode {
            node: cfg.node.clone(),
            run_dir: cfg.run_dir.clone(),
            params,
            consensus,
            replaced: 0,
            wide: wide_read.then_some(wide),
            wide_replaced: 0,
            estimator: None,
            score: NodeScore::default(),
            slices: 0,
            across_slices,
            held: None,
        })
    })
}
