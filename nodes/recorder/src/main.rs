//! `evseg-recorder`: records the node outputs the launcher wires to it into one MCAP file.
//!
//! The launcher adds this node when a run is recorded (`evseg run --record FILE` or a `record:`
//! section in graph.yaml), with one input per recorded output (port name = `node/output`). It
//! takes each port on its own, in arrival order, and acknowledges each port's progress, so in
//! lock-step mode producers wait for it and nothing is dropped.

use std::collections::BTreeMap;
use std::path::PathBuf;

use evseg_recorder::write::{ChannelSpec, McapRecorder, WriterSettings};
use evseg_recorder::{END_METADATA, GRAPH_ATTACHMENT, PARAMS_METADATA, RUN_METADATA};
use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, NodeConfig, RawConsumer, run_raw_consumer};
use evseg_schemas::Envelope;

fn description() -> evseg_schemas::describe::NodeDescription {
    Describe::new(
        "evseg-recorder",
        "records node outputs into one MCAP file (inputs are chosen by the launcher, one per output)",
    )
    .required(
        "path",
        "the MCAP file to write (absolute, or relative to the node's working folder)",
    )
    .param(
        "metadata",
        serde_json::Value::Null,
        "run facts stored as the `evseg.run` metadata record (object of strings; the launcher fills it)",
    )
    .param(
        "chunk_bytes",
        WriterSettings::default().chunk_bytes,
        "target uncompressed MCAP chunk size, bytes, 1024..=1073741824 (default: the mcap crate's 1 MiB)",
    )
    .param(
        "zstd_level",
        WriterSettings::default().zstd_level,
        "zstd level of the chunks, 0..=22 (0 = zstd's default, 3; 20 and above need much memory)",
    )
    .build()
}

struct Recorder {
    file: Option<McapRecorder>,
    topics: Vec<String>,
}

fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

fn string_map(value: &serde_json::Value) -> BTreeMap<String, String> {
    match value {
        serde_json::Value::Object(m) => m
            .iter()
            .map(|(k, v)| {
                let text = match v {
                    serde_json::Value::String(s) => s.clone(),
                    other => other.to_string(),
                };
                (k.clone(), text)
            })
            .collect(),
        _ => BTreeMap::new(),
    }
}

fn make(cfg: &NodeConfig) -> Result<Recorder, BoxError> {
    let path: PathBuf = cfg.param::<String>("path")?.into();
    let settings = WriterSettings {
        chunk_bytes: cfg
            .param_opt("chunk_bytes")?
            .unwrap_or(WriterSettings::default().chunk_bytes),
        zstd_level: cfg
            .param_opt("zstd_level")?
            .unwrap_or(WriterSettings::default().zstd_level),
    };
    let channels: Vec<ChannelSpec> = cfg
        .inputs
        .iter()
        .map(|i| ChannelSpec {
            topic: i.port.clone(),
            schema: i.schema.clone(),
            version: evseg_schemas::schema_version(&i.schema).unwrap_or(0),
            metadata: BTreeMap::from([
                ("key".to_string(), i.key.clone()),
                ("producer".to_string(), i.producer.clone()),
            ]),
        })
        .collect();
    let mut file = McapRecorder::create(&path, &channels, &settings)?;
    let mut run = cfg.params.get("metadata").map(string_map).unwrap_or_default();
    run.entry("instance".into())
        .or_insert_with(|| cfg.instance.clone());
    run.entry("mode".into())
        .or_insert_with(|| format!("{:?}", cfg.mode).to_lowercase());
    run.entry("window".into())
        .or_insert_with(|| cfg.window.to_string());
    run.entry("recorder_version".into())
        .or_insert_with(|| env!("CARGO_PKG_VERSION").to_string());
    file.metadata(RUN_METADATA, run)?;
    let graph_path = cfg.run_dir.join(GRAPH_ATTACHMENT);
    match std::fs::read(&graph_path) {
        Ok(graph) => {
            if let Ok(g) = serde_json::from_slice::<serde_json::Value>(&graph) {
                let params: BTreeMap<String, String> = g["nodes"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter_map(|n| Some((n["id"].as_str()?.to_string(), n["params"].to_string())))
                    .collect();
                file.metadata(PARAMS_METADATA, params)?;
            }
            file.attach(GRAPH_ATTACHMENT, "application/json", &graph, now_ns())?;
        }
        Err(e) => tracing::warn!("no {} to store in the recording: {e}", graph_path.display()),
    }
    if let Ok(yaml) = std::fs::read(cfg.run_dir.join("graph.yaml")) {
        file.attach("graph.yaml", "application/yaml", &yaml, now_ns())?;
    }
    tracing::info!(file = %path.display(), channels = channels.len(), "recording");
    Ok(Recorder {
        file: Some(file),
        topics: channels.into_iter().map(|c| c.topic).collect(),
    })
}

impl RawConsumer for Recorder {
    fn frame(&mut self, port: usize, envelope: &Envelope, frame: &[u8]) -> Result<(), BoxError> {
        match self.file.as_mut() {
            Some(f) => Ok(f.write_frame(port, envelope, frame)?),
            None => Err("recording already finished".into()),
        }
    }

    fn finish(&mut self) -> Result<(), BoxError> {
        let Some(mut file) = self.file.take() else {
            return Ok(());
        };
        let counts: BTreeMap<String, String> = self
            .topics
            .iter()
            .zip(file.counts())
            .map(|(t, n)| (t.clone(), n.to_string()))
            .collect();
        tracing::info!(?counts, "recording finished");
        file.metadata(END_METADATA, counts)?;
        file.finish()?;
        Ok(())
    }
}

fn main() -> std::process::ExitCode {
    run_raw_consumer(description(), make)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn description_has_no_fixed_ports_and_requires_a_path() {
        let d = description();
        assert!(d.inputs.is_empty() && d.outputs.is_empty());
        assert!(d.params.iter().any(|p| p.name == "path" && p.required));
    }

    #[test]
    fn run_metadata_values_become_strings() {
        let m = string_map(&serde_json::json!({"a": "x", "b": 3, "c": {"d": 1}}));
        assert_eq!(m["a"], "x");
        assert_eq!(m["b"], "3");
        assert_eq!(m["c"], "{\"d\":1}");
        assert!(string_map(&serde_json::Value::Null).is_empty());
    }
}
