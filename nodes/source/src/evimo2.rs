//! EVIMO2 v2 sequence folders (see METHOD_NOTES section 4): events, IMU, camera and object
//! poses, and masks as ground truth (EVIMO2 has no per-event labels; the evaluator looks events
//! up in the mask nearest in time).

use std::path::Path;

use evseg_evimo2::imu_check::{ImuCheckParams, ImuVerdict, check, trajectory_rates};
use evseg_evimo2::{MaskReader, ReadOptions, Sequence};
use evseg_schemas::{CameraInfo, CameraMotion, ImuSample, ObjectPose, Truth};

pub use crate::order::DEFAULT_REORDER_WINDOW_S;
use crate::order::{ReorderBuffer, check_reorder_window};
use crate::{Batch, EventSource, SourceError};

/// Reads an EVIMO2 v2 folder batch by batch.
pub struct Evimo2Source {
    camera: CameraInfo,
    events: evseg_evimo2::EventReader,
    masks: Option<MaskReader>,
    next_mask: usize,
    imu: Vec<ImuSample>,
    next_imu: usize,
    poses: Vec<CameraMotion>,
    next_pose: usize,
    objects: Vec<ObjectPose>,
    next_object: usize,
    /// Stop after this many seconds of sensor time.
    seconds: Option<f64>,
    done: bool,
    /// How far past a batch's end the file is read, seconds, so that events stamped before the
    /// end but stored after later ones still reach their batch.
    reorder_window_s: f64,
    /// Events read ahead of the last batch's end, sorted by time.
    pending: ReorderBuffer,
    /// Events whose pixel lies outside the sensor of `meta['meta']` (dropped, counted).
    pub outside_sensor: u64,
    /// The folder (for warnings).
    folder: std::path::PathBuf,
    /// True once the first event dropped for its time has been reported.
    warned_time_outlier: bool,
}

impl Evimo2Source {
    /// Opens `folder` with `options` (IMU topic, IMU-to-camera rotation and offset overrides).
    pub fn open(folder: &Path, options: &ReadOptions, seconds: Option<f64>) -> Result<Self, SourceError> {
        let seq = Sequence::open(folder, options).map_err(|e| SourceError::Read(e.to_string()))?;
        for fallback in &seq.camera_fallbacks {
            tracing::warn!(
                "{}: meta['meta'] lacks camera fields; {fallback}",
                folder.display()
            );
        }
        let events = seq.events().map_err(|e| SourceError::Read(e.to_string()))?;
        let masks = match seq.masks() {
            Ok(m) => Some(m),
            Err(e) => {
                tracing::warn!(
                    "{}: no masks ({e}); the run has no segmentation ground truth",
                    folder.display()
                );
                None
            }
        };
        let mut objects = seq.object_poses();
        objects.sort_by(|a, b| a.t.total_cmp(&b.t));
        Ok(Self {
            camera: seq.camera.clone(),
            events,
            masks,
            next_mask: 0,
            imu: seq.imu.clone(),
            next_imu: 0,
            poses: seq.camera_poses.clone(),
            next_pose: 0,
            objects,
            next_object: 0,
            seconds,
            done: false,
            reorder_window_s: DEFAULT_REORDER_WINDOW_S,
            pending: ReorderBuffer::default(),
            outside_sensor: 0,
            folder: folder.to_path_buf(),
            warned_time_outlier: false,
        })
    }

    /// Drops the events of `events` whose pixel lies outside the camera's sensor (a writer's
    /// off-by-one at the border, or a resolution in meta that does not match the events), so
    /// every stage downstream gets pixels it can index; counts them and warns at the first.
    fn drop_outside_sensor(&mut self, events: evseg_schemas::Events) -> evseg_schemas::Events {
        let (w, h) = (self.camera.width, self.camera.height);
        let inside = |i: usize| events.x[i] < w && events.y[i] < h;
        if (0..events.len()).all(inside) {
            return events;
        }
        let mut kept = evseg_schemas::Events::with_capacity(events.len());
        for i in 0..events.len() {
            if inside(i) {
                kept.push(events.t[i], events.x[i], events.y[i], events.p[i]);
            } else {
                if self.outside_sensor == 0 {
                    tracing::warn!(
                        "event at pixel ({}, {}), t {:.6} s, is outside the {w}x{h} sensor of meta['meta']; \
                         such events are dropped (counted: events_outside_sensor)",
                        events.x[i],
                        events.y[i],
                        events.t[i]
                    );
                }
                self.outside_sensor += 1;
            }
        }
        kept
    }

    /// How far past each batch's end the file is read to sort late-stored events into their
    /// batch, seconds (default [`DEFAULT_REORDER_WINDOW_S`]; 0 = batches end at the first
    /// event stored at or after their end). An event stored more than this after later ones
    /// still arrives late and is dropped and counted by the slicer.
    pub fn set_reorder_window(&mut self, seconds: f64) -> Result<(), SourceError> {
        self.reorder_window_s = check_reorder_window(seconds)?;
        Ok(())
    }

    /// Events that were out of order in the file and were sorted into place (not dropped).
    pub fn reordered(&self) -> u64 {
        self.pending.reordered()
    }

    /// Reads the file up to `t_read` into the time-sorted pending buffer.
    fn read_ahead(&mut self, t_read: f64) -> Result<(), SourceError> {
        let fresh = self
            .events
            .read_until(t_read)
            .map_err(|e| SourceError::Read(e.to_string()))?;
        self.pending.push(fresh);
        if let (false, (_, Some((row, t)))) = (self.warned_time_outlier, self.events.time_outliers()) {
            self.warned_time_outlier = true;
            tracing::warn!(
                "{}: event {row} has time {t} s, not finite or more than {} s away from the events \
                 around it in the file (a corrupt time, or the file's times jump); such events \
                 are dropped (counted: event_times_dropped; parameter max_time_gap_s)",
                self.folder.join(evseg_evimo2::EVENTS_T).display(),
                self.events.max_time_gap_s()
            );
        }
        Ok(())
    }
}

/// Where the stages' camera rotation rate comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RotationSource {
    /// The folder's IMU (the method's input, as in the paper).
    Imu,
    /// The folder's camera trajectory, differentiated ([`trajectory_rates`]): for folders
    /// without an IMU. The trajectory is the ground truth, so a run with it is not an IMU run:
    /// the rotation is then exact and only the translation direction is estimated.
    Trajectory,
}

impl std::str::FromStr for RotationSource {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "imu" => Ok(Self::Imu),
            "trajectory" => Ok(Self::Trajectory),
            other => Err(format!(
                "rotation_source must be imu or trajectory, got `{other}`"
            )),
        }
    }
}

/// What [`Evimo2Source::check_imu`] does when the IMU's mapping disagrees with the trajectory.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImuCheckMode {
    /// No check.
    Off,
    /// Log the disagreement and the mapping that agrees; keep the configured one.
    Warn,
    /// Log it and use the mapping that agrees, unless the mapping was set explicitly (node
    /// parameters `imu_to_camera` / `imu_time_offset_s`), which is then kept with the warning.
    Auto,
}

impl std::str::FromStr for ImuCheckMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "off" => Ok(Self::Off),
            "warn" => Ok(Self::Warn),
            "auto" => Ok(Self::Auto),
            other => Err(format!("imu_check must be off, warn or auto, got `{other}`")),
        }
    }
}

impl Evimo2Source {
    /// Sets where the rotation rate comes from. With [`RotationSource::Trajectory`] the folder's
    /// IMU samples (if any) are replaced by one sample per interval of the camera trajectory
    /// (its mean rate, camera frame, at the interval's middle; the accelerometer reads 0, as
    /// nothing downstream uses it), the IMU-to-camera rotation becomes the identity and its
    /// offset 0. Returns the number of samples made; an error when the trajectory gives none.
    /// With [`RotationSource::Imu`] a folder without IMU samples gets a warning naming the
    /// parameter.
    pub fn set_rotation_source(
        &mut self,
        source: RotationSource,
        folder: &Path,
    ) -> Result<usize, SourceError> {
        match source {
            RotationSource::Imu => {
                if self.imu.is_empty() {
                    tracing::warn!(
                        "{}: the folder has no IMU samples, so the stages get no rotation rate and fit the flow un-derotated (the egomotion is then poor); `--set <source>.rotation_source=trajectory` takes the rate from the folder's camera trajectory (ground truth)",
                        folder.display()
                    );
                }
                Ok(self.imu.len())
            }
            RotationSource::Trajectory => {
                let rates = trajectory_rates(&self.poses);
                if rates.is_empty() {
                    return Err(SourceError::Param(format!(
                        "rotation_source: trajectory: {} has no camera trajectory to take the rotation rate from (no `full_trajectory` and no camera pose in `frames` of meta, or poses more than 0.1 s apart)",
                        folder.display()
                    )));
                }
                self.imu = rates
                    .iter()
                    .map(|r| ImuSample {
                        t: 0.5 * (r.t0 + r.t1),
                        gyro: r.rate,
                        accel: [0.0; 3],
                    })
                    .collect();
                self.next_imu = 0;
                self.camera.imu_to_camera = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
                self.camera.imu_time_offset_s = 0.0;
                tracing::warn!(
                    samples = self.imu.len(),
                    "{}: the rotation rate comes from the folder's camera trajectory (rotation_source: trajectory), not from an IMU: the trajectory is the ground truth, so this run's segmentation and egomotion figures are not those of an IMU run",
                    folder.display()
                );
                Ok(self.imu.len())
            }
        }
    }

    /// Checks the IMU's mapping into the camera frame (axes and time offset) against the rotation
    /// rate of the folder's camera trajectory ([`evseg_evimo2::imu_check`]); with
    /// [`ImuCheckMode::Auto`] and `explicit` false (the mapping came from the file or the EVIMO2
    /// defaults, not from the user) a disagreeing mapping is replaced by the one that agrees.
    /// Returns the verdict (on the configured mapping).
    pub fn check_imu(&mut self, mode: ImuCheckMode, explicit: bool) -> ImuVerdict {
        if mode == ImuCheckMode::Off {
            return ImuVerdict::Inconclusive;
        }
        let verdict = check(
            &self.poses,
            &self.imu,
            &self.camera.imu_to_camera,
            self.camera.imu_time_offset_s,
            &ImuCheckParams::default(),
        );
        match verdict {
            ImuVerdict::Inconclusive => tracing::info!(
                "IMU check: inconclusive (no IMU, no trajectory, or too little rotation); the IMU mapping is used as configured"
            ),
            ImuVerdict::Consistent(a) => tracing::info!(
                "IMU check: the IMU agrees with the camera trajectory (rms error {:.3} rad/s against rms rate {:.3}, {} intervals)",
                a.rms_error_rad_s,
                a.rms_rate_rad_s,
                a.intervals
            ),
            ImuVerdict::Mismatch { configured, better } => {
                let adopt = mode == ImuCheckMode::Auto && !explicit;
                tracing::warn!(
                    "IMU check: the IMU mapped with imu_to_camera {:?}, offset {} s disagrees with the camera trajectory (rms error {:.3} rad/s against rms rate {:.3}); imu_to_camera {:?}, offset {} s agrees (rms error {:.3}); {}",
                    configured.imu_to_camera,
                    configured.time_offset_s,
                    configured.rms_error_rad_s,
                    configured.rms_rate_rad_s,
                    better.imu_to_camera,
                    better.time_offset_s,
                    better.rms_error_rad_s,
                    if adopt {
                        "using it (imu_check: auto; set imu_to_camera / imu_time_offset_s to override)"
                    } else {
                        "keeping the configured mapping (set explicitly, or imu_check: warn)"
                    }
                );
                if adopt {
                    self.camera.imu_to_camera = better.imu_to_camera;
                    self.camera.imu_time_offset_s = better.time_offset_s;
                }
            }
        }
        verdict
    }
}

/// Items of a time-sorted list from `*next` with time `< t_end`.
fn take_until<T: Clone>(items: &[T], next: &mut usize, t_end: f64, t: impl Fn(&T) -> f64) -> Vec<T> {
    let start = *next;
    while *next < items.len() && t(&items[*next]) < t_end {
        *next += 1;
    }
    items[start..*next].to_vec()
}

impl EventSource for Evimo2Source {
    fn counters(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("events_reordered", self.pending.reordered()),
            ("times_not_increasing", self.events.non_monotonic()),
            ("event_times_dropped", self.events.time_outliers().0),
            ("events_outside_sensor", self.outside_sensor),
            (
                "masks_read_with_raw_ids",
                self.masks.as_ref().map_or(0, |m| m.raw_id_masks() as u64),
            ),
        ]
    }

    fn camera(&self) -> CameraInfo {
        self.camera.clone()
    }

    fn next_batch(&mut self, t_end: f64) -> Result<Option<Batch>, SourceError> {
        if self.done {
            return Ok(None);
        }
        let limit = self.seconds.unwrap_or(f64::INFINITY);
        let t_end_eff = t_end.min(limit);
        self.read_ahead(t_end_eff + self.reorder_window_s)?;
        let events = self.pending.take_before(t_end_eff);
        let events = self.drop_outside_sensor(events);
        let exhausted =
            (self.events.position() >= self.events.len() && self.pending.is_empty()) || t_end >= limit;
        let offset = self.camera.imu_time_offset_s;
        let imu = take_until(&self.imu, &mut self.next_imu, t_end_eff, |s| s.t + offset);
        let camera = take_until(&self.poses, &mut self.next_pose, t_end_eff, |p| p.t);
        let objects = take_until(&self.objects, &mut self.next_object, t_end_eff, |o| o.t);
        let mut masks = Vec::new();
        if let Some(reader) = self.masks.as_mut() {
            while self.next_mask < reader.len() && reader.entries()[self.next_mask].t < t_end_eff {
                let raw_before = reader.raw_id_masks();
                masks.push(
                    reader
                        .read(self.next_mask)
                        .map_err(|e| SourceError::Read(e.to_string()))?,
                );
                if raw_before == 0 && reader.raw_id_masks() == 1 {
                    tracing::warn!(
                        mask = self.next_mask,
                        "dataset_mask.npz: most values of a mask are not multiples of 1000 (EVIMO2 \
                         stores object id * 1000); its values are taken as the object ids themselves, \
                         as are those of every such mask (counted: masks_read_with_raw_ids)"
                    );
                }
                self.next_mask += 1;
            }
        }
        if exhausted {
            self.done = true;
        }
        let truth = Truth {
            masks,
            camera,
            objects,
            ..Truth::default()
        };
        Ok(Some(Batch {
            events,
            imu,
            truth: Some(truth),
        }))
    }

    fn has_truth(&self) -> bool {
        true
    }
}

#[cfg(test)]
mod tests {
    use super::ImuCheckMode;

    #[test]
    fn an_unknown_imu_check_mode_is_an_error_naming_the_choices() {
        assert_eq!("auto".parse::<ImuCheckMode>(), Ok(ImuCheckMode::Auto));
        assert_eq!("warn".parse::<ImuCheckMode>(), Ok(ImuCheckMode::Warn));
        assert_eq!("off".parse::<ImuCheckMode>(), Ok(ImuCheckMode::Off));
        let err = "Auto!".parse::<ImuCheckMode>().unwrap_err();
        assert!(
            err.contains("off, warn or auto") && err.contains("Auto!"),
            "{err}"
        );
    }
}
