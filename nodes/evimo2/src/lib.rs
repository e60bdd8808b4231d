//! Read and write EVIMO2 v2 sequence folders (npy/npz, pickled meta).

pub mod error;
pub mod meta;
pub mod npy;
pub mod npz;
pub mod pickle_write;
pub mod pylit;
pub mod reader;
pub mod writer;

pub use meta::{EVIMO2_IMU_TIME_OFFSET_S, EVIMO2_IMU_TO_CAMERA, FrameTruth, MetaOptions};
pub use reader::{DepthFrame, DepthReader, EventReader, FrameEntry, MaskReader, ReadOptions, Sequence};
pub use writer::{
    DEFAULT_IMU_TOPIC, MetaForm, SequenceData, WriteOptions, write_sequence, write_sequence_with,
};

pub use error::{Evimo2Error, Result};
