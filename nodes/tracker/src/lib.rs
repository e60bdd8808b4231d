//! Kalman-filter tracking of the merged segments (paper section 3.5, last paragraph: "The
//! resulting merged clusters are tracked using a Kalman Filter-based tracker, which assigns each
//! segment a consistent track ID (ID 0 for background, positive integers for foreground)").
//!
//! - [`kalman`]: constant-velocity Kalman filter on a segment's image centroid (pixels, px/s);
//! - [`association`]: gated matching cost (Mahalanobis distance of centroids and box overlap)
//!   and the optimal (Hungarian) matching of tracks to segments;
//! - [`tracker`]: the per-slice loop ([`Tracker::update`]): predict, expire, match, correct,
//!   open new tracks, relabel events with track ids;
//! - [`params`]: every constant, with its default and where it came from.
//!
//! Image coordinates are pixels (x right, y down); times are seconds on the sequence clock; a
//! slice's time is the centre of its window.

#![deny(missing_docs)]

pub mod association;
pub mod error;
pub mod kalman;
pub mod params;
pub mod tracker;

pub use error::TrackerError;
pub use params::{TentativeEvents, TrackerParams};
pub use tracker::Tracker;

#[cfg(test)]
mod tests;
