//! AEDAT 4 (iniVation DV) decoder.
//!
//! Layout: `#!AER-DAT4.0\r\n`, a u32 length and an `IOHE` flatbuffer (compression: 0 none, 1 LZ4,
//! 2 LZ4 high, 3 zstd, 4 zstd high; position of the trailing data table, -1 when absent; an XML
//! description naming each stream's id, type `EVTS`/`IMUS`/`FRME`/`TRIG` and sensor size), then
//! packets `[stream id i32][size i32][compressed size-prefixed flatbuffer]` up to the data table.
//!
//! `EVTS` packets hold structs `{t: i64 µs, x: i16, y: i16, on: bool}` (16 bytes); `IMUS` packets
//! hold tables `{t: i64 µs, temperature, accelerometer x y z (g), gyroscope x y z (deg/s),
//! magnetometer x y z}`, converted here to m/s² and rad/s. Frame and trigger packets are skipped
//! without being decompressed. Only the first `EVTS` stream is decoded (DV writes one).
//!
//! The `aedat` crate is not used; see the crate README for why.

use std::f64::consts::PI;
use std::fs::File;
use std::io::{BufReader, ErrorKind, Read};
use std::path::{Path, PathBuf};

use evseg_schemas::messages::ImuSample;

use crate::decoder::{FormatDecoder, TimeBase};
use crate::flatbuffer::{self, Table};
use crate::{Chunk, DecodeError, DecodeStats, Format, OpenOptions, OutOfRange, STANDARD_GRAVITY};

/// The first bytes of every AEDAT 4 file.
pub(crate) const MAGIC: &[u8] = b"#!AER-DAT4.0\r\n";

/// Size of one event struct in an `EVTS` packet, bytes.
const EVENT_SIZE: usize = 16;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Compression {
    None,
    Lz4,
    Zstd,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum StreamKind {
    Events,
    Imu,
    /// Frames, triggers, a second event stream, anything else: skipped.
    Skipped,
}

/// An IMU sample before the time origin is known: t in µs, gyro in deg/s, accel in g.
#[derive(Debug, Clone, Copy)]
struct RawImu {
    t_us: i64,
    gyro: [f32; 3],
    accel: [f32; 3],
}

/// Streaming AEDAT 4 decoder.
pub(crate) struct Aedat4Decoder {
    path: PathBuf,
    file: BufReader<File>,
    /// File offset of the next packet header.
    offset: u64,
    /// Start of the data table (end of the packets), when the header gives it.
    data_end: Option<u64>,
    compression: Compression,
    streams: Vec<(i32, StreamKind)>,
    width: u16,
    height: u16,
    policy: OutOfRange,
    max_packet_bytes: usize,
    has_imu: bool,
    compressed: Vec<u8>,
    /// The current decompressed packet.
    packet: Vec<u8>,
    /// Position of the next event struct in `packet`, and how many are left.
    event_pos: usize,
    events_left: usize,
    /// File offset of the current packet's header.
    packet_offset: u64,
    /// Last event time, µs (events are kept non-decreasing).
    t_us: i64,
    clock: TimeBase,
    pending_imu: Vec<RawImu>,
    stats: DecodeStats,
}

fn corrupt(path: &Path, offset: u64, what: impl Into<String>) -> DecodeError {
    DecodeError::Corrupt {
        path: path.to_path_buf(),
        offset,
        what: what.into(),
    }
}

/// Reads until `buf` is full or the end of the file; returns the bytes read.
fn read_full(file: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// The streams of a file: (stream id, kind) pairs.
type Streams = Vec<(i32, StreamKind)>;

/// Stream ids, kinds and the event sensor size from the header's XML description.
fn parse_description(xml: &str) -> Result<(Streams, Option<(u16, u16)>), String> {
    let document = roxmltree::Document::parse(xml).map_err(|e| format!("header XML: {e}"))?;
    let out_info = document
        .descendants()
        .find(|n| n.has_tag_name("node") && n.attribute("name") == Some("outInfo"))
        .ok_or("header XML has no outInfo node")?;
    let attr = |node: roxmltree::Node, key: &str| {
        node.children()
            .find(|c| c.has_tag_name("attr") && c.attribute("key") == Some(key))
            .and_then(|c| c.text())
            .map(|t| t.trim().to_string())
    };
    let mut streams = Vec::new();
    let mut geometry = None;
    for stream in out_info.children().filter(|n| n.has_tag_name("node")) {
        let name = stream.attribute("name").unwrap_or("");
        let id: i32 = name
            .parse()
            .map_err(|_| format!("stream node name {name:?} is not an id"))?;
        let kind = match attr(stream, "typeIdentifier").as_deref() {
            Some("EVTS") if geometry.is_none() => {
                let info = stream
                    .children()
                    .find(|n| n.has_tag_name("node") && n.attribute("name") == Some("info"))
                    .ok_or_else(|| format!("event stream {id} has no info node"))?;
                let size = |key| {
                    attr(info, key)
                        .and_then(|v| v.parse::<u16>().ok())
                        .filter(|&v| v > 0)
                        .ok_or_else(|| format!("event stream {id} has no valid {key}"))
                };
                geometry = Some((size("sizeX")?, size("sizeY")?));
                StreamKind::Events
            }
            Some("IMUS") if !streams.iter().any(|&(_, k)| k == StreamKind::Imu) => StreamKind::Imu,
            _ => StreamKind::Skipped,
        };
        streams.push((id, kind));
    }
    Ok((streams, geometry))
}

impl Aedat4Decoder {
    /// Opens `path` and reads its header.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<Self, DecodeError> {
        let io_error = |offset, source| DecodeError::Io {
            path: path.to_path_buf(),
            offset,
            source,
        };
        let mut file = BufReader::with_capacity(
            options.read_block_bytes.max(64),
            File::open(path).map_err(|e| io_error(0, e))?,
        );
        let mut head = [0u8; 18];
        let n = read_full(&mut file, &mut head).map_err(|e| io_error(0, e))?;
        if n < MAGIC.len() || &head[..MAGIC.len()] != MAGIC {
            return Err(corrupt(path, 0, "not an AEDAT 4 file (no `#!AER-DAT4.0` magic)"));
        }
        if n < 18 {
            return Err(DecodeError::Truncated {
                path: path.to_path_buf(),
                offset: 14,
                what: "header length".into(),
            });
        }
        let header_len = u32::from_le_bytes([head[14], head[15], head[16], head[17]]) as usize;
        if header_len > options.max_packet_bytes {
            return Err(corrupt(
                path,
                14,
                format!("header length {header_len} bytes is implausible"),
            ));
        }
        let mut header = vec![0u8; header_len];
        if read_full(&mut file, &mut header).map_err(|e| io_error(18, e))? < header_len {
            return Err(DecodeError::Truncated {
                path: path.to_path_buf(),
                offset: 18,
                what: format!("header of {header_len} bytes"),
            });
        }
        let fault = |what: String| corrupt(path, 18, format!("IOHeader: {what}"));
        if flatbuffer::identifier(&header).map_err(fault)? != *b"IOHE" {
            return Err(fault("no IOHE identifier".into()));
        }
        let table = Table::root(&header).map_err(fault)?;
        let compression = match table.i32(0, 0).map_err(fault)? {
            0 => Compression::None,
            1 | 2 => Compression::Lz4,
            3 | 4 => Compression::Zstd,
            other => return Err(fault(format!("unknown compression {other}"))),
        };
        let data_position = table.i64(1, -1).map_err(fault)?;
        let description = table
            .string(2)
            .map_err(fault)?
            .ok_or_else(|| fault("no description".into()))?;
        let (streams, geometry) = parse_description(description).map_err(fault)?;
        let Some((width, height)) = geometry else {
            return Err(DecodeError::Unsupported {
                path: path.to_path_buf(),
                what: "the AEDAT 4 file has no event (EVTS) stream".into(),
            });
        };
        let start = 18 + header_len as u64;
        Ok(Aedat4Decoder {
            path: path.to_path_buf(),
            file,
            offset: start,
            data_end: (data_position > 0).then_some(data_position as u64),
            compression,
            has_imu: streams.iter().any(|&(_, k)| k == StreamKind::Imu),
            streams,
            width,
            height,
            policy: options.out_of_range,
            max_packet_bytes: options.max_packet_bytes,
            compressed: Vec::new(),
            packet: Vec::new(),
            event_pos: 0,
            events_left: 0,
            packet_offset: start,
            t_us: i64::MIN,
            clock: TimeBase::default(),
            pending_imu: Vec::new(),
            stats: DecodeStats::default(),
        })
    }

    /// Reads, decompresses and indexes the next packet. Returns `Ok(false)` at the end.
    fn next_packet(&mut self) -> Result<bool, DecodeError> {
        let offset = self.offset;
        if self.data_end.is_some_and(|end| offset >= end) {
            return Ok(false);
        }
        let io_error = |source| DecodeError::Io {
            path: self.path.clone(),
            offset,
            source,
        };
        let mut head = [0u8; 8];
        let n = read_full(&mut self.file, &mut head).map_err(io_error)?;
        if n == 0 && self.data_end.is_none() {
            return Ok(false);
        }
        if n < 8 {
            let what = match self.data_end {
                Some(end) => format!("packet header ({n} of 8 bytes); the data table should start at {end}"),
                None => format!("packet header ({n} of 8 bytes)"),
            };
            return Err(DecodeError::Truncated {
                path: self.path.clone(),
                offset,
                what,
            });
        }
        let stream = i32::from_le_bytes([head[0], head[1], head[2], head[3]]);
        let size = i32::from_le_bytes([head[4], head[5], head[6], head[7]]);
        if size < 0 || size as usize > self.max_packet_bytes {
            return Err(corrupt(
                &self.path,
                offset,
                format!("packet size {size} bytes is implausible"),
            ));
        }
        let size = size as usize;
        let end = offset + 8 + size as u64;
        if let Some(data_end) = self.data_end
            && end > data_end
        {
            return Err(corrupt(
                &self.path,
                offset,
                format!("packet ends at {end}, past the data table at {data_end}"),
            ));
        }
        let Some(&(_, kind)) = self.streams.iter().find(|&&(id, _)| id == stream) else {
            return Err(corrupt(
                &self.path,
                offset,
                format!("packet of undeclared stream id {stream}"),
            ));
        };
        self.compressed.resize(size, 0);
        let n = read_full(&mut self.file, &mut self.compressed).map_err(io_error)?;
        if n < size {
            return Err(DecodeError::Truncated {
                path: self.path.clone(),
                offset,
                what: format!("packet of {size} bytes, of which the file holds {n}"),
            });
        }
        self.offset = end;
        self.packet_offset = offset;
        if kind == StreamKind::Skipped {
            self.stats.skipped_packets += 1;
            return Ok(true);
        }
        self.decompress()?;
        let (root, id) = self
            .flatbuffer_root(kind)
            .map_err(|e| corrupt(&self.path, offset, e))?;
        let buf = &self.packet[4..];
        let table = Table::at(buf, root).map_err(|e| corrupt(&self.path, offset, e))?;
        match kind {
            StreamKind::Events => {
                let (start, len) = table
                    .vector(0, EVENT_SIZE)
                    .map_err(|e| corrupt(&self.path, offset, e))?
                    .unwrap_or((0, 0));
                self.event_pos = 4 + start;
                self.events_left = len;
            }
            StreamKind::Imu => {
                let fault = |e: String| {
                    corrupt(
                        &self.path,
                        offset,
                        format!("{} packet: {e}", String::from_utf8_lossy(&id)),
                    )
                };
                let Some((start, len)) = table.vector(0, 4).map_err(fault)? else {
                    return Ok(true);
                };
                for i in 0..len {
                    let imu = table.vector_table(start, i).map_err(fault)?;
                    let f = |index| imu.f32(index, 0.0).map_err(fault);
                    self.pending_imu.push(RawImu {
                        t_us: imu.i64(0, 0).map_err(fault)?,
                        accel: [f(2)?, f(3)?, f(4)?],
                        gyro: [f(5)?, f(6)?, f(7)?],
                    });
                }
            }
            StreamKind::Skipped => {}
        }
        Ok(true)
    }

    /// Decompresses `compressed` into `packet`.
    fn decompress(&mut self) -> Result<(), DecodeError> {
        self.packet.clear();
        let limit = self.max_packet_bytes as u64 + 1;
        let result = match self.compression {
            Compression::None => {
                std::mem::swap(&mut self.packet, &mut self.compressed);
                Ok(self.packet.len())
            }
            Compression::Lz4 => lz4_flex::frame::FrameDecoder::new(&self.compressed[..])
                .take(limit)
                .read_to_end(&mut self.packet),
            Compression::Zstd => match ruzstd::decoding::StreamingDecoder::new(&self.compressed[..]) {
                Ok(decoder) => decoder.take(limit).read_to_end(&mut self.packet),
                Err(e) => Err(std::io::Error::other(e.to_string())),
            },
        };
        let name = match self.compression {
            Compression::None => "uncompressed",
            Compression::Lz4 => "LZ4",
            Compression::Zstd => "zstd",
        };
        match result {
            Err(e) => Err(corrupt(
                &self.path,
                self.packet_offset,
                format!("{name} packet does not decompress: {e}"),
            )),
            Ok(n) if n as u64 >= limit => Err(corrupt(
                &self.path,
                self.packet_offset,
                format!("packet decompresses to more than {} bytes", self.max_packet_bytes),
            )),
            Ok(_) => Ok(()),
        }
    }

    /// Checks the size prefix and identifier of the decompressed packet; returns the root table
    /// position (relative to the buffer after the size prefix) and the identifier.
    fn flatbuffer_root(&self, kind: StreamKind) -> Result<(usize, [u8; 4]), String> {
        let size = flatbuffer::u32_at(&self.packet, 0)? as usize;
        if size + 4 > self.packet.len() {
            return Err(format!(
                "flatbuffer size prefix {size} exceeds the {} decompressed bytes",
                self.packet.len()
            ));
        }
        let buf = &self.packet[4..];
        let id = flatbuffer::identifier(buf)?;
        let expected = if kind == StreamKind::Events {
            b"EVTS"
        } else {
            b"IMUS"
        };
        if id != *expected {
            return Err(format!(
                "packet identifier {:?} does not match its stream type {:?}",
                String::from_utf8_lossy(&id),
                String::from_utf8_lossy(expected)
            ));
        }
        Ok((flatbuffer::u32_at(buf, 0)? as usize, id))
    }

    /// Moves the pending IMU samples into `out` once the time origin is known.
    fn flush_imu(&mut self, out: &mut Chunk) {
        let Some(origin) = self.clock.origin else {
            return;
        };
        const DEG: f64 = PI / 180.0;
        out.imu.extend(self.pending_imu.drain(..).map(|s| ImuSample {
            t: TimeBase::relative(origin, s.t_us),
            gyro: s.gyro.map(|v| v as f64 * DEG),
            accel: s.accel.map(|v| v as f64 * STANDARD_GRAVITY),
        }));
    }

    /// Decodes events of the current packet into `out` until `target`.
    fn drain_events(&mut self, out: &mut Chunk, target: usize) -> Result<(), DecodeError> {
        while self.events_left > 0 && out.events.len() < target {
            let b = &self.packet[self.event_pos..self.event_pos + EVENT_SIZE];
            let t = i64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]);
            let x = i16::from_le_bytes([b[8], b[9]]);
            let y = i16::from_le_bytes([b[10], b[11]]);
            let on = b[12];
            self.event_pos += EVENT_SIZE;
            self.events_left -= 1;
            if x < 0 || y < 0 || x as u16 >= self.width || y as u16 >= self.height {
                if self.policy == OutOfRange::Error {
                    return Err(corrupt(
                        &self.path,
                        self.packet_offset,
                        format!(
                            "event at x={x}, y={y} outside the {}x{} sensor",
                            self.width, self.height
                        ),
                    ));
                }
                self.stats.out_of_range += 1;
                continue;
            }
            if t < self.t_us {
                self.stats.time_regressions += 1;
            } else {
                self.t_us = t;
            }
            let t = self.clock.seconds(self.t_us);
            let e = &mut out.events;
            e.t.push(t);
            e.x.push(x as u16);
            e.y.push(y as u16);
            e.p.push((on != 0) as u8);
        }
        Ok(())
    }
}

impl FormatDecoder for Aedat4Decoder {
    fn fill(&mut self, out: &mut Chunk, target: usize) -> Result<bool, DecodeError> {
        loop {
            let drained = self.drain_events(out, target);
            self.flush_imu(out);
            drained?;
            if out.events.len() >= target {
                return Ok(true);
            }
            if !self.next_packet()? {
                if self.clock.origin.is_none()
                    && let Some(first) = self.pending_imu.first()
                {
                    self.clock.origin = Some(first.t_us);
                }
                self.flush_imu(out);
                return Ok(false);
            }
        }
    }

    fn geometry(&self) -> (u16, u16) {
        (self.width, self.height)
    }

    fn time_origin_us(&self) -> Option<i64> {
        self.clock.origin
    }

    fn format(&self) -> Format {
        Format::Aedat4
    }

    fn stats(&self) -> DecodeStats {
        self.stats
    }

    fn has_imu(&self) -> bool {
        self.has_imu
    }
}
