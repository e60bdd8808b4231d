//! `evseg-slicer`: fixed time windows over the source's event packets.

use std::process::ExitCode;

use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::{EventPacket, Slice, Truth};
use evseg_slicer::{SliceOut, Slicer, SlicerParams};

struct SlicerNode(Slicer);

fn publish(out: &mut Outputs, slices: Vec<SliceOut>) -> Result<(), BoxError> {
    for s in slices {
        out.send("slices", s.seq, s.t_start, s.t_end, &s.slice)?;
        if let Some(truth) = &s.truth {
            out.send("truth", s.seq, s.t_start, s.t_end, truth)?;
        }
    }
    Ok(())
}

impl Stage for SlicerNode {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let packet: EventPacket = input.get("events")?;
        let truth: Option<Truth> = input.get_opt("truth")?;
        let (_, t_end) = input.span();
        let late_before = self.0.late_events();
        let no_rate_before = self.0.slices_without_rate();
        let slices = self.0.push(packet, truth, t_end)?;
        if no_rate_before == 0 && self.0.slices_without_rate() > 0 {
            tracing::warn!(
                packet = input.seq(),
                "a slice without IMU samples (none in the window or within imu_hold_ms before it): \
                 no camera rotation rate, the stages cannot remove the rotational flow; counted, \
                 the total is logged at the end"
            );
        }
        let late = self.0.late_events() - late_before;
        if late > 0 {
            tracing::warn!(
                packet = input.seq(),
                late,
                total = self.0.late_events(),
                "events older than the open window dropped (source out of order)"
            );
        }
        publish(out, slices)
    }

    fn finish(&mut self, out: &mut Outputs) -> Result<(), BoxError> {
        let slices = self.0.finish();
        publish(out, slices)?;
        let without = self.0.slices_without_rate();
        if without > 0 {
            tracing::warn!(slices = without, "slices without a camera rotation rate (no IMU)");
        }
        Ok(())
    }
}

fn main() -> ExitCode {
    let d = SlicerParams::default();
    let description = Describe::new(
        "evseg-slicer",
        "Cuts events into fixed time windows with their IMU samples and camera rotation rate",
    )
    .input::<EventPacket>("events", "event packets of a source, in time order")
    .optional_input::<Truth>("truth", "the source's ground truth, aligned with its packets")
    .output::<Slice>("slices", "one slice per window, empty windows included")
    .output::<Truth>(
        "truth",
        "ground truth cut to the slices (only when the truth input is wired)",
    )
    .param("window_ms", d.window_s * 1e3, "window length, milliseconds")
    .param(
        "imu_hold_ms",
        d.imu_hold_s * 1e3,
        "carry the last IMU rate into an IMU-less window for at most this long, ms",
    )
    .build();
    run_stage(description, |cfg: &NodeConfig| {
        let params = SlicerParams {
            window_s: cfg.param::<f64>("window_ms")? * 1e-3,
            imu_hold_s: cfg.param::<f64>("imu_hold_ms")? * 1e-3,
        };
        Ok(SlicerNode(Slicer::new(params)?))
    })
}
