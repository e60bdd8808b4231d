//! `evseg-viewer`: draws a running graph in Rerun — writes an .rrd file into the run folder, or
//! streams to a running viewer (`connect` parameter).
//!
//! It takes every input on its own, in arrival order (an unjoined consumer, like the recorder),
//! so inputs that lag their slice (the evaluator's metrics wait for look-ahead ground truth) or
//! are not connected never hold it up; per-event messages are joined with their slice inside
//! the library ([`evseg_viewer::RunLogger`]), the same code `evseg view run.mcap` uses. It takes
//! part in lock-step credit like any consumer, so nothing is lost.

use std::path::PathBuf;
use std::process::ExitCode;

use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, NodeConfig, RawConsumer, run_raw_consumer};
use evseg_schemas::describe::NodeDescription;
use evseg_schemas::{Envelope, Metrics, NormalFlow, Segmentation, Slice, Tracks, Truth};
use evseg_viewer::{RunLogger, Sink, ViewerParams, log_frame};

/// Default of the `rrd` parameter: this file in the run folder.
const DEFAULT_RRD: &str = "viewer.rrd";

fn description() -> NodeDescription {
    let d = ViewerParams::default();
    Describe::new(
        "evseg-viewer",
        "Rerun view of a run: events coloured by polarity, segment / track id, normal-flow direction and \
         ground-truth object; track boxes `id N`; egomotion and metrics as time series. Writes an .rrd \
         file or streams to a running viewer",
    )
    .input::<Slice>("slices", "the slices whose events are drawn (pixels)")
    .optional_input::<NormalFlow>(
        "flow",
        "per-event normal flow, drawn as direction (hue) and magnitude",
    )
    .optional_input::<Tracks>(
        "tracks",
        "per-event track ids, track boxes, egomotion (tracker or baseline)",
    )
    .optional_input::<Segmentation>(
        "segments",
        "per-event segment labels, segment boxes, egomotion (hierarchical merger)",
    )
    .optional_input::<Truth>(
        "truth",
        "the slicer's ground truth: per-event object ids, true camera motion",
    )
    .optional_input::<Metrics>(
        "metrics",
        "the evaluator's per-slice figures, drawn as time series",
    )
    .param(
        "rrd",
        DEFAULT_RRD,
        "the .rrd file to write; a relative path is under the run folder (ignored when `connect` is set)",
    )
    .param(
        "connect",
        serde_json::Value::Null,
        "gRPC URL of a running viewer to stream to instead of a file, e.g. rerun+http://127.0.0.1:9876/proxy",
    )
    .param(
        "max_points_per_slice",
        d.max_points_per_slice as u64,
        "most events drawn per slice and layer; larger slices are decimated evenly in time order",
    )
    .param(
        "point_radius_ui",
        d.point_radius_ui,
        "event dot radius, UI points",
    )
    .param(
        "flow_full_scale",
        d.flow_full_scale,
        "normal-flow magnitude (normalized units/s) drawn at full brightness",
    )
    .param(
        "cache_slices",
        d.cache_slices as u64,
        "slices kept to join late per-event messages with their slice",
    )
    .build()
}

struct Viewer {
    logger: Option<RunLogger>,
    /// Producer node of each input port (config order): names the entities.
    producers: Vec<String>,
    sink: Sink,
}

fn usize_param(cfg: &NodeConfig, name: &str) -> Result<usize, BoxError> {
    let v: u64 = cfg.param(name)?;
    usize::try_from(v).map_err(|_| format!("parameter `{name}`: {v} is too large").into())
}

fn make(cfg: &NodeConfig) -> Result<Viewer, BoxError> {
    let params = ViewerParams {
        max_points_per_slice: usize_param(cfg, "max_points_per_slice")?,
        point_radius_ui: cfg.param("point_radius_ui")?,
        flow_full_scale: cfg.param("flow_full_scale")?,
        cache_slices: usize_param(cfg, "cache_slices")?,
    };
    let sink = match cfg.param_opt::<String>("connect")? {
        Some(url) => Sink::Grpc(url),
        None => Sink::File(cfg.run_dir.join(cfg.param::<PathBuf>("rrd")?)),
    };
    let stream = evseg_viewer::open(&sink, &cfg.instance)?;
    let mut logger = RunLogger::new(stream, params)?;
    if let Some(slices) = cfg.inputs.iter().find(|i| i.port == "slices") {
        logger.expect_slices_from(&slices.producer);
    }
    tracing::info!(%sink, "viewer logging");
    Ok(Viewer {
        logger: Some(logger),
        producers: cfg.inputs.iter().map(|i| i.producer.clone()).collect(),
        sink,
    })
}

impl RawConsumer for Viewer {
    fn frame(&mut self, port: usize, _envelope: &Envelope, frame: &[u8]) -> Result<(), BoxError> {
        let logger = self.logger.as_mut().ok_or("viewer already finished")?;
        let producer = self
            .producers
            .get(port)
            .ok_or_else(|| format!("frame on unknown input port {port}"))?;
        Ok(log_frame(logger, producer, frame)?)
    }

    fn finish(&mut self) -> Result<(), BoxError> {
        let Some(logger) = self.logger.take() else {
            return Ok(());
        };
        let s = logger.finish().map_err(|e| match e {
            evseg_viewer::ViewError::Flush { reason, .. } => evseg_viewer::ViewError::Flush {
                sink: self.sink.to_string(),
                reason,
            },
            other => other,
        })?;
        tracing::info!(
            sink = %self.sink,
            slices = s.slices,
            layers = s.layers,
            boxes = s.boxes,
            scalars = s.scalars,
            unmatched = s.unmatched,
            misaligned = s.misaligned,
            "viewer finished"
        );
        if let Some(p) = &s.first_problem {
            tracing::warn!("viewer: first problem: {p}");
        }
        Ok(())
    }
}

fn main() -> ExitCode {
    run_raw_consumer(description(), make)
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::Message;

    #[test]
    fn description_names_the_ports_and_every_parameter() {
        let d = description();
        let port = |n: &str| d.input(n).map(|p| (p.schema.as_str(), p.optional));
        assert_eq!(port("slices"), Some((Slice::SCHEMA, false)));
        assert_eq!(port("flow"), Some((NormalFlow::SCHEMA, true)));
        assert_eq!(port("tracks"), Some((Tracks::SCHEMA, true)));
        assert_eq!(port("segments"), Some((Segmentation::SCHEMA, true)));
        assert_eq!(port("truth"), Some((Truth::SCHEMA, true)));
        assert_eq!(port("metrics"), Some((Metrics::SCHEMA, true)));
        assert!(d.outputs.is_empty());
        let names: Vec<&str> = d.params.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "rrd",
                "connect",
                "max_points_per_slice",
                "point_radius_ui",
                "flow_full_scale",
                "cache_slices"
            ]
        );
        let default_of = |n: &str| d.params.iter().find(|p| p.name == n).map(|p| p.default.clone());
        assert_eq!(default_of("rrd"), Some(DEFAULT_RRD.into()));
        assert_eq!(default_of("connect"), Some(serde_json::Value::Null));
        assert_eq!(default_of("max_points_per_slice"), Some(10_000.into()));
    }
}
