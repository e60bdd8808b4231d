//! The SDK every evseg node uses.
//!
//! A node binary is a few lines: build a [`NodeDescription`](evseg_schemas::describe::NodeDescription)
//! of its ports and parameters, implement [`Stage`] or [`Source`] with the algorithm (which lives
//! in a library crate with no Zenoh in it), and call [`run_stage`] or [`run_source`]. The runtime
//! then:
//! - answers `--describe` with the description (the launcher checks graphs against it);
//! - reads the config the launcher wrote (`--config FILE`): keys, wiring, parameters, mode;
//! - opens the Zenoh session, declares subscribers, then a liveliness token;
//! - joins inputs by slice sequence number (feedback inputs get the previous slice);
//! - in lock-step mode, holds at most `window` messages in flight per edge, waiting for each
//!   consumer's progress (hop-by-hop credit, so nothing is lost however slow a stage is); in live
//!   mode, never waits and drops the oldest input when a queue overflows, counting drops;
//! - refuses messages of the wrong schema or version with an error naming both;
//! - publishes progress and statistics, ends streams cleanly, and stops on SIGTERM/SIGINT.
//!
//! A node whose inputs the launcher chooses (the recorder) implements [`RawConsumer`] instead and
//! calls [`run_raw_consumer`]: every port on its own, no join, any schema, same credits. A source
//! whose outputs the launcher chooses (the replay source) calls [`run_raw_source`] and publishes
//! recorded frames with [`Outputs::send_bytes`], polling [`Outputs::credit_available`].

#![warn(missing_docs)]

pub mod config;
pub mod describe;
pub mod error;
pub mod join;
pub mod memory;
pub mod node;
pub mod progress;
pub mod raw;
pub mod signals;
pub mod transport;

pub use config::{Mode, NodeConfig};
pub use error::{BoxError, RuntimeError};
pub use node::{Inputs, Outputs, Source, Stage, run_raw_source, run_source, run_stage};
pub use raw::{RawConsumer, run_raw_consumer};
