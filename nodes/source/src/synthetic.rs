//! The built-in event-camera simulator (crate `evseg-sim`) as a source, with full ground truth.

use evseg_schemas::CameraInfo;
use evseg_sim::{Simulator, preset};

/// Names of the simulator's scene presets (the `scene` parameter of a `synthetic` source and
/// `evseg sim --scene`).
pub use evseg_sim::PRESET_NAMES;

use crate::{Batch, EventSource, SourceError};

/// A simulated sequence.
pub struct SyntheticSource {
    sim: Simulator,
}

impl SyntheticSource {
    /// Scene preset `scene` with `seed`, optionally cut or stretched to `seconds`.
    pub fn new(scene: &str, seed: u64, seconds: Option<f64>) -> Result<Self, SourceError> {
        Self::from_config(scene_config(scene, seed, seconds, &[])?)
    }

    /// A scene of the caller's own (a preset with changed sensor, IMU or scene settings, say);
    /// refuses a configuration the simulator's checks refuse.
    pub fn from_config(config: evseg_sim::SceneConfig) -> Result<Self, SourceError> {
        let sim = Simulator::new(config).map_err(|e| SourceError::Param(e.to_string()))?;
        Ok(Self { sim })
    }
}

/// The configuration of preset `scene` with `seed`, optionally cut or stretched to `seconds`,
/// with the simulator's named `settings` applied in order (`evseg_sim::SETTINGS`: contrast
/// thresholds, noise, IMU noise, texture contrast, camera motion, ...).
pub fn scene_config(
    scene: &str,
    seed: u64,
    seconds: Option<f64>,
    settings: &[(String, f64)],
) -> Result<evseg_sim::SceneConfig, SourceError> {
    let mut config = preset(scene, seed).map_err(|e| SourceError::Param(e.to_string()))?;
    if let Some(s) = seconds {
        if !(s.is_finite() && s > 0.0 && s <= evseg_sim::MAX_DURATION_S) {
            return Err(SourceError::Param(format!(
                "seconds must be within (0, {}] for the simulator, got {s}",
                evseg_sim::MAX_DURATION_S
            )));
        }
        config.duration_s = s;
    }
    for (name, value) in settings {
        evseg_sim::apply_setting(&mut config, name, *value).map_err(|e| SourceError::Param(e.to_string()))?;
    }
    Ok(config)
}

impl EventSource for SyntheticSource {
    fn camera(&self) -> CameraInfo {
        self.sim.camera_info()
    }

    fn next_batch(&mut self, t_end: f64) -> Result<Option<Batch>, SourceError> {
        if self.sim.is_finished() {
            return Ok(None);
        }
        let chunk = self.sim.next_chunk(t_end.min(self.sim.duration()));
        Ok(Some(Batch {
            events: chunk.events,
            imu: chunk.imu,
            truth: Some(chunk.truth),
        }))
    }

    fn has_truth(&self) -> bool {
        true
    }
}

/// Simulates `scene` (seed, optional length) and writes it as an EVIMO2 v2 sequence folder at
/// `out` (events, masks at the simulator's mask rate, camera and object poses per mask frame,
/// full camera trajectory, IMU in the EVIMO2 axis convention, pickled `meta`). Returns the number
/// of events written. `resolution_scale` scales the sensor's size and focal lengths (same field
/// of view; in (0, 8]).
pub fn write_evimo2(
    scene: &str,
    seed: u64,
    seconds: Option<f64>,
    resolution_scale: f64,
    out: &std::path::Path,
) -> Result<u64, SourceError> {
    write_evimo2_config(scene_config(scene, seed, seconds, &[])?, resolution_scale, out)
}

/// As [`write_evimo2`], for a configuration of the caller's own (from [`scene_config`], say).
pub fn write_evimo2_config(
    mut config: evseg_sim::SceneConfig,
    resolution_scale: f64,
    out: &std::path::Path,
) -> Result<u64, SourceError> {
    use evseg_evimo2::{FrameTruth, SequenceWriter, WriteOptions};
    if !(resolution_scale.is_finite() && resolution_scale > 0.0 && resolution_scale <= 8.0) {
        return Err(SourceError::Param(format!(
            "resolution scale must be in (0, 8], got {resolution_scale}"
        )));
    }
    if resolution_scale != 1.0 {
        config = config.with_resolution_scale(resolution_scale);
    }
    let mut sim = Simulator::new(config).map_err(|e| SourceError::Param(e.to_string()))?;
    let camera = sim.camera_info();
    let write_err = |e: evseg_evimo2::Evimo2Error| SourceError::Read(e.to_string());
    // Events and masks go to their files as they are simulated; only the small ground truth
    // (poses at 200 Hz, IMU, the masks' times) is kept for the meta written at the end.
    let mut writer =
        SequenceWriter::create(out, &camera, 0.0, &WriteOptions::default()).map_err(write_err)?;
    let (mut imu, mut poses, mut mask_times, mut objects) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let step = 0.05;
    let mut t: f64 = 0.0;
    while !sim.is_finished() {
        t += step;
        let chunk = sim.next_chunk(t.min(sim.duration()));
        writer.push_events(&chunk.events).map_err(write_err)?;
        for m in &chunk.truth.masks {
            writer.push_mask(mask_times.len() as u64, m).map_err(write_err)?;
            mask_times.push(m.t);
        }
        imu.extend(chunk.imu);
        poses.extend(chunk.truth.camera);
        objects.extend(chunk.truth.objects);
    }
    poses.sort_by(|a, b| a.t.total_cmp(&b.t));
    objects.sort_by(|a, b| a.t.total_cmp(&b.t));
    // One ground-truth frame per mask: the camera pose nearest in time (the trajectory is sampled
    // at 200 Hz, masks at 60 Hz) and the object poses of the mask's instant. Both lists are in
    // time order (chunk after chunk), so each is searched by bisection.
    let frames: Vec<FrameTruth> = mask_times
        .iter()
        .enumerate()
        .map(|(k, &mt)| {
            let after = poses.partition_point(|p: &evseg_schemas::CameraMotion| p.t < mt);
            let camera = [after.checked_sub(1), Some(after)]
                .into_iter()
                .flatten()
                .filter_map(|i| poses.get(i))
                .min_by(|a, b| (a.t - mt).abs().total_cmp(&(b.t - mt).abs()))
                .copied();
            let first = objects.partition_point(|o: &evseg_schemas::ObjectPose| o.t < mt - 1e-9);
            let objs = objects[first..]
                .iter()
                .take_while(|o| o.t <= mt + 1e-9)
                .copied()
                .collect();
            FrameTruth {
                id: k as u64,
                t: mt,
                camera,
                objects: objs,
            }
        })
        .collect();
    writer
        .finish(evseg_evimo2::DEFAULT_IMU_TOPIC, &imu, &poses, &frames)
        .map_err(write_err)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Events of the first `seconds` of a source.
    fn count(mut src: SyntheticSource, seconds: f64) -> usize {
        let mut n = 0;
        while let Some(b) = src.next_batch(seconds).unwrap() {
            n += b.events.len();
        }
        n
    }

    #[test]
    fn a_changed_configuration_is_the_one_simulated_and_a_bad_one_is_refused() {
        let mut config = preset("one-object", 5).unwrap();
        config.duration_s = 0.02;
        let same = count(SyntheticSource::from_config(config.clone()).unwrap(), 0.02);
        assert_eq!(
            same,
            count(SyntheticSource::new("one-object", 5, Some(0.02)).unwrap(), 0.02)
        );
        // Thresholds twice as high: far fewer crossings of the same scene.
        let mut high = config.clone();
        high.esim.c_on *= 2.0;
        high.esim.c_off *= 2.0;
        let fewer = count(SyntheticSource::from_config(high).unwrap(), 0.02);
        assert!(
            fewer * 2 < same,
            "{fewer} events at twice the thresholds, {same} at the preset's"
        );
        let mut bad = config;
        bad.esim.c_on = -1.0;
        let err = SyntheticSource::from_config(bad)
            .err()
            .expect("a negative threshold is refused");
        assert!(err.to_string().contains("c_on"), "{err}");
    }

    #[test]
    fn named_settings_change_the_preset_and_an_unknown_one_is_refused_by_name() {
        let config = scene_config("one-object", 5, Some(0.02), &[("contrast".into(), 0.4)]).unwrap();
        assert_eq!((config.esim.c_on, config.esim.c_off), (0.4, 0.4));
        let fewer = count(SyntheticSource::from_config(config).unwrap(), 0.02);
        let same = count(SyntheticSource::new("one-object", 5, Some(0.02)).unwrap(), 0.02);
        assert!(fewer * 2 < same, "{fewer} events at 0.4, {same} at 0.2");
        let err = scene_config("one-object", 5, None, &[("contrast_pos".into(), 0.4)])
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(err.contains("contrast_pos") && err.contains("c_sigma"), "{err}");
    }
}
