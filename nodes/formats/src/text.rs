//! Text events in the Event Camera Dataset layout (Mueggler et al., 2017):
//!
//! * `events.txt`: one event per line, `t x y p`: t in seconds (float), x and y in pixels,
//!   p = 1 (ON) or 0 (OFF; `-1` is accepted as OFF too);
//! * `calib.txt` beside it (optional): `fx fy cx cy k1 k2 p1 p2 k3` on one line (pixels; OpenCV
//!   radial-tangential distortion); 4 values (pinhole) or 8 (k3 = 0) are accepted too;
//! * `imu.txt` beside it (optional): `t ax ay az gx gy gz` per line, t in seconds, accelerometer in
//!   m/s², gyroscope in rad/s.
//!
//! Fields may be separated by spaces, tabs or commas. Empty lines and lines starting with `#` are
//! skipped, as is a first line of column names. Any other malformed line is an error naming the
//! file and the line. Event times may decrease (a tool that writes each render interval pixel by
//! pixel stores them so): such events are passed on as stored and counted
//! ([`DecodeStats::times_out_of_order`]); the reader sorts them into place (the source node's
//! reorder window). Times are relative to the first event's.

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};

use evseg_schemas::messages::{CameraInfo, Distortion, ImuSample};

use crate::decoder::FormatDecoder;
use crate::{Chunk, DecodeError, DecodeStats, Format, OpenOptions, OutOfRange};

/// Longest line accepted, bytes: far above any real line (under 100 bytes), it only keeps a
/// binary file opened as text from being buffered whole.
const MAX_LINE: u64 = 64 * 1024;

/// A text file read line by line, with line numbers.
struct LineReader {
    path: PathBuf,
    reader: BufReader<File>,
    line: Vec<u8>,
    /// Number of the line in `line` (1-based).
    number: u64,
    /// Whether a data line has been seen (a column-name line is only allowed before).
    seen_data: bool,
}

impl LineReader {
    fn open(path: &Path, block: usize) -> Result<Self, DecodeError> {
        let file = File::open(path).map_err(|source| DecodeError::Io {
            path: path.to_path_buf(),
            offset: 0,
            source,
        })?;
        Ok(LineReader {
            path: path.to_path_buf(),
            reader: BufReader::with_capacity(block.max(64), file),
            line: Vec::new(),
            number: 0,
            seen_data: false,
        })
    }

    fn error(&self, what: impl Into<String>) -> DecodeError {
        DecodeError::BadLine {
            path: self.path.clone(),
            line: self.number,
            what: what.into(),
        }
    }

    /// The numeric fields of the next data line (`N` of them), or `None` at the end of the file.
    fn next_fields<const N: usize>(&mut self) -> Result<Option<[f64; N]>, DecodeError> {
        loop {
            self.line.clear();
            let n = (&mut self.reader)
                .take(MAX_LINE)
                .read_until(b'\n', &mut self.line)
                .map_err(|source| DecodeError::Io {
                    path: self.path.clone(),
                    offset: 0,
                    source,
                })?;
            if n == 0 {
                return Ok(None);
            }
            self.number += 1;
            if n as u64 == MAX_LINE && self.line.last() != Some(&b'\n') {
                return Err(self.error(format!(
                    "line longer than {MAX_LINE} bytes (not a text event file?)"
                )));
            }
            let text = std::str::from_utf8(&self.line).map_err(|_| self.error("not UTF-8 text"))?;
            let text = text.trim();
            if text.is_empty() || text.starts_with('#') {
                continue;
            }
            let fields: Vec<&str> = text
                .split(|c: char| c.is_whitespace() || c == ',')
                .filter(|f| !f.is_empty())
                .collect();
            let numbers: Vec<Option<f64>> = fields.iter().map(|f| f.parse::<f64>().ok()).collect();
            if !self.seen_data && numbers.iter().all(Option::is_none) {
                continue; // column names
            }
            self.seen_data = true;
            if fields.len() != N {
                return Err(self.error(format!("expected {N} fields, found {}: {text:?}", fields.len())));
            }
            let mut out = [0.0; N];
            for (i, (field, number)) in fields.iter().zip(&numbers).enumerate() {
                match number {
                    Some(v) if v.is_finite() => out[i] = *v,
                    _ => return Err(self.error(format!("field {} is not a finite number: {field:?}", i + 1))),
                }
            }
            return Ok(Some(out));
        }
    }
}

/// One event line checked: (t s, x, y, p).
fn event_from(reader: &LineReader, f: [f64; 4]) -> Result<(f64, u16, u16, u8), DecodeError> {
    let coordinate = |v: f64, name| {
        if v.fract() == 0.0 && (0.0..=u16::MAX as f64).contains(&v) {
            Ok(v as u16)
        } else {
            Err(reader.error(format!("{name} = {v} is not a pixel coordinate")))
        }
    };
    let p = match f[3] {
        1.0 => 1,
        0.0 | -1.0 => 0,
        other => return Err(reader.error(format!("polarity {other} is not 0, 1 or -1"))),
    };
    Ok((f[0], coordinate(f[1], "x")?, coordinate(f[2], "y")?, p))
}

/// The sensor size implied by the largest coordinates of the file (one pass over it).
fn scan_geometry(path: &Path, block: usize) -> Result<(u16, u16), DecodeError> {
    let mut reader = LineReader::open(path, block)?;
    let (mut max_x, mut max_y, mut any) = (0u16, 0u16, false);
    loop {
        // Malformed lines are skipped here; the decoding pass reports them after the events
        // before them.
        match reader.next_fields::<4>() {
            Ok(Some(f)) => {
                if let Ok((_, x, y, _)) = event_from(&reader, f) {
                    max_x = max_x.max(x);
                    max_y = max_y.max(y);
                    any = true;
                }
            }
            Ok(None) => break,
            Err(DecodeError::BadLine { .. }) => {}
            Err(other) => return Err(other),
        }
    }
    if !any || max_x == u16::MAX || max_y == u16::MAX {
        return Err(DecodeError::Unsupported {
            path: path.to_path_buf(),
            what: "cannot infer the sensor size from the events: give it as width and height in the source node's camera_file (OpenOptions::geometry in code)".into(),
        });
    }
    Ok((max_x + 1, max_y + 1))
}

/// Reads `calib.txt`: fx fy cx cy [k1 k2 p1 p2 [k3]].
fn read_calibration(path: &Path) -> Result<(f64, f64, f64, f64, Distortion), DecodeError> {
    let mut reader = LineReader::open(path, 4096)?;
    let fields = loop {
        reader.line.clear();
        let n = reader
            .reader
            .read_until(b'\n', &mut reader.line)
            .map_err(|source| DecodeError::Io {
                path: path.to_path_buf(),
                offset: 0,
                source,
            })?;
        if n == 0 {
            return Err(DecodeError::BadLine {
                path: path.to_path_buf(),
                line: reader.number,
                what: "no calibration line".into(),
            });
        }
        reader.number += 1;
        let text = String::from_utf8_lossy(&reader.line).trim().to_string();
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let mut values = Vec::new();
        for field in text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|f| !f.is_empty())
        {
            match field.parse::<f64>() {
                Ok(v) if v.is_finite() => values.push(v),
                _ => return Err(reader.error(format!("{field:?} is not a finite number"))),
            }
        }
        break values;
    };
    let distortion = match fields.len() {
        4 => Distortion::None,
        8 => Distortion::RadTan {
            k1: fields[4],
            k2: fields[5],
            p1: fields[6],
            p2: fields[7],
            k3: 0.0,
        },
        9 => Distortion::RadTan {
            k1: fields[4],
            k2: fields[5],
            p1: fields[6],
            p2: fields[7],
            k3: fields[8],
        },
        n => {
            return Err(reader.error(format!(
                "expected 4, 8 or 9 values (fx fy cx cy k1 k2 p1 p2 k3), found {n}"
            )));
        }
    };
    if fields[0] <= 0.0 || fields[1] <= 0.0 {
        return Err(reader.error("focal lengths must be positive"));
    }
    Ok((fields[0], fields[1], fields[2], fields[3], distortion))
}

/// Streaming text decoder.
pub(crate) struct TextDecoder {
    events: LineReader,
    width: u16,
    height: u16,
    policy: OutOfRange,
    /// Time of the first event, s (file clock).
    origin_s: Option<f64>,
    /// Time of the newest event so far, s (file clock).
    last_t: f64,
    imu: Option<LineReader>,
    /// The next IMU sample read ahead: t (s, file clock), accel, gyro.
    next_imu: Option<[f64; 7]>,
    calibration: Option<(f64, f64, f64, f64, Distortion)>,
    stats: DecodeStats,
}

impl TextDecoder {
    /// Opens `path` and, with `options.text_sidecars`, `calib.txt` and `imu.txt` beside it.
    pub fn open(path: &Path, options: &OpenOptions) -> Result<Self, DecodeError> {
        let block = options.read_block_bytes;
        let events = LineReader::open(path, block)?;
        let (width, height) = match options.geometry {
            Some(g) => g,
            None => scan_geometry(path, block)?,
        };
        let sibling = |name: &str| {
            let candidate = path.parent().unwrap_or(Path::new(".")).join(name);
            (options.text_sidecars && candidate.is_file() && candidate.as_path() != path).then_some(candidate)
        };
        let calibration = sibling("calib.txt").map(|p| read_calibration(&p)).transpose()?;
        let mut imu = sibling("imu.txt")
            .map(|p| LineReader::open(&p, block))
            .transpose()?;
        let next_imu = match imu.as_mut() {
            Some(reader) => reader.next_fields::<7>()?,
            None => None,
        };
        Ok(TextDecoder {
            events,
            width,
            height,
            policy: options.out_of_range,
            origin_s: None,
            last_t: f64::NEG_INFINITY,
            imu,
            next_imu,
            calibration,
            stats: DecodeStats::default(),
        })
    }

    /// Moves IMU samples up to time `until` (s, file clock) into `out`.
    fn emit_imu(&mut self, out: &mut Chunk, until: f64) -> Result<(), DecodeError> {
        let Some(reader) = self.imu.as_mut() else {
            return Ok(());
        };
        while let Some(s) = self.next_imu {
            if s[0] > until {
                break;
            }
            let origin = *self.origin_s.get_or_insert(s[0]);
            out.imu.push(ImuSample {
                t: s[0] - origin,
                accel: [s[1], s[2], s[3]],
                gyro: [s[4], s[5], s[6]],
            });
            self.next_imu = reader.next_fields::<7>()?;
        }
        Ok(())
    }
}

impl FormatDecoder for TextDecoder {
    fn fill(&mut self, out: &mut Chunk, target: usize) -> Result<bool, DecodeError> {
        while out.events.len() < target {
            let Some(fields) = self.events.next_fields::<4>()? else {
                self.emit_imu(out, f64::INFINITY)?;
                return Ok(false);
            };
            let (t, x, y, p) = event_from(&self.events, fields)?;
            if x >= self.width || y >= self.height {
                if self.policy == OutOfRange::Error {
                    return Err(self.events.error(format!(
                        "event at x={x}, y={y} outside the {}x{} sensor",
                        self.width, self.height
                    )));
                }
                self.stats.out_of_range += 1;
                continue;
            }
            if t < self.last_t {
                self.stats.times_out_of_order += 1;
            }
            self.last_t = self.last_t.max(t);
            let origin = *self.origin_s.get_or_insert(t);
            // The IMU samples up to this event go first, read per event (not per chunk) so that
            // a bad `imu.txt` line stops the events at the same event whatever the chunk size:
            // the first event at or after the last good sample before it.
            self.emit_imu(out, t)?;
            out.events.push(t - origin, x, y, p);
        }
        Ok(true)
    }

    fn geometry(&self) -> (u16, u16) {
        (self.width, self.height)
    }

    fn time_origin_us(&self) -> Option<i64> {
        self.origin_s.map(|s| (s * 1e6).round() as i64)
    }

    fn format(&self) -> Format {
        Format::Text
    }

    fn stats(&self) -> DecodeStats {
        self.stats
    }

    fn calibration(&self) -> Option<CameraInfo> {
        let (fx, fy, cx, cy, distortion) = self.calibration?;
        Some(CameraInfo {
            width: self.width,
            height: self.height,
            fx,
            fy,
            cx,
            cy,
            distortion,
            // Event Camera Dataset: the DAVIS IMU axes are those of the camera's optical frame.
            imu_to_camera: CameraInfo::IDENTITY,
            imu_time_offset_s: 0.0,
            time_origin_us: self.time_origin_us().unwrap_or(0),
            sensor: "text".into(),
        })
    }

    fn has_imu(&self) -> bool {
        self.imu.is_some()
    }
}
