//! `evseg view`: an MCAP recording of a run (from `evseg run --record`) turned into a Rerun
//! recording, through the same [`RunLogger`] the live node uses.

use std::path::Path;

use evseg_recorder::read::{ChannelInfo, Recording, read};
use evseg_schemas::Message;

use crate::error::ViewError;
use crate::frames::log_frame;
use crate::logger::{LogStats, RunLogger};
use crate::params::ViewerParams;
use crate::sink::{Sink, open};

/// What [`view_recording`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewSummary {
    /// The MCAP recording as read (completeness, channels).
    pub recording: Recording,
    /// The node whose slices were drawn, if any.
    pub slices_from: Option<String>,
    /// What was logged.
    pub stats: LogStats,
}

/// The node that produced a channel: its `producer` metadata, else the topic up to the first `/`.
pub fn producer(channel: &ChannelInfo) -> &str {
    channel
        .metadata
        .get("producer")
        .map(String::as_str)
        .unwrap_or_else(|| channel.topic.split('/').next().unwrap_or(&channel.topic))
}

/// Reads the recording at `mcap` (a cut-off one up to its last complete chunk) and logs every
/// message to `sink` in file order. The slices drawn are those of the first `evseg.Slice`
/// channel. The file sink is complete when this returns.
pub fn view_recording(mcap: &Path, sink: &Sink, params: &ViewerParams) -> Result<ViewSummary, ViewError> {
    params.validate()?;
    // First pass: the channels, to know whose slices the per-event truth is aligned with.
    let channels = read(mcap, |_| Ok(()))?;
    let slices_from = channels
        .channels
        .values()
        .find(|c| c.schema == evseg_schemas::Slice::SCHEMA)
        .map(|c| producer(c).to_string());
    let name = mcap
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "evseg".into());
    let mut logger = RunLogger::new(open(sink, &name)?, params.clone())?;
    if let Some(p) = &slices_from {
        logger.expect_slices_from(p);
    }
    let mut failure: Option<ViewError> = None;
    let recording = read(mcap, |m| {
        if failure.is_none()
            && let Err(e) = log_frame(&mut logger, producer(m.channel), m.data)
        {
            failure = Some(e);
        }
        Ok(())
    })?;
    if let Some(e) = failure {
        return Err(e);
    }
    let stats = logger.finish().map_err(|e| match e {
        ViewError::Flush { reason, .. } => ViewError::Flush {
            sink: sink.to_string(),
            reason,
        },
        other => other,
    })?;
    Ok(ViewSummary {
        recording,
        slices_from,
        stats,
    })
}
