//! Writing an EVIMO2 v2 sequence folder (for the simulator and for tests).
//!
//! Files written: `dataset_events_t.npy` (`<f8`, (N,), absolute seconds = `t_start_s + t`),
//! `dataset_events_xy.npy` (`<u2`, (N, 2)), `dataset_events_p.npy` (`|u1`, (N,)),
//! `dataset_mask.npz` (`mask_%010d` = frame id, `<u2` (H, W), object id * 1000),
//! `dataset_depth.npz` when depth is given (`depth_%010d`, `<u2` mm), and `dataset_info.npz` with
//! `index` (`<u4`, event index every `discretization` s, as EVIMO2's pydvs tool computes it),
//! `discretization` (`<f8` scalar), `K` (`<f8` 3x3), `D` (`<f8` (4,) = k1, k2, k3, k4 as EVIMO2
//! writes it: for 'radtan' that is k1, k2, k3 = RadTan k3, k4 = 0 — the tangential p1, p2 are only
//! in meta), and `meta` (pickled dict or Python-literal string, see [`MetaForm`]).
//!
//! IMU samples are written as given: they must be in the IMU frame (EVIMO2 convention: the camera
//! frame rate is `w_cam = R * w_imu` with `R` = [`CameraInfo::imu_to_camera`]), on the IMU clock.
//! `imu_to_camera`, `imu_time_offset_s` and `sensor` are stored as extra keys of `meta['meta']`
//! (`evseg_*`), which the reader uses unless overridden; EVIMO2 tools ignore them.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use evseg_schemas::{CameraInfo, CameraMotion, Distortion, Events, ImuSample, Mask};

use crate::error::{Evimo2Error, Result};
use crate::meta::{self, FrameTruth};
use crate::npy;
use crate::npz::NpzWriter;
use crate::pickle_write;
use crate::reader::{DEPTH_NPZ, EVENTS_P, EVENTS_T, EVENTS_XY, INFO_NPZ, MASK_ID_SCALE, MASK_NPZ};

/// How `meta` is stored in `dataset_info.npz`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum MetaForm {
    /// A pickled 0-d object array, as `np.savez(..., meta=dict)` writes it (EVIMO2's own form).
    #[default]
    Pickle,
    /// A 0-d `<U` string holding the dict as a Python literal (the form some public code writes).
    Literal,
}

/// Writer settings.
#[derive(Debug, Clone, PartialEq)]
pub struct WriteOptions {
    /// Form of `meta`. Default: [`MetaForm::Pickle`].
    pub meta_form: MetaForm,
    /// Deflate the `.npz` members (`np.savez_compressed`); else store them (`np.savez`).
    /// Default: true (masks compress ~50x).
    pub compress: bool,
    /// Spacing of the `index` entries, seconds. Default 0.01, EVIMO2's `discretization`.
    pub discretization_s: f64,
    /// Event rows written per buffered block. Default 65 536 (bounded memory for long sequences).
    pub block_events: usize,
}

impl Default for WriteOptions {
    fn default() -> Self {
        Self {
            meta_form: MetaForm::Pickle,
            compress: true,
            discretization_s: 0.01,
            block_events: 1 << 16,
        }
    }
}

/// Everything a sequence folder holds. All `t` are seconds relative to `t_start_s`.
#[derive(Debug, Clone, PartialEq)]
pub struct SequenceData {
    /// Events, `t` relative seconds (file order is kept). For the reader's times to equal these,
    /// the first event should be at `t = 0` (the reader measures time from the first event).
    pub events: Events,
    /// Absolute time of relative `t = 0`, seconds on the EVIMO2 clock (added to every time written).
    /// [`CameraInfo::time_origin_us`] is not written; the reader recomputes it from the first event.
    pub t_start_s: f64,
    /// Camera calibration and IMU convention.
    pub camera: CameraInfo,
    /// Key of `meta['imu']`, e.g. `/prophesee/left/imu`.
    pub imu_topic: String,
    /// IMU samples, IMU frame (rad/s, m/s²), `t` on the IMU clock.
    pub imu: Vec<ImuSample>,
    /// Camera poses (camera -> world) for `full_trajectory`; velocities are not written.
    pub camera_poses: Vec<CameraMotion>,
    /// Ground-truth frames: id (mask key), time, camera pose, object poses (object -> camera).
    pub frames: Vec<FrameTruth>,
    /// One mask per frame, `masks[i]` belongs to `frames[i]` (its own `t` is not written).
    pub masks: Vec<Mask>,
    /// Optional depth per frame, millimetres, row-major, same size as the masks.
    pub depth_mm: Option<Vec<Vec<u16>>>,
}

/// The default IMU topic name of EVIMO2's left Prophesee camera.
pub const DEFAULT_IMU_TOPIC: &str = "/prophesee/left/imu";

/// Writes `data` into `folder` (created if needed) with default [`WriteOptions`].
pub fn write_sequence(folder: &Path, data: &SequenceData) -> Result<()> {
    write_sequence_with(folder, data, &WriteOptions::default())
}

/// Writes `data` into `folder` (created if needed), through [`SequenceWriter`].
pub fn write_sequence_with(folder: &Path, data: &SequenceData, options: &WriteOptions) -> Result<()> {
    validate(folder, data, options)?;
    let mut writer = SequenceWriter::create(folder, &data.camera, data.t_start_s, options)?;
    writer.push_events(&data.events)?;
    for (frame, mask) in data.frames.iter().zip(&data.masks) {
        writer.push_mask(frame.id, mask)?;
    }
    if let Some(depth) = &data.depth_mm {
        write_depth(folder, data, depth, options)?;
    }
    writer.finish(&data.imu_topic, &data.imu, &data.camera_poses, &data.frames)?;
    Ok(())
}

fn validate(folder: &Path, data: &SequenceData, options: &WriteOptions) -> Result<()> {
    let bad = |file: &str, message: String| Evimo2Error::BadInput {
        file: folder.join(file).display().to_string(),
        message,
    };
    if let Some(problem) = events_problem(&data.events, 0) {
        return Err(bad(EVENTS_T, problem));
    }
    if let Some(problem) = discretization_problem(options) {
        return Err(bad(INFO_NPZ, problem));
    }
    if data.masks.len() != data.frames.len() {
        return Err(bad(
            MASK_NPZ,
            format!("{} masks for {} frames", data.masks.len(), data.frames.len()),
        ));
    }
    let pixels = data.camera.width as usize * data.camera.height as usize;
    for (i, (frame, mask)) in data.frames.iter().zip(&data.masks).enumerate() {
        if let Some(problem) = mask_problem(i, mask, &data.camera) {
            return Err(bad(MASK_NPZ, problem));
        }
        if data.frames[..i].iter().any(|f| f.id == frame.id) {
            return Err(bad(MASK_NPZ, format!("frame id {} appears twice", frame.id)));
        }
    }
    if let Some(depth) = &data.depth_mm {
        if depth.len() != data.frames.len() {
            return Err(bad(
                DEPTH_NPZ,
                format!("{} depth frames for {} frames", depth.len(), data.frames.len()),
            ));
        }
        if let Some(i) = depth.iter().position(|d| d.len() != pixels) {
            return Err(bad(
                DEPTH_NPZ,
                format!(
                    "depth frame {i} has {} values, camera has {pixels} pixels",
                    depth[i].len()
                ),
            ));
        }
    }
    Ok(())
}

/// One event column file written as rows arrive: the header reserves room for the largest row
/// count and is rewritten with the real one by [`NpyColumn::finish`].
struct NpyColumn {
    name: String,
    w: BufWriter<File>,
    descr: &'static str,
    /// Values per row (1, or 2 for x, y).
    width: usize,
    header_len: usize,
}

impl NpyColumn {
    fn create(path: &Path, descr: &'static str, width: usize) -> Result<Self> {
        let name = path.display().to_string();
        let f = File::create(path).map_err(|e| Evimo2Error::io(&name, e))?;
        let mut w = BufWriter::new(f);
        let header = npy::encode_header(descr, false, &Self::shape(u64::MAX as usize, width));
        w.write_all(&header).map_err(|e| Evimo2Error::io(&name, e))?;
        Ok(Self {
            name,
            w,
            descr,
            width,
            header_len: header.len(),
        })
    }

    fn shape(rows: usize, width: usize) -> Vec<usize> {
        if width == 1 { vec![rows] } else { vec![rows, width] }
    }

    fn write(&mut self, bytes: &[u8]) -> Result<()> {
        self.w
            .write_all(bytes)
            .map_err(|e| Evimo2Error::io(&self.name, e))
    }

    /// Writes the header with `rows` over the reserved one and closes the file.
    fn finish(mut self, rows: u64) -> Result<()> {
        let rows = usize::try_from(rows)
            .map_err(|_| Evimo2Error::invalid(&self.name, "too many rows for this platform"))?;
        let header =
            npy::encode_header_at_least(self.descr, false, &Self::shape(rows, self.width), self.header_len);
        let io = |e| Evimo2Error::io(&self.name, e);
        self.w.flush().map_err(io)?;
        let f = self.w.get_mut();
        f.seek(SeekFrom::Start(0)).map_err(io)?;
        f.write_all(&header).map_err(io)?;
        f.flush().map_err(io)
    }
}

/// Writes a sequence folder while the sequence is produced (the simulator's `evseg sim`): events
/// go to the three column files and masks into `dataset_mask.npz` as they arrive, so memory holds
/// only the small ground truth (frames, poses, IMU); the event count goes into the column headers
/// and the index into `dataset_info.npz` at [`SequenceWriter::finish`].
pub struct SequenceWriter {
    folder: PathBuf,
    options: WriteOptions,
    camera: CameraInfo,
    t_start_s: f64,
    t: NpyColumn,
    xy: NpyColumn,
    p: NpyColumn,
    index: EventIndex,
    masks: NpzWriter,
    /// Frame ids of the masks written, in order.
    mask_ids: Vec<u64>,
    buf: Vec<u8>,
}

impl SequenceWriter {
    /// Creates `folder` (if needed) and its event and mask files for a camera `camera`; times
    /// pushed are relative to `t_start_s` (absolute seconds on the EVIMO2 clock).
    pub fn create(
        folder: &Path,
        camera: &CameraInfo,
        t_start_s: f64,
        options: &WriteOptions,
    ) -> Result<Self> {
        if let Some(message) = discretization_problem(options) {
            return Err(Evimo2Error::BadInput {
                file: folder.join(INFO_NPZ).display().to_string(),
                message,
            });
        }
        std::fs::create_dir_all(folder).map_err(|e| Evimo2Error::io(folder.display(), e))?;
        Ok(Self {
            folder: folder.to_path_buf(),
            options: options.clone(),
            camera: camera.clone(),
            t_start_s,
            t: NpyColumn::create(&folder.join(EVENTS_T), "<f8", 1)?,
            xy: NpyColumn::create(&folder.join(EVENTS_XY), "<u2", 2)?,
            p: NpyColumn::create(&folder.join(EVENTS_P), "|u1", 1)?,
            index: EventIndex::new(options.discretization_s),
            masks: NpzWriter::create(&folder.join(MASK_NPZ), options.compress)?,
            mask_ids: Vec::new(),
            buf: Vec::new(),
        })
    }

    /// Appends `events` (times relative to `t_start_s`, finite), in blocks of
    /// [`WriteOptions::block_events`].
    pub fn push_events(&mut self, events: &Events) -> Result<()> {
        if let Some(problem) = events_problem(events, self.index.events()) {
            return Err(self.bad(EVENTS_T, problem));
        }
        let block = self.options.block_events.max(1);
        for start in (0..events.len()).step_by(block) {
            let end = (start + block).min(events.len());
            self.buf.clear();
            for &t in &events.t[start..end] {
                let abs = t + self.t_start_s;
                self.index.push(abs);
                self.buf.extend_from_slice(&abs.to_le_bytes());
            }
            self.t.write(&self.buf)?;
            self.buf.clear();
            for (x, y) in events.x[start..end].iter().zip(&events.y[start..end]) {
                self.buf.extend_from_slice(&x.to_le_bytes());
                self.buf.extend_from_slice(&y.to_le_bytes());
            }
            self.xy.write(&self.buf)?;
            self.p.write(&events.p[start..end])?;
        }
        Ok(())
    }

    /// Appends the mask of ground-truth frame `frame_id` (the camera's size, object ids up to
    /// 65).
    pub fn push_mask(&mut self, frame_id: u64, mask: &Mask) -> Result<()> {
        let (w, h) = (self.camera.width, self.camera.height);
        if let Some(problem) = mask_problem(self.mask_ids.len(), mask, &self.camera) {
            return Err(self.bad(MASK_NPZ, problem));
        }
        if self.mask_ids.contains(&frame_id) {
            return Err(self.bad(MASK_NPZ, format!("frame id {frame_id} appears twice")));
        }
        let image = u16_image(w, h, mask.ids.iter().map(|&id| id * MASK_ID_SCALE));
        self.masks.add(&format!("mask_{frame_id:010}"), &image)?;
        self.mask_ids.push(frame_id);
        Ok(())
    }

    /// Finishes the files: the event count into the column headers, the masks' archive, and
    /// `dataset_info.npz` with the index and the meta of `frames` (one per mask pushed, in that
    /// order), `imu` (samples of `imu_topic`) and `camera_poses`. Returns the events written.
    pub fn finish(
        self,
        imu_topic: &str,
        imu: &[ImuSample],
        camera_poses: &[CameraMotion],
        frames: &[FrameTruth],
    ) -> Result<u64> {
        let ids: Vec<u64> = frames.iter().map(|f| f.id).collect();
        if ids != self.mask_ids {
            return Err(self.bad(
                MASK_NPZ,
                format!(
                    "{} masks for {} frames (or in another order)",
                    self.mask_ids.len(),
                    frames.len()
                ),
            ));
        }
        let n = self.index.events();
        if n > u64::from(u32::MAX) {
            return Err(self.bad(
                INFO_NPZ,
                "more than 2^32 events do not fit EVIMO2's uint32 index".into(),
            ));
        }
        self.t.finish(n)?;
        self.xy.finish(n)?;
        self.p.finish(n)?;
        self.masks.finish()?;
        let info = InfoParts {
            camera: &self.camera,
            t_start_s: self.t_start_s,
            imu_topic,
            imu,
            camera_poses,
            frames,
        };
        write_info(&self.folder, &info, &self.index.finish(), &self.options)?;
        Ok(n)
    }

    fn bad(&self, file: &str, message: String) -> Evimo2Error {
        Evimo2Error::BadInput {
            file: self.folder.join(file).display().to_string(),
            message,
        }
    }
}

/// What is wrong with `events` (the first of them event number `first`): columns of different
/// lengths, or a time that is not finite (the index of `dataset_info.npz` steps through the
/// times: it would never end); `None` when they can be written.
fn events_problem(events: &Events, first: u64) -> Option<String> {
    if !events.is_consistent() {
        return Some("event columns have different lengths".into());
    }
    let i = events.t.iter().position(|t| !t.is_finite())?;
    Some(format!(
        "event {} has time {} s, not a finite number",
        first + i as u64,
        events.t[i]
    ))
}

/// What is wrong with the index spacing of `options`, if anything.
fn discretization_problem(options: &WriteOptions) -> Option<String> {
    let d = options.discretization_s;
    (d.is_nan() || d <= 0.0).then(|| format!("discretization {d} s is not positive"))
}

/// What is wrong with mask number `i` for `camera`: another size, or an object id whose EVIMO2
/// value (id * 1000) does not fit uint16; `None` when it can be written.
fn mask_problem(i: usize, mask: &Mask, camera: &CameraInfo) -> Option<String> {
    let (w, h) = (camera.width, camera.height);
    if mask.width != w || mask.height != h || mask.ids.len() != w as usize * h as usize {
        return Some(format!(
            "mask {i} is {}x{} with {} ids, camera is {w}x{h}",
            mask.width,
            mask.height,
            mask.ids.len()
        ));
    }
    let max_id = u16::MAX / MASK_ID_SCALE;
    mask.ids
        .iter()
        .find(|&&id| id > max_id)
        .map(|id| format!("mask {i}: object id {id} * 1000 does not fit uint16 (max id {max_id})"))
}

fn u16_image(width: u16, height: u16, values: impl Iterator<Item = u16>) -> Vec<u8> {
    let data: Vec<u8> = values.flat_map(u16::to_le_bytes).collect();
    npy::encode_array("<u2", &[height as usize, width as usize], &data)
}

fn write_depth(folder: &Path, data: &SequenceData, depth: &[Vec<u16>], options: &WriteOptions) -> Result<()> {
    let (w, h) = (data.camera.width, data.camera.height);
    let mut npz = NpzWriter::create(&folder.join(DEPTH_NPZ), options.compress)?;
    for (frame, d) in data.frames.iter().zip(depth) {
        npz.add(
            &format!("depth_{:010}", frame.id),
            &u16_image(w, h, d.iter().copied()),
        )?;
    }
    npz.finish()
}

/// EVIMO2's event index built as event times arrive (see [`event_index`]).
struct EventIndex {
    idx: Vec<u32>,
    last: Option<f64>,
    n: u64,
    w: f64,
}

impl EventIndex {
    fn new(w: f64) -> Self {
        Self {
            idx: vec![0],
            last: None,
            n: 0,
            w,
        }
    }

    /// Events pushed so far.
    fn events(&self) -> u64 {
        self.n
    }

    fn push(&mut self, t: f64) {
        let i = self.n as u32;
        let last = self.last.get_or_insert(t);
        while t - *last > self.w {
            self.idx.push(i);
            *last += self.w;
        }
        self.n += 1;
    }

    fn finish(mut self) -> Vec<u32> {
        if self.n < 2 {
            return vec![0];
        }
        self.idx.push((self.n - 1) as u32);
        self.idx
    }
}

/// EVIMO2's event index (pydvs `get_index`): `[0]`, then for each event `i` and while
/// `t[i] - last > w`: push `i` and advance `last` by `w`; finally push `N - 1`.
/// Fewer than 2 events give `[0]`.
pub fn event_index(t_abs: impl Iterator<Item = f64>, n: usize, w: f64) -> Vec<u32> {
    let mut index = EventIndex::new(w);
    for t in t_abs.take(n) {
        index.push(t);
    }
    index.finish()
}

fn f64_array(shape: &[usize], values: &[f64]) -> Vec<u8> {
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    npy::encode_array("<f8", shape, &data)
}

/// What `dataset_info.npz` holds besides the event index.
struct InfoParts<'a> {
    camera: &'a CameraInfo,
    t_start_s: f64,
    imu_topic: &'a str,
    imu: &'a [ImuSample],
    camera_poses: &'a [CameraMotion],
    frames: &'a [FrameTruth],
}

fn write_info(folder: &Path, data: &InfoParts<'_>, index: &[u32], options: &WriteOptions) -> Result<()> {
    let path = folder.join(INFO_NPZ);
    let cam = data.camera;
    let mut npz = NpzWriter::create(&path, options.compress)?;
    let start = data.t_start_s;
    let index_bytes: Vec<u8> = index.iter().flat_map(|v| v.to_le_bytes()).collect();
    npz.add("index", &npy::encode_array("<u4", &[index.len()], &index_bytes))?;
    npz.add("discretization", &f64_array(&[], &[options.discretization_s]))?;
    let k = [cam.fx, 0.0, cam.cx, 0.0, cam.fy, cam.cy, 0.0, 0.0, 1.0];
    npz.add("K", &f64_array(&[3, 3], &k))?;
    let d = match cam.distortion {
        Distortion::None => [0.0; 4],
        Distortion::RadTan { k1, k2, k3, .. } => [k1, k2, k3, 0.0],
        Distortion::Equidistant { k1, k2, k3, k4 } => [k1, k2, k3, k4],
    };
    npz.add("D", &f64_array(&[4], &d))?;
    let value = meta::build(
        cam,
        data.imu_topic,
        data.imu,
        data.camera_poses,
        data.frames,
        start,
    );
    let meta_npy = match options.meta_form {
        MetaForm::Pickle => {
            let mut out = npy::encode_header("|O", false, &[]);
            out.extend_from_slice(&pickle_write::numpy_object_scalar(&value));
            out
        }
        MetaForm::Literal => {
            let text = value.to_string();
            let chars = text.chars().count().max(1);
            let mut bytes: Vec<u8> = text.chars().flat_map(|c| (c as u32).to_le_bytes()).collect();
            bytes.resize(chars * 4, 0);
            npy::encode_array(&format!("<U{chars}"), &[], &bytes)
        }
    };
    npz.add("meta", &meta_npy)?;
    npz.finish()
}
