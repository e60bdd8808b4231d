//! Read and write EVIMO2 v2 sequence folders (npy/npz, pickled meta).

pub mod error;
pub mod meta;
pub mod npy;
pub mod npz;
pub mod pickle_write;
pub mod pylit;
pub mod reader;
pub mod writer;

pub use meta::{FrameTruth, MetaOptions, EVIMO2_IMU_TIME_OFFSET_S, EVIMO2_IMU_TO_CAMERA};
pub use reader::{DepthFrame, DepthReader, EventReader, FrameEntry, MaskReader, ReadOptions, Sequence};
pub use writer::{write_sequence, write_sequence_with, MetaForm, SequenceData, WriteOptions, DEFAULT_IMU_TOPIC};

pub use error::{Evimo2Error, Result};
