//! Reading an EVIMO2 v2 sequence folder.
//!
//! Time convention of everything this module returns: seconds **relative to the first event**,
//! i.e. `t = t_file - t0` where `t0` is the earliest time among the first 65 536 stored events of
//! `dataset_events_t.npy` that is kept (not dropped for its time, see [`EventReader`]; absolute,
//! seconds on the EVIMO2 sequence clock, the clock of every `ts` in meta). In a time-sorted file, as EVIMO2's own, that is `dataset_events_t.npy[0]`; in a
//! file stored out of order it keeps the earliest events at non-negative times. `t0` is kept as
//! [`Sequence::t0_s`] and, rounded to µs, as [`CameraInfo::time_origin_us`]. A folder with no events has `t0 = 0`. IMU sample times
//! are on the IMU clock (add [`CameraInfo::imu_time_offset_s`] for camera time).

use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use evseg_schemas::{CameraInfo, CameraMotion, Events, ImuSample, Mask};

use crate::error::{Evimo2Error, Result};
use crate::meta::{self, FrameTruth, MetaOptions};
use crate::npy::{self, DType, NpyHeader};
use crate::npz::NpzReader;

/// Event times file.
pub const EVENTS_T: &str = "dataset_events_t.npy";
/// Event pixel coordinates file, (N, 2) = (x, y).
pub const EVENTS_XY: &str = "dataset_events_xy.npy";
/// Event polarity file.
pub const EVENTS_P: &str = "dataset_events_p.npy";
/// Masks archive (`mask_%010d` keys).
pub const MASK_NPZ: &str = "dataset_mask.npz";
/// Depth archive (`depth_%010d` keys), optional.
pub const DEPTH_NPZ: &str = "dataset_depth.npz";
/// Calibration, index and meta archive.
pub const INFO_NPZ: &str = "dataset_info.npz";

/// EVIMO2 stores object id * this factor in masks.
pub const MASK_ID_SCALE: u16 = 1000;

/// Default largest time difference, seconds, between an event and the last event kept before it
/// (in file order) for the event to count as part of the recording (see
/// [`EventReader::open_with_gap`]). An event camera fires continually (background activity
/// alone gives every pixel events within seconds), so an event stamped further than this from
/// its predecessors is a corrupt time: it is dropped and counted
/// ([`EventReader::time_outliers`]) instead of opening a gap of millions of empty time slices.
pub const DEFAULT_MAX_TIME_GAP_S: f64 = 10.0;

/// Allowed values, seconds, of the largest time gap ([`EventReader::open_with_gap`]): from a
/// millisecond (a slice) to about eleven days (no practical limit).
pub const MAX_TIME_GAP_RANGE_S: std::ops::RangeInclusive<f64> = 1e-3..=1e6;

/// Consecutive events beyond the largest time gap from the last kept one after which the file is
/// taken to jump (a clock reset or a shifted block, not a few corrupt values), and reading stops
/// with an error naming the first of them.
pub const MAX_CONSECUTIVE_TIME_OUTLIERS: u64 = 10_000;

/// Events read per block while scanning times in [`EventReader::read_until`] (64 Ki events =
/// 512 KiB of float64): large enough for sequential-read speed, small enough to stay in cache.
const DEFAULT_SCAN_BLOCK: usize = 1 << 16;

/// One column file of the events (`t`, `xy` or `p`), read by row ranges.
struct Column {
    file: File,
    name: String,
    header: NpyHeader,
    /// Bytes per row (item size * elements per row).
    row_bytes: usize,
    rows: u64,
}

impl Column {
    /// Opens `path`, checks dtype class and shape `(N,)`/`(N, 1)` (`width` 1) or `(N, width)`, and
    /// that the file holds all the data the header announces.
    fn open(path: &Path, width: usize, want: &str, accept: fn(DType) -> bool) -> Result<Self> {
        let name = path.display().to_string();
        let mut file = File::open(path).map_err(|e| Evimo2Error::io(&name, e))?;
        let header = npy::read_header(&mut std::io::BufReader::new(&mut file), &name)?;
        if !accept(header.dtype) {
            return Err(Evimo2Error::invalid(
                &name,
                format!("dtype '{}' is not {want}", header.descr),
            ));
        }
        let rows = match header.shape.as_slice() {
            [n] if width == 1 => *n as u64,
            [n, w] if *w == width => *n as u64,
            other => {
                let expected = if width == 1 {
                    "(N,) or (N, 1)".to_string()
                } else {
                    format!("(N, {width})")
                };
                return Err(Evimo2Error::invalid(
                    &name,
                    format!("shape {other:?} is not {expected}"),
                ));
            }
        };
        if header.fortran_order && width > 1 {
            return Err(Evimo2Error::invalid(
                &name,
                "Fortran-order (column-major) arrays are not supported",
            ));
        }
        let row_bytes = header.dtype.item_size() * width;
        let need = header.data_offset + rows * row_bytes as u64;
        let have = file.metadata().map_err(|e| Evimo2Error::io(&name, e))?.len();
        if have < need {
            return Err(Evimo2Error::format(
                &name,
                have,
                format!(
                    "truncated: header announces {rows} rows ({need} bytes in all) but the file has {have} bytes"
                ),
            ));
        }
        Ok(Self {
            file,
            name,
            header,
            row_bytes,
            rows,
        })
    }

    /// Reads rows `start..start + count` as raw bytes into `buf`.
    fn read_rows(&mut self, start: u64, count: usize, buf: &mut Vec<u8>) -> Result<()> {
        let offset = self.header.data_offset + start * self.row_bytes as u64;
        buf.resize(count * self.row_bytes, 0);
        self.file
            .seek(SeekFrom::Start(offset))
            .map_err(|e| Evimo2Error::io(&self.name, e))?;
        self.file.read_exact(buf).map_err(|e| {
            if e.kind() == std::io::ErrorKind::UnexpectedEof {
                Evimo2Error::format(
                    &self.name,
                    offset,
                    "file ended while reading events (truncated since opened?)",
                )
            } else {
                Evimo2Error::io(&self.name, e)
            }
        })
    }
}

fn is_float(d: DType) -> bool {
    matches!(d, DType::F8 | DType::F4)
}

/// Streams the events of a sequence folder in chunks, never loading the files whole.
///
/// Events come in file order. EVIMO2 files are time-sorted, but files in the wild may not be:
/// a timestamp smaller than the previous one is counted ([`EventReader::non_monotonic`]) and passed
/// through unchanged. A time that is not finite, or lies more than the largest time gap from the
/// last event kept before it (the first block's median stands in before the first), is dropped
/// with its event and counted ([`EventReader::time_outliers`]); a run of more than
/// [`MAX_CONSECUTIVE_TIME_OUTLIERS`] of them is an error (the times jump).
pub struct EventReader {
    t: Column,
    xy: Column,
    p: Column,
    /// Absolute time of the first event, seconds.
    t0: f64,
    /// Next event to return.
    pos: u64,
    /// Decoded absolute times of rows `pos..pos + t_cache.len() - t_head`.
    t_cache: Vec<f64>,
    t_head: usize,
    /// Time of the last returned event (relative), for the monotonicity count.
    last_t: f64,
    non_monotonic: u64,
    /// Absolute time of the last event kept (in file order), the reference of the gap test; the
    /// first block's median before any is kept.
    last_kept_abs: Option<f64>,
    /// Events dropped for their time, and how many of them came in a row at the end.
    time_outliers: u64,
    consecutive_outliers: u64,
    /// Dropped events that `take` has passed over (the others are still in the time cache).
    outliers_passed: u64,
    /// Row and stored time of the first dropped event.
    first_outlier: Option<(u64, f64)>,
    /// Rows read per block when scanning times, see [`DEFAULT_SCAN_BLOCK`].
    scan_block: usize,
    /// Largest time gap, s, of an event from the last kept one (see
    /// [`EventReader::open_with_gap`]).
    max_gap_s: f64,
    buf: Vec<u8>,
}

impl std::fmt::Debug for EventReader {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("EventReader")
            .field("events", &self.t.rows)
            .field("position", &self.pos)
            .field("t0", &self.t0)
            .finish()
    }
}

impl EventReader {
    /// Opens the three event files of `folder` and checks their dtypes, shapes, sizes and that they
    /// hold the same number of events; the largest time gap is [`DEFAULT_MAX_TIME_GAP_S`].
    pub fn open(folder: &Path) -> Result<Self> {
        Self::open_with_gap(folder, DEFAULT_MAX_TIME_GAP_S)
    }

    /// [`EventReader::open`] with the largest time gap `max_gap_s` (s, within
    /// [`MAX_TIME_GAP_RANGE_S`]): an event whose time is not finite or lies further than this
    /// from the last event kept before it (in file order) is dropped and counted
    /// ([`EventReader::time_outliers`]). A recording with a real pause longer than the default
    /// needs a larger value.
    pub fn open_with_gap(folder: &Path, max_gap_s: f64) -> Result<Self> {
        if !MAX_TIME_GAP_RANGE_S.contains(&max_gap_s) {
            return Err(Evimo2Error::invalid(
                folder.join(EVENTS_T).display().to_string(),
                format!(
                    "largest time gap {max_gap_s} s is outside {}..={} s",
                    MAX_TIME_GAP_RANGE_S.start(),
                    MAX_TIME_GAP_RANGE_S.end()
                ),
            ));
        }
        let t = Column::open(&folder.join(EVENTS_T), 1, "float64/float32", is_float)?;
        let xy = Column::open(&folder.join(EVENTS_XY), 2, "an integer type", DType::is_integer)?;
        let p = Column::open(&folder.join(EVENTS_P), 1, "a bool, integer or float type", |d| {
            d.is_integer() || is_float(d)
        })?;
        if t.rows != xy.rows || t.rows != p.rows {
            return Err(Evimo2Error::invalid(
                format!("{}, {}, {}", t.name, xy.name, p.name),
                format!(
                    "event files disagree on the number of events: t has {}, xy has {}, p has {}",
                    t.rows, xy.rows, p.rows
                ),
            ));
        }
        let mut reader = Self {
            t,
            xy,
            p,
            t0: 0.0,
            pos: 0,
            t_cache: Vec::new(),
            t_head: 0,
            last_t: f64::NEG_INFINITY,
            non_monotonic: 0,
            last_kept_abs: None,
            time_outliers: 0,
            consecutive_outliers: 0,
            outliers_passed: 0,
            first_outlier: None,
            scan_block: DEFAULT_SCAN_BLOCK,
            max_gap_s,
            buf: Vec::new(),
        };
        if reader.t.rows > 0 {
            // The first scan block (see the module docs on t0); dropped times are NaN here.
            reader.fill_t(1)?;
            let earliest = reader
                .t_cache
                .iter()
                .copied()
                .filter(|t| t.is_finite())
                .fold(f64::INFINITY, f64::min);
            reader.t0 = if earliest.is_finite() { earliest } else { 0.0 };
        }
        Ok(reader)
    }

    /// The largest time gap, s (see [`EventReader::open_with_gap`]).
    pub fn max_time_gap_s(&self) -> f64 {
        self.max_gap_s
    }

    /// Sets how many events are read per block while scanning times (default 65 536; min 1).
    pub fn set_scan_block(&mut self, rows: usize) {
        self.scan_block = rows.max(1);
    }

    /// Total number of events in the files.
    pub fn len(&self) -> u64 {
        self.t.rows
    }

    /// True when the files hold no events.
    pub fn is_empty(&self) -> bool {
        self.t.rows == 0
    }

    /// Index of the next event to be returned.
    pub fn position(&self) -> u64 {
        self.pos
    }

    /// Absolute time of the first event, seconds on the EVIMO2 clock (0 when there are none).
    pub fn t0_s(&self) -> f64 {
        self.t0
    }

    /// Number of events returned so far whose time is smaller than the previous event's.
    pub fn non_monotonic(&self) -> u64 {
        self.non_monotonic
    }

    /// Events dropped so far for their time (not finite, or beyond the largest time gap from the
    /// events before them), with the row and stored time of the first; they are never returned.
    pub fn time_outliers(&self) -> (u64, Option<(u64, f64)>) {
        (self.time_outliers, self.first_outlier)
    }

    /// Marks the times of rows `first_row..` (cache entries `from..`) that are not finite or lie
    /// beyond the largest time gap from the last kept event as NaN (dropped by `take`).
    fn screen_times(&mut self, from: usize, first_row: u64) -> Result<()> {
        let block = &self.t_cache[from..];
        let gap = self.max_gap_s;
        let near = |a: f64, b: f64| (b - a).abs() <= gap;
        // The usual block: every time within the gap of the one before it (the first of the
        // file's: of itself; NaN fails every comparison), all kept. Tested without a carried
        // dependency, so it vectorises.
        let Some(&first) = block.first() else {
            return Ok(());
        };
        if near(self.last_kept_abs.unwrap_or(first), first)
            && block.windows(2).fold(true, |ok, w| ok & near(w[0], w[1]))
        {
            self.consecutive_outliers = 0;
            self.last_kept_abs = block.last().copied();
            return Ok(());
        }
        if self.last_kept_abs.is_none() {
            // Before any is kept, the block's median stands in (robust to a few bad times).
            let mut finite: Vec<f64> = block.iter().copied().filter(|t| t.is_finite()).collect();
            if !finite.is_empty() {
                let mid = finite.len() / 2;
                let (_, median, _) = finite.select_nth_unstable_by(mid, f64::total_cmp);
                self.last_kept_abs = Some(*median);
            }
        }
        let Some(mut reference) = self.last_kept_abs else {
            // No finite time in the block: every one is dropped.
            for k in from..self.t_cache.len() {
                self.drop_time(k, first_row + (k - from) as u64, f64::NAN)?;
            }
            return Ok(());
        };
        for k in from..self.t_cache.len() {
            let t = self.t_cache[k];
            // (A NaN fails the comparison; an infinity lies beyond any gap.)
            if near(reference, t) {
                reference = t;
                self.consecutive_outliers = 0;
            } else {
                self.drop_time(k, first_row + (k - from) as u64, reference)?;
            }
        }
        self.last_kept_abs = Some(reference);
        Ok(())
    }

    /// Drops the time of cache entry `k` (file row `row`; `reference` the last kept time):
    /// counts it, marks it NaN for `take`, and fails once too many came in a row.
    #[cold]
    fn drop_time(&mut self, k: usize, row: u64, reference: f64) -> Result<()> {
        self.first_outlier.get_or_insert((row, self.t_cache[k]));
        self.time_outliers += 1;
        self.consecutive_outliers += 1;
        if self.consecutive_outliers > MAX_CONSECUTIVE_TIME_OUTLIERS {
            let start = row + 1 - self.consecutive_outliers;
            return Err(Evimo2Error::format(
                &self.t.name,
                self.t.header.data_offset + start * self.t.row_bytes as u64,
                format!(
                    "event times jump: from event {start} on, {} events in a row lie more than \
                     {} s (the largest time gap) from the event before them (t = \
                     {reference:.6} s); the recording is not continuous, or pauses for longer",
                    self.consecutive_outliers, self.max_gap_s
                ),
            ));
        }
        self.t_cache[k] = f64::NAN;
        Ok(())
    }

    /// Ensures the time cache holds at least `want` rows from `pos` (fewer at the end of file).
    fn fill_t(&mut self, want: usize) -> Result<()> {
        let have = self.t_cache.len() - self.t_head;
        if have >= want {
            return Ok(());
        }
        if self.t_head > 0 {
            self.t_cache.drain(..self.t_head);
            self.t_head = 0;
        }
        let cache_end = self.pos + self.t_cache.len() as u64;
        let remaining = self.t.rows - cache_end;
        let count = ((want - have).max(self.scan_block) as u64).min(remaining) as usize;
        if count == 0 {
            return Ok(());
        }
        let mut buf = std::mem::take(&mut self.buf);
        self.t.read_rows(cache_end, count, &mut buf)?;
        let (dtype, big) = (self.t.header.dtype, self.t.header.big_endian);
        let from = self.t_cache.len();
        npy::decode_f64_into(dtype, big, &buf, &mut self.t_cache);
        self.buf = buf;
        self.screen_times(from, cache_end)
    }

    /// Returns the next `count` events (cached times must already cover them), without those
    /// whose time was dropped (`screen_times`).
    fn take(&mut self, count: usize) -> Result<Events> {
        let mut events = Events::with_capacity(count);
        let times = &self.t_cache[self.t_head..self.t_head + count];
        // Dropped times are rare: the columns are copied whole unless one may lie in the block
        // (some were dropped that were not yet passed over).
        let dropped = self.time_outliers > self.outliers_passed && times.iter().any(|t| t.is_nan());
        for &abs in times {
            if dropped && abs.is_nan() {
                self.outliers_passed += 1;
                continue;
            }
            let t = abs - self.t0;
            if t < self.last_t {
                self.non_monotonic += 1;
            }
            self.last_t = t;
            events.t.push(t);
        }
        let mut buf = std::mem::take(&mut self.buf);
        self.xy.read_rows(self.pos, count, &mut buf)?;
        let xy = npy::decode_u16(self.xy.header.dtype, self.xy.header.big_endian, &buf).map_err(|bad| {
            let row = self.pos + bad.map_or(0, |i| i as u64 / 2);
            Evimo2Error::format(
                &self.xy.name,
                self.xy.header.data_offset + row * self.xy.row_bytes as u64,
                format!("event {row}: pixel coordinate outside 0..=65535"),
            )
        })?;
        let kept = |i: &usize| !times[*i].is_nan();
        if dropped {
            events.x.extend((0..count).filter(kept).map(|i| xy[2 * i]));
            events.y.extend((0..count).filter(kept).map(|i| xy[2 * i + 1]));
        } else {
            events.x.extend(xy.iter().step_by(2));
            events.y.extend(xy.iter().skip(1).step_by(2));
        }
        self.p.read_rows(self.pos, count, &mut buf)?;
        let p =
            npy::decode_polarity(self.p.header.dtype, self.p.header.big_endian, &buf).map_err(
                |bad| match bad {
                    Some(i) => {
                        let row = self.pos + i as u64;
                        Evimo2Error::format(
                            &self.p.name,
                            self.p.header.data_offset + row * self.p.row_bytes as u64,
                            format!("event {row}: polarity is NaN"),
                        )
                    }
                    None => Evimo2Error::invalid(
                        &self.p.name,
                        format!("dtype '{}' is not a numeric type", self.p.header.descr),
                    ),
                },
            )?;
        events.p = if dropped {
            (0..count).filter(kept).map(|i| p[i]).collect()
        } else {
            p
        };
        self.buf = buf;
        self.t_head += count;
        self.pos += count as u64;
        Ok(events)
    }

    /// The next up to `max_events` events (t relative to the first event, seconds), or `None` at
    /// the end of the files.
    pub fn next_chunk(&mut self, max_events: usize) -> Result<Option<Events>> {
        let count = (max_events as u64).min(self.t.rows - self.pos) as usize;
        if count == 0 {
            return Ok(None);
        }
        self.fill_t(count)?;
        self.take(count).map(Some)
    }

    /// All events from the current position up to (excluding) the first one with relative time
    /// `>= t_end` seconds. Empty when the next event is already at or after `t_end` or the files
    /// are exhausted.
    pub fn read_until(&mut self, t_end: f64) -> Result<Events> {
        let abs_end = t_end + self.t0;
        let mut scanned = 0usize;
        loop {
            let cached = self.t_cache.len() - self.t_head;
            if scanned == cached {
                if self.pos + cached as u64 >= self.t.rows {
                    break;
                }
                self.fill_t(cached + self.scan_block)?;
            }
            let window = &self.t_cache[self.t_head + scanned..];
            match window.iter().position(|&t| t >= abs_end) {
                Some(i) => {
                    scanned += i;
                    break;
                }
                None => scanned += window.len(),
            }
        }
        self.take(scanned)
    }

    /// Reads every remaining event.
    pub fn read_all(&mut self) -> Result<Events> {
        let remaining = usize::try_from(self.t.rows - self.pos).map_err(|_| {
            Evimo2Error::invalid(&self.t.name, "too many events to hold in memory on this platform")
        })?;
        Ok(self.next_chunk(remaining)?.unwrap_or_default())
    }
}

/// One depth frame (no schema type exists for depth).
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFrame {
    /// Frame id (the number in `depth_%010d`).
    pub id: u64,
    /// Frame time, seconds relative to the first event.
    pub t: f64,
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// Depth per pixel, millimetres, row-major; 0 = unknown.
    pub depth_mm: Vec<u16>,
}

/// One per-frame member of a mask or depth archive.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameEntry {
    /// Frame id parsed from the member name.
    pub id: u64,
    /// Frame time from meta, seconds relative to the first event.
    pub t: f64,
    /// Member name, e.g. `mask_0000000012.npy`.
    pub member: String,
}

/// Lazily reads the per-frame (H, W) uint16 arrays of `dataset_mask.npz` or `dataset_depth.npz`.
#[derive(Debug)]
pub struct FrameArrayReader {
    npz: NpzReader,
    entries: Vec<FrameEntry>,
    width: u16,
    height: u16,
}

impl FrameArrayReader {
    /// Lists the `prefix_%010d.npy` members of `path` and gives each the time of the meta frame
    /// with the same id. Entries are sorted by id. A member without a matching frame is an error.
    pub fn open(path: &Path, prefix: &str, frames: &[FrameTruth], width: u16, height: u16) -> Result<Self> {
        let npz = NpzReader::open(path)?;
        let mut entries = Vec::new();
        for member in npz.member_names() {
            let Some(digits) = member.strip_prefix(prefix).and_then(|m| m.strip_prefix('_')) else {
                continue;
            };
            let Some(digits) = digits.strip_suffix(".npy") else {
                continue;
            };
            let Ok(id) = digits.parse::<u64>() else { continue };
            let Some(frame) = frames.iter().find(|f| f.id == id) else {
                return Err(Evimo2Error::invalid(
                    format!("{}[{member}]", npz.file()),
                    format!("no frame with id {id} in meta['frames'] to give this {prefix} a time"),
                ));
            };
            entries.push(FrameEntry {
                id,
                t: frame.t,
                member,
            });
        }
        entries.sort_by_key(|e| e.id);
        Ok(Self {
            npz,
            entries,
            width,
            height,
        })
    }

    /// The frames in the archive, sorted by id.
    pub fn entries(&self) -> &[FrameEntry] {
        &self.entries
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when the archive has no frames.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Reads frame `index` (position in [`Self::entries`]) as raw uint16 values, row-major.
    pub fn read_raw(&mut self, index: usize) -> Result<(FrameEntry, Vec<u16>)> {
        let Some(entry) = self.entries.get(index).cloned() else {
            return Err(Evimo2Error::invalid(
                self.npz.file(),
                format!("frame index {index} out of range ({} frames)", self.entries.len()),
            ));
        };
        let label = format!("{}[{}]", self.npz.file(), entry.member);
        let arr = self.npz.read_member(&entry.member)?;
        let h = &arr.header;
        if h.shape != [self.height as usize, self.width as usize] {
            return Err(Evimo2Error::invalid(
                &label,
                format!(
                    "shape {:?} differs from the camera's (res_y, res_x) = ({}, {})",
                    h.shape, self.height, self.width
                ),
            ));
        }
        if h.fortran_order {
            return Err(Evimo2Error::invalid(
                &label,
                "Fortran-order (column-major) arrays are not supported",
            ));
        }
        let values = npy::decode_u16(h.dtype, h.big_endian, &arr.data).map_err(|bad| match bad {
            Some(i) => Evimo2Error::format(
                &label,
                h.data_offset,
                format!("pixel {i}: value outside 0..=65535"),
            ),
            None => Evimo2Error::invalid(&label, format!("dtype '{}' is not an integer type", h.descr)),
        })?;
        Ok((entry, values))
    }
}

/// Lazily reads the masks of `dataset_mask.npz` as [`Mask`]s (ids = stored value / 1000, integer
/// division; 0 = background).
///
/// A mask most of whose non-zero pixels are not multiples of 1000 was written with the object
/// ids themselves (a tool that left out EVIMO2's factor): dividing would turn every object of it
/// into background and the run would silently have no moving object to score. Such a mask is
/// read with its values as ids, and counted ([`MaskReader::raw_id_masks`]) so the caller can say
/// so.
#[derive(Debug)]
pub struct MaskReader {
    inner: FrameArrayReader,
    raw_id_masks: usize,
}

impl MaskReader {
    /// The frames in the archive, sorted by id.
    pub fn entries(&self) -> &[FrameEntry] {
        self.inner.entries()
    }

    /// Number of masks.
    pub fn len(&self) -> usize {
        self.inner.len()
    }

    /// Masks read so far whose values were taken as object ids because most of their non-zero
    /// values were not multiples of [`MASK_ID_SCALE`] (see the type's documentation).
    pub fn raw_id_masks(&self) -> usize {
        self.raw_id_masks
    }

    /// True when there are no masks.
    pub fn is_empty(&self) -> bool {
        self.inner.is_empty()
    }

    /// Reads mask `index` (position in [`Self::entries`]).
    pub fn read(&mut self, index: usize) -> Result<Mask> {
        let (entry, mut values) = self.inner.read_raw(index)?;
        // Most non-zero pixels decide, so a few stray values do not turn an EVIMO2 mask around.
        let (scaled, raw) = values
            .iter()
            .filter(|&&v| v != 0)
            .fold((0usize, 0usize), |(s, r), v| {
                if v % MASK_ID_SCALE == 0 {
                    (s + 1, r)
                } else {
                    (s, r + 1)
                }
            });
        if raw <= scaled {
            for v in &mut values {
                *v /= MASK_ID_SCALE;
            }
        } else {
            self.raw_id_masks += 1;
        }
        Ok(Mask {
            t: entry.t,
            width: self.inner.width,
            height: self.inner.height,
            ids: values,
        })
    }

    /// Iterates over all masks in id order, reading each on demand.
    pub fn iter(&mut self) -> impl Iterator<Item = Result<Mask>> + '_ {
        (0..self.len()).map(move |i| self.read(i))
    }
}

/// Lazily reads `dataset_depth.npz`.
#[derive(Debug)]
pub struct DepthReader {
    inner: FrameArrayReader,
}

impl DepthReader {
    /// The frames in the archive, sorted by id.
    pub fn entries(&self) -> &[FrameEntry] {
        self.inner.entries()
    }

    /// Number of depth frames.
    pub fn len(&self) -> usize {
        self.inner.len()
    }

    /// True when there are no depth frames.
    pub fn is_empty(&self) -> bool {
        self.inner.is_empty()
    }

    /// Reads depth frame `index` (position in [`Self::entries`]).
    pub fn read(&mut self, index: usize) -> Result<DepthFrame> {
        let (entry, depth_mm) = self.inner.read_raw(index)?;
        Ok(DepthFrame {
            id: entry.id,
            t: entry.t,
            width: self.inner.width,
            height: self.inner.height,
            depth_mm,
        })
    }
}

/// Options for [`Sequence::open`]; see [`MetaOptions`] for each field's default.
pub type ReadOptions = MetaOptions;

/// An opened EVIMO2 v2 sequence folder: calibration, IMU, poses and frame list in memory; events,
/// masks and depth streamed on demand.
#[derive(Debug, Clone, PartialEq)]
pub struct Sequence {
    /// The folder.
    pub folder: PathBuf,
    /// Camera calibration and conventions.
    pub camera: CameraInfo,
    /// Absolute time of the first event, seconds on the EVIMO2 clock: every relative time is
    /// `ts - t0_s`.
    pub t0_s: f64,
    /// `meta['meta']['ros_time_offset']` (Unix seconds of the EVIMO2 clock's zero), if present.
    pub ros_time_offset_s: Option<f64>,
    /// Number of events.
    pub event_count: u64,
    /// IMU topics in the file, sorted.
    pub imu_topics: Vec<String>,
    /// The IMU topic read into `imu`.
    pub imu_topic: Option<String>,
    /// IMU samples, IMU frame (rad/s, m/s²), `t` relative to the first event on the IMU clock.
    pub imu: Vec<ImuSample>,
    /// Camera poses (camera -> world) from `full_trajectory`, or `frames` without it.
    pub camera_poses: Vec<CameraMotion>,
    /// Ground-truth frames (times, camera pose, object poses object -> camera).
    pub frames: Vec<FrameTruth>,
    /// Camera fields that `meta['meta']` lacks, with the file they were taken from instead
    /// (intrinsics from `dataset_info.npz[K]`, resolution from the masks' shape); empty when
    /// `meta['meta']` has them all. A reader should say so: such a folder was written by a
    /// tool that does not follow the layout to the letter.
    pub camera_fallbacks: Vec<String>,
    /// Largest time gap, s, of the event reader ([`EventReader::open_with_gap`]).
    pub max_time_gap_s: f64,
}

impl Sequence {
    /// Reads `dataset_info.npz` and the first event time.
    pub fn open(folder: &Path, options: &ReadOptions) -> Result<Self> {
        check_sequence_folder(folder)?;
        let max_time_gap_s = options.max_time_gap_s.unwrap_or(DEFAULT_MAX_TIME_GAP_S);
        let events = EventReader::open_with_gap(folder, max_time_gap_s)?;
        let t0 = events.t0_s();
        let info_path = folder.join(INFO_NPZ);
        let mut info = NpzReader::open(&info_path)?;
        let label = format!("{}[meta.npy]", info.file());
        let arr = info.read_key("meta")?;
        let value = meta::meta_from_npy(&arr, &label)?;
        // Only consulted for fields that meta['meta'] lacks.
        let k = info.read_key("K").ok().and_then(|a| intrinsic_matrix(&a));
        let mask_path = folder.join(MASK_NPZ);
        let resolution = || mask_resolution(&mask_path);
        let fallback = meta::CameraFallback {
            k,
            resolution: &resolution,
            resolution_source: MASK_NPZ,
        };
        let m = meta::convert_with(&value, t0, options, &fallback, &label)?;
        Ok(Self {
            folder: folder.to_path_buf(),
            camera: m.camera,
            t0_s: t0,
            ros_time_offset_s: m.ros_time_offset_s,
            event_count: events.len(),
            imu_topics: m.imu_topics,
            imu_topic: m.imu_topic,
            imu: m.imu,
            camera_poses: m.camera_poses,
            frames: m.frames,
            camera_fallbacks: m.camera_fallbacks,
            max_time_gap_s,
        })
    }

    /// Opens the event files for streaming from the first event (with the sequence's largest
    /// time gap).
    pub fn events(&self) -> Result<EventReader> {
        EventReader::open_with_gap(&self.folder, self.max_time_gap_s)
    }

    /// Opens `dataset_mask.npz`.
    pub fn masks(&self) -> Result<MaskReader> {
        let inner = FrameArrayReader::open(
            &self.folder.join(MASK_NPZ),
            "mask",
            &self.frames,
            self.camera.width,
            self.camera.height,
        )?;
        Ok(MaskReader {
            inner,
            raw_id_masks: 0,
        })
    }

    /// Opens `dataset_depth.npz`, or `None` when the folder has none.
    pub fn depth(&self) -> Result<Option<DepthReader>> {
        let path = self.folder.join(DEPTH_NPZ);
        if !path.exists() {
            return Ok(None);
        }
        let inner = FrameArrayReader::open(
            &path,
            "depth",
            &self.frames,
            self.camera.width,
            self.camera.height,
        )?;
        Ok(Some(DepthReader { inner }))
    }

    /// Object poses of all frames, in frame order (object -> camera, relative times).
    pub fn object_poses(&self) -> Vec<evseg_schemas::ObjectPose> {
        self.frames
            .iter()
            .flat_map(|f| f.objects.iter().copied())
            .collect()
    }
}

/// `K` of `dataset_info.npz` as a row-major 3 x 3 matrix, if it is one: a float array of shape
/// (3, 3) with finite, positive focal lengths. Anything else is `None` (it is only a fallback).
fn intrinsic_matrix(arr: &npy::NpyArray) -> Option<[f64; 9]> {
    let h = &arr.header;
    if h.shape != [3, 3] {
        return None;
    }
    let mut v = Vec::with_capacity(9);
    if !npy::decode_f64_into(h.dtype, h.big_endian, &arr.data, &mut v) || v.len() != 9 {
        return None;
    }
    let mut k = [0.0; 9];
    for r in 0..3 {
        for c in 0..3 {
            // Fortran order stores columns first.
            k[3 * r + c] = if h.fortran_order {
                v[3 * c + r]
            } else {
                v[3 * r + c]
            };
        }
    }
    let ok = k.iter().all(|x| x.is_finite()) && k[0] > 0.0 && k[4] > 0.0;
    ok.then_some(k)
}

/// The sensor's (width, height) from the shape (height, width) of the first mask in `path`
/// (`dataset_mask.npz`), if it has one; `None` on any problem (it is only a fallback).
fn mask_resolution(path: &Path) -> Option<(u16, u16)> {
    let mut npz = NpzReader::open(path).ok()?;
    let first = npz
        .member_names()
        .into_iter()
        .filter(|n| n.starts_with("mask_"))
        .min()?;
    let shape = npz.read_member(&first).ok()?.header.shape;
    match shape[..] {
        [h, w] => Some((u16::try_from(w).ok()?, u16::try_from(h).ok()?)),
        _ => None,
    }
}

/// How deep [`check_sequence_folder`] looks below a folder that is not a sequence: EVIMO2's
/// layout is `<camera>/<category>/<split>/<sequence>/`, so 4 levels reach the sequences from
/// the dataset's root.
pub const SEQUENCE_SEARCH_DEPTH: usize = 4;

/// Most folders [`check_sequence_folder`] visits while looking for sequences below a folder.
pub const SEQUENCE_SEARCH_VISITS: usize = 10_000;

/// Most sequence folders named in the error of [`check_sequence_folder`].
const SEQUENCE_SEARCH_NAMED: usize = 5;

/// Checks that `folder` is an EVIMO2 sequence folder (holds [`EVENTS_T`]) before its files are
/// opened. When it is a folder that is not one, the error names the sequence folders below it
/// (a user who passed the dataset's root or a split's folder sees which paths to pass).
fn check_sequence_folder(folder: &Path) -> Result<()> {
    let shown = folder.display().to_string();
    if !folder.is_dir() {
        let message = if folder.exists() {
            "is not a folder; an EVIMO2 v2 sequence is a folder of .npy and .npz files".to_string()
        } else {
            "no such folder".to_string()
        };
        return Err(Evimo2Error::invalid(shown, message));
    }
    if folder.join(EVENTS_T).is_file() {
        return Ok(());
    }
    let (found, complete) = sequence_folders_below(folder);
    let message = if found.is_empty() {
        format!(
            "not an EVIMO2 v2 sequence folder (no {EVENTS_T}), and none of the folders up to \
             {SEQUENCE_SEARCH_DEPTH} levels below it is one"
        )
    } else {
        let named: Vec<String> = found
            .iter()
            .take(SEQUENCE_SEARCH_NAMED)
            .map(|p| p.strip_prefix(folder).unwrap_or(p).display().to_string())
            .collect();
        let more = found.len() - named.len();
        let count = match (more, complete) {
            (0, true) => String::new(),
            (_, true) => format!(" and {more} more"),
            (_, false) => format!(" and more (the search stopped after {SEQUENCE_SEARCH_VISITS} folders)"),
        };
        format!(
            "not an EVIMO2 v2 sequence folder (no {EVENTS_T}); the sequence folders below it \
             include {}{count}; pass one of them as the path",
            named.join(", ")
        )
    };
    Err(Evimo2Error::invalid(shown, message))
}

/// The EVIMO2 v2 sequence folders at or below `root`: `root` itself when it holds [`EVENTS_T`],
/// else the folders up to [`SEQUENCE_SEARCH_DEPTH`] levels below it that do, sorted by path;
/// and whether the search visited every folder within that depth (it stops after
/// [`SEQUENCE_SEARCH_VISITS`]). Unreadable folders are skipped. For tools that run many
/// sequences (`evseg bench --sequences`); opening one checks it with a clear error instead.
pub fn find_sequence_folders(root: &Path) -> (Vec<PathBuf>, bool) {
    if root.join(EVENTS_T).is_file() {
        return (vec![root.to_path_buf()], true);
    }
    sequence_folders_below(root)
}

/// Folders below `root` (up to [`SEQUENCE_SEARCH_DEPTH`] levels, sorted) that hold [`EVENTS_T`],
/// and whether the search visited every folder within that depth. Unreadable folders are
/// skipped: this only feeds an error message.
fn sequence_folders_below(root: &Path) -> (Vec<PathBuf>, bool) {
    let mut found = Vec::new();
    let mut level = vec![root.to_path_buf()];
    let mut visits = 0usize;
    // Each folder once, whatever links lead to it, and never one that holds `root` (a link to
    // `.` or to an ancestor would list the tree again, or folders outside it).
    let root_real = root.canonicalize().unwrap_or_else(|_| root.to_path_buf());
    let mut seen = std::collections::HashSet::from([root_real.clone()]);
    for _ in 0..SEQUENCE_SEARCH_DEPTH {
        let mut next = Vec::new();
        for dir in &level {
            let Ok(entries) = std::fs::read_dir(dir) else {
                continue;
            };
            let mut children: Vec<PathBuf> = entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_dir())
                .collect();
            children.sort();
            children.retain(|p| {
                p.canonicalize()
                    .is_ok_and(|real| !root_real.starts_with(&real) && seen.insert(real))
            });
            for child in children {
                visits += 1;
                if visits > SEQUENCE_SEARCH_VISITS {
                    return (found, false);
                }
                if child.join(EVENTS_T).is_file() {
                    found.push(child);
                } else {
                    next.push(child);
                }
            }
        }
        level = next;
    }
    (found, true)
}
