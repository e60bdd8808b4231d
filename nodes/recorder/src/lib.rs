//! Recordings of evseg runs as MCAP files: writing them (the `evseg-recorder` node), reading them
//! back record by record (a file cut off mid-write is read up to its last complete chunk), and
//! exporting them as NumPy files.
//!
//! A recording has one channel per recorded node output (topic `node/output`, schema name =
//! the message schema, e.g. `evseg.Slice`, channel metadata `schema_version`, `key`,
//! `producer`), message encoding [`MESSAGE_ENCODING`]; each message is the exact frame that
//! travelled on the wire (envelope and body, see `evseg_schemas::codec`), log time = the frame's
//! publish time (ns since the Unix epoch), MCAP sequence = the frame's sequence number (slice or
//! batch number). The run's metadata (metadata record [`RUN_METADATA`]), each node's parameters
//! ([`PARAMS_METADATA`]) and the resolved graph (attachment `graph.resolved.json`) are stored too.
//! Chunks are zstd-compressed.

#![warn(missing_docs)]

pub mod error;
pub mod export;
pub mod read;
pub mod write;

pub use error::RecordError;

/// MCAP message encoding of every channel: an evseg frame (bincode 2 envelope and body).
pub const MESSAGE_ENCODING: &str = "evseg-bincode2";
/// MCAP schema encoding: the schema data is a text naming the Rust type and the codec.
pub const SCHEMA_ENCODING: &str = "evseg-rust-serde";
/// Name of the metadata record with the run's facts (graph hash, evseg version, instance, ...).
pub const RUN_METADATA: &str = "evseg.run";
/// Name of the metadata record with each node's parameters (node id -> JSON object).
pub const PARAMS_METADATA: &str = "evseg.params";
/// Name of the metadata record written when the recording ends (messages per topic).
pub const END_METADATA: &str = "evseg.recording";
/// Name of the attachment holding the resolved graph.
pub const GRAPH_ATTACHMENT: &str = "graph.resolved.json";
