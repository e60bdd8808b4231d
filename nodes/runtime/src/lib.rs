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
//! # Writing a stage of your own
//!
//! A replacement for one of the method's stages (here a normal-flow estimator, to run in place
//! of `evseg-normal-flow`) is a binary that declares the same ports with the same message types
//! (`<binary> --describe` prints a node's ports, parameters and their documentation) and any
//! parameters of its own. Build it, put it on `PATH` (or next to `evseg`, or name it by a path
//! relative to the graph file), and compare it with the built-in stage on a recording:
//! `evseg ab graph.yaml --recording run.mcap --swap flow=my-normal-flow`. Parameters of the
//! built-in stage it does not declare are dropped from variant B, and optional inputs of other
//! nodes that read an output it does not publish are left unwired, each with a note; a port it
//! lacks that another node needs is refused with the graph's file, line and column.
//!
//! ```no_run
//! use evseg_runtime::describe::Describe;
//! use evseg_runtime::{BoxError, Inputs, Outputs, Stage, run_stage};
//! use evseg_schemas::{NormalFlow, Slice};
//!
//! struct MyFlow {
//!     /// A parameter: given in graph.yaml `params:` or with `--set flow.min_speed=...`.
//!     min_speed: f32,
//!     /// The output, reused from slice to slice.
//!     flow: NormalFlow,
//! }
//!
//! impl Stage for MyFlow {
//!     fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
//!         let slice: Slice = input.get("slices")?;
//!         // One estimate per event, aligned with `slice.events`; confidence 0 = none.
//!         self.flow.reset_invalid(slice.events.len());
//!         // ... the estimator: fill nx, ny (normalized units per second) and confidence,
//!         // leaving estimates slower than `self.min_speed` at confidence 0 ...
//!         let (t0, t1) = input.span();
//!         out.send("flow", input.seq(), t0, t1, &self.flow)?;
//!         Ok(())
//!     }
//! }
//!
//! fn main() -> std::process::ExitCode {
//!     let description = Describe::new("my-normal-flow", "Normal flow by my method")
//!         .input::<Slice>("slices", "slices of events")
//!         .output::<NormalFlow>("flow", "normal flow per event, normalized units/s")
//!         .param("min_speed", 0.0, "slowest estimate kept, normalized units/s")
//!         .build();
//!     run_stage(description, |cfg| {
//!         Ok(MyFlow {
//!             min_speed: cfg.param("min_speed")?,
//!             flow: NormalFlow::default(),
//!         })
//!     })
//! }
//! ```
//!
//! `evseg-baseline` (`nodes/baseline/src/main.rs`) is a complete stage of this shape with its
//! tests.
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
