//! The pipeline's message types. See the crate docs for the units and frames conventions.

use serde::{Deserialize, Serialize};

use crate::codec::Message;

/// Events as a structure of arrays; all four vectors have the same length.
///
/// Sorted by time (non-decreasing `t`) within one message.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Events {
    /// Timestamps, seconds on the sequence clock.
    #[serde(with = "crate::columns::f64s")]
    pub t: Vec<f64>,
    /// Column, pixels (0 = left).
    #[serde(with = "crate::columns::u16s")]
    pub x: Vec<u16>,
    /// Row, pixels (0 = top).
    #[serde(with = "crate::columns::u16s")]
    pub y: Vec<u16>,
    /// Polarity: 1 = brightness increase (ON), 0 = decrease (OFF).
    #[serde(with = "crate::columns::u8s")]
    pub p: Vec<u8>,
}

impl Events {
    /// Number of events.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    /// True when there are no events.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// An empty set with room for `n` events.
    pub fn with_capacity(n: usize) -> Self {
        Self {
            t: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            p: Vec::with_capacity(n),
        }
    }

    /// Appends one event (`t` in s, `x`,`y` in pixels, `p` 0/1).
    pub fn push(&mut self, t: f64, x: u16, y: u16, p: u8) {
        self.t.push(t);
        self.x.push(x);
        self.y.push(y);
        self.p.push(p);
    }

    /// Appends the events `range` of `other`.
    pub fn extend_from(&mut self, other: &Events, range: std::ops::Range<usize>) {
        self.t.extend_from_slice(&other.t[range.clone()]);
        self.x.extend_from_slice(&other.x[range.clone()]);
        self.y.extend_from_slice(&other.y[range.clone()]);
        self.p.extend_from_slice(&other.p[range]);
    }

    /// True when the four columns have the same length.
    pub fn is_consistent(&self) -> bool {
        let n = self.t.len();
        self.x.len() == n && self.y.len() == n && self.p.len() == n
    }
}

/// One IMU sample in the IMU's own frame.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ImuSample {
    /// Timestamp, seconds on the sequence clock (IMU clock; add
    /// [`CameraInfo::imu_time_offset_s`] to get camera time).
    pub t: f64,
    /// Angular rate, rad/s, IMU frame.
    pub gyro: [f64; 3],
    /// Specific force, m/s², IMU frame.
    pub accel: [f64; 3],
}

/// Lens distortion of the camera, applied to normalized coordinates.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub enum Distortion {
    /// Ideal pinhole.
    #[default]
    None,
    /// Radial-tangential (OpenCV / Brown-Conrady): k1, k2, p1, p2, k3.
    RadTan {
        /// Radial r² coefficient.
        k1: f64,
        /// Radial r⁴ coefficient.
        k2: f64,
        /// Tangential coefficient 1.
        p1: f64,
        /// Tangential coefficient 2.
        p2: f64,
        /// Radial r⁶ coefficient.
        k3: f64,
    },
    /// Equidistant (Kannala-Brandt / OpenCV fisheye): k1..k4 on theta.
    Equidistant {
        /// theta³ coefficient.
        k1: f64,
        /// theta⁵ coefficient.
        k2: f64,
        /// theta⁷ coefficient.
        k3: f64,
        /// theta⁹ coefficient.
        k4: f64,
    },
}

/// Camera calibration and sensor facts. Repeated in every [`EventPacket`] so a consumer that
/// joins late (live mode, replay) always has it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraInfo {
    /// Sensor width, pixels.
    pub width: u16,
    /// Sensor height, pixels.
    pub height: u16,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// Lens distortion.
    pub distortion: Distortion,
    /// Rotation taking IMU-frame vectors to the camera frame, row-major 3x3
    /// (`v_cam = R * v_imu`).
    pub imu_to_camera: [f64; 9],
    /// Offset added to IMU timestamps to put them on the camera clock, seconds.
    pub imu_time_offset_s: f64,
    /// Absolute time of t = 0 on the sequence clock, µs (sensor or Unix epoch, as the file says).
    pub time_origin_us: i64,
    /// Free-form name of the sensor or source ("simulator", "davis346", ...).
    pub sensor: String,
}

impl CameraInfo {
    /// The identity rotation, row-major.
    pub const IDENTITY: [f64; 9] = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];

    /// An ideal pinhole camera of `width` x `height` pixels with focal length `f` pixels and the
    /// principal point at the image centre; no distortion, IMU frame = camera frame, no offset.
    pub fn pinhole(width: u16, height: u16, f: f64, sensor: &str) -> Self {
        Self {
            width,
            height,
            fx: f,
            fy: f,
            cx: (f64::from(width) - 1.0) / 2.0,
            cy: (f64::from(height) - 1.0) / 2.0,
            distortion: Distortion::None,
            imu_to_camera: Self::IDENTITY,
            imu_time_offset_s: 0.0,
            time_origin_us: 0,
            sensor: sensor.to_string(),
        }
    }

    /// A vector of the IMU frame (a gyro rate, rad/s) in the camera frame:
    /// `imu_to_camera * v`.
    pub fn imu_vector_to_camera(&self, v: [f64; 3]) -> [f64; 3] {
        Self::rotate(&self.imu_to_camera, v)
    }

    /// `r * v` for a row-major 3x3 rotation `r` (as [`CameraInfo::imu_to_camera`]): what
    /// [`CameraInfo::imu_vector_to_camera`] does with the camera's own rotation, for a candidate
    /// one.
    pub fn rotate(r: &[f64; 9], v: [f64; 3]) -> [f64; 3] {
        [
            r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
            r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
            r[6] * v[0] + r[7] * v[1] + r[8] * v[2],
        ]
    }
}

/// What a source publishes per batch on its `events` output: a time-ordered chunk of events, the
/// IMU samples of the same time span, and the camera description.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EventPacket {
    /// Camera calibration (identical in every packet of a stream).
    pub camera: CameraInfo,
    /// The events of this batch, time-ordered.
    pub events: Events,
    /// IMU samples with `t` in this batch's time span (may be empty).
    pub imu: Vec<ImuSample>,
}

impl Message for EventPacket {
    const SCHEMA: &'static str = "evseg.EventPacket";
    const VERSION: u16 = 1;
}

/// A fixed time window of events, as made by the slicer. Its envelope carries the slice number
/// and the window `[t_start, t_end)`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Slice {
    /// Camera calibration.
    pub camera: CameraInfo,
    /// Events with `t_start <= t < t_end`, time-ordered.
    pub events: Events,
    /// IMU samples whose camera-clock time falls in the window.
    pub imu: Vec<ImuSample>,
    /// Mean camera rotation rate over the window, rad/s, camera frame; `None` without IMU data.
    pub omega: Option<[f64; 3]>,
}

impl Message for Slice {
    const SCHEMA: &'static str = "evseg.Slice";
    const VERSION: u16 = 1;
}

/// Per-event normal flow, aligned with the slice's events.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct NormalFlow {
    /// Normal flow x component, normalized coordinates per second.
    #[serde(with = "crate::columns::f32s")]
    pub nx: Vec<f32>,
    /// Normal flow y component, normalized coordinates per second.
    #[serde(with = "crate::columns::f32s")]
    pub ny: Vec<f32>,
    /// Confidence in [0, 1]; 0 = no reliable estimate (the flow values are then 0).
    #[serde(with = "crate::columns::f32s")]
    pub confidence: Vec<f32>,
}

impl NormalFlow {
    /// Makes the flow `n` events long with no estimate anywhere (flow 0, confidence 0), reusing
    /// its buffers: the start of an estimator's output for a slice of `n` events.
    pub fn reset_invalid(&mut self, n: usize) {
        for column in [&mut self.nx, &mut self.ny, &mut self.confidence] {
            column.clear();
            column.resize(n, 0.0);
        }
    }
}

impl Message for NormalFlow {
    const SCHEMA: &'static str = "evseg.NormalFlow";
    const VERSION: u16 = 1;
}

/// A cluster id per event (over-segmentation), aligned with the slice's events.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Clusters {
    /// Cluster index per event; `u16::MAX` = not assigned (for example, no valid flow).
    #[serde(with = "crate::columns::u16s")]
    pub id: Vec<u16>,
    /// Number of clusters.
    pub count: u16,
}

impl Message for Clusters {
    const SCHEMA: &'static str = "evseg.Clusters";
    const VERSION: u16 = 1;
}

/// Per-event residual of a motion model fit, aligned with the slice's events.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Residuals {
    /// Residual normal flow, normalized coordinates per second (NaN where no flow).
    #[serde(with = "crate::columns::f32s")]
    pub residual: Vec<f32>,
    /// True where the event is a candidate background event.
    pub background: Vec<bool>,
    /// Model parameters of the fit (meaning set by the producing node, documented there).
    pub model: Vec<f64>,
}

impl Message for Residuals {
    const SCHEMA: &'static str = "evseg.Residuals";
    const VERSION: u16 = 1;
}

/// One motion segment of a slice.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Segment {
    /// Label used in [`Segmentation::label`] (0 = background).
    pub label: u32,
    /// Translation estimate with depth 1, camera frame, normalized units per second.
    pub translation: [f64; 3],
    /// Centroid, pixels.
    pub centroid: [f64; 2],
    /// Bounding box `[x_min, y_min, x_max, y_max]`, pixels.
    pub bbox: [f32; 4],
    /// Events in the segment.
    pub events: u32,
}

/// A per-event labelling of a slice into motion segments, aligned with the slice's events.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Segmentation {
    /// Segment label per event (0 = background).
    #[serde(with = "crate::columns::u32s")]
    pub label: Vec<u32>,
    /// The segments.
    pub segments: Vec<Segment>,
    /// Camera egomotion estimated on the final background (paper section 3.5, last paragraph).
    pub egomotion: Egomotion,
}

impl Message for Segmentation {
    const SCHEMA: &'static str = "evseg.Segmentation";
    /// v2: `egomotion` added.
    const VERSION: u16 = 2;
}

/// The background merger's coarse segmentation of a slice (paper section 3.4), aligned with the
/// slice's events: the over-segmentation clusters judged background are merged into group 0, the
/// others are kept as groups of their own for the hierarchical merger.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct CoarseSegmentation {
    /// Group per event: 0 = merged background, `g >= 1` = over-segmentation cluster `g - 1`,
    /// [`CoarseSegmentation::UNASSIGNED`] = no cluster (no valid flow).
    #[serde(with = "crate::columns::u32s")]
    pub group: Vec<u32>,
    /// Residual normal flow per event under the refined background motion, normalized units/s
    /// (NaN without valid flow).
    #[serde(with = "crate::columns::f32s")]
    pub residual: Vec<f32>,
    /// Per group (index = group number): fraction of its events that lie on the persistent
    /// background map, in [0, 1] (NaN for a group without events).
    pub map_overlap: Vec<f32>,
    /// Camera egomotion estimated by the linear SVM on the coarse background.
    pub egomotion: Egomotion,
}

impl CoarseSegmentation {
    /// Group value of an event that belongs to no group.
    pub const UNASSIGNED: u32 = u32::MAX;
}

impl Message for CoarseSegmentation {
    const SCHEMA: &'static str = "evseg.CoarseSegmentation";
    const VERSION: u16 = 1;
}

/// Camera egomotion estimate for one slice.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Egomotion {
    /// Unit direction of translation, camera frame (only the direction is observable).
    pub direction: [f64; 3],
    /// Rotation rate used, rad/s, camera frame.
    pub omega: [f64; 3],
    /// True when an estimate could be made.
    pub valid: bool,
}

/// One tracked object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Track {
    /// Stable track id (never 0, which is background, nor [`Tracks::UNCONFIRMED`]).
    pub id: u32,
    /// Filtered centroid, pixels.
    pub centroid: [f64; 2],
    /// Filtered image velocity, pixels per second.
    pub velocity: [f64; 2],
    /// Bounding box `[x_min, y_min, x_max, y_max]`, pixels.
    pub bbox: [f32; 4],
    /// Translation estimate with depth 1, camera frame, normalized units per second.
    pub translation: [f64; 3],
    /// Slices since the track was created.
    pub age: u32,
    /// Events assigned in this slice.
    pub events: u32,
}

/// The final output of a slice: per-event track ids, the tracks and the egomotion.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Tracks {
    /// Track id per event (0 = background, [`Tracks::UNCONFIRMED`] = moving, but its track is
    /// not confirmed yet), aligned with the slice's events. Any non-zero label is moving.
    #[serde(with = "crate::columns::u32s")]
    pub label: Vec<u32>,
    /// Tracks alive in this slice.
    pub tracks: Vec<Track>,
    /// Camera egomotion.
    pub egomotion: Egomotion,
}

impl Tracks {
    /// Label of an event that is moving but whose track has not yet been matched often enough
    /// to be confirmed (a tracker's tentative track, as SORT's): it counts as moving (the
    /// segmentation), but names no object (no identity is claimed). Never a track id.
    pub const UNCONFIRMED: u32 = u32::MAX;
}

impl Message for Tracks {
    const SCHEMA: &'static str = "evseg.Tracks";
    const VERSION: u16 = 1;
}

/// Camera motion at one instant, world and camera frames.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct CameraMotion {
    /// Time, seconds on the sequence clock.
    pub t: f64,
    /// Camera position in the world, metres.
    pub position: [f64; 3],
    /// Camera orientation (camera -> world), quaternion `[x, y, z, w]`.
    pub orientation: [f64; 4],
    /// Linear velocity, m/s, camera frame (`None` where only poses are known).
    pub linear_velocity: Option<[f64; 3]>,
    /// Angular velocity, rad/s, camera frame.
    pub angular_velocity: Option<[f64; 3]>,
}

/// An object's pose relative to the camera at one instant.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ObjectPose {
    /// Object id (as in masks and per-event ids; never 0).
    pub id: u32,
    /// Time, seconds on the sequence clock.
    pub t: f64,
    /// Object origin in the camera frame, metres.
    pub position: [f64; 3],
    /// Object orientation (object -> camera), quaternion `[x, y, z, w]`.
    pub orientation: [f64; 4],
}

/// A ground-truth object mask.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Mask {
    /// Time of the mask, seconds on the sequence clock.
    pub t: f64,
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// Object id per pixel, row-major (0 = background).
    #[serde(with = "crate::columns::u16s")]
    pub ids: Vec<u16>,
}

/// Ground truth of one batch or slice, as far as the source knows it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Object id per event (0 = background), aligned with the events; empty if unknown.
    #[serde(with = "crate::columns::u16s")]
    pub event_object: Vec<u16>,
    /// True optical flow per event, x, pixels per second; empty if unknown.
    #[serde(with = "crate::columns::f32s")]
    pub flow_x: Vec<f32>,
    /// True optical flow per event, y, pixels per second; empty if unknown.
    #[serde(with = "crate::columns::f32s")]
    pub flow_y: Vec<f32>,
    /// Masks whose time falls in the span.
    pub masks: Vec<Mask>,
    /// Camera motion samples in the span.
    pub camera: Vec<CameraMotion>,
    /// Object poses in the span.
    pub objects: Vec<ObjectPose>,
}

impl Message for Truth {
    const SCHEMA: &'static str = "evseg.Truth";
    const VERSION: u16 = 1;
}

/// One named figure of a slice or a sequence.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Metric {
    /// Name, with its unit when it has one (`iou`, `direction_error_deg`, ...).
    pub name: String,
    /// Value (NaN when not defined for this slice).
    pub value: f64,
}

/// Per-slice evaluation figures.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// The figures.
    pub values: Vec<Metric>,
}

impl Message for Metrics {
    const SCHEMA: &'static str = "evseg.Metrics";
    const VERSION: u16 = 1;
}

/// Name and current version of every message schema, for `evseg check`, `--describe` and
/// end-of-stream frames.
pub const ALL_SCHEMAS: &[(&str, u16)] = &[
    (EventPacket::SCHEMA, EventPacket::VERSION),
    (Slice::SCHEMA, Slice::VERSION),
    (NormalFlow::SCHEMA, NormalFlow::VERSION),
    (Clusters::SCHEMA, Clusters::VERSION),
    (Residuals::SCHEMA, Residuals::VERSION),
    (CoarseSegmentation::SCHEMA, CoarseSegmentation::VERSION),
    (Segmentation::SCHEMA, Segmentation::VERSION),
    (Tracks::SCHEMA, Tracks::VERSION),
    (Truth::SCHEMA, Truth::VERSION),
    (Metrics::SCHEMA, Metrics::VERSION),
];

/// Current version of the schema called `name`, if it is one of the pipeline's.
pub fn schema_version(name: &str) -> Option<u16> {
    ALL_SCHEMAS.iter().find(|(n, _)| *n == name).map(|(_, v)| *v)
}
