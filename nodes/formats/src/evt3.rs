//! Prophesee EVT 3.0 `.raw` decoder (16-bit little-endian words, type in the 4 high bits).
//!
//! Word types: EVT_ADDR_Y 0x0 (y, bit 11 = system type), EVT_ADDR_Y of exposure-measurement rows
//! 0x1, EVT_ADDR_X 0x2 (x, bit 11 = polarity: one event), VECT_BASE_X 0x3 (x, polarity),
//! VECT_12 0x4 / VECT_8 0x5 (one event per set bit at base + bit, then base += 12 / 8),
//! EVT_TIME_LOW 0x6 (12 low bits of the 24-bit time), CONTINUED_4 0x7, EVT_TIME_HIGH 0x8 (12 high
//! bits), EXT_TRIGGER 0xA, OTHERS 0xE, CONTINUED_12 0xF.
//!
//! Time follows OpenEB's `EVT3Decoder`: words before the first EVT_TIME_HIGH are skipped; a new
//! time high resets the time low; the 24-bit time loops (+2^24 µs) when the time high goes back
//! by 2^11 or more. Timestamps are kept non-decreasing as faery does (a decrease, which only a
//! damaged stream has, is counted in [`DecodeStats::time_regressions`]). On clean streams this
//! equals faery 0.7.1, which produced the golden values.

use std::path::Path;

use crate::block_reader::BlockReader;
use crate::decoder::{MAX_EVENTS_PER_RECORD, RecordDecoder, RecordState, Stop, TimeBase};
use crate::prophesee::{EvtVersion, open_raw};
use crate::{Chunk, DecodeError, DecodeStats, Format, OpenOptions, OutOfRange};

/// A time high this far below the previous one means the 24-bit time looped (OpenEB).
const LOOP_THRESHOLD_HIGH: u32 = 1 << 11;
/// Duration of one loop of the 24-bit time, µs.
const TIME_LOOP_US: i64 = 1 << 24;

/// Decoder state besides the file reader.
pub(crate) struct State {
    width: u16,
    height: u16,
    policy: OutOfRange,
    time_base_set: bool,
    time_high: u32,
    time_low: u32,
    loops: i64,
    /// Current time, µs, non-decreasing.
    t_us: i64,
    /// `t_us` in seconds from the origin (valid once the origin is set).
    t_s: f64,
    clock: TimeBase,
    y: u16,
    /// The last EVT_ADDR_Y was a change-detection row (type 0x0, not 0x1).
    is_cd: bool,
    y_in_range: bool,
    base_x: u16,
    vect_polarity: u8,
    stats: DecodeStats,
}

/// Streaming EVT 3.0 decoder.
pub(crate) type Evt3Decoder = RecordDecoder<State>;

impl Evt3Decoder {
    /// Opens `path`, reads its header and positions the decoder at the first data word.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<Self, DecodeError> {
        let (header, (width, height)) = open_raw(path, EvtVersion::Evt3, options, None)?;
        Ok(RecordDecoder {
            reader: BlockReader::open(path, header.length, options.read_block_bytes)?,
            state: State {
                width,
                height,
                policy: options.out_of_range,
                time_base_set: false,
                time_high: 0,
                time_low: 0,
                loops: 0,
                t_us: 0,
                t_s: 0.0,
                clock: TimeBase::default(),
                y: 0,
                is_cd: false,
                y_in_range: false,
                base_x: 0,
                vect_polarity: 0,
                stats: DecodeStats::default(),
            },
        })
    }
}

impl State {
    #[inline]
    fn update_time(&mut self) {
        // Saturating: loops stay far below 2^39 (one per time-high word of a file), but a
        // crafted stream must not overflow.
        let candidate = self
            .loops
            .saturating_mul(TIME_LOOP_US)
            .saturating_add(((self.time_high as i64) << 12) | self.time_low as i64);
        if candidate >= self.t_us {
            self.t_us = candidate;
            if let Some(origin) = self.clock.origin {
                self.t_s = TimeBase::relative(origin, candidate);
            }
        } else {
            self.stats.time_regressions += 1;
        }
    }

    #[inline]
    fn time_seconds(&mut self) -> f64 {
        if self.clock.origin.is_none() {
            self.clock.origin = Some(self.t_us);
            self.t_s = 0.0;
        }
        self.t_s
    }

    /// Emits the events of a VECT_12 / VECT_8 word with valid-bit mask `bits` over `n` columns.
    #[inline]
    fn vector(&mut self, out: &mut Chunk, mut bits: u32, n: u16) {
        let base = self.base_x;
        self.base_x = base.saturating_add(n);
        if !self.is_cd {
            return;
        }
        if !self.y_in_range {
            self.stats.out_of_range += bits.count_ones() as u64;
            return;
        }
        let room = self.width.saturating_sub(base);
        if room < n {
            let keep = (1u32 << room) - 1;
            self.stats.out_of_range += (bits & !keep).count_ones() as u64;
            bits &= keep;
        }
        if bits == 0 {
            return;
        }
        let t = self.time_seconds();
        let (y, p) = (self.y, self.vect_polarity);
        let e = &mut out.events;
        while bits != 0 {
            let bit = bits.trailing_zeros() as u16;
            bits &= bits - 1;
            e.t.push(t);
            e.x.push(base + bit);
            e.y.push(y);
            e.p.push(p);
        }
    }

    /// Decodes the whole 16-bit words of `bytes` into `out` until `target` events. Returns the
    /// number of bytes consumed and why it stopped.
    fn decode_words(&mut self, bytes: &[u8], out: &mut Chunk, target: usize) -> (usize, Stop) {
        let words = bytes.len() / 2;
        let mut i = 0;
        if !self.time_base_set {
            while i < words {
                let w = u16::from_le_bytes([bytes[2 * i], bytes[2 * i + 1]]);
                if w >> 12 == 0x8 {
                    self.time_base_set = true;
                    self.time_high = (w & 0xFFF) as u32;
                    break;
                }
                self.stats.words_before_time_base += 1;
                i += 1;
            }
        }
        while i < words {
            let w = u16::from_le_bytes([bytes[2 * i], bytes[2 * i + 1]]);
            i += 1;
            match w >> 12 {
                0x2 => {
                    let x = w & 0x7FF;
                    if self.is_cd {
                        if self.y_in_range && x < self.width {
                            let t = self.time_seconds();
                            let e = &mut out.events;
                            e.t.push(t);
                            e.x.push(x);
                            e.y.push(self.y);
                            e.p.push((w >> 11) as u8 & 1);
                            if e.t.len() >= target {
                                return (2 * i, Stop::Full);
                            }
                        } else if self.policy == OutOfRange::Error {
                            let what = format!("EVT_ADDR_X x={x} outside the sensor width {}", self.width);
                            return (2 * (i - 1), Stop::Fault(i - 1, what));
                        } else {
                            self.stats.out_of_range += 1;
                        }
                    }
                }
                0x0 => {
                    self.y = w & 0x7FF;
                    self.is_cd = true;
                    self.y_in_range = self.y < self.height;
                    if !self.y_in_range && self.policy == OutOfRange::Error {
                        let what = format!(
                            "EVT_ADDR_Y y={} outside the sensor height {}",
                            self.y, self.height
                        );
                        return (2 * (i - 1), Stop::Fault(i - 1, what));
                    }
                }
                0x6 => {
                    self.time_low = (w & 0xFFF) as u32;
                    self.update_time();
                }
                0x8 => {
                    let high = (w & 0xFFF) as u32;
                    if self.time_high >= LOOP_THRESHOLD_HIGH + high {
                        self.loops += 1;
                    }
                    if high != self.time_high {
                        self.time_low = 0;
                    }
                    self.time_high = high;
                    self.update_time();
                }
                0x3 => {
                    self.base_x = w & 0x7FF;
                    self.vect_polarity = (w >> 11) as u8 & 1;
                }
                0x4 => {
                    self.vector(out, (w & 0xFFF) as u32, 12);
                    if out.events.len() >= target {
                        return (2 * i, Stop::Full);
                    }
                }
                0x5 => {
                    self.vector(out, (w & 0xFF) as u32, 8);
                    if out.events.len() >= target {
                        return (2 * i, Stop::Full);
                    }
                }
                0x1 => self.is_cd = false,
                0xA => self.stats.triggers += 1,
                _ => {}
            }
        }
        (2 * i, Stop::Block)
    }
}

impl RecordState for State {
    const FORMAT: Format = Format::Evt3;
    const RECORD_BYTES: usize = 2;

    fn decode(&mut self, bytes: &[u8], _start: u64, out: &mut Chunk, target: usize) -> (usize, Stop) {
        self.decode_words(bytes, out, target)
    }

    fn fault_offset(&self, start: u64, index: usize) -> u64 {
        start + 2 * index as u64
    }

    fn truncated_at_end(&self, left: usize, offset: u64) -> Option<(u64, String)> {
        (left > 0).then(|| (offset, "1 byte left, an EVT 3.0 word has 2".to_string()))
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

    /// Reserves room for the chunk asked for, capped: `target` may be "everything"
    /// (`usize::MAX`).
    fn prepare(&self, out: &mut Chunk, target: usize) {
        let room = target.saturating_sub(out.events.len()).min(1 << 20) + MAX_EVENTS_PER_RECORD;
        let e = &mut out.events;
        e.t.reserve(room);
        e.x.reserve(room);
        e.y.reserve(room);
        e.p.reserve(room);
    }
}
