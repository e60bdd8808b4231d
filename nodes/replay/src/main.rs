//! `evseg-replay`: publishes recorded node outputs on their original keys.
//!
//! `evseg replay` starts this node instead of the nodes upstream of (and including) the replay
//! point. Its outputs are chosen by the launcher: one per replayed output, named like the
//! recording's topic (`node/output`) and bound to that output's original key, with the live
//! consumers. It reads the recording in a thread (a cut-off file up to its last complete chunk),
//! validates each frame's envelope against its channel, and publishes the frames unchanged: per
//! output in recorded order, with lock-step credits like the original producer, optionally paced
//! at `speed` times the recorded publish times; then ends every output.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, sync_channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use evseg_recorder::RecordError;
use evseg_recorder::read::Recording;
use evseg_replay::ReplayError;
use evseg_replay::keep::KeptSlices;
use evseg_replay::schedule::{Pacing, Pending, Scheduler};
use evseg_runtime::describe::Describe;
use evseg_runtime::transport::POLL;
use evseg_runtime::{BoxError, NodeConfig, Outputs, RuntimeError, Source, run_raw_source, signals};
use evseg_schemas::{FrameKind, codec};

/// Default of `read_ahead`: recorded frames held in memory beyond those being published. A
/// lock-step run keeps every output within `window` frames of the others, so a few dozen
/// frames always reach the next frame of every output; 32 slices of 100k events are about 50 MB.
const READ_AHEAD: usize = 32;

fn description() -> evseg_schemas::describe::NodeDescription {
    Describe::new(
        "evseg-replay",
        "publishes the recorded outputs of an MCAP recording on their original keys (outputs are chosen by the launcher, one per replayed output)",
    )
    .required(
        "path",
        "the MCAP recording (written by `evseg run --record`) to replay",
    )
    .param(
        "speed",
        serde_json::Value::Null,
        "playback speed relative to the recorded publish times (1 = as recorded, 2 = twice as fast); null = as fast as lock-step credits allow",
    )
    .param(
        "limits",
        serde_json::Value::Null,
        "most frames replayed per output (object: topic -> count; null = all); the launcher sets it for a cut-off recording so that the outputs of one node end at the same slice",
    )
    .param(
        "keep",
        serde_json::Value::Null,
        "slices to replay, renumbered 0, 1, 2, ... in order (`{\"ranges\": [[start, end], ...]}` of recorded slice numbers; null = every frame, numbers as recorded); `evseg replay --skip-gaps` sets it to the slices every replayed channel holds",
    )
    .param(
        "read_ahead",
        READ_AHEAD,
        "recorded frames held in memory ahead of publishing (>= 1)",
    )
    .build()
}

/// A frame as the reader thread hands it over.
struct Raw {
    port: usize,
    index: u64,
    log_ns: u64,
    bytes: Vec<u8>,
}

struct Replay {
    file: PathBuf,
    /// (output name = topic, schema) per output port.
    ports: Vec<(String, String)>,
    rx: Receiver<Raw>,
    reader: Option<JoinHandle<Result<Recording, RecordError>>>,
    eof: bool,
    order: u64,
    sched: Scheduler,
    pacing: Pacing,
    read_ahead: usize,
    published: u64,
    started: Option<Instant>,
    /// Slices replayed, renumbered (`keep`); `None`: every frame as recorded.
    keep: Option<KeptSlices>,
    /// Frames left out by `keep`.
    left_out: u64,
}

fn param_err(name: &str, reason: impl std::fmt::Display) -> ReplayError {
    ReplayError::Param {
        name: name.into(),
        reason: reason.to_string(),
    }
}

fn make(cfg: &NodeConfig) -> Result<Replay, BoxError> {
    let file: PathBuf = cfg.param::<String>("path")?.into();
    let speed: Option<f64> = cfg.param_opt("speed")?;
    if let Some(s) = speed
        && !(s.is_finite() && s > 0.0)
    {
        return Err(param_err("speed", format!("must be a number > 0 or null, got {s}")).into());
    }
    let read_ahead: usize = cfg.param_opt("read_ahead")?.unwrap_or(READ_AHEAD);
    if read_ahead == 0 {
        return Err(param_err("read_ahead", "must be >= 1").into());
    }
    let ports: Vec<(String, String)> = cfg
        .outputs
        .iter()
        .map(|o| (o.port.clone(), o.schema.clone()))
        .collect();
    let topics: BTreeMap<String, usize> = ports
        .iter()
        .enumerate()
        .map(|(i, (t, _))| (t.clone(), i))
        .collect();
    let limits_by_topic: BTreeMap<String, u64> = cfg.param_opt("limits")?.unwrap_or_default();
    let limits: Vec<u64> = ports
        .iter()
        .map(|(t, _)| limits_by_topic.get(t).copied().unwrap_or(u64::MAX))
        .collect();
    let keep: Option<KeptSlices> = cfg.param_opt("keep")?;
    if let Some(k) = &keep {
        k.validate().map_err(|e| param_err("keep", e))?;
    }
    let (tx, rx) = sync_channel(read_ahead);
    let reader_file = file.clone();
    let reader = std::thread::Builder::new()
        .name("replay-reader".into())
        .spawn(move || read_frames(&reader_file, &topics, &limits, &tx))
        .map_err(|e| format!("cannot start the reader thread: {e}"))?;
    tracing::info!(file = %file.display(), outputs = ports.len(), ?speed, "replaying");
    Ok(Replay {
        file,
        sched: Scheduler::new(ports.len()),
        ports,
        rx,
        reader: Some(reader),
        eof: false,
        order: 0,
        pacing: Pacing::new(speed),
        read_ahead,
        published: 0,
        started: None,
        keep,
        left_out: 0,
    })
}

/// Streams the frames of the replayed topics to `tx`, in file order, at most `limits[port]`
/// per output.
fn read_frames(
    file: &std::path::Path,
    topics: &BTreeMap<String, usize>,
    limits: &[u64],
    tx: &SyncSender<Raw>,
) -> Result<Recording, RecordError> {
    let mut counts = vec![0u64; topics.len()];
    evseg_recorder::read::read(file, |m| {
        let Some(&port) = topics.get(&m.channel.topic) else {
            return Ok(());
        };
        let index = counts[port];
        counts[port] += 1;
        if index >= limits[port] {
            return Ok(());
        }
        tx.send(Raw {
            port,
            index,
            log_ns: m.log_time,
            bytes: m.data.to_vec(),
        })
        .map_err(|_| RecordError::Io {
            file: file.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::BrokenPipe, "the replay stopped reading"),
        })
    })
}

impl Replay {
    /// Checks a recorded frame against its channel and queues it.
    fn admit(&mut self, raw: Raw) -> Result<(), ReplayError> {
        let (topic, schema) = &self.ports[raw.port];
        let bad = |reason: String| ReplayError::BadFrame {
            file: self.file.clone(),
            topic: topic.clone(),
            index: raw.index,
            reason,
        };
        let (envelope, _) = codec::decode_header(&raw.bytes).map_err(|e| bad(e.to_string()))?;
        if envelope.kind != FrameKind::Data {
            return Err(bad("an end-of-stream frame among the data frames".into()));
        }
        if envelope.schema != *schema {
            return Err(bad(format!(
                "frame of schema {}, channel of {schema}",
                envelope.schema
            )));
        }
        let (seq, bytes) = match &self.keep {
            None => (envelope.seq, raw.bytes),
            Some(keep) => match keep.rank(envelope.seq) {
                None => {
                    self.left_out += 1;
                    return Ok(());
                }
                Some(n) => (n, codec::with_seq(&raw.bytes, n).map_err(|e| bad(e.to_string()))?),
            },
        };
        self.sched.push(Pending {
            port: raw.port,
            order: self.order,
            index: raw.index,
            log_ns: raw.log_ns,
            seq,
            t_end: envelope.t_end,
            bytes,
        });
        self.order += 1;
        Ok(())
    }

    /// The reader finished: says how complete the file was.
    fn reader_done(&mut self) -> Result<(), BoxError> {
        self.eof = true;
        let Some(handle) = self.reader.take() else {
            return Ok(());
        };
        let recording = handle
            .join()
            .map_err(|_| format!("{}: the reader thread panicked", self.file.display()))??;
        if recording.truncated.is_some() {
            tracing::warn!("replaying what was recovered: {}", recording.completeness());
        } else {
            tracing::info!("{}", recording.completeness());
        }
        Ok(())
    }
}

impl Source for Replay {
    fn step(&mut self, out: &mut Outputs) -> Result<bool, BoxError> {
        loop {
            if signals::stop_requested() {
                return Err(Box::new(RuntimeError::Stopped));
            }
            let now = Instant::now();
            let mut next_due: Option<Instant> = None;
            let (ports, pacing) = (&self.ports, &mut self.pacing);
            let pick = self.sched.pick(|f| {
                if let Some(due) = pacing.due(f.log_ns, now)
                    && due > now
                {
                    next_due = Some(next_due.map_or(due, |d| d.min(due)));
                    return Ok(false);
                }
                out.credit_available(&ports[f.port].0, f.seq)
            })?;
            if let Some(port) = pick
                && let Some(frame) = self.sched.pop(port)
            {
                self.started.get_or_insert(now);
                out.send_bytes(&self.ports[port].0, frame.seq, frame.t_end, frame.bytes)?;
                self.published += 1;
                return Ok(true);
            }
            let wait = next_due.map_or(POLL, |d| d.saturating_duration_since(now).min(POLL));
            if !self.eof && self.sched.held() < self.read_ahead {
                match self.rx.recv_timeout(wait.max(Duration::from_millis(1))) {
                    Ok(raw) => self.admit(raw)?,
                    Err(RecvTimeoutError::Timeout) => {}
                    Err(RecvTimeoutError::Disconnected) => self.reader_done()?,
                }
                continue;
            }
            if self.eof && self.sched.held() == 0 {
                let secs = self.started.map_or(0.0, |t| t.elapsed().as_secs_f64());
                tracing::info!(
                    frames = self.published,
                    left_out = self.left_out,
                    seconds = secs,
                    per_second = self.published as f64 / secs.max(1e-9),
                    "replay finished"
                );
                return Ok(false);
            }
            out.wait_progress(wait)?;
        }
    }
}

fn main() -> std::process::ExitCode {
    run_raw_source(description(), make)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn description_has_no_fixed_ports_and_requires_a_path() {
        let d = description();
        assert!(d.inputs.is_empty() && d.outputs.is_empty());
        assert!(d.params.iter().any(|p| p.name == "path" && p.required));
        assert!(d.params.iter().any(|p| p.name == "speed" && !p.required));
    }
}
