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
use std::io::{BufWriter, Write};
use std::path::Path;

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

/// Writes `data` into `folder` (created if needed).
pub fn write_sequence_with(folder: &Path, data: &SequenceData, options: &WriteOptions) -> Result<()> {
    validate(folder, data, options)?;
    std::fs::create_dir_all(folder).map_err(|e| Evimo2Error::io(folder.display(), e))?;
    write_events(folder, data, options)?;
    write_frames(folder, data, options)?;
    write_info(folder, data, options)
}

fn validate(folder: &Path, data: &SequenceData, options: &WriteOptions) -> Result<()> {
    let bad = |file: &str, message: String| Evimo2Error::BadInput {
        file: folder.join(file).display().to_string(),
        message,
    };
    if !data.events.is_consistent() {
        return Err(bad(EVENTS_T, "event columns have different lengths".into()));
    }
    if let Some(i) = data.events.t.iter().position(|t| !t.is_finite()) {
        // (The index of `dataset_info.npz` steps through the times: it would never end.)
        return Err(bad(
            EVENTS_T,
            format!("event {i} has time {} s, not a finite number", data.events.t[i]),
        ));
    }
    if options.discretization_s.is_nan() || options.discretization_s <= 0.0 {
        return Err(bad(
            INFO_NPZ,
            format!("discretization {} s is not positive", options.discretization_s),
        ));
    }
    if data.masks.len() != data.frames.len() {
        return Err(bad(
            MASK_NPZ,
            format!("{} masks for {} frames", data.masks.len(), data.frames.len()),
        ));
    }
    let pixels = data.camera.width as usize * data.camera.height as usize;
    let max_id = u16::MAX / MASK_ID_SCALE;
    for (i, (frame, mask)) in data.frames.iter().zip(&data.masks).enumerate() {
        if mask.width != data.camera.width || mask.height != data.camera.height || mask.ids.len() != pixels {
            return Err(bad(
                MASK_NPZ,
                format!(
                    "mask {i} is {}x{} with {} ids, camera is {}x{}",
                    mask.width,
                    mask.height,
                    mask.ids.len(),
                    data.camera.width,
                    data.camera.height
                ),
            ));
        }
        if let Some(id) = mask.ids.iter().find(|&&id| id > max_id) {
            return Err(bad(
                MASK_NPZ,
                format!("mask {i}: object id {id} * 1000 does not fit uint16 (max id {max_id})"),
            ));
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

/// Streams one column file: header then `n` rows from `values`, encoded `block` rows at a time.
fn write_column<T>(
    path: &Path,
    descr: &str,
    shape: &[usize],
    values: impl Iterator<Item = T>,
    block: usize,
    encode: impl Fn(T, &mut Vec<u8>),
) -> Result<()> {
    let name = path.display().to_string();
    let f = File::create(path).map_err(|e| Evimo2Error::io(&name, e))?;
    let mut w = BufWriter::new(f);
    w.write_all(&npy::encode_header(descr, false, shape))
        .map_err(|e| Evimo2Error::io(&name, e))?;
    let mut buf = Vec::new();
    let mut rows = 0;
    for v in values {
        encode(v, &mut buf);
        rows += 1;
        if rows % block.max(1) == 0 {
            w.write_all(&buf).map_err(|e| Evimo2Error::io(&name, e))?;
            buf.clear();
        }
    }
    w.write_all(&buf).map_err(|e| Evimo2Error::io(&name, e))?;
    w.flush().map_err(|e| Evimo2Error::io(&name, e))
}

fn write_events(folder: &Path, data: &SequenceData, options: &WriteOptions) -> Result<()> {
    let ev = &data.events;
    let n = ev.len();
    let start = data.t_start_s;
    let block = options.block_events;
    write_column(&folder.join(EVENTS_T), "<f8", &[n], ev.t.iter(), block, |t, b| {
        b.extend_from_slice(&(t + start).to_le_bytes())
    })?;
    write_column(
        &folder.join(EVENTS_XY),
        "<u2",
        &[n, 2],
        ev.x.iter().zip(&ev.y),
        block,
        |(x, y), b| {
            b.extend_from_slice(&x.to_le_bytes());
            b.extend_from_slice(&y.to_le_bytes());
        },
    )?;
    write_column(&folder.join(EVENTS_P), "|u1", &[n], ev.p.iter(), block, |p, b| {
        b.push(*p)
    })
}

fn u16_image(width: u16, height: u16, values: impl Iterator<Item = u16>) -> Vec<u8> {
    let data: Vec<u8> = values.flat_map(u16::to_le_bytes).collect();
    npy::encode_array("<u2", &[height as usize, width as usize], &data)
}

fn write_frames(folder: &Path, data: &SequenceData, options: &WriteOptions) -> Result<()> {
    let (w, h) = (data.camera.width, data.camera.height);
    let mut masks = NpzWriter::create(&folder.join(MASK_NPZ), options.compress)?;
    for (frame, mask) in data.frames.iter().zip(&data.masks) {
        let image = u16_image(w, h, mask.ids.iter().map(|&id| id * MASK_ID_SCALE));
        masks.add(&format!("mask_{:010}", frame.id), &image)?;
    }
    masks.finish()?;
    if let Some(depth) = &data.depth_mm {
        let mut npz = NpzWriter::create(&folder.join(DEPTH_NPZ), options.compress)?;
        for (frame, d) in data.frames.iter().zip(depth) {
            npz.add(
                &format!("depth_{:010}", frame.id),
                &u16_image(w, h, d.iter().copied()),
            )?;
        }
        npz.finish()?;
    }
    Ok(())
}

/// EVIMO2's event index (pydvs `get_index`): `[0]`, then for each event `i` and while
/// `t[i] - last > w`: push `i` and advance `last` by `w`; finally push `N - 1`.
/// Fewer than 2 events give `[0]`.
pub fn event_index(t_abs: impl Iterator<Item = f64>, n: usize, w: f64) -> Vec<u32> {
    let mut idx = vec![0u32];
    if n < 2 {
        return idx;
    }
    let mut last = None;
    for (i, t) in t_abs.enumerate() {
        let last_t = last.get_or_insert(t);
        while t - *last_t > w {
            idx.push(i as u32);
            *last_t += w;
        }
    }
    idx.push((n - 1) as u32);
    idx
}

fn f64_array(shape: &[usize], values: &[f64]) -> Vec<u8> {
    let data: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
    npy::encode_array("<f8", shape, &data)
}

fn write_info(folder: &Path, data: &SequenceData, options: &WriteOptions) -> Result<()> {
    let path = folder.join(INFO_NPZ);
    let cam = &data.camera;
    if data.events.len() > u32::MAX as usize {
        return Err(Evimo2Error::BadInput {
            file: path.display().to_string(),
            message: "more than 2^32 events do not fit EVIMO2's uint32 index".into(),
        });
    }
    let mut npz = NpzWriter::create(&path, options.compress)?;
    let start = data.t_start_s;
    let index = event_index(
        data.events.t.iter().map(|t| t + start),
        data.events.len(),
        options.discretization_s,
    );
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
        &data.imu_topic,
        &data.imu,
        &data.camera_poses,
        &data.frames,
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
