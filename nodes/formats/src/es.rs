//! Event Stream `.es` decoder (neuromorphic-paris Event Stream specification, version 2.x).
//!
//! Header: `Event Stream` (12 bytes), version major, minor, patch, stream type (0 generic, 1 DVS,
//! 2 ATIS, 3 display, 4 color), then for DVS and ATIS the sensor width and height (u16 LE each).
//! Only DVS and ATIS streams carry polarity events; the other types are refused.
//!
//! DVS events: byte 0 = `t_delta << 1 | is_increase` (0xFF: overflow, +127 µs; 0xFE: reset),
//! then x (u16 LE), y (u16 LE). ATIS events: byte 0 = `t_delta << 2 | polarity << 1 | is_tc`
//! (0b111111xx: overflow, +63 µs times xx), then x, y. ATIS threshold-crossing (exposure) events
//! are skipped and counted in [`DecodeStats::exposure_events`]; change-detection events keep
//! their polarity. Times start at 0 µs at the beginning of the stream.
//!
//! Event Stream puts the origin at the bottom-left corner (y up, the neuromorphic-paris
//! convention); events are returned with y flipped to the top-left origin of
//! [`evseg_schemas::messages::Events`] (`y = height - 1 - y_file`), as faery does.

use std::path::Path;

use crate::block_reader::BlockReader;
use crate::decoder::{RecordDecoder, RecordState, Stop, TimeBase};
use crate::{Chunk, DecodeError, DecodeStats, Format, OpenOptions, OutOfRange};

/// The first bytes of every Event Stream file.
pub(crate) const MAGIC: &[u8] = b"Event Stream";

/// Decoder state besides the file reader.
pub(crate) struct State {
    width: u16,
    height: u16,
    atis: bool,
    policy: OutOfRange,
    /// Current time, µs since the start of the stream.
    t_us: i64,
    clock: TimeBase,
    /// 0: waiting for byte 0; 1..=4: bytes of x and y read so far + 1.
    phase: u8,
    x: u16,
    y: u16,
    polarity: u8,
    is_exposure: bool,
    /// File offset of the current event's byte 0.
    event_offset: u64,
    stats: DecodeStats,
}

/// Streaming Event Stream decoder.
pub(crate) type EsDecoder = RecordDecoder<State>;

impl EsDecoder {
    /// Opens `path`, reads its header and positions the decoder at the first event byte.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<Self, DecodeError> {
        let mut reader = BlockReader::open(path, 0, options.read_block_bytes)?;
        let truncated = |what: &str| DecodeError::Truncated {
            path: path.to_path_buf(),
            offset: 0,
            what: format!("Event Stream header: {what}"),
        };
        while reader.available().len() < 20 && reader.refill()? {}
        let head = reader.available();
        if head.len() < 16 {
            return Err(truncated("shorter than 16 bytes"));
        }
        if &head[..12] != MAGIC {
            return Err(DecodeError::Corrupt {
                path: path.to_path_buf(),
                offset: 0,
                what: "not an Event Stream file (no `Event Stream` magic)".into(),
            });
        }
        let (major, minor, patch) = (head[12], head[13], head[14]);
        let unsupported = |what: String| DecodeError::Unsupported {
            path: path.to_path_buf(),
            what,
        };
        if major != 2 {
            return Err(unsupported(format!(
                "Event Stream version {major}.{minor}.{patch} is not supported (version 2.x is)"
            )));
        }
        let atis = match head[15] {
            1 => false,
            2 => true,
            0 => {
                return Err(unsupported(
                    "Event Stream of generic events: no polarity events to decode".into(),
                ));
            }
            3 => {
                return Err(unsupported(
                    "Event Stream of display events: no polarity events to decode".into(),
                ));
            }
            4 => {
                return Err(unsupported(
                    "Event Stream of color events: no polarity events to decode".into(),
                ));
            }
            other => {
                return Err(DecodeError::Corrupt {
                    path: path.to_path_buf(),
                    offset: 15,
                    what: format!("unknown Event Stream type {other}"),
                });
            }
        };
        if head.len() < 20 {
            return Err(truncated("no sensor size"));
        }
        let width = u16::from_le_bytes([head[16], head[17]]);
        let height = u16::from_le_bytes([head[18], head[19]]);
        if width == 0 || height == 0 {
            return Err(DecodeError::Corrupt {
                path: path.to_path_buf(),
                offset: 16,
                what: format!("empty sensor size {width}x{height}"),
            });
        }
        reader.consume(20);
        Ok(RecordDecoder {
            reader,
            state: State {
                width,
                height,
                atis,
                policy: options.out_of_range,
                t_us: 0,
                clock: TimeBase::default(),
                phase: 0,
                x: 0,
                y: 0,
                polarity: 0,
                is_exposure: false,
                event_offset: 20,
                stats: DecodeStats::default(),
            },
        })
    }
}

impl State {
    /// Decodes `bytes` (starting at file offset `start`) until `target` events.
    fn decode_bytes(&mut self, bytes: &[u8], start: u64, out: &mut Chunk, target: usize) -> (usize, Stop) {
        for (k, &b) in bytes.iter().enumerate() {
            match self.phase {
                0 => {
                    if self.atis {
                        if b & 0xFC == 0xFC {
                            self.t_us += 63 * (b & 0x03) as i64;
                            continue;
                        }
                        self.t_us += (b >> 2) as i64;
                        self.is_exposure = b & 1 == 1;
                        self.polarity = (b >> 1) & 1;
                    } else {
                        if b == 0xFF {
                            self.t_us += 127;
                            continue;
                        }
                        if b == 0xFE {
                            continue;
                        }
                        self.t_us += (b >> 1) as i64;
                        self.polarity = b & 1;
                    }
                    self.event_offset = start + k as u64;
                    self.phase = 1;
                }
                1 => {
                    self.x = b as u16;
                    self.phase = 2;
                }
                2 => {
                    self.x |= (b as u16) << 8;
                    self.phase = 3;
                }
                3 => {
                    self.y = b as u16;
                    self.phase = 4;
                }
                _ => {
                    self.y |= (b as u16) << 8;
                    self.phase = 0;
                    if self.is_exposure {
                        self.is_exposure = false;
                        self.stats.exposure_events += 1;
                    } else if self.x < self.width && self.y < self.height {
                        let t = self.clock.seconds(self.t_us);
                        let e = &mut out.events;
                        e.t.push(t);
                        e.x.push(self.x);
                        e.y.push(self.height - 1 - self.y);
                        e.p.push(self.polarity);
                        if e.t.len() >= target {
                            return (k + 1, Stop::Full);
                        }
                    } else if self.policy == OutOfRange::Error {
                        let what = format!(
                            "event at x={}, y={} outside the {}x{} sensor",
                            self.x, self.y, self.width, self.height
                        );
                        return (k + 1, Stop::Fault(0, what));
                    } else {
                        self.stats.out_of_range += 1;
                    }
                }
            }
        }
        (bytes.len(), Stop::Block)
    }
}

impl RecordState for State {
    const FORMAT: Format = Format::EventStream;
    const RECORD_BYTES: usize = 1;

    fn decode(&mut self, bytes: &[u8], start: u64, out: &mut Chunk, target: usize) -> (usize, Stop) {
        self.decode_bytes(bytes, start, out, target)
    }

    /// A fault is the current event's: its first byte.
    fn fault_offset(&self, _start: u64, _index: usize) -> u64 {
        self.event_offset
    }

    fn truncated_at_end(&self, _left: usize, _offset: u64) -> Option<(u64, String)> {
        (self.phase != 0).then(|| (self.event_offset, "the file ends inside an event".to_string()))
    }

    fn geometry(&self) -> (u16, u16) {
        (self.width, self.height)
    }

    fn time_origin_us(&self) -> Option<i64> {
        self.clock.origin
    }

    fn stats(&self) -> DecodeStats {
        self.stats
    }
}
