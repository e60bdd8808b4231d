//! Vendor event-camera files (AEDAT4, Prophesee EVT 2.0/3.0, Event Stream, text) through the
//! streaming decoders of `evseg-formats`, with a camera file for calibration where the format
//! has none.

use std::path::Path;

use evseg_formats::{EventDecoder, OpenOptions};
use evseg_schemas::{CameraInfo, ImuSample};

use crate::order::{DEFAULT_REORDER_WINDOW_S, ReorderBuffer, check_reorder_window};
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
    /// Events read ahead of the last batch's end, sorted by time.
    pending: ReorderBuffer,
    /// How far past a batch's end the file is read, seconds (see
    /// [`FileSource::set_reorder_window`]).
    reorder_window_s: f64,
    imu: Vec<ImuSample>,
    /// Time of the newest IMU sample read so far (sensor clock, s), if any.
    imu_last_t: Option<f64>,
    eof: bool,
    seconds: Option<f64>,
    /// Added to every time the decoder gives, seconds: so that the earliest event of the first
    /// read, not the first one stored, is at 0 (the decoders count time from the first stored
    /// event, and a text file stored out of order may hold earlier ones after it, which would
    /// otherwise come before the first packet and be dropped). `None` until the first read
    /// with events; 0 for every sorted file.
    time_shift_s: Option<f64>,
}

impl FileSource {
    /// Opens `path`; `camera_file` supplies calibration the format lacks.
    pub fn open(path: &Path, camera_file: Option<&Path>, seconds: Option<f64>) -> Result<Self, SourceError> {
        // A camera file's sensor size serves files that do not state theirs (EVT 3.0 without a
        // geometry line, text); a file that states it keeps its own, checked against the camera
        // file's by `build_camera_info`.
        let mut options = OpenOptions::default();
        if let Some(file) = camera_file {
            let cam = evseg_formats::CameraFile::load(file)
                .map_err(|e| SourceError::Param(format!("{}: {e}", path.display())))?;
            if let (Some(w), Some(h)) = (cam.width, cam.height) {
                options.geometry = Some((w, h));
            }
        }
        let decoder = evseg_formats::open(path, &options).map_err(|e| SourceError::Read(e.to_string()))?;
        let camera = evseg_formats::build_camera_info(decoder.as_ref(), camera_file)
            .map_err(|e| SourceError::Param(format!("{}: {e}", path.display())))?;
        Ok(Self::from_decoder(decoder, camera, seconds))
    }

    /// A source reading `decoder` (already opened), with `camera` describing it; stops after
    /// `seconds` of sensor time when given.
    pub fn from_decoder(decoder: Box<dyn EventDecoder>, camera: CameraInfo, seconds: Option<f64>) -> Self {
        Self {
            decoder,
            camera,
            pending: ReorderBuffer::default(),
            reorder_window_s: DEFAULT_REORDER_WINDOW_S,
            imu: Vec::new(),
            imu_last_t: None,
            eof: false,
            seconds,
            time_shift_s: None,
        }
    }

    /// How far past each batch's end the file is read to sort late-stored events into their
    /// batch, seconds (default [`DEFAULT_REORDER_WINDOW_S`]; 0 = batches end at the first
    /// event read at or after their end). The vendor decoders' output is sorted (they raise a
    /// decreasing timestamp and count it); text and Event Stream files are passed on as stored,
    /// so this is what keeps an event stored after later ones in its batch. An event stored more
    /// than this after later ones still arrives late and is dropped and counted by the slicer.
    pub fn set_reorder_window(&mut self, seconds: f64) -> Result<(), SourceError> {
        self.reorder_window_s = check_reorder_window(seconds)?;
        Ok(())
    }

    /// Events that were out of order in the file and were sorted into place (not dropped).
    pub fn reordered(&self) -> u64 {
        self.pending.reordered()
    }
}

impl EventSource for FileSource {
    fn camera(&self) -> CameraInfo {
        self.camera.clone()
    }

    fn counters(&self) -> Vec<(&'static str, u64)> {
        let s = self.decoder.stats();
        vec![
            ("events_reordered", self.pending.reordered()),
            ("time_regressions_raised", s.time_regressions),
            ("times_out_of_order_in_file", s.times_out_of_order),
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
        // Read until the events have passed t_end by the reorder window and, when the file has
        // an IMU, the IMU has passed t_end too (bounded read-ahead), so no event or IMU sample
        // of this batch arrives with the next one.
        let t_read = t_end + self.reorder_window_s;
        let short = |s: &Self| {
            let events_short = s.pending.last_time().is_none_or(|t| t < t_read);
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
                Some(mut chunk) => {
                    let shift = match self.time_shift_s {
                        Some(s) => s,
                        None if chunk.events.is_empty() => 0.0,
                        None => {
                            let earliest = chunk.events.t.iter().copied().fold(0.0, f64::min);
                            // The camera's absolute origin moves back with the times.
                            self.camera.time_origin_us += (earliest * 1e6).round() as i64;
                            // IMU samples read before the first events (a file that starts
                            // with an IMU packet) move with them, or they would sit `earliest`
                            // off the events' clock.
                            self.imu.iter_mut().for_each(|s| s.t -= earliest);
                            self.imu_last_t = self.imu_last_t.map(|t| t - earliest);
                            *self.time_shift_s.insert(-earliest)
                        }
                    };
                    if shift != 0.0 {
                        chunk.events.t.iter_mut().for_each(|t| *t += shift);
                        chunk.imu.iter_mut().for_each(|s| s.t += shift);
                    }
                    self.pending.push(chunk.events);
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
        let events = self.pending.take_before(t_end);
        let cut = self.imu.partition_point(|s| s.t + offset < t_end);
        let imu: Vec<ImuSample> = self.imu.drain(..cut).collect();
        if t_end >= limit {
            self.eof = true;
            self.pending.clear();
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

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_formats::{Chunk, DecodeError, DecodeStats, Format};

    /// A decoder giving fixed chunks: `(event times, IMU times)` each, relative seconds.
    struct Chunks(std::collections::VecDeque<(Vec<f64>, Vec<f64>)>);

    impl EventDecoder for Chunks {
        fn decode_into(&mut self, out: &mut Chunk, _max_events: usize) -> Result<bool, DecodeError> {
            *out = Chunk::with_capacity(4);
            let Some((events, imu)) = self.0.pop_front() else {
                return Ok(false);
            };
            for t in events {
                out.events.push(t, 1, 1, 1);
            }
            out.imu = imu
                .into_iter()
                .map(|t| ImuSample {
                    t,
                    accel: [0.0; 3],
                    gyro: [0.0; 3],
                })
                .collect();
            Ok(true)
        }
        fn geometry(&self) -> (u16, u16) {
            (4, 4)
        }
        fn time_origin_us(&self) -> Option<i64> {
            Some(0)
        }
        fn format(&self) -> Format {
            Format::Text
        }
        fn stats(&self) -> DecodeStats {
            DecodeStats::default()
        }
    }

    #[test]
    fn imu_samples_read_before_the_first_events_move_with_the_events_clock() {
        // The file starts with an IMU packet; the first events hold one stored 4 ms before the
        // first stored event, so every time moves by +4 ms, the early IMU samples included.
        let chunks = vec![
            (vec![], vec![0.000, 0.005]),
            (vec![0.000, -0.004, 0.002, 0.012], vec![0.010, 0.015]),
        ];
        let mut camera = CameraInfo::pinhole(4, 4, 2.0, "test");
        camera.imu_time_offset_s = 0.0;
        let mut source = FileSource::from_decoder(Box::new(Chunks(chunks.into())), camera, None);
        source.set_reorder_window(0.0).unwrap();
        let batch = source.next_batch(0.1).unwrap().unwrap();
        let events: Vec<f64> = batch.events.t.iter().map(|t| (t * 1e3).round()).collect();
        let imu: Vec<f64> = batch.imu.iter().map(|s| (s.t * 1e3).round()).collect();
        assert_eq!(events, [0.0, 4.0, 6.0, 16.0]);
        assert_eq!(imu, [4.0, 9.0, 14.0, 19.0]);
        assert_eq!(source.camera().time_origin_us, -4000);
    }
}
