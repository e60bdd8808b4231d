//! EVIMO2's `meta` dict: loading it from `dataset_info.npz` (pickled object array or unicode
//! literal), converting it to the pipeline's types, and building it for the writer.
//!
//! Times: every `ts` in the meta is in seconds on the EVIMO2 sequence clock, the same clock as
//! `dataset_events_t.npy`. The converted values use times relative to `t0` (the absolute time of
//! the first event): `t = ts - t0`.

use evseg_schemas::{CameraInfo, CameraMotion, Distortion, ImuSample, ObjectPose};

use crate::error::{Evimo2Error, Result};
use crate::npy::{self, DType, NpyArray};
use crate::pylit::{self, PyValue};

/// EVIMO2's IMU-to-camera rotation, row-major: `w_cam = (w_imu.y, -w_imu.x, w_imu.z)`, as in the
/// public EVIMO2 egomotion code (see METHOD_NOTES §4).
pub const EVIMO2_IMU_TO_CAMERA: [f64; 9] = [0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0];

/// EVIMO2's IMU time offset, seconds, added to IMU timestamps (public EVIMO2 egomotion code).
pub const EVIMO2_IMU_TIME_OFFSET_S: f64 = -0.02;

/// Extra key written by this crate in `meta['meta']`: the IMU-to-camera rotation (9 floats,
/// row-major). Real EVIMO2 files do not have it; the EVIMO2 default then applies.
pub const KEY_IMU_TO_CAMERA: &str = "evseg_imu_to_camera";
/// Extra key written by this crate in `meta['meta']`: the IMU time offset, seconds.
pub const KEY_IMU_TIME_OFFSET: &str = "evseg_imu_time_offset_s";
/// Extra key written by this crate in `meta['meta']`: the sensor name.
pub const KEY_SENSOR: &str = "evseg_sensor";

/// Decodes the `meta` member of `dataset_info.npz`: either a 0-d object array (a pickle whose
/// unpickled state holds the dict) or a unicode string holding a Python literal.
pub fn meta_from_npy(arr: &NpyArray, file: &str) -> Result<PyValue> {
    match arr.header.dtype {
        DType::Object => meta_from_pickle(&arr.data, arr.header.data_offset, file),
        DType::Unicode(_) => {
            let text =
                npy::decode_unicode(arr.header.dtype, arr.header.big_endian, &arr.data).map_err(|at| {
                    Evimo2Error::format(
                        file,
                        arr.header.data_offset + at as u64,
                        "invalid code point in string",
                    )
                })?;
            pylit::parse(&text).map_err(|e| {
                Evimo2Error::format(
                    file,
                    arr.header.data_offset + 4 * e.offset as u64,
                    format!("meta string is not a Python literal: {}", e.message),
                )
            })
        }
        _ => Err(Evimo2Error::invalid(
            file,
            format!(
                "meta has dtype '{}'; expected '|O' (pickled dict) or '<U..' (dict literal)",
                arr.header.descr
            ),
        )),
    }
}

fn meta_from_pickle(data: &[u8], data_offset: u64, file: &str) -> Result<PyValue> {
    let opts = serde_pickle::DeOptions::new().replace_unresolved_globals();
    let value = serde_pickle::value_from_slice(data, opts)
        .map_err(|e| Evimo2Error::format(file, data_offset, format!("meta pickle cannot be read: {e}")))?;
    // np.save of a 0-d object array pickles ndarray._reconstruct(...) + BUILD(state); with the
    // numpy globals unresolved, the result is the state tuple (1, (), dtype, False, [obj]).
    let inner = match value {
        serde_pickle::Value::Dict(_) => value,
        serde_pickle::Value::Tuple(mut state) => match state.pop() {
            Some(serde_pickle::Value::List(mut items)) if items.len() == 1 => items.remove(0),
            _ => {
                return Err(Evimo2Error::format(
                    file,
                    data_offset,
                    "meta pickle is not a 0-d object array (state's last field is not a 1-element list)",
                ));
            }
        },
        other => {
            return Err(Evimo2Error::format(
                file,
                data_offset,
                format!(
                    "meta pickle holds {}, not a dict or an object array",
                    pickle_type_name(&other)
                ),
            ));
        }
    };
    Ok(from_pickle(inner))
}

fn pickle_type_name(v: &serde_pickle::Value) -> &'static str {
    use serde_pickle::Value as V;
    match v {
        V::None => "None",
        V::Bool(_) => "bool",
        V::I64(_) | V::Int(_) => "int",
        V::F64(_) => "float",
        V::Bytes(_) => "bytes",
        V::String(_) => "str",
        V::List(_) => "list",
        V::Tuple(_) => "tuple",
        V::Set(_) | V::FrozenSet(_) => "set",
        V::Dict(_) => "dict",
    }
}

/// Converts serde-pickle's value tree to [`PyValue`] (sets become lists; integers beyond i128
/// become floats).
pub fn from_pickle(v: serde_pickle::Value) -> PyValue {
    use serde_pickle::Value as V;
    match v {
        V::None => PyValue::None,
        V::Bool(b) => PyValue::Bool(b),
        V::I64(i) => PyValue::Int(i128::from(i)),
        V::Int(big) => {
            let text = big.to_string();
            match text.parse::<i128>() {
                Ok(i) => PyValue::Int(i),
                Err(_) => PyValue::Float(text.parse::<f64>().unwrap_or(f64::NAN)),
            }
        }
        V::F64(f) => PyValue::Float(f),
        V::Bytes(b) => PyValue::Bytes(b),
        V::String(s) => PyValue::Str(s),
        V::List(items) => PyValue::List(items.into_iter().map(from_pickle).collect()),
        V::Tuple(items) => PyValue::Tuple(items.into_iter().map(from_pickle).collect()),
        V::Set(items) | V::FrozenSet(items) => {
            PyValue::List(items.into_iter().map(|h| from_pickle(h.into_value())).collect())
        }
        V::Dict(map) => PyValue::Dict(
            map.into_iter()
                .map(|(k, v)| (from_pickle(k.into_value()), from_pickle(v)))
                .collect(),
        ),
    }
}

/// Typed access to meta fields with errors that give the field's path.
struct Field<'a> {
    file: &'a str,
    path: String,
    value: &'a PyValue,
}

impl<'a> Field<'a> {
    fn err(&self, message: impl Into<String>) -> Evimo2Error {
        Evimo2Error::Meta {
            file: self.file.to_string(),
            path: self.path.clone(),
            message: message.into(),
        }
    }

    fn key(&self, key: &str) -> Result<Field<'a>> {
        self.opt(key)?
            .ok_or_else(|| self.err(format!("missing key '{key}'")))
    }

    fn opt(&self, key: &str) -> Result<Option<Field<'a>>> {
        if !matches!(self.value, PyValue::Dict(_)) {
            return Err(self.err(format!("expected a dict, found {}", self.value.type_name())));
        }
        Ok(self.value.get(key).map(|value| Field {
            file: self.file,
            path: format!("{}['{key}']", self.path),
            value,
        }))
    }

    fn f64(&self) -> Result<f64> {
        self.value.as_f64().ok_or_else(|| {
            self.err(format!(
                "expected a number, found {}{}",
                self.value.type_name(),
                if matches!(self.value, PyValue::None) {
                    " (numpy scalar objects inside meta are not supported)"
                } else {
                    ""
                }
            ))
        })
    }

    fn num(&self, key: &str) -> Result<f64> {
        self.key(key)?.f64()
    }

    /// [`Field::num`] that must be finite (a time, a rate, an intrinsic): NaN or infinity is an
    /// error naming the field, since nothing downstream can place or use it.
    fn finite(&self, key: &str) -> Result<f64> {
        let f = self.key(key)?;
        let v = f.f64()?;
        if v.is_finite() {
            Ok(v)
        } else {
            Err(f.err(format!("{v} is not a finite number")))
        }
    }

    fn finite_xyz(&self) -> Result<[f64; 3]> {
        Ok([self.finite("x")?, self.finite("y")?, self.finite("z")?])
    }

    fn int(&self) -> Result<i128> {
        self.value
            .as_i128()
            .ok_or_else(|| self.err(format!("expected an integer, found {}", self.value.type_name())))
    }

    fn str(&self) -> Result<&'a str> {
        self.value
            .as_str()
            .ok_or_else(|| self.err(format!("expected a string, found {}", self.value.type_name())))
    }

    fn seq(&self) -> Result<Vec<Field<'a>>> {
        let items = self
            .value
            .as_seq()
            .ok_or_else(|| self.err(format!("expected a list, found {}", self.value.type_name())))?;
        Ok(items
            .iter()
            .enumerate()
            .map(|(i, value)| Field {
                file: self.file,
                path: format!("{}[{i}]", self.path),
                value,
            })
            .collect())
    }

    fn dict_items(&self) -> Result<Vec<(&'a PyValue, Field<'a>)>> {
        match self.value {
            PyValue::Dict(items) => Ok(items
                .iter()
                .map(|(k, value)| {
                    let path = match k {
                        PyValue::Str(s) => format!("{}['{s}']", self.path),
                        other => format!("{}[{other}]", self.path),
                    };
                    (
                        k,
                        Field {
                            file: self.file,
                            path,
                            value,
                        },
                    )
                })
                .collect()),
            other => Err(self.err(format!("expected a dict, found {}", other.type_name()))),
        }
    }

    fn xyz(&self) -> Result<[f64; 3]> {
        Ok([self.num("x")?, self.num("y")?, self.num("z")?])
    }

    /// `{pos: {t: {x,y,z}, q: {x,y,z,w}}}` -> (position, quaternion xyzw).
    fn pose(&self) -> Result<([f64; 3], [f64; 4])> {
        let pos = self.key("pos")?;
        let t = pos.key("t")?.xyz()?;
        let q = pos.key("q")?;
        Ok((t, [q.num("x")?, q.num("y")?, q.num("z")?, q.num("w")?]))
    }
}

/// Options for turning meta into pipeline types. `None` fields use the documented default.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MetaOptions {
    /// IMU topic to use (a key of `meta['imu']`). Default: the first key in sorted order
    /// (`/prophesee/left/imu` on EVIMO2 rigs that have both Prophesee IMUs).
    pub imu_topic: Option<String>,
    /// IMU-to-camera rotation, row-major. Default: `meta['meta']['evseg_imu_to_camera']` if the file
    /// has it (files written by this crate), else [`EVIMO2_IMU_TO_CAMERA`].
    pub imu_to_camera: Option<[f64; 9]>,
    /// IMU time offset, seconds. Default: `meta['meta']['evseg_imu_time_offset_s']` if present, else
    /// [`EVIMO2_IMU_TIME_OFFSET_S`].
    pub imu_time_offset_s: Option<f64>,
    /// Sensor name for [`CameraInfo::sensor`]. Default: `meta['meta']['evseg_sensor']` if present,
    /// else `"evimo2"`.
    pub sensor: Option<String>,
    /// Largest time gap, s, of an event from the last one kept before it in the event files
    /// (not meta: the event reader's, see [`crate::EventReader::open_with_gap`]). Default:
    /// [`crate::DEFAULT_MAX_TIME_GAP_S`].
    pub max_time_gap_s: Option<f64>,
}

/// One ground-truth frame of `meta['frames']`.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameTruth {
    /// Frame id: the number in the `mask_%010d` / `depth_%010d` member names (`meta` key `id`; the
    /// position in `frames` when the file has no ids).
    pub id: u64,
    /// Frame time, seconds relative to the first event.
    pub t: f64,
    /// Camera pose (camera -> world) at the frame, velocities `None`; `None` when the frame has no
    /// `cam` entry.
    pub camera: Option<CameraMotion>,
    /// Poses (object -> camera) of the objects visible in this frame, sorted by id.
    pub objects: Vec<ObjectPose>,
}

/// Everything the meta holds, converted.
#[derive(Debug, Clone, PartialEq)]
pub struct MetaContents {
    /// Camera calibration. `time_origin_us` = `round(t0 * 1e6)`.
    pub camera: CameraInfo,
    /// `meta['meta']['ros_time_offset']`, seconds (Unix time of the EVIMO2 clock's zero) if present.
    pub ros_time_offset_s: Option<f64>,
    /// All IMU topics in `meta['imu']`, sorted.
    pub imu_topics: Vec<String>,
    /// The topic whose samples are in `imu` (`None` when the file has no IMU data).
    pub imu_topic: Option<String>,
    /// IMU samples of `imu_topic`, IMU frame, `t` seconds relative to the first event on the IMU
    /// clock (add `camera.imu_time_offset_s` for camera time).
    pub imu: Vec<ImuSample>,
    /// Camera poses from `full_trajectory` (Vicon rate), or from `frames` when it is absent;
    /// camera -> world, `t` relative to the first event, velocities `None`.
    pub camera_poses: Vec<CameraMotion>,
    /// Ground-truth frames, in file order.
    pub frames: Vec<FrameTruth>,
    /// Camera fields that `meta['meta']` lacks and [`CameraFallback`] supplied, each with its
    /// source (e.g. "fx, fy, cx, cy from dataset_info.npz[K]"); empty for a complete meta.
    pub camera_fallbacks: Vec<String>,
}

/// Where the camera's calibration comes from when `meta['meta']` lacks it: the same folder's
/// other files. Only a field missing from `meta['meta']` is taken from here.
pub struct CameraFallback<'a> {
    /// `dataset_info.npz[K]`, row-major (fx = K[0], cx = K[2], fy = K[4], cy = K[5]), pixels.
    pub k: Option<[f64; 9]>,
    /// The sensor's (width, height) in pixels, e.g. from the masks' shape; called only when
    /// `res_x` or `res_y` is missing.
    pub resolution: &'a dyn Fn() -> Option<(u16, u16)>,
    /// Where `resolution` looks, for messages (e.g. "dataset_mask.npz").
    pub resolution_source: &'a str,
}

impl CameraFallback<'_> {
    /// No fallback: every camera field must be in `meta['meta']`.
    pub const NONE: CameraFallback<'static> = CameraFallback {
        k: None,
        resolution: &|| None,
        resolution_source: "nothing",
    };
}

/// Converts the meta dict. `t0` = absolute time of the first event, seconds on the EVIMO2 clock.
/// Every camera field must be in `meta['meta']` ([`convert_with`] takes a fallback).
pub fn convert(meta: &PyValue, t0: f64, opts: &MetaOptions, file: &str) -> Result<MetaContents> {
    convert_with(meta, t0, opts, &CameraFallback::NONE, file)
}

/// [`convert`], with camera fields missing from `meta['meta']` taken from `fallback`.
pub fn convert_with(
    meta: &PyValue,
    t0: f64,
    opts: &MetaOptions,
    fallback: &CameraFallback<'_>,
    file: &str,
) -> Result<MetaContents> {
    let root = Field {
        file,
        path: String::new(),
        value: meta,
    };
    let m = root.key("meta")?;
    let (camera, camera_fallbacks) = camera_info(&m, t0, opts, fallback)?;
    let ros_time_offset_s = m.opt("ros_time_offset")?.map(|f| f.f64()).transpose()?;

    let (imu_topics, imu_topic, imu) = imu_samples(&root, t0, opts)?;

    let frames = match root.opt("frames")? {
        Some(list) => list
            .seq()?
            .iter()
            .enumerate()
            .map(|(i, f)| frame(f, i, t0))
            .collect::<Result<Vec<_>>>()?,
        None => Vec::new(),
    };
    let camera_poses = match root.opt("full_trajectory")? {
        Some(list) => list
            .seq()?
            .iter()
            .filter_map(|f| camera_pose(f, t0).transpose())
            .collect::<Result<Vec<_>>>()?,
        None => frames.iter().filter_map(|f| f.camera).collect(),
    };
    Ok(MetaContents {
        camera,
        ros_time_offset_s,
        imu_topics,
        imu_topic,
        imu,
        camera_poses,
        frames,
        camera_fallbacks,
    })
}

fn camera_info(
    m: &Field<'_>,
    t0: f64,
    opts: &MetaOptions,
    fallback: &CameraFallback<'_>,
) -> Result<(CameraInfo, Vec<String>)> {
    let mut fallbacks = Vec::new();
    // Intrinsics: meta['meta'] first, else all four from K (never a mix of the two sources).
    let intrinsic_keys = ["fx", "fy", "cx", "cy"];
    let mut missing = Vec::new();
    for key in intrinsic_keys {
        if m.opt(key)?.is_none() {
            missing.push(key);
        }
    }
    let intrinsics = if missing.is_empty() {
        [m.num("fx")?, m.num("fy")?, m.num("cx")?, m.num("cy")?]
    } else if let Some(k) = fallback.k {
        fallbacks.push("fx, fy, cx, cy from dataset_info.npz[K]".to_string());
        [k[0], k[4], k[2], k[5]]
    } else {
        return Err(m.err(format!(
            "missing {} (and dataset_info.npz has no usable K to take them from)",
            missing.join(", ")
        )));
    };
    if !(intrinsics.iter().all(|v| v.is_finite()) && intrinsics[0] >= 1.0 && intrinsics[1] >= 1.0) {
        return Err(m.err(format!(
            "camera intrinsics fx, fy, cx, cy = {intrinsics:?} px are not usable (finite, focal \
             lengths >= 1 px){}",
            if missing.is_empty() {
                ""
            } else {
                " (taken from dataset_info.npz[K])"
            }
        )));
    }
    let resolution = if m.opt("res_x")?.is_some() && m.opt("res_y")?.is_some() {
        let dim = |key: &str| -> Result<u16> {
            let f = m.key(key)?;
            let v = f.int()?;
            u16::try_from(v).map_err(|_| f.err(format!("resolution {v} out of range 0..=65535")))
        };
        (dim("res_x")?, dim("res_y")?)
    } else if let Some(r) = (fallback.resolution)() {
        fallbacks.push(format!("res_x, res_y from {}", fallback.resolution_source));
        r
    } else {
        return Err(m.err(format!(
            "missing res_x or res_y (and {} gives no resolution)",
            fallback.resolution_source
        )));
    };
    let coef = |key: &str| -> Result<f64> { m.opt(key)?.map_or(Ok(0.0), |f| f.f64()) };
    let model = match m.opt("dist_model")? {
        Some(f) => Some(f.str()?.to_ascii_lowercase()),
        None => None,
    };
    let has_coefficients = ["k1", "k2", "p1", "p2"].iter().any(|k| m.value.get(k).is_some());
    let distortion = match model.as_deref() {
        Some("radtan" | "plumb_bob") | None if model.is_some() || has_coefficients => Distortion::RadTan {
            k1: coef("k1")?,
            k2: coef("k2")?,
            p1: coef("p1")?,
            p2: coef("p2")?,
            k3: coef("k3")?,
        },
        None => Distortion::None,
        Some("equidistant" | "fisheye") => Distortion::Equidistant {
            k1: coef("k1")?,
            k2: coef("k2")?,
            k3: coef("k3")?,
            k4: coef("k4")?,
        },
        Some("none") => Distortion::None,
        Some(other) => {
            return Err(m.key("dist_model")?.err(format!(
                "unknown distortion model '{other}' (expected 'radtan', 'equidistant' or 'none')"
            )));
        }
    };
    let imu_to_camera = match (&opts.imu_to_camera, m.opt(KEY_IMU_TO_CAMERA)?) {
        (Some(r), _) => *r,
        (None, Some(f)) => {
            let items = f.seq()?;
            if items.len() != 9 {
                return Err(f.err(format!("expected 9 numbers, found {}", items.len())));
            }
            let mut r = [0.0; 9];
            for (slot, item) in r.iter_mut().zip(&items) {
                *slot = item.f64()?;
            }
            r
        }
        (None, None) => EVIMO2_IMU_TO_CAMERA,
    };
    let imu_time_offset_s = match (opts.imu_time_offset_s, m.opt(KEY_IMU_TIME_OFFSET)?) {
        (Some(v), _) => v,
        (None, Some(f)) => f.f64()?,
        (None, None) => EVIMO2_IMU_TIME_OFFSET_S,
    };
    let sensor = match (&opts.sensor, m.opt(KEY_SENSOR)?) {
        (Some(s), _) => s.clone(),
        (None, Some(f)) => f.str()?.to_string(),
        (None, None) => "evimo2".to_string(),
    };
    let camera = CameraInfo {
        width: resolution.0,
        height: resolution.1,
        fx: intrinsics[0],
        fy: intrinsics[1],
        cx: intrinsics[2],
        cy: intrinsics[3],
        distortion,
        imu_to_camera,
        imu_time_offset_s,
        time_origin_us: (t0 * 1e6).round() as i64,
        sensor,
    };
    Ok((camera, fallbacks))
}

type ImuParts = (Vec<String>, Option<String>, Vec<ImuSample>);

fn imu_samples(root: &Field<'_>, t0: f64, opts: &MetaOptions) -> Result<ImuParts> {
    let Some(imu) = root.opt("imu")? else {
        return match &opts.imu_topic {
            Some(wanted) => Err(Evimo2Error::ImuTopic {
                file: root.file.to_string(),
                wanted: wanted.clone(),
                available: "none: meta has no 'imu'".into(),
            }),
            None => Ok((Vec::new(), None, Vec::new())),
        };
    };
    let items = imu.dict_items()?;
    let mut topics: Vec<String> = items
        .iter()
        .filter_map(|(k, _)| k.as_str().map(str::to_string))
        .collect();
    topics.sort();
    let wanted = match &opts.imu_topic {
        Some(w) => w.clone(),
        None => match topics.first() {
            Some(first) => first.clone(),
            None => return Ok((topics, None, Vec::new())),
        },
    };
    let Some((_, list)) = items
        .iter()
        .rev()
        .find(|(k, _)| k.as_str() == Some(wanted.as_str()))
    else {
        return Err(Evimo2Error::ImuTopic {
            file: root.file.to_string(),
            wanted,
            available: if topics.is_empty() {
                "none".into()
            } else {
                topics.join(", ")
            },
        });
    };
    let samples = list
        .seq()?
        .iter()
        .map(|s| {
            Ok(ImuSample {
                t: s.finite("ts")? - t0,
                gyro: s.key("angular_velocity")?.finite_xyz()?,
                accel: s.key("linear_acceleration")?.finite_xyz()?,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((topics, Some(wanted), samples))
}

/// The `cam` pose of a frame or trajectory entry, `None` when the entry has no `cam`.
fn camera_pose(entry: &Field<'_>, t0: f64) -> Result<Option<CameraMotion>> {
    let Some(cam) = entry.opt("cam")? else {
        return Ok(None);
    };
    let ts = entry.num("ts")?;
    let (position, orientation) = cam.pose()?;
    Ok(Some(CameraMotion {
        t: ts - t0,
        position,
        orientation,
        linear_velocity: None,
        angular_velocity: None,
    }))
}

fn frame(entry: &Field<'_>, index: usize, t0: f64) -> Result<FrameTruth> {
    let id = match entry.opt("id")? {
        Some(f) => {
            let v = f.int()?;
            u64::try_from(v).map_err(|_| f.err(format!("frame id {v} is not a non-negative integer")))?
        }
        None => index as u64,
    };
    let ts = entry.finite("ts")?;
    let camera = camera_pose(entry, t0)?;
    let mut objects = Vec::new();
    for (key, value) in entry.dict_items()? {
        let id = match key {
            PyValue::Str(s) if !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit()) => {
                s.parse::<u32>().ok()
            }
            PyValue::Int(i) => u32::try_from(*i).ok(),
            _ => None,
        };
        let Some(id) = id else { continue };
        if id == 0 {
            return Err(value.err("object id 0 is reserved for the background"));
        }
        let (position, orientation) = value.pose()?;
        let t = value.opt("ts")?.map_or(Ok(ts), |f| f.f64())? - t0;
        // A key repeated in a literal: the last one wins, as in Python.
        objects.retain(|o: &ObjectPose| o.id != id);
        objects.push(ObjectPose {
            id,
            t,
            position,
            orientation,
        });
    }
    objects.sort_by_key(|o| o.id);
    Ok(FrameTruth {
        id,
        t: ts - t0,
        camera,
        objects,
    })
}

fn s(x: &str) -> PyValue {
    PyValue::Str(x.to_string())
}

fn xyz(v: [f64; 3]) -> PyValue {
    PyValue::Dict(vec![
        (s("x"), PyValue::Float(v[0])),
        (s("y"), PyValue::Float(v[1])),
        (s("z"), PyValue::Float(v[2])),
    ])
}

fn pose(position: [f64; 3], q: [f64; 4], ts: f64) -> PyValue {
    let q = PyValue::Dict(vec![
        (s("w"), PyValue::Float(q[3])),
        (s("x"), PyValue::Float(q[0])),
        (s("y"), PyValue::Float(q[1])),
        (s("z"), PyValue::Float(q[2])),
    ]);
    PyValue::Dict(vec![
        (
            s("pos"),
            PyValue::Dict(vec![(s("q"), q), (s("t"), xyz(position))]),
        ),
        (s("ts"), PyValue::Float(ts)),
    ])
}

/// Full-trajectory entries have no ground-truth frame; EVIMO2 writes `id` = 2^64 - 1 for them.
const NO_FRAME_ID: i128 = u64::MAX as i128;

/// Builds the meta dict for the writer. `t_start` is the absolute time (s) of relative t = 0.
pub fn build(
    camera: &CameraInfo,
    imu_topic: &str,
    imu: &[ImuSample],
    camera_poses: &[CameraMotion],
    frames: &[FrameTruth],
    t_start: f64,
) -> PyValue {
    let (model, k1, k2, k3, k4, p1, p2) = match camera.distortion {
        Distortion::None => ("none", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
        Distortion::RadTan { k1, k2, p1, p2, k3 } => ("radtan", k1, k2, k3, 0.0, p1, p2),
        Distortion::Equidistant { k1, k2, k3, k4 } => ("equidistant", k1, k2, k3, k4, 0.0, 0.0),
    };
    let f = PyValue::Float;
    let meta = PyValue::Dict(vec![
        (s("cx"), f(camera.cx)),
        (s("cy"), f(camera.cy)),
        (s("dist_model"), s(model)),
        (s("fx"), f(camera.fx)),
        (s("fy"), f(camera.fy)),
        (s("k1"), f(k1)),
        (s("k2"), f(k2)),
        (s("k3"), f(k3)),
        (s("k4"), f(k4)),
        (s("p1"), f(p1)),
        (s("p2"), f(p2)),
        (s("res_x"), PyValue::Int(i128::from(camera.width))),
        (s("res_y"), PyValue::Int(i128::from(camera.height))),
        (
            s(KEY_IMU_TO_CAMERA),
            PyValue::List(camera.imu_to_camera.iter().map(|v| f(*v)).collect()),
        ),
        (s(KEY_IMU_TIME_OFFSET), f(camera.imu_time_offset_s)),
        (s(KEY_SENSOR), s(&camera.sensor)),
    ]);
    let frames_v = PyValue::List(
        frames
            .iter()
            .map(|fr| {
                let ts = fr.t + t_start;
                let mut items = Vec::new();
                for o in &fr.objects {
                    items.push((
                        s(&o.id.to_string()),
                        pose(o.position, o.orientation, o.t + t_start),
                    ));
                }
                if let Some(c) = &fr.camera {
                    items.push((s("cam"), pose(c.position, c.orientation, ts)));
                }
                items.push((s("gt_frame"), s(&format!("depth_mask_{}.png", fr.id))));
                items.push((s("id"), PyValue::Int(i128::from(fr.id))));
                items.push((s("ts"), f(ts)));
                PyValue::Dict(items)
            })
            .collect(),
    );
    let trajectory = PyValue::List(
        camera_poses
            .iter()
            .map(|c| {
                let ts = c.t + t_start;
                PyValue::Dict(vec![
                    (s("cam"), pose(c.position, c.orientation, ts)),
                    (s("gt_frame"), s(&format!("depth_mask_{NO_FRAME_ID}.png"))),
                    (s("id"), PyValue::Int(NO_FRAME_ID)),
                    (s("ts"), f(ts)),
                ])
            })
            .collect(),
    );
    let imu_v = PyValue::List(
        imu.iter()
            .map(|m| {
                PyValue::Dict(vec![
                    (s("angular_velocity"), xyz(m.gyro)),
                    (s("linear_acceleration"), xyz(m.accel)),
                    (s("ts"), f(m.t + t_start)),
                ])
            })
            .collect(),
    );
    PyValue::Dict(vec![
        (s("frames"), frames_v),
        (s("full_trajectory"), trajectory),
        (s("imu"), PyValue::Dict(vec![(s(imu_topic), imu_v)])),
        (s("meta"), meta),
    ])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn convert_text(text: &str, t0: f64) -> Result<MetaContents> {
        convert(&pylit::parse(text).unwrap(), t0, &MetaOptions::default(), "m")
    }

    const CAM: &str = "'fx': 2.0, 'fy': 3.0, 'cx': 4.0, 'cy': 5.0, 'res_x': 8, 'res_y': 6";

    #[test]
    fn unusable_numbers_are_errors_naming_the_field() {
        let pos =
            "{'pos': {'t': {'x': 1.0, 'y': 2.0, 'z': 3.0}, 'q': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}}}";
        let imu = |gx: &str| {
            format!(
                "'imu': {{'/i': [{{'ts': 10.0, 'angular_velocity': {{'x': {gx}, 'y': 0.0, 'z': 0.0}}, \
                 'linear_acceleration': {{'x': 0.0, 'y': 0.0, 'z': 9.8}}}}]}}"
            )
        };
        let cases = [
            (
                format!(
                    "{{'meta': {{{CAM}}}, 'frames': [{{'ts': 10.5, 'cam': {pos}}}, {{'ts': nan, 'cam': {pos}}}]}}"
                ),
                "m: meta['frames'][1]['ts']",
                "NaN is not a finite number",
            ),
            (
                format!(
                    "{{'meta': {{{}}}, 'frames': []}}",
                    CAM.replace("'fx': 2.0", "'fx': 0")
                ),
                "m: meta['meta']",
                "fx, fy, cx, cy = [0.0, 3.0, 4.0, 5.0] px are not usable",
            ),
            (
                format!("{{'meta': {{{CAM}}}, 'frames': [], {}}}", imu("nan")),
                "['angular_velocity']['x']",
                "NaN is not a finite number",
            ),
        ];
        for (text, at, says) in cases {
            let e = convert_text(&text, 10.0).unwrap_err().to_string();
            assert!(e.contains(at) && e.contains(says), "{e}");
        }
        assert!(
            convert_text(
                &format!("{{'meta': {{{CAM}}}, 'frames': [], {}}}", imu("0.5")),
                10.0
            )
            .is_ok()
        );
    }

    #[test]
    fn frames_without_ids_use_positions_and_poses_fall_back_to_frames() {
        let pos =
            "{'pos': {'t': {'x': 1.0, 'y': 2.0, 'z': 3.0}, 'q': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}}}";
        let text = format!(
            "{{'meta': {{{CAM}}}, 'frames': [{{'ts': 10.5, 'cam': {pos}, '7': {pos}}}, {{'ts': 10.75, 'cam': {pos}}}]}}"
        );
        let m = convert_text(&text, 10.0).unwrap();
        assert_eq!(
            m.frames.iter().map(|f| (f.id, f.t)).collect::<Vec<_>>(),
            vec![(0, 0.5), (1, 0.75)]
        );
        assert_eq!(m.frames[0].objects.len(), 1);
        assert_eq!(m.frames[0].objects[0].id, 7);
        assert_eq!(m.frames[0].objects[0].t, 0.5);
        assert_eq!(
            m.camera_poses.iter().map(|c| c.t).collect::<Vec<_>>(),
            vec![0.5, 0.75]
        );
        assert_eq!(m.camera_poses[0].position, [1.0, 2.0, 3.0]);
        // No 'imu' key: no samples, no topic.
        assert!(m.imu.is_empty() && m.imu_topic.is_none());
        // No distortion keys at all: ideal pinhole.
        assert_eq!(m.camera.distortion, Distortion::None);
        assert_eq!(m.camera.time_origin_us, 10_000_000);
    }

    #[test]
    fn distortion_models() {
        let d = |extra: &str| {
            convert_text(&format!("{{'meta': {{{CAM}, {extra}}}}}"), 0.0).map(|m| m.camera.distortion)
        };
        assert_eq!(
            d("'dist_model': 'equidistant', 'k1': 0.5, 'k2': 0.25, 'k3': 0.125, 'k4': 1e-3, 'p1': 9.0")
                .unwrap(),
            Distortion::Equidistant {
                k1: 0.5,
                k2: 0.25,
                k3: 0.125,
                k4: 1e-3
            }
        );
        // radtan takes p1, p2 from meta (not D's k3/k4 positions); k3 from meta, k4 ignored.
        assert_eq!(
            d("'dist_model': 'radtan', 'k1': 0.5, 'k2': 0.25, 'k3': 0.0, 'k4': 7.0, 'p1': 0.01, 'p2': 0.02")
                .unwrap(),
            Distortion::RadTan {
                k1: 0.5,
                k2: 0.25,
                p1: 0.01,
                p2: 0.02,
                k3: 0.0
            }
        );
        // EVIMO (v1) style: coefficients without a model name are radtan.
        assert_eq!(
            d("'k1': 0.5, 'k2': 0.25, 'p1': 0.01, 'p2': 0.02").unwrap(),
            Distortion::RadTan {
                k1: 0.5,
                k2: 0.25,
                p1: 0.01,
                p2: 0.02,
                k3: 0.0
            }
        );
        assert_eq!(d("'dist_model': 'none'").unwrap(), Distortion::None);
        let e = d("'dist_model': 'mei'").unwrap_err().to_string();
        assert!(e.contains("['meta']['dist_model']") && e.contains("'mei'"), "{e}");
        let e = d("'res_x': 70000").unwrap_err().to_string();
        assert!(e.contains("out of range"), "{e}");
    }

    #[test]
    fn build_then_convert_is_identity_for_each_distortion() {
        for distortion in [
            Distortion::None,
            Distortion::RadTan {
                k1: 0.5,
                k2: -0.25,
                p1: 0.01,
                p2: 0.02,
                k3: 0.125,
            },
            Distortion::Equidistant {
                k1: 0.5,
                k2: 0.25,
                k3: 0.125,
                k4: 1e-3,
            },
        ] {
            let camera = CameraInfo {
                width: 8,
                height: 6,
                fx: 2.0,
                fy: 3.0,
                cx: 4.0,
                cy: 5.0,
                distortion,
                imu_to_camera: CameraInfo::IDENTITY,
                imu_time_offset_s: 0.001,
                time_origin_us: 2_000_000,
                sensor: "s".into(),
            };
            let v = build(&camera, "/imu", &[], &[], &[], 2.0);
            let m = convert(&v, 2.0, &MetaOptions::default(), "m").unwrap();
            assert_eq!(m.camera, camera);
            let lit = convert(
                &pylit::parse(&v.to_string()).unwrap(),
                2.0,
                &MetaOptions::default(),
                "m",
            )
            .unwrap();
            assert_eq!(lit.camera, camera);
        }
    }
}
