//! Prophesee EVT 2.0 `.raw` decoder (32-bit little-endian words, type in the 4 high bits).
//!
//! Word types: CD_OFF 0x0 / CD_ON 0x1 (bits 27..22: 6 low time bits, 21..11: x, 10..0: y),
//! EVT_TIME_HIGH 0x8 (bits 27..0: time bits 33..6), EXT_TRIGGER 0xA, OTHERS 0xE, CONTINUED 0xF.
//!
//! Time follows OpenEB and faery: words before the first EVT_TIME_HIGH are skipped (OpenEB); the
//! 34-bit time loops (+2^34 µs) when a time high is below the previous one; timestamps are kept
//! non-decreasing (faery), decreases being counted in [`DecodeStats::time_regressions`].

use std::path::Path;

use crate::block_reader::BlockReader;
use crate::decoder::{FormatDecoder, Stop, TimeBase};
use crate::prophesee::{EvtVersion, open_raw};
use crate::{Chunk, DecodeError, DecodeStats, Format, OpenOptions, OutOfRange};

/// Duration of one loop of the 34-bit time, µs.
const TIME_LOOP_US: i64 = 1 << 34;

/// Decoder state besides the file reader.
struct State {
    width: u16,
    height: u16,
    policy: OutOfRange,
    time_base_set: bool,
    /// Time high without loops, µs.
    time_high: i64,
    loops: i64,
    /// Current time, µs, non-decreasing.
    t_us: i64,
    clock: TimeBase,
    stats: DecodeStats,
}

/// Streaming EVT 2.0 decoder.
pub(crate) struct Evt2Decoder {
    reader: BlockReader,
    state: State,
}

impl Evt2Decoder {
    /// Opens `path`, reads its header and positions the decoder at the first data word.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<Self, DecodeError> {
        let (header, (width, height)) = open_raw(
            path,
            EvtVersion::Evt2,
            options,
            Some(options.evt2_default_geometry),
        )?;
        Ok(Evt2Decoder {
            reader: BlockReader::open(path, header.length, options.read_block_bytes)?,
            state: State {
                width,
                height,
                policy: options.out_of_range,
                time_base_set: false,
                time_high: 0,
                loops: 0,
                t_us: 0,
                clock: TimeBase::default(),
                stats: DecodeStats::default(),
            },
        })
    }
}

impl State {
    /// Raises the current time to `time high + low` (never lowers it).
    #[inline]
    fn advance_time(&mut self, low: u32) {
        // Saturating: a crafted file could hold more time-high loops than an i64 of µs counts.
        let candidate = self
            .loops
            .saturating_mul(TIME_LOOP_US)
            .saturating_add(self.time_high + low as i64);
        if candidate >= self.t_us {
            self.t_us = candidate;
        } else {
            self.stats.time_regressions += 1;
        }
    }

    /// Decodes the whole words of `bytes` until `target` events; returns the bytes consumed.
    fn decode(&mut self, bytes: &[u8], out: &mut Chunk, target: usize) -> (usize, Stop) {
        let words = bytes.len() / 4;
        for k in 0..words {
            let w = u32::from_le_bytes([bytes[4 * k], bytes[4 * k + 1], bytes[4 * k + 2], bytes[4 * k + 3]]);
            let kind = w >> 28;
            if !self.time_base_set && kind != 0x8 {
                self.stats.words_before_time_base += 1;
                continue;
            }
            match kind {
                0x0 | 0x1 => {
                    self.advance_time((w >> 22) & 0x3F);
                    let x = ((w >> 11) & 0x7FF) as u16;
                    let y = (w & 0x7FF) as u16;
                    if x < self.width && y < self.height {
                        let t = self.clock.seconds(self.t_us);
                        let e = &mut out.events;
                        e.t.push(t);
                        e.x.push(x);
                        e.y.push(y);
                        e.p.push(kind as u8);
                        if e.t.len() >= target {
                            return (4 * (k + 1), Stop::Full);
                        }
                    } else if self.policy == OutOfRange::Error {
                        let what = format!(
                            "CD event at x={x}, y={y} outside the {}x{} sensor",
                            self.width, self.height
                        );
                        return (4 * k, Stop::Fault(k, what));
                    } else {
                        self.stats.out_of_range += 1;
                    }
                }
                0x8 => {
                    let high = ((w & 0x0FFF_FFFF) as i64) << 6;
                    if self.time_base_set && high < self.time_high {
                        self.loops += 1;
                    }
                    self.time_base_set = true;
                    self.time_high = high;
                }
                0xA => {
                    self.advance_time((w >> 22) & 0x3F);
                    self.stats.triggers += 1;
                }
                _ => {}
            }
        }
        (4 * words, Stop::Block)
    }
}

impl FormatDecoder for Evt2Decoder {
    fn fill(&mut self, out: &mut Chunk, target: usize) -> Result<bool, DecodeError> {
        loop {
            let bytes = self.reader.available();
            if bytes.len() < 4 {
                if self.reader.refill()? {
                    continue;
                }
                let left = self.reader.available().len();
                if left == 0 {
                    return Ok(false);
                }
                return Err(DecodeError::Truncated {
                    path: self.reader.path().to_path_buf(),
                    offset: self.reader.offset(),
                    what: format!("{left} bytes left, an EVT 2.0 word has 4"),
                });
            }
            let (consumed, stop) = self.state.decode(bytes, out, target);
            let start = self.reader.offset();
            self.reader.consume(consumed);
            match stop {
                Stop::Full => return Ok(true),
                Stop::Block => {}
                Stop::Fault(word, what) => {
                    return Err(DecodeError::Corrupt {
                        path: self.reader.path().to_path_buf(),
                        offset: start + 4 * word as u64,
                        what,
                    });
                }
            }
        }
    }

    fn geometry(&self) -> (u16, u16) {
        (self.state.width, self.state.height)
    }

    fn time_origin_us(&self) -> Option<i64> {
        self.state.clock.origin
    }

    fn format(&self) -> Format {
        Format::Evt2
    }

    fn stats(&self) -> DecodeStats {
        self.state.stats
    }
}
