//! Streaming decoders for event-camera files: AEDAT 4 (iniVation DV), Prophesee EVT 2.0 / EVT 3.0
//! `.raw`, Event Stream `.es` (v2) and text (`t x y p` per line, the Event Camera Dataset layout).
//!
//! Every decoder reads its file in blocks with bounded memory (a 10 GB file works) and hands out
//! [`Chunk`]s of events as [`evseg_schemas::messages::Events`] columns:
//!
//! * `t`: seconds, relative to the first event of the file ([`EventDecoder::time_origin_us`] gives
//!   that first event's absolute time in µs, on the file's own clock);
//! * `x`, `y`: pixels, 0 = left / top; `p`: 1 = ON (brightness increase), 0 = OFF.
//!
//! IMU samples (AEDAT 4, text `imu.txt`) come in SI units: angular rate in rad/s, specific force in
//! m/s², IMU frame, `t` in seconds on the same relative clock as the events.
//!
//! Faults never panic: a truncated or corrupt file yields every complete event before the fault,
//! then a [`DecodeError`] naming the file and the byte offset (or line).
//!
//! ```no_run
//! let mut decoder = evseg_formats::open("recording.raw", &evseg_formats::OpenOptions::default())?;
//! while let Some(chunk) = decoder.next_chunk(100_000)? {
//!     println!("{} events", chunk.events.len());
//! }
//! # Ok::<(), evseg_formats::DecodeError>(())
//! ```

#![deny(missing_docs)]

mod aedat4;
mod block_reader;
pub mod camera_file;
mod decoder;
mod error;
mod es;
mod evt2;
mod evt3;
mod flatbuffer;
mod prophesee;
mod text;

use std::io::Read;
use std::path::Path;

pub use camera_file::{CameraFile, CameraFileError, DistortionSpec, build_camera_info};
pub use error::DecodeError;
use evseg_schemas::messages::{CameraInfo, Events, ImuSample};

/// Standard gravity, m/s² per g (the unit of AEDAT 4 accelerometer values).
pub const STANDARD_GRAVITY: f64 = 9.80665;

/// One batch of decoded data.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Chunk {
    /// Events in file order; `t` in seconds relative to the first event. Non-decreasing, except
    /// for a text file stored out of time order: its events are passed on as stored, counted
    /// in [`DecodeStats::times_out_of_order`], for the reader to sort (the binary formats raise
    /// a decreasing timestamp instead, [`DecodeStats::time_regressions`]).
    pub events: Events,
    /// IMU samples decoded in the same stretch of the file (time-ordered, IMU frame, rad/s and
    /// m/s², `t` in seconds on the events' relative clock). Their times are close to, but not
    /// clipped to, the events' time span.
    pub imu: Vec<ImuSample>,
}

impl Chunk {
    /// An empty chunk with room for `n` events.
    pub fn with_capacity(n: usize) -> Self {
        Chunk {
            events: Events::with_capacity(n),
            imu: Vec::new(),
        }
    }

    /// Empties the chunk, keeping its allocations.
    pub fn clear(&mut self) {
        self.events.t.clear();
        self.events.x.clear();
        self.events.y.clear();
        self.events.p.clear();
        self.imu.clear();
    }

    /// True when the chunk holds neither events nor IMU samples.
    pub fn is_empty(&self) -> bool {
        self.events.is_empty() && self.imu.is_empty()
    }
}

/// The file formats this crate decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// iniVation DV AEDAT 4 (`#!AER-DAT4.0`), `.aedat4`.
    Aedat4,
    /// Prophesee EVT 2.0 `.raw` (32-bit words).
    Evt2,
    /// Prophesee EVT 3.0 `.raw` (16-bit words).
    Evt3,
    /// Event Stream `.es`, version 2 (DVS and ATIS streams).
    EventStream,
    /// Text, one `t x y p` event per line (t in seconds), Event Camera Dataset layout.
    Text,
}

/// What to do with an event whose coordinates fall outside the sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum OutOfRange {
    /// Stop with [`DecodeError::Corrupt`] / [`DecodeError::BadLine`] (what faery does; a
    /// coordinate outside the sensor usually means a corrupt file or a wrong sensor size).
    #[default]
    Error,
    /// Drop the event and count it in [`DecodeStats::out_of_range`].
    Drop,
}

/// Options for [`open`]. Every field has a default; see each field for where it comes from.
#[derive(Debug, Clone)]
pub struct OpenOptions {
    /// Format to use; `None` picks it from the file's magic bytes, then its extension.
    pub format: Option<Format>,
    /// Sensor size (width, height) in pixels for files that do not state it (EVT 2.0 / EVT 3.0
    /// without a geometry line, text). A file that states its size uses its own. `None`: EVT 2.0
    /// uses [`OpenOptions::evt2_default_geometry`], EVT 3.0 fails, text scans the file once for
    /// the largest coordinates.
    pub geometry: Option<(u16, u16)>,
    /// Sensor size for EVT 2.0 files without a geometry line: 640 x 480, the Prophesee Gen3
    /// sensor that wrote EVT 2.0 files before geometry lines existed (shared/data/real/README.md).
    pub evt2_default_geometry: (u16, u16),
    /// Policy for events outside the sensor. Default [`OutOfRange::Error`]. EVT 3.0 vector events
    /// past the right edge are always dropped and counted, as faery and OpenEB do.
    pub out_of_range: OutOfRange,
    /// Bytes read from the file at a time: 1 MiB, large enough to amortise system calls and small
    /// enough to stay in L2/L3 cache while it is decoded.
    pub read_block_bytes: usize,
    /// Largest AEDAT 4 packet accepted, compressed or not: 256 MiB. DV writes packets of at most
    /// a few MiB; a larger size field means a corrupt file and must not make us allocate it.
    pub max_packet_bytes: usize,
    /// For text files: read `calib.txt` and `imu.txt` from the events file's directory when they
    /// exist (Event Camera Dataset layout). Default true.
    pub text_sidecars: bool,
}

impl Default for OpenOptions {
    fn default() -> Self {
        OpenOptions {
            format: None,
            geometry: None,
            evt2_default_geometry: (640, 480),
            out_of_range: OutOfRange::Error,
            read_block_bytes: 1 << 20,
            max_packet_bytes: 256 << 20,
            text_sidecars: true,
        }
    }
}

/// Counters of what a decoder met besides the events it returned.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecodeStats {
    /// Events returned so far.
    pub events: u64,
    /// IMU samples returned so far.
    pub imu_samples: u64,
    /// Events dropped because their coordinates fall outside the sensor.
    pub out_of_range: u64,
    /// ATIS exposure-measurement (threshold crossing) events skipped (Event Stream ATIS).
    pub exposure_events: u64,
    /// External trigger words skipped (EVT 2.0 / EVT 3.0).
    pub triggers: u64,
    /// AEDAT 4 packets skipped (frames, triggers, unknown streams).
    pub skipped_packets: u64,
    /// Times an event's timestamp was below the previous one's and was raised to it (keeps
    /// [`Events`] sorted; non-zero only for damaged streams).
    pub time_regressions: u64,
    /// Events stamped before an event stored earlier in the file, passed on as stored for the
    /// reader to sort (text files, whose writers may store events out of order).
    pub times_out_of_order: u64,
    /// Prophesee words read before the first time-high word, whose time is unknown and which are
    /// skipped as OpenEB does.
    pub words_before_time_base: u64,
}

/// A streaming decoder of one event-camera file.
pub trait EventDecoder: Send {
    /// Replaces the content of `out` with the next chunk: at most `max_events` events (at least 1
    /// event is always allowed) and the IMU samples decoded with them. Returns `Ok(false)`, with
    /// `out` empty, once the file is exhausted.
    ///
    /// On a fault, the events decoded before it are returned first (`Ok(true)`), and the next call
    /// returns the error; after the error, calls return `Ok(false)`.
    fn decode_into(&mut self, out: &mut Chunk, max_events: usize) -> Result<bool, DecodeError>;

    /// The next chunk (see [`EventDecoder::decode_into`]), or `None` at the end of the file.
    fn next_chunk(&mut self, max_events: usize) -> Result<Option<Chunk>, DecodeError> {
        let mut chunk = Chunk::with_capacity(max_events.clamp(1, 1 << 20));
        if self.decode_into(&mut chunk, max_events)? {
            Ok(Some(chunk))
        } else {
            Ok(None)
        }
    }

    /// Sensor size (width, height), pixels.
    fn geometry(&self) -> (u16, u16);

    /// Absolute time of the first event (t = 0 of the chunks), µs on the file's clock (Unix epoch
    /// for AEDAT 4; camera clock for Prophesee and Event Stream files; the text file's own seconds
    /// times 1e6 for text). Known from [`open`] on, as `open` decodes ahead to the first event.
    /// `None` only for a file without events (then the first IMU sample's time, if any, is used).
    fn time_origin_us(&self) -> Option<i64>;

    /// The format being decoded.
    fn format(&self) -> Format;

    /// Counters of skipped and dropped data so far.
    fn stats(&self) -> DecodeStats;

    /// Camera calibration stored with the file (text `calib.txt`), if any, with
    /// `time_origin_us` filled in.
    fn calibration(&self) -> Option<CameraInfo> {
        None
    }

    /// True when the file carries an IMU stream (AEDAT 4 IMU stream, text `imu.txt`).
    fn has_imu(&self) -> bool {
        false
    }
}

/// Opens `path` and returns a decoder positioned at its first event. The format comes from
/// `options.format`, else the file's magic bytes (`#!AER-DAT4.0`, `Event Stream`, a `%` header
/// naming EVT 2.0 or 3.0), else its extension (`.aedat4`, `.raw`, `.es`, `.txt`, `.csv`).
pub fn open(path: impl AsRef<Path>, options: &OpenOptions) -> Result<Box<dyn EventDecoder>, DecodeError> {
    let path = path.as_ref();
    let format = match options.format {
        Some(format) => format,
        None => detect_format(path)?,
    };
    let decoder: Box<dyn EventDecoder> = match format {
        Format::Aedat4 => Box::new(decoder::Buffered::new(aedat4::Aedat4Decoder::open(
            path, options,
        )?)?),
        Format::Evt2 => Box::new(decoder::Buffered::new(evt2::Evt2Decoder::open(path, options)?)?),
        Format::Evt3 => Box::new(decoder::Buffered::new(evt3::Evt3Decoder::open(path, options)?)?),
        Format::EventStream => Box::new(decoder::Buffered::new(es::EsDecoder::open(path, options)?)?),
        Format::Text => Box::new(decoder::Buffered::new(text::TextDecoder::open(path, options)?)?),
    };
    Ok(decoder)
}

/// Picks the format of `path` from its first bytes, else from its extension.
pub fn detect_format(path: &Path) -> Result<Format, DecodeError> {
    let io_error = |source| DecodeError::Io {
        path: path.to_path_buf(),
        offset: 0,
        source,
    };
    let mut head = Vec::with_capacity(4096);
    std::fs::File::open(path)
        .map_err(io_error)?
        .take(4096)
        .read_to_end(&mut head)
        .map_err(io_error)?;
    if head.starts_with(aedat4::MAGIC) {
        return Ok(Format::Aedat4);
    }
    if head.starts_with(es::MAGIC) {
        return Ok(Format::EventStream);
    }
    if head.first() == Some(&b'%') {
        match prophesee::read_header(path)?.version {
            Some(prophesee::EvtVersion::Evt2) => return Ok(Format::Evt2),
            Some(prophesee::EvtVersion::Evt3) => return Ok(Format::Evt3),
            Some(prophesee::EvtVersion::Other(version)) => {
                return Err(DecodeError::Unsupported {
                    path: path.to_path_buf(),
                    what: format!(
                        "Prophesee event format {version:?} is not supported (EVT 2.0 and 3.0 are)"
                    ),
                });
            }
            None => {}
        }
    }
    let extension = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    match extension.as_deref() {
        Some("aedat4") => Ok(Format::Aedat4),
        Some("es") => Ok(Format::EventStream),
        Some("txt") | Some("csv") => Ok(Format::Text),
        Some("raw") => Err(DecodeError::Unsupported {
            path: path.to_path_buf(),
            what: "the .raw header names no event format (no `% evt` or `% format` line): \
                   add a `% evt 3.0` (or 2.0) line to the header (OpenOptions::format in code)"
                .into(),
        }),
        _ => Err(DecodeError::Unsupported {
            path: path.to_path_buf(),
            what: "unknown event file format (not AEDAT 4, EVT 2.0/3.0 .raw, Event Stream .es or text)"
                .into(),
        }),
    }
}
