//! Replay of a recording: the source side of `evseg replay`.
//!
//! `evseg replay run.mcap --graph graph.yaml --from slicer` starts the nodes downstream of
//! `slicer` live and, instead of `slicer` and the nodes upstream of it, one `evseg-replay`
//! process that publishes the recorded frames of their outputs on the same Zenoh keys. This crate
//! holds what that needs besides Zenoh: checking a recording has the channels a replay needs
//! ([`check`]), and choosing which recorded frame to publish next ([`schedule`]): per output in
//! recorded order, across outputs the earliest recorded frame that has lock-step credit (and, when
//! paced, whose recorded publish time has come), so the replay never waits on one output while a
//! consumer needs another.

#![warn(missing_docs)]

pub mod check;
pub mod error;
pub mod keep;
pub mod schedule;

pub use error::ReplayError;
