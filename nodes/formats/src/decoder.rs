//! The per-format decoder contract ([`FormatDecoder`]) and the wrapper ([`Buffered`]) that turns
//! one into an [`EventDecoder`]: exact chunk sizes, decoding ahead to the first event at open
//! time, and errors delivered after the events that precede them.

use evseg_schemas::messages::{CameraInfo, Events};

use crate::block_reader::BlockReader;
use crate::{Chunk, DecodeError, DecodeStats, EventDecoder, Format};

/// Most events one record of any format can produce (an EVT 3.0 VECT_12 word); a
/// [`FormatDecoder::fill`] may overshoot its target by less than this.
pub(crate) const MAX_EVENTS_PER_RECORD: usize = 12;

/// Why a block decoder stopped inside the bytes it was given.
pub(crate) enum Stop {
    /// Reached the target event count.
    Full,
    /// Consumed every whole record of the block.
    Block,
    /// A record the format does not allow, at this index (word or byte, as the decoder says), with
    /// its description.
    Fault(usize, String),
}

/// What each format implements.
pub(crate) trait FormatDecoder: Send {
    /// Appends events (and IMU samples met on the way) to `out` until `out.events.len() >=
    /// target` or the end of the file; may overshoot `target` by less than
    /// [`MAX_EVENTS_PER_RECORD`]. Must make progress (consume input) on every call.
    ///
    /// Returns `Ok(true)` when more may follow and `Ok(false)` at the clean end of the file. On
    /// `Err`, `out` holds exactly the complete events decoded before the fault.
    fn fill(&mut self, out: &mut Chunk, target: usize) -> Result<bool, DecodeError>;
    /// Sensor size (width, height), pixels.
    fn geometry(&self) -> (u16, u16);
    /// Absolute time of the first event, µs, once known.
    fn time_origin_us(&self) -> Option<i64>;
    /// The format.
    fn format(&self) -> Format;
    /// Counters (the `events` and `imu_samples` fields are filled by [`Buffered`]).
    fn stats(&self) -> DecodeStats;
    /// Calibration stored with the file.
    fn calibration(&self) -> Option<CameraInfo> {
        None
    }
    /// True when the file carries an IMU stream.
    fn has_imu(&self) -> bool {
        false
    }
}

/// The record decoding of a format read in whole records from a [`BlockReader`] (EVT 2.0,
/// EVT 3.0, Event Stream): [`RecordDecoder`] runs the read loop, this the format.
pub(crate) trait RecordState: Send {
    /// The format.
    const FORMAT: Format;
    /// Bytes a record needs (the decoder refills below this).
    const RECORD_BYTES: usize;
    /// Decodes the whole records of `bytes` (starting at file offset `start`) into `out` until
    /// `out.events.len() >= target`: the bytes consumed and why it stopped.
    fn decode(&mut self, bytes: &[u8], start: u64, out: &mut Chunk, target: usize) -> (usize, Stop);
    /// File offset of the fault at record `index` of the block that started at `start`.
    fn fault_offset(&self, start: u64, index: usize) -> u64;
    /// At the end of the file with `left` bytes (fewer than a record) undecoded, the next at
    /// file offset `offset`: `None` for a clean end, else where and what is truncated.
    fn truncated_at_end(&self, left: usize, offset: u64) -> Option<(u64, String)>;
    /// Sensor size (width, height), pixels.
    fn geometry(&self) -> (u16, u16);
    /// Absolute time of the first event, µs, once known.
    fn time_origin_us(&self) -> Option<i64>;
    /// Counters.
    fn stats(&self) -> DecodeStats;
    /// Prepares `out` before a fill up to `target` events (default: nothing).
    fn prepare(&self, _out: &mut Chunk, _target: usize) {}
}

/// A [`RecordState`] and the reader of its file: the [`FormatDecoder`] of the record formats.
pub(crate) struct RecordDecoder<S> {
    /// The file, positioned at the next undecoded byte.
    pub reader: BlockReader,
    /// The format's state.
    pub state: S,
}

impl<S: RecordState> FormatDecoder for RecordDecoder<S> {
    fn fill(&mut self, out: &mut Chunk, target: usize) -> Result<bool, DecodeError> {
        self.state.prepare(out, target);
        loop {
            let bytes = self.reader.available();
            if bytes.len() < S::RECORD_BYTES {
                if self.reader.refill()? {
                    continue;
                }
                let left = self.reader.available().len();
                return match self.state.truncated_at_end(left, self.reader.offset()) {
                    None => Ok(false),
                    Some((offset, what)) => Err(DecodeError::Truncated {
                        path: self.reader.path().to_path_buf(),
                        offset,
                        what,
                    }),
                };
            }
            let start = self.reader.offset();
            let (consumed, stop) = self.state.decode(bytes, start, out, target);
            self.reader.consume(consumed);
            match stop {
                Stop::Full => return Ok(true),
                Stop::Block => {}
                Stop::Fault(index, what) => {
                    return Err(DecodeError::Corrupt {
                        path: self.reader.path().to_path_buf(),
                        offset: self.state.fault_offset(start, index),
                        what,
                    });
                }
            }
        }
    }

    fn geometry(&self) -> (u16, u16) {
        self.state.geometry()
    }

    fn time_origin_us(&self) -> Option<i64> {
        self.state.time_origin_us()
    }

    fn format(&self) -> Format {
        S::FORMAT
    }

    fn stats(&self) -> DecodeStats {
        self.state.stats()
    }
}

/// Converts absolute µs timestamps to seconds relative to the first one seen.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct TimeBase {
    /// The first timestamp seen, µs.
    pub origin: Option<i64>,
}

impl TimeBase {
    /// Seconds from the origin to `t_us` (which becomes the origin if none is set yet).
    #[inline]
    pub fn seconds(&mut self, t_us: i64) -> f64 {
        let origin = *self.origin.get_or_insert(t_us);
        Self::relative(origin, t_us)
    }

    /// Seconds from `origin_us` to `t_us`, exact for differences below 2^53 µs, never
    /// overflowing.
    #[inline]
    pub fn relative(origin_us: i64, t_us: i64) -> f64 {
        match t_us.checked_sub(origin_us) {
            Some(d) => d as f64 / 1e6,
            None => (t_us as f64 - origin_us as f64) / 1e6,
        }
    }
}

/// Wraps a [`FormatDecoder`] into an [`EventDecoder`].
pub(crate) struct Buffered<F> {
    inner: F,
    /// Events decoded ahead (priming, overshoot), delivered first.
    carry: Chunk,
    /// An error met after some events: returned on the call after those events.
    pending_error: Option<DecodeError>,
    /// The inner decoder reached the end or failed.
    inner_done: bool,
    events_returned: u64,
    imu_returned: u64,
}

impl<F: FormatDecoder> Buffered<F> {
    /// Wraps `inner` and decodes ahead to its first event, so that the time origin is known. A
    /// fault before any event is returned here.
    pub fn new(mut inner: F) -> Result<Self, DecodeError> {
        let mut carry = Chunk::default();
        let mut pending_error = None;
        let mut inner_done = false;
        while carry.events.is_empty() && !inner_done {
            match inner.fill(&mut carry, 1) {
                Ok(more) => inner_done = !more,
                Err(error) => {
                    if carry.is_empty() {
                        return Err(error);
                    }
                    pending_error = Some(error);
                    inner_done = true;
                }
            }
        }
        Ok(Buffered {
            inner,
            carry,
            pending_error,
            inner_done,
            events_returned: 0,
            imu_returned: 0,
        })
    }

    fn take_from_carry(&mut self, out: &mut Chunk, max_events: usize) {
        let n = self.carry.events.len().min(max_events);
        if n > 0 {
            out.events.extend_from(&self.carry.events, 0..n);
            let c = &mut self.carry.events;
            c.t.drain(0..n);
            c.x.drain(0..n);
            c.y.drain(0..n);
            c.p.drain(0..n);
        }
        out.imu.append(&mut self.carry.imu);
    }
}

fn split_tail(events: &mut Events, at: usize) -> Events {
    Events {
        t: events.t.split_off(at),
        x: events.x.split_off(at),
        y: events.y.split_off(at),
        p: events.p.split_off(at),
    }
}

impl<F: FormatDecoder> EventDecoder for Buffered<F> {
    fn decode_into(&mut self, out: &mut Chunk, max_events: usize) -> Result<bool, DecodeError> {
        out.clear();
        let max_events = max_events.max(1);
        self.take_from_carry(out, max_events);
        while out.events.len() < max_events && !self.inner_done {
            match self.inner.fill(out, max_events) {
                Ok(more) => self.inner_done = !more,
                Err(error) => {
                    self.inner_done = true;
                    if out.is_empty() {
                        return Err(error);
                    }
                    self.pending_error = Some(error);
                }
            }
        }
        if out.events.len() > max_events {
            // Only reached with an empty carry: the carry is drained before the inner decoder runs.
            self.carry.events = split_tail(&mut out.events, max_events);
        }
        if out.is_empty() {
            return match self.pending_error.take() {
                Some(error) => Err(error),
                None => Ok(false),
            };
        }
        self.events_returned += out.events.len() as u64;
        self.imu_returned += out.imu.len() as u64;
        Ok(true)
    }

    fn geometry(&self) -> (u16, u16) {
        self.inner.geometry()
    }

    fn time_origin_us(&self) -> Option<i64> {
        self.inner.time_origin_us()
    }

    fn format(&self) -> Format {
        self.inner.format()
    }

    fn stats(&self) -> DecodeStats {
        DecodeStats {
            events: self.events_returned,
            imu_samples: self.imu_returned,
            ..self.inner.stats()
        }
    }

    fn calibration(&self) -> Option<CameraInfo> {
        self.inner.calibration()
    }

    fn has_imu(&self) -> bool {
        self.inner.has_imu()
    }
}
