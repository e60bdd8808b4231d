//! `evseg-inspect`: a sink that checks a slice stream and writes `inspect-<node>.json` into the
//! run folder. Its `delay_ms` parameter makes it an artificially slow stage for testing that
//! lock-step runs lose nothing.

use std::process::ExitCode;
use std::time::Duration;

use evseg_inspect::Inspector;
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::Slice;

struct InspectNode {
    inspector: Inspector,
    delay: Duration,
    report_path: std::path::PathBuf,
}

impl Stage for InspectNode {
    fn process(&mut self, input: &Inputs, _out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let (t0, t1) = input.span();
        self.inspector.add(input.seq(), t0, t1, &slice);
        if !self.delay.is_zero() {
            std::thread::sleep(self.delay);
        }
        Ok(())
    }

    fn finish(&mut self, _out: &mut Outputs) -> Result<(), BoxError> {
        let json = serde_json::to_string_pretty(self.inspector.report())?;
        std::fs::write(&self.report_path, json)
            .map_err(|e| format!("cannot write {}: {e}", self.report_path.display()))?;
        Ok(())
    }
}

fn main() -> ExitCode {
    let description = Describe::new(
        "evseg-inspect",
        "Checks a slice stream (order, gaps, digest of every event) and writes a JSON summary",
    )
    .input::<Slice>("slices", "the slices to check")
    .param(
        "delay_ms",
        0.0,
        "artificial processing time per slice, milliseconds (testing back-pressure)",
    )
    .build();
    run_stage(description, |cfg: &NodeConfig| {
        let delay_ms: f64 = cfg.param("delay_ms")?;
        if !(delay_ms.is_finite() && delay_ms >= 0.0) {
            return Err(format!("delay_ms must be >= 0, got {delay_ms}").into());
        }
        Ok(InspectNode {
            inspector: Inspector::default(),
            delay: Duration::from_secs_f64(delay_ms * 1e-3),
            report_path: cfg.run_dir.join(format!("inspect-{}.json", cfg.node)),
        })
    })
}
