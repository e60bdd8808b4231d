//! `evseg-evaluator`: scores a result stream (`evseg.Tracks` from the tracker or any segmenter)
//! against the slicer's ground truth, publishes per-slice metrics for live display, and at the
//! end writes the report folder and prints the scoreboard table to stdout.

use std::path::PathBuf;
use std::process::ExitCode;

use evseg_evaluator::report::{markdown, write_report};
use evseg_evaluator::{EvalParams, Evaluator, SliceInput, SliceReport};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::describe::NodeDescription;
use evseg_schemas::{Metrics, Slice, Tracks, Truth};

/// Default of the `report_dir` parameter: a folder of this name in the run folder.
const DEFAULT_REPORT_DIR: &str = "report";

struct EvaluatorNode {
    ev: Evaluator,
    sequence: String,
    report_dir: PathBuf,
}

fn publish(out: &mut Outputs, reports: &[SliceReport]) -> Result<(), BoxError> {
    for r in reports {
        out.send::<Metrics>("metrics", r.seq, r.t_start, r.t_end, &r.metrics())?;
    }
    Ok(())
}

impl Stage for EvaluatorNode {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let truth: Truth = input.get("truth")?;
        let result: Tracks = input.get("result")?;
        let (t_start, t_end) = input.span();
        let reports = self.ev.push(SliceInput {
            seq: input.seq(),
            t_start,
            t_end,
            slice: &slice,
            truth: &truth,
            result: &result,
        })?;
        publish(out, &reports)
    }

    fn finish(&mut self, out: &mut Outputs) -> Result<(), BoxError> {
        let reports = self.ev.finish()?;
        publish(out, &reports)?;
        let files = write_report(&self.report_dir, &self.ev, &self.sequence)?;
        tracing::info!(dir = %self.report_dir.display(), files = files.len(), "report written");
        println!(
            "{}",
            markdown::scoreboard_table(&[self.ev.summary(&self.sequence)])
        );
        Ok(())
    }
}

/// The node's self-description (`--describe`).
fn description() -> NodeDescription {
    let d = EvalParams::default();
    Describe::new(
        "evseg-evaluator",
        "Scores segmentation (IoU per event, vs nearest mask, per object), egomotion (direction error, \
         per-axis RMSE of direction x true speed) and object image motion against ground truth; writes \
         a report folder",
    )
    .input::<Slice>("slices", "the slices (events, camera, window)")
    .input::<Truth>("truth", "the slicer's ground truth of each slice")
    .input::<Tracks>("result", "the result to score: per-event labels (0 = background), tracks, egomotion")
    .output::<Metrics>(
        "metrics",
        "per-slice figures for live display (NaN = not available), published once the slice's \
         look-ahead ground truth has arrived",
    )
    .param("sequence", "sequence", "name of the sequence in the report's rows")
    .param(
        "report_dir",
        serde_json::Value::Null,
        "report folder; null = `report` in the run folder; a relative path is under the run folder",
    )
    .param("frames_in_plot", d.frames_in_plot as u64, "slices with a moving object shown in frames.png")
    .param(
        "min_speed_mps",
        d.min_speed_mps,
        "camera speed (m/s) below which the direction error is skipped; 1 mm Vicon noise over 30 ms is 0.03 m/s",
    )
    .param(
        "max_gap_ms",
        d.max_gap_s * 1e3,
        "largest gap (ms) between ground-truth samples that is interpolated (EVIMO2 Vicon dropouts are longer)",
    )
    .param(
        "lookahead_ms",
        d.lookahead_s * 1e3,
        "how long (ms of sensor time) a slice waits for ground truth carried by later slices; >= max_gap_ms",
    )
    .param(
        "default_mask_period_ms",
        d.default_mask_period_s * 1e3,
        "mask period (ms) assumed until two masks are seen; EVIMO2 masks are 60 Hz",
    )
    .param(
        "switch_min_iou",
        d.switch_min_iou,
        "IoU above which a matched track id is the object's identity for the id switches (0.5 as MOTS; 0 = every match)",
    )
    .build()
}

fn make(cfg: &NodeConfig) -> Result<EvaluatorNode, BoxError> {
    let frames: u64 = cfg.param("frames_in_plot")?;
    let params = EvalParams {
        frames_in_plot: usize::try_from(frames).map_err(|_| format!("frames_in_plot {frames} too large"))?,
        min_speed_mps: cfg.param("min_speed_mps")?,
        max_gap_s: cfg.param::<f64>("max_gap_ms")? * 1e-3,
        lookahead_s: cfg.param::<f64>("lookahead_ms")? * 1e-3,
        default_mask_period_s: cfg.param::<f64>("default_mask_period_ms")? * 1e-3,
        switch_min_iou: cfg.param("switch_min_iou")?,
        ..EvalParams::default()
    };
    let report_dir = match cfg.param_opt::<PathBuf>("report_dir")? {
        None => cfg.run_dir.join(DEFAULT_REPORT_DIR),
        Some(p) => cfg.run_dir.join(p),
    };
    Ok(EvaluatorNode {
        ev: Evaluator::new(params)?,
        sequence: cfg.param("sequence")?,
        report_dir,
    })
}

fn main() -> ExitCode {
    run_stage(description(), make)
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::Message;

    #[test]
    fn description_round_trips_and_names_ports_and_defaults() {
        let d = description();
        let json = serde_json::to_string_pretty(&d).unwrap();
        let back: NodeDescription = serde_json::from_str(&json).unwrap();
        assert_eq!(back, d);
        assert_eq!(back.input("slices").unwrap().schema, Slice::SCHEMA);
        assert_eq!(back.input("truth").unwrap().schema, Truth::SCHEMA);
        assert_eq!(back.input("result").unwrap().schema, Tracks::SCHEMA);
        assert_eq!(back.output("metrics").unwrap().schema, Metrics::SCHEMA);
        assert_eq!(back.param("sequence").unwrap().default, "sequence");
        assert_eq!(back.param("frames_in_plot").unwrap().default, 4);
        assert!(back.param("report_dir").unwrap().default.is_null());
    }

    fn config(params: serde_json::Value) -> NodeConfig {
        let mut p = serde_json::Map::new();
        for prm in description().params {
            p.insert(prm.name, prm.default);
        }
        if let serde_json::Value::Object(o) = params {
            p.extend(o);
        }
        let mut cfg = NodeConfig::with_params("eval", p);
        cfg.run_dir = PathBuf::from("/runs/r1");
        cfg
    }

    #[test]
    fn parameters_build_the_evaluator_and_bad_ones_are_refused() {
        let n = make(&config(serde_json::json!({}))).unwrap();
        assert_eq!(n.report_dir, PathBuf::from("/runs/r1/report"));
        assert_eq!(n.sequence, "sequence");
        assert_eq!(n.ev.params().frames_in_plot, 4);
        let n = make(&config(
            serde_json::json!({"report_dir": "scores", "sequence": "13-05"}),
        ))
        .unwrap();
        assert_eq!(n.report_dir, PathBuf::from("/runs/r1/scores"));
        assert_eq!(n.sequence, "13-05");
        assert!(make(&config(serde_json::json!({"lookahead_ms": 1.0}))).is_err());
        assert!(make(&config(serde_json::json!({"frames_in_plot": -1}))).is_err());
    }
}
