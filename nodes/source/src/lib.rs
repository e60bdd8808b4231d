//! Event sources, each behind one trait so the source node (and in-process tools such as the
//! transport benchmark) can drive any of them batch by batch.

#![warn(missing_docs)]

pub mod evimo2;
pub mod file;
mod order;
pub mod pattern;
pub mod synthetic;

use evseg_schemas::{CameraInfo, Events, ImuSample, Truth};

/// One batch of a source: events in `[t_start, t_end)`, the IMU samples of that span, and the
/// ground truth when the source has it.
#[derive(Debug, Clone, PartialEq)]
pub struct Batch {
    /// Events, time-ordered, seconds on the sequence clock.
    pub events: Events,
    /// IMU samples of the span (IMU frame).
    pub imu: Vec<ImuSample>,
    /// Ground truth aligned with `events`, if known.
    pub truth: Option<Truth>,
}

/// A source of events.
pub trait EventSource: Send {
    /// Camera description (constant over the stream).
    fn camera(&self) -> CameraInfo;

    /// Everything with `t < t_end` not yet returned; `None` once the source is exhausted.
    fn next_batch(&mut self, t_end: f64) -> Result<Option<Batch>, SourceError>;

    /// True when the source provides ground truth.
    fn has_truth(&self) -> bool;

    /// What the source did to its input so far that a user should know of, as (name, count):
    /// events sorted back into time order, samples skipped or repaired by a decoder, masks read
    /// in another convention. The node logs the non-zero ones and writes all of them to its
    /// summary file when the stream ends. Empty for sources that change nothing.
    fn counters(&self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }
}

/// Why a source cannot continue.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    /// A parameter is invalid.
    #[error("{0}")]
    Param(String),
    /// Reading the input failed.
    #[error("{0}")]
    Read(String),
}
