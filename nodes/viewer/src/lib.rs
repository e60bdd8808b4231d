//! Rerun visualisation of evseg runs.
//!
//! One library serves the live `evseg-viewer` node (frames from the graph, streamed to a
//! running viewer or written to an .rrd file) and `evseg view run.mcap` (frames from a
//! recording): both hand encoded frames to [`frames::log_frame`], which decodes them and calls
//! the [`logger::RunLogger`]. The entity layout and timelines are documented in [`logger`].
//!
//! Drawn: each slice's events as 2-D points (pixels) coloured by polarity, by every segment /
//! track labelling (stable colour per id), by normal-flow direction and by the ground-truth
//! object; track boxes labelled `id N`; egomotion (estimated and true) and evaluator metrics as
//! time series. Slices are decimated to [`ViewerParams::max_points_per_slice`] events.

#![warn(missing_docs)]

pub mod colour;
pub mod decimate;
pub mod error;
pub mod frames;
pub mod logger;
pub mod params;
pub mod recording;
pub mod sink;

pub use error::ViewError;
pub use frames::log_frame;
pub use logger::{LogStats, Origin, RunLogger};
pub use params::ViewerParams;
pub use recording::{ViewSummary, view_recording};
pub use sink::{Sink, open};

/// Re-export of the Rerun SDK this crate logs with (for tests and callers that build streams,
/// e.g. an in-memory sink).
pub use rerun;
