//! `evseg-source`: publishes event packets (and ground truth, when the source has it) batch by
//! batch. `kind` selects the source.

use std::process::ExitCode;
use std::time::Instant;

use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Mode, NodeConfig, Outputs, Source, run_source};
use evseg_schemas::describe::{NodeDescription, Param};
use evseg_schemas::digest::EventDigest;
use evseg_schemas::{EventPacket, Truth};
use evseg_source::evimo2::{Evimo2Source, ImuCheckMode, RotationSource};
use evseg_source::file::FileSource;
use evseg_source::pattern::{Pattern, PatternParams};
use evseg_source::synthetic::SyntheticSource;
use evseg_source::{EventSource, SourceError};

struct SourceNode {
    source: Box<dyn EventSource>,
    batch_s: f64,
    seq: u64,
    /// Real-time factor for live runs (0 = as fast as possible).
    speed: f64,
    /// When the first batch was due, for live pacing (set at the first step, not when the node
    /// was built: it is built before it connects).
    started: Option<Instant>,
    summary: SourceSummary,
    summary_path: std::path::PathBuf,
    /// What the events come from, for messages ("EVIMO2 folder /data/seq", "file x.raw", ...).
    input: String,
}

/// What the source writes to `source-<node>.json` when it ends.
#[derive(serde::Serialize)]
struct SourceSummary {
    /// Digest of every event published, in order.
    digest: EventDigest,
    /// Wall clock of the first publication, ns since the Unix epoch (throughput figures).
    first_publish_ns: Option<u64>,
    /// [`evseg_source::EventSource::counters`] at the end of the stream.
    counters: std::collections::BTreeMap<&'static str, u64>,
}

impl Source for SourceNode {
    fn step(&mut self, out: &mut Outputs) -> Result<bool, BoxError> {
        let t_start = self.seq as f64 * self.batch_s;
        let t_end = t_start + self.batch_s;
        let Some(batch) = self.source.next_batch(t_end)? else {
            self.summary.counters = self.source.counters().into_iter().collect();
            let changed: Vec<_> = self.summary.counters.iter().filter(|(_, n)| **n > 0).collect();
            if !changed.is_empty() {
                tracing::warn!(
                    counters = ?changed,
                    summary = %self.summary_path.display(),
                    "the input was not used as it stands (counts also in the summary file)"
                );
            }
            if self.summary.digest.count == 0 {
                tracing::warn!(
                    "{}: the input holds no events (or none that could be read); the stages \
                     received empty packets only",
                    self.input
                );
            }
            let json = serde_json::to_string_pretty(&self.summary)?;
            std::fs::write(&self.summary_path, json)
                .map_err(|e| format!("cannot write {}: {e}", self.summary_path.display()))?;
            return Ok(false);
        };
        if self.speed > 0.0 {
            let due = t_start / self.speed;
            let now = self
                .started
                .get_or_insert_with(Instant::now)
                .elapsed()
                .as_secs_f64();
            if due > now
                && let Ok(wait) = std::time::Duration::try_from_secs_f64(due - now)
            {
                std::thread::sleep(wait);
            }
        }
        self.summary.digest.add(&batch.events);
        self.summary.first_publish_ns.get_or_insert_with(|| {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos() as u64)
                .unwrap_or(0)
        });
        let packet = EventPacket {
            camera: self.source.camera(),
            events: batch.events,
            imu: batch.imu,
        };
        out.send("events", self.seq, t_start, t_end, &packet)?;
        if let Some(truth) = batch.truth {
            out.send("truth", self.seq, t_start, t_end, &truth)?;
        }
        self.seq += 1;
        Ok(true)
    }
}

/// The `max_time_gap_s` parameter, s, checked against [`evseg_evimo2::MAX_TIME_GAP_RANGE_S`].
fn max_time_gap_s(cfg: &NodeConfig) -> Result<f64, BoxError> {
    let gap: f64 = cfg.param("max_time_gap_s")?;
    let range = evseg_evimo2::MAX_TIME_GAP_RANGE_S;
    if !range.contains(&gap) {
        return Err(format!(
            "max_time_gap_s: {gap} s is outside {}..={} s",
            range.start(),
            range.end()
        )
        .into());
    }
    Ok(gap)
}

/// The `reorder_window_ms` parameter in seconds (checked by the source that takes it).
fn reorder_window_s(cfg: &NodeConfig) -> Result<f64, BoxError> {
    let ms: f64 = cfg.param("reorder_window_ms")?;
    Ok(ms * 1e-3)
}

fn path_param(cfg: &NodeConfig) -> Result<std::path::PathBuf, BoxError> {
    let path: Option<String> = cfg.param_opt("path")?;
    // The runtime prefixes set-up errors with the node's name.
    let path = path.ok_or_else(|| {
        format!(
            "this source kind needs the `path` parameter: `--set {}.path=PATH` on the command line, or `path:` in the node's params",
            cfg.node
        )
    })?;
    Ok(std::path::PathBuf::from(path))
}

fn open(cfg: &NodeConfig) -> Result<Box<dyn EventSource>, BoxError> {
    let kind: String = cfg.param("kind")?;
    let seconds: Option<f64> = cfg.param_opt("seconds")?;
    match kind.as_str() {
        "synthetic" => {
            let scene: String = cfg.param("scene")?;
            let settings: std::collections::BTreeMap<String, f64> = cfg.param("settings")?;
            let settings: Vec<(String, f64)> = settings.into_iter().collect();
            let config =
                evseg_source::synthetic::scene_config(&scene, cfg.param("seed")?, seconds, &settings)?;
            Ok(Box::new(SyntheticSource::from_config(config)?))
        }
        "evimo2" => {
            let options = evseg_evimo2::ReadOptions {
                imu_topic: cfg.param_opt("imu_topic")?,
                imu_to_camera: cfg.param_opt("imu_to_camera")?,
                imu_time_offset_s: cfg.param_opt("imu_time_offset_s")?,
                sensor: None,
                max_time_gap_s: Some(max_time_gap_s(cfg)?),
            };
            let path = path_param(cfg)?;
            let mut source = Evimo2Source::open(&path, &options, seconds)?;
            source.set_reorder_window(reorder_window_s(cfg)?)?;
            let rotation: String = cfg.param("rotation_source")?;
            let rotation = rotation.parse::<RotationSource>()?;
            if rotation == RotationSource::Imu {
                let mode: String = cfg.param("imu_check")?;
                let explicit = options.imu_to_camera.is_some() || options.imu_time_offset_s.is_some();
                source.check_imu(mode.parse::<ImuCheckMode>()?, explicit);
            }
            source.set_rotation_source(rotation, &path)?;
            Ok(Box::new(source))
        }
        "file" => {
            let camera_file: Option<String> = cfg.param_opt("camera_file")?;
            let camera_file = camera_file.map(std::path::PathBuf::from);
            let mut source = FileSource::open(&path_param(cfg)?, camera_file.as_deref(), seconds)?;
            source.set_reorder_window(reorder_window_s(cfg)?)?;
            Ok(Box::new(source))
        }
        "pattern" => Ok(Box::new(Pattern::new(PatternParams {
            rate: cfg.param("rate")?,
            seconds: seconds.unwrap_or(3.0),
            width: cfg.param("width")?,
            height: cfg.param("height")?,
            seed: cfg.param("seed")?,
        })?)),
        other => Err(Box::new(SourceError::Param(format!(
            "unknown source kind `{other}` (known: synthetic, evimo2, file, pattern)"
        )))),
    }
}

/// Live mode's real-time factors other than 0 (as fast as possible): from a thousandth of real
/// time (a 3 s sequence then takes 50 minutes) to a thousand times it.
const SPEED_RANGE: std::ops::RangeInclusive<f64> = 1e-3..=1e3;

/// Most events of one pattern packet (`rate` x `batch_ms`): 10 M events, about 130 MB.
const MAX_PATTERN_PACKET_EVENTS: f64 = 1e7;

/// Source parameters that only some kinds read. A value other than the default given to any
/// other kind would be ignored, so the node names it in a warning instead (for example
/// `rotation_source: trajectory` on a `file` recording, whose rotation still comes from its IMU).
const KIND_PARAMS: &[(&str, &[&str])] = &[
    ("path", &["evimo2", "file"]),
    ("scene", &["synthetic"]),
    ("seed", &["synthetic", "pattern"]),
    ("camera_file", &["file"]),
    ("imu_topic", &["evimo2"]),
    ("imu_to_camera", &["evimo2"]),
    ("imu_time_offset_s", &["evimo2"]),
    ("rotation_source", &["evimo2"]),
    ("imu_check", &["evimo2"]),
    ("reorder_window_ms", &["evimo2", "file"]),
    ("max_time_gap_s", &["evimo2"]),
    ("rate", &["pattern"]),
    ("width", &["pattern"]),
    ("height", &["pattern"]),
];

/// The parameters of `params` that source kind `kind` does not read although they differ from
/// their defaults (`defaults`, from the node's description), each with the kinds that read it.
/// Numbers compare by value (`50` equals `50.0`).
fn ignored_params(
    kind: &str,
    params: &serde_json::Map<String, serde_json::Value>,
    defaults: &[Param],
) -> Vec<(&'static str, &'static [&'static str])> {
    let same = |a: &serde_json::Value, b: &serde_json::Value| match (a.as_f64(), b.as_f64()) {
        (Some(x), Some(y)) => x == y,
        _ => a == b,
    };
    KIND_PARAMS
        .iter()
        .filter(|(_, kinds)| !kinds.contains(&kind))
        .filter(|(name, _)| {
            let Some(value) = params.get(*name) else {
                return false;
            };
            let default = defaults
                .iter()
                .find(|p| p.name == *name)
                .map_or(&serde_json::Value::Null, |p| &p.default);
            !same(value, default)
        })
        .copied()
        .collect()
}

/// The node's description: ports and parameters with their defaults.
fn description() -> NodeDescription {
    Describe::new(
        "evseg-source",
        "Publishes event packets and ground truth from a recording, the simulator or a test pattern",
    )
    .output::<EventPacket>(
        "events",
        "event packets with their IMU samples and the camera description",
    )
    .output::<Truth>(
        "truth",
        "ground truth aligned with the packets (sources that have it)",
    )
    .required("kind", "source kind: synthetic (built-in simulator), evimo2 (EVIMO2 v2 folder), file (AEDAT4, EVT2/EVT3 .raw, .es, text), pattern (transport test pattern)")
    .param("path", serde_json::Value::Null, "evimo2: sequence folder; file: recording")
    .param("scene", "two-objects", &format!("synthetic: scene preset ({})", evseg_source::synthetic::PRESET_NAMES.join(", ")))
    .param("settings", serde_json::json!({}), &format!("synthetic: the simulator's named settings applied to the preset, e.g. {{\"contrast\": 0.3}} ({})", evseg_sim::setting_names()))
    .param("camera_file", serde_json::Value::Null, "file: JSON camera file (intrinsics, distortion, IMU-to-camera rotation, time offset)")
    .param("imu_topic", serde_json::Value::Null, "evimo2: IMU topic in meta (default: the first)")
    .param("imu_to_camera", serde_json::Value::Null, "evimo2: IMU-to-camera rotation, row-major 9 numbers (default: EVIMO2 convention)")
    .param("imu_time_offset_s", serde_json::Value::Null, "evimo2: IMU time offset, seconds (default: -0.02, EVIMO2 convention)")
    .param("reorder_window_ms", evseg_source::evimo2::DEFAULT_REORDER_WINDOW_S * 1e3, "evimo2, file: how far past each packet's end the input is read, so events stored out of time order still reach their packet, milliseconds (0 = none)")
    .param("max_time_gap_s", evseg_evimo2::DEFAULT_MAX_TIME_GAP_S, "evimo2: an event stamped further than this from the last event kept before it (in file order) is a corrupt time, dropped and counted (event_times_dropped); raise it for a recording that pauses longer, seconds (0.001..=1e6)")
    .param("rotation_source", "imu", "evimo2: where the stages' camera rotation rate comes from: imu (the folder's IMU, the method's input) or trajectory (the folder's camera trajectory, differentiated: for folders without an IMU; it is the ground truth, so the run is not an IMU run)")
    .param("imu_check", "auto", "evimo2: check the IMU's axes and time offset against the camera trajectory (off, warn, auto = use the mapping that agrees when it was not set explicitly)")
    .param("batch_ms", 10.0, "sensor time per published packet, milliseconds")
    .param("speed", 0.0, "live mode: real-time factor (1 = sensor time), 0 = as fast as possible, else 0.001..=1000")
    .param("seconds", serde_json::Value::Null, "stop after this many seconds of sensor time (simulator: default the preset's length, at most 3600 s; pattern: default 3 s)")
    .param("rate", 1.0e6, "pattern: events per second of sensor time (up to 1e8, and at most 1e7 events per packet of batch_ms)")
    .param("width", 640, "pattern: sensor width, pixels")
    .param("height", 480, "pattern: sensor height, pixels")
    .param("seed", 7, "seed (pattern, simulator)")
    .build()
}

fn main() -> ExitCode {
    let description = description();
    let defaults = description.params.clone();
    run_source(description, move |cfg: &NodeConfig| {
        let kind: String = cfg.param("kind")?;
        for (name, kinds) in ignored_params(&kind, &cfg.params, &defaults) {
            tracing::warn!(
                node = %cfg.node,
                param = name,
                value = %cfg.params.get(name).unwrap_or(&serde_json::Value::Null),
                "parameter `{name}` is read by source kind {} only; ignored for kind `{kind}`",
                kinds.join(" and ")
            );
        }
        let batch_ms: f64 = cfg.param("batch_ms")?;
        if !(0.1..=60_000.0).contains(&batch_ms) {
            // Shorter packets flood the graph (10 000 per second of sensor time at 0.1 ms).
            return Err(format!("batch_ms must be within 0.1..=60000 ms, got {batch_ms}").into());
        }
        if kind == "pattern" {
            // The pattern allocates a packet's events at once.
            let rate: f64 = cfg.param("rate")?;
            let per_packet = rate * batch_ms * 1e-3;
            if per_packet > MAX_PATTERN_PACKET_EVENTS {
                return Err(format!(
                    "rate {rate} events/s x batch_ms {batch_ms} ms is {per_packet:.3e} events per \
                     packet; at most {MAX_PATTERN_PACKET_EVENTS:.0e} (lower rate or batch_ms)"
                )
                .into());
            }
        }
        let speed: f64 = cfg.param("speed")?;
        if !(speed == 0.0 || SPEED_RANGE.contains(&speed)) {
            return Err(format!(
                "speed must be 0 (as fast as possible) or within {}..={} (times real time), got {}",
                SPEED_RANGE.start(),
                SPEED_RANGE.end(),
                evseg_schemas::params::short_number(speed)
            )
            .into());
        }
        Ok(SourceNode {
            source: open(cfg)?,
            batch_s: batch_ms * 1e-3,
            seq: 0,
            speed: if cfg.mode == Mode::Live {
                speed.max(0.0)
            } else {
                0.0
            },
            started: None,
            summary: SourceSummary {
                digest: EventDigest::default(),
                first_publish_ns: None,
                counters: Default::default(),
            },
            summary_path: cfg.run_dir.join(format!("source-{}.json", cfg.node)),
            input: match cfg.param_opt::<String>("path")? {
                Some(path) if kind == "evimo2" || kind == "file" => format!("{kind} input {path}"),
                _ => format!("{kind} source"),
            },
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn params(pairs: &[(&str, serde_json::Value)]) -> serde_json::Map<String, serde_json::Value> {
        pairs.iter().map(|(k, v)| (k.to_string(), v.clone())).collect()
    }

    #[test]
    fn every_kind_specific_parameter_is_one_the_node_describes() {
        let d = description();
        for (name, kinds) in KIND_PARAMS {
            assert!(
                d.params.iter().any(|p| p.name == *name),
                "{name} is not described"
            );
            assert!(!kinds.is_empty(), "{name} names no kind");
        }
    }

    #[test]
    fn a_parameter_of_another_source_kind_is_reported_unless_it_keeps_its_default() {
        let d = description();
        // The default graph switched to a file recording on the command line: its simulator
        // settings keep their defaults, so nothing is reported.
        let p = params(&[
            ("kind", json!("file")),
            ("path", json!("x.raw")),
            ("scene", json!("two-objects")),
            ("seed", json!(7)),
            ("reorder_window_ms", json!(50)),
            ("rotation_source", json!("imu")),
        ]);
        assert!(ignored_params("file", &p, &d.params).is_empty());
        // The ground-truth rotation asked of a file recording, and a simulator scene: both named.
        let p = params(&[
            ("kind", json!("file")),
            ("rotation_source", json!("trajectory")),
            ("scene", json!("fast-rotation")),
            ("camera_file", json!("cam.json")),
        ]);
        let names: Vec<&str> = ignored_params("file", &p, &d.params)
            .iter()
            .map(|(n, _)| *n)
            .collect();
        assert_eq!(names, ["scene", "rotation_source"]);
        // The same settings on the kinds that read them are not reported.
        assert!(
            ignored_params(
                "evimo2",
                &params(&[("rotation_source", json!("trajectory"))]),
                &d.params
            )
            .is_empty()
        );
        assert!(
            ignored_params(
                "synthetic",
                &params(&[("scene", json!("fast-rotation"))]),
                &d.params
            )
            .is_empty()
        );
        // An optional parameter (default null) given to a kind that does not read it.
        let p = params(&[("imu_time_offset_s", json!(-0.01))]);
        let found = ignored_params("synthetic", &p, &d.params);
        assert_eq!(found.len(), 1);
        assert_eq!(found[0], ("imu_time_offset_s", &["evimo2"][..]));
    }
}
