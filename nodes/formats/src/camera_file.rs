//! Camera files: the calibration a decoder's file lacks, as JSON, turned into a
//! [`CameraInfo`].
//!
//! Every key is optional in the file; which ones are needed depends on what the event file
//! already carries (see [`build_camera_info`]). Unknown keys are errors (they are usually typos).
//!
//! ```json
//! {
//!   "sensor": "davis346",
//!   "width": 346, "height": 260,
//!   "fx": 320.5, "fy": 320.1, "cx": 172.3, "cy": 130.9,
//!   "distortion": {"model": "rad_tan", "k1": -0.35, "k2": 0.15, "p1": 0.0, "p2": 0.0, "k3": 0.0},
//!   "imu_to_camera": [1, 0, 0, 0, 1, 0, 0, 0, 1],
//!   "imu_time_offset_s": 0.0
//! }
//! ```
//!
//! * `width`, `height`: pixels; checked against the event file's sensor size when given.
//! * `fx`, `fy`, `cx`, `cy`: pinhole intrinsics, pixels.
//! * `distortion`: `{"model": "none"}`, `{"model": "rad_tan", k1, k2, p1, p2, k3}` (OpenCV
//!   radial-tangential; `k3` may be left out, 0) or `{"model": "equidistant", k1, k2, k3, k4}`
//!   (Kannala-Brandt); default none.
//! * `imu_to_camera`: rotation taking IMU-frame vectors to the camera frame, row-major 3x3
//!   (`v_cam = R v_imu`); required when the event file has an IMU stream.
//! * `imu_time_offset_s`: added to IMU times to put them on the camera clock, seconds; default 0
//!   (AEDAT 4 and the Event Camera Dataset timestamp IMU and events with one device clock).

use std::path::{Path, PathBuf};

use evseg_schemas::messages::{CameraInfo, Distortion};
use serde::Deserialize;

use crate::{EventDecoder, Format};

/// Lens distortion as written in a camera file.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum DistortionSpec {
    /// Ideal pinhole.
    None,
    /// OpenCV radial-tangential on normalized coordinates.
    RadTan {
        /// Radial r² coefficient.
        k1: f64,
        /// Radial r⁴ coefficient.
        k2: f64,
        /// Tangential coefficient 1.
        p1: f64,
        /// Tangential coefficient 2.
        p2: f64,
        /// Radial r⁶ coefficient (default 0).
        #[serde(default)]
        k3: f64,
    },
    /// Kannala-Brandt equidistant, on the angle theta.
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

impl From<DistortionSpec> for Distortion {
    fn from(spec: DistortionSpec) -> Self {
        match spec {
            DistortionSpec::None => Distortion::None,
            DistortionSpec::RadTan { k1, k2, p1, p2, k3 } => Distortion::RadTan { k1, k2, p1, p2, k3 },
            DistortionSpec::Equidistant { k1, k2, k3, k4 } => Distortion::Equidistant { k1, k2, k3, k4 },
        }
    }
}

/// The content of a camera file; see the module docs for the keys and units.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraFile {
    /// Free-form sensor name.
    pub sensor: Option<String>,
    /// Sensor width, pixels.
    pub width: Option<u16>,
    /// Sensor height, pixels.
    pub height: Option<u16>,
    /// Focal length along x, pixels.
    pub fx: Option<f64>,
    /// Focal length along y, pixels.
    pub fy: Option<f64>,
    /// Principal point x, pixels.
    pub cx: Option<f64>,
    /// Principal point y, pixels.
    pub cy: Option<f64>,
    /// Lens distortion.
    pub distortion: Option<DistortionSpec>,
    /// IMU-to-camera rotation, row-major.
    pub imu_to_camera: Option<[f64; 9]>,
    /// IMU-to-camera clock offset, seconds.
    pub imu_time_offset_s: Option<f64>,
}

/// Why a camera description could not be built.
#[derive(Debug, thiserror::Error)]
pub enum CameraFileError {
    /// The camera file could not be read.
    #[error("{}: cannot read camera file: {source}", .path.display())]
    Io {
        /// The camera file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The camera file is not valid JSON of the expected shape.
    #[error("{}:{line}:{column}: {message}", .path.display())]
    Parse {
        /// The camera file.
        path: PathBuf,
        /// Line, 1-based.
        line: usize,
        /// Column, 1-based.
        column: usize,
        /// What is wrong.
        message: String,
    },
    /// Parameters that neither the camera file nor the event file gives.
    #[error("missing camera parameters {}: {hint}", .missing.join(", "))]
    Missing {
        /// Names of the missing parameters, as camera-file keys.
        missing: Vec<&'static str>,
        /// Where they were looked for.
        hint: String,
    },
    /// A parameter with an impossible value.
    #[error("{}: {what}", .path.display())]
    Invalid {
        /// The camera file (or the event file, for embedded calibration).
        path: PathBuf,
        /// What is wrong.
        what: String,
    },
}

impl CameraFile {
    /// Reads and parses the camera file at `path`.
    pub fn load(path: &Path) -> Result<Self, CameraFileError> {
        let text = std::fs::read_to_string(path).map_err(|source| CameraFileError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses camera-file JSON (`path` is only used in errors).
    pub fn parse(text: &str, path: &Path) -> Result<Self, CameraFileError> {
        serde_json::from_str(text).map_err(|e| CameraFileError::Parse {
            path: path.to_path_buf(),
            line: e.line(),
            column: e.column(),
            message: e.to_string(),
        })
    }
}

fn format_name(format: Format) -> &'static str {
    match format {
        Format::Aedat4 => "aedat4",
        Format::Evt2 => "evt2",
        Format::Evt3 => "evt3",
        Format::EventStream => "event_stream",
        Format::Text => "text",
    }
}

/// Checks that `r` (row-major) is a rotation: orthonormal with determinant +1, to 1e-3.
fn is_rotation(r: &[f64; 9]) -> bool {
    let row = |i: usize| [r[3 * i], r[3 * i + 1], r[3 * i + 2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let orthonormal =
        (0..3).all(|i| (0..3).all(|j| (dot(row(i), row(j)) - if i == j { 1.0 } else { 0.0 }).abs() < 1e-3));
    let det = r[0] * (r[4] * r[8] - r[5] * r[7]) - r[1] * (r[3] * r[8] - r[5] * r[6])
        + r[2] * (r[3] * r[7] - r[4] * r[6]);
    orthonormal && (det - 1.0).abs() < 1e-3
}

/// Builds the [`CameraInfo`] of an opened event file: each value comes from the camera file when
/// given, else from the calibration stored with the event file ([`EventDecoder::calibration`]).
/// Sensor size and time origin always come from the decoder.
///
/// Required: `fx`, `fy`, `cx`, `cy`, and `imu_to_camera` when the event file has an IMU stream.
/// When some are missing, the error lists all of them. Defaults: no distortion, IMU time offset 0,
/// sensor name = the format's name.
pub fn build_camera_info(
    decoder: &dyn EventDecoder,
    camera_file: Option<&Path>,
) -> Result<CameraInfo, CameraFileError> {
    let file = camera_file.map(CameraFile::load).transpose()?.unwrap_or_default();
    let file_path = camera_file.map(Path::to_path_buf).unwrap_or_default();
    let embedded = decoder.calibration();
    let (width, height) = decoder.geometry();
    for (name, given, actual) in [("width", file.width, width), ("height", file.height, height)] {
        if let Some(given) = given
            && given != actual
        {
            return Err(CameraFileError::Invalid {
                path: file_path,
                what: format!("{name} {given} differs from the event file's sensor {name} {actual}"),
            });
        }
    }
    let mut missing = Vec::new();
    let mut pick = |name: &'static str, from_file: Option<f64>, from_embedded: Option<f64>| {
        let value = from_file.or(from_embedded);
        if value.is_none() {
            missing.push(name);
        }
        value.unwrap_or(f64::NAN)
    };
    let fx = pick("fx", file.fx, embedded.as_ref().map(|c| c.fx));
    let fy = pick("fy", file.fy, embedded.as_ref().map(|c| c.fy));
    let cx = pick("cx", file.cx, embedded.as_ref().map(|c| c.cx));
    let cy = pick("cy", file.cy, embedded.as_ref().map(|c| c.cy));
    let imu_to_camera = file.imu_to_camera.or(embedded.as_ref().map(|c| c.imu_to_camera));
    if imu_to_camera.is_none() && decoder.has_imu() {
        missing.push("imu_to_camera");
    }
    if !missing.is_empty() {
        let hint = match camera_file {
            Some(path) => format!(
                "neither the camera file {} nor the {} event file gives them",
                path.display(),
                format_name(decoder.format())
            ),
            None => format!(
                "the {} event file carries no calibration: give a camera file",
                format_name(decoder.format())
            ),
        };
        return Err(CameraFileError::Missing { missing, hint });
    }
    let invalid = |what: String| CameraFileError::Invalid {
        path: file_path.clone(),
        what,
    };
    for (name, v) in [("fx", fx), ("fy", fy), ("cx", cx), ("cy", cy)] {
        if !v.is_finite() {
            return Err(invalid(format!("{name} = {v} is not finite")));
        }
    }
    if fx <= 0.0 || fy <= 0.0 {
        return Err(invalid(format!(
            "focal lengths must be positive (fx = {fx}, fy = {fy})"
        )));
    }
    let imu_to_camera = imu_to_camera.unwrap_or(CameraInfo::IDENTITY);
    if !is_rotation(&imu_to_camera) {
        return Err(invalid(format!(
            "imu_to_camera {imu_to_camera:?} is not a rotation matrix"
        )));
    }
    let imu_time_offset_s = file
        .imu_time_offset_s
        .or(embedded.as_ref().map(|c| c.imu_time_offset_s))
        .unwrap_or(0.0);
    if !imu_time_offset_s.is_finite() {
        return Err(invalid(format!(
            "imu_time_offset_s = {imu_time_offset_s} is not finite"
        )));
    }
    Ok(CameraInfo {
        width,
        height,
        fx,
        fy,
        cx,
        cy,
        distortion: file
            .distortion
            .map(Distortion::from)
            .or(embedded.as_ref().map(|c| c.distortion))
            .unwrap_or(Distortion::None),
        imu_to_camera,
        imu_time_offset_s,
        time_origin_us: decoder.time_origin_us().unwrap_or(0),
        sensor: file
            .sensor
            .or(embedded.map(|c| c.sensor))
            .unwrap_or_else(|| format_name(decoder.format()).to_string()),
    })
}
