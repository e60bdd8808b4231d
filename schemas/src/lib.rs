//! Message types of the evseg pipeline.
//!
//! Every message that crosses a process boundary is defined here, with its units and frames, so
//! that every node (and every alternative implementation of a node) agrees on one contract.
//!
//! Conventions used throughout:
//! - **Time**: `f64` seconds on the sequence clock, 0 at the first event of the recording; the
//!   absolute start of that clock (µs since the Unix epoch or the sensor's own epoch) is kept in
//!   [`CameraInfo::time_origin_us`].
//! - **Pixels**: `x` to the right, `y` down, origin at the centre of the top-left pixel.
//! - **Normalized coordinates**: undistorted pinhole coordinates with focal length 1
//!   (`x_n = (x_px - cx) / fx` after undistortion).
//! - **Camera frame**: x right, y down, z forward (optical axis), right-handed.
//! - **Per-event arrays** are aligned index for index with the events of the slice they belong to.
//!
//! The wire format lives in [`codec`] alone; the key layout in [`keys`]; node self-descriptions
//! (`--describe`) in [`describe`].

#![warn(missing_docs)]

pub mod align;
pub mod codec;
pub mod columns;
pub mod describe;
pub mod digest;
pub mod keys;
pub mod messages;
pub mod params;
pub mod recording;

pub use codec::{CodecError, Envelope, Frame, FrameKind, Message, decode, decode_header, encode, encode_end};
pub use messages::*;
