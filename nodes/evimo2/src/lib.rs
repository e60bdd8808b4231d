//! Read and write EVIMO2 v2 sequence folders (npy/npz, pickled meta).
//!
//! An EVIMO2 v2 sequence folder holds `dataset_events_{t,xy,p}.npy`, `dataset_mask.npz`,
//! optionally `dataset_depth.npz`, and `dataset_info.npz` (`index`, `discretization`, `K`, `D`,
//! `meta`); see METHOD_NOTES §4. Everything is parsed by hand except zip (the `zip` crate) and
//! unpickling (`serde-pickle`).
//!
//! # Reading
//! [`Sequence::open`] reads the calibration, IMU, poses and frame list; [`Sequence::events`]
//! streams events in chunks ([`EventReader::next_chunk`], [`EventReader::read_until`]);
//! [`Sequence::masks`] / [`Sequence::depth`] read one frame at a time.
//!
//! # Times
//! Every time returned is in seconds **relative to the first event**: `t = t_file - t0` with
//! `t0` the earliest of the first 65 536 stored times, `dataset_events_t.npy[0]` in a sorted
//! file ([`Sequence::t0_s`]; `round(t0 * 1e6)` is
//! [`evseg_schemas::CameraInfo::time_origin_us`]). Meta `ts` values share the events' clock.
//! IMU sample times stay on the IMU clock: add `CameraInfo::imu_time_offset_s` (EVIMO2 default
//! -0.02 s) for camera time.
//!
//! # Frames
//! Camera poses are camera -> world; object poses are object -> camera (positions in metres,
//! quaternions `[x, y, z, w]`). IMU samples are in the IMU frame; `CameraInfo::imu_to_camera`
//! (EVIMO2 default: `w_cam = (w_imu.y, -w_imu.x, w_imu.z)`) rotates them into the camera frame.
//! Masks hold object ids (stored value / 1000, 0 = background), ids matching [`FrameTruth`]'s
//! object poses.
//!
//! # Writing
//! [`write_sequence`] / [`write_sequence_with`] write a folder numpy 1.x and 2.x load, with `meta`
//! pickled exactly as `np.savez(..., meta=dict)` does or, optionally, as a `<U` Python literal.
#![warn(missing_docs)]

pub mod error;
pub mod imu_check;
pub mod meta;
pub mod npy;
pub mod npz;
pub mod pickle_write;
pub mod pylit;
pub mod reader;
pub mod writer;

pub use error::{Evimo2Error, Result};
pub use meta::{CameraFallback, EVIMO2_IMU_TIME_OFFSET_S, EVIMO2_IMU_TO_CAMERA, FrameTruth, MetaOptions};
pub use reader::{
    DEFAULT_MAX_TIME_GAP_S, DepthFrame, DepthReader, EVENTS_T, EventReader, FrameEntry, MAX_TIME_GAP_RANGE_S,
    MaskReader, ReadOptions, Sequence, find_sequence_folders,
};
pub use writer::{
    DEFAULT_IMU_TOPIC, MetaForm, SequenceData, SequenceWriter, WriteOptions, write_sequence,
    write_sequence_with,
};
