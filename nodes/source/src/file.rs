//! Vendor event-camera files (AEDAT4, Prophesee EVT 2.0/3.0, Event Stream, text) through the
//! streaming decoders of `evseg-formats`, with a camera file for calibration where the format
//! has none.

use std::path::Path;

use evseg_formats::{EventDecoder, OpenOptions};
use evseg_schemas::{CameraInfo, Events, ImuSample};

use crate::order::{sort_by_time, take_before};
use crate::{Batch, EventSource, SourceError};

/// Events decoded per read from the file.
pub const READ_CHUNK: usize = 65_536;

/// A camera file recording as a source.
pub struct FileSource {
    decoder: Box<dyn EventDecoder>,
    camera: CameraInfo,
    pending: Events,
    imu: Vec<ImuSample>,
    eof: bool,
    seconds: Option<f64>,
    /// Events out of order within a read (sorted, not dropped).
    pub reordered: u64,
}

impl FileSource {
    /// Opens `path`; `camera_file` supplies calibration the format lacks.
    pub fn open(path: &Path, camera_file: Option<&Path>, seconds: Option<f64>) -> Result<Self, SourceError> {
        let decoder = evseg_formats::open(path, &OpenOptions::default())
            .map_err(|e| SourceError::Read(e.to_string()))?;
        let camera = evseg_formats::build_camera_info(decoder.as_ref(), camera_file)
            .map_err(|e| SourceError::Param(format!("{}: {e}", path.display())))?;
        Ok(Self {
            decoder,
            camera,
            pending: Events::default(),
            imu: Vec::new(),
            eof: false,
            seconds,
            reordered: 0,
        })
    }
}

impl EventSource for FileSource {
    fn camera(&self) -> CameraInfo {
        self.camera.clone()
    }

    fn next_batch(&mut self, t_end: f64) -> Result<Option<Batch>, SourceError> {
        let limit = self.seconds.unwrap_or(f64::INFINITY);
        let t_end = t_end.min(limit);
        while !self.eof && self.pending.t.last().is_none_or(|&t| t < t_end) {
            match self
                .decoder
                .next_chunk(READ_CHUNK)
                .map_err(|e| SourceError::Read(e.to_string()))?
            {
                Some(chunk) => {
                    let mut ev = chunk.events;
                    self.reordered += sort_by_time(&mut ev) as u64;
                    let n = ev.len();
                    self.pending.extend_from(&ev, 0..n);
                    self.imu.extend(chunk.imu);
                }
                None => self.eof = true,
            }
        }
        if self.eof && self.pending.is_empty() {
            return Ok(None);
        }
        let events = take_before(&mut self.pending, t_end);
        let offset = self.camera.imu_time_offset_s;
        let cut = self.imu.partition_point(|s| s.t + offset < t_end);
        let imu: Vec<ImuSample> = self.imu.drain(..cut).collect();
        if t_end >= limit {
            self.eof = true;
            self.pending = Events::default();
        }
        Ok(Some(Batch {
            events,
            imu,
            truth: None,
        }))
    }

    fn has_truth(&self) -> bool {
        false
    }
}
