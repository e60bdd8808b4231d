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

/// Most events held ahead of a batch's end while waiting for the IMU to pass it too. Vendors
/// write IMU packets after the event packets of the same time (DV does), so a batch cut as soon
/// as the events pass its end would miss IMU samples that follow; a recording whose IMU stops
/// early stops the read-ahead at this bound (about 13 MB of events).
pub const MAX_IMU_READ_AHEAD: usize = 1_000_000;

/// A camera file recording as a source.
pub struct FileSource {
    decoder: Box<dyn EventDecoder>,
    camera: CameraInfo,
    pending: Events,
    imu: Vec<ImuSample>,
    /// Time of the newest IMU sample read so far (sensor clock, s), if any.
    imu_last_t: Option<f64>,
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
            imu_last_t: None,
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

    fn counters(&self) -> Vec<(&'static str, u64)> {
        let s = self.decoder.stats();
        vec![
            ("events_reordered", self.reordered),
            ("time_regressions_raised", s.time_regressions),
            ("out_of_range_dropped", s.out_of_range),
            ("words_before_time_base_skipped", s.words_before_time_base),
            ("trigger_words_skipped", s.triggers),
            ("exposure_events_skipped", s.exposure_events),
            ("packets_skipped", s.skipped_packets),
        ]
    }

    fn next_batch(&mut self, t_end: f64) -> Result<Option<Batch>, SourceError> {
        let limit = self.seconds.unwrap_or(f64::INFINITY);
        let t_end = t_end.min(limit);
        let offset = self.camera.imu_time_offset_s;
        // Read until the events have passed t_end and, when the file has an IMU, the IMU too
        // (bounded read-ahead), so no IMU sample of this batch arrives with the next one.
        let short = |s: &Self| {
            let events_short = s.pending.t.last().is_none_or(|&t| t < t_end);
            let imu_short =
                s.imu_last_t.is_some_and(|t| t + offset < t_end) && s.pending.len() < MAX_IMU_READ_AHEAD;
            events_short || imu_short
        };
        while !self.eof && short(self) {
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
                    if let Some(last) = chunk.imu.last() {
                        self.imu_last_t = Some(self.imu_last_t.map_or(last.t, |t| t.max(last.t)));
                    }
                    self.imu.extend(chunk.imu);
                }
                None => self.eof = true,
            }
        }
        if self.eof && self.pending.is_empty() {
            return Ok(None);
        }
        let events = take_before(&mut self.pending, t_end);
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
