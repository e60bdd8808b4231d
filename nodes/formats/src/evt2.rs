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
use crate::decoder::{RecordDecoder, RecordState, Stop, TimeBase};
use crate::prophesee::{EvtVersion, open_raw};
use crate::{Chunk, DecodeError, DecodeStats, Format, OpenOptions, OutOfRange};

/// Duration of one loop of the 34-bit time, µs.
const TIME_LOOP_US: i64 = 1 << 34;

/// Decoder state besides the file reader.
pub(crate) struct State {
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
pub(crate) type Evt2Decoder = RecordDecoder<State>;

impl Evt2Decoder {
    /// Opens `path`, reads its header and positions the decoder at the first data word.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<Self, DecodeError> {
        let (header, (width, height)) = open_raw(
            path,
            EvtVersion::Evt2,
            options,
            Some(options.evt2_default_geometry),
        )?;
        Ok(RecordDecoder {
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
    fn decode_words(&mut self, bytes: &[u8], out: &mut Chunk, target: usize) -> (usize, Stop) {
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

impl RecordState for State {
    const FORMAT: Format = Format::Evt2;
    const RECORD_BYTES: usize = 4;

    fn decode(&mut self, bytes: &[u8], _start: u64, out: &mut Chunk, target: usize) -> (usize, Stop) {
        self.decode_words(bytes, out, target)
    }

    fn fault_offset(&self, start: u64, index: usize) -> u64 {
        start + 4 * index as u64
    }

    fn truncated_at_end(&self, left: usize, offset: u64) -> Option<(u64, String)> {
        (left > 0).then(|| (offset, format!("{left} bytes left, an EVT 2.0 word has 4")))
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
