//! Named changes to a scene's sensor, IMU, textures and camera motion, so that a sequence can
//! differ from the presets the way another camera or event simulator would: `evseg sim --set
//! contrast=0.3`, the synthetic source's `settings` parameter, and the method study's `SIM_SET`
//! (hierarchical merger's `examples/method_on_sim.rs`) all go through [`apply_setting`].

use crate::SimError;
use crate::config::SceneConfig;
use crate::trajectory::RigidTrajectory;

/// Every setting [`apply_setting`] knows, with what it changes and its unit.
pub const SETTINGS: &[(&str, &str)] = &[
    (
        "contrast",
        "ON and OFF contrast thresholds, log intensity (presets 0.2)",
    ),
    ("c_on", "ON contrast threshold, log intensity"),
    ("c_off", "OFF contrast threshold, log intensity"),
    (
        "c_sigma",
        "pixel-to-pixel threshold mismatch, standard deviation as a fraction of the threshold",
    ),
    ("refractory_s", "refractory period, seconds"),
    (
        "noise_rate_hz",
        "background-activity noise, events per pixel per second",
    ),
    ("hot_pixels", "number of hot pixels (a whole number)"),
    ("hot_pixel_rate_hz", "events per second of each hot pixel"),
    (
        "gyro_noise_std",
        "gyroscope white noise, standard deviation, rad/s",
    ),
    (
        "gyro_bias",
        "gyroscope bias, rad/s, as (+b, -b, +b) on the IMU's three axes",
    ),
    (
        "texture_contrast",
        "factor on the contrast of every texture (capped at 5)",
    ),
    (
        "camera_motion",
        "factor on every rate and amplitude of the camera trajectory, 0..=5 (0 holds the camera still)",
    ),
    (
        "edge_supersampling",
        "1: a pixel on a geometric edge averages 2 x 2 sub-samples (a pixel integrating its whole area); 0: its centre only",
    ),
];

/// The names of [`SETTINGS`], comma-separated (for help texts and errors).
pub fn setting_names() -> String {
    SETTINGS
        .iter()
        .map(|(name, _)| *name)
        .collect::<Vec<_>>()
        .join(", ")
}

/// Changes setting `name` of `cfg` to `value` (see [`SETTINGS`]). Unknown names, values that
/// are not finite (or, for `hot_pixels`, not a whole number >= 0), `camera_motion` outside
/// 0..=[`MAX_CAMERA_MOTION`], and values that leave a valid configuration invalid (a negative
/// threshold, say: the error names the setting and the field, as [`SceneConfig::validate`]
/// does) are refused.
pub fn apply_setting(cfg: &mut SceneConfig, name: &str, value: f64) -> Result<(), SimError> {
    if !value.is_finite() {
        return Err(SimError::Config(format!(
            "setting {name}: value {value} is not a finite number"
        )));
    }
    // A configuration that was valid must stay so; the error then names the setting, not
    // only the field it changed (`esim.c_on`).
    // Changed on a copy, so that a refused setting leaves `cfg` as it was.
    let was_valid = cfg.validate().is_ok();
    let mut changed = cfg.clone();
    set(&mut changed, name, value)?;
    if was_valid && let Err(e) = changed.validate() {
        let what = match e {
            SimError::Config(m) => m,
            other => other.to_string(),
        };
        return Err(SimError::Config(format!("setting {name} = {value}: {what}")));
    }
    *cfg = changed;
    Ok(())
}

/// Largest `camera_motion` factor: five times the presets' motion is already faster than a
/// hand-held camera; the render steps grow with it (10 took four times as long, 1000 ran for
/// minutes per packet).
pub const MAX_CAMERA_MOTION: f64 = 5.0;

/// The change of [`apply_setting`], unchecked against the rest of the configuration.
fn set(cfg: &mut SceneConfig, name: &str, value: f64) -> Result<(), SimError> {
    let e = &mut cfg.esim;
    match name {
        "contrast" => {
            e.c_on = value;
            e.c_off = value;
        }
        "c_on" => e.c_on = value,
        "c_off" => e.c_off = value,
        "c_sigma" => e.c_sigma = value,
        "refractory_s" => e.refractory_s = value,
        "noise_rate_hz" => e.noise_rate_hz = value,
        "hot_pixels" => {
            if value < 0.0 || value.fract() != 0.0 || value > f64::from(u32::MAX) {
                return Err(SimError::Config(format!(
                    "setting hot_pixels: {value} is not a whole number of pixels"
                )));
            }
            e.hot_pixels = value as u32;
        }
        "hot_pixel_rate_hz" => e.hot_pixel_rate_hz = value,
        "gyro_noise_std" => cfg.imu.gyro_noise_std = value,
        "gyro_bias" => cfg.imu.gyro_bias = [value, -value, value],
        "texture_contrast" => crate::scale_contrast(cfg, value),
        "camera_motion" => {
            if !(0.0..=MAX_CAMERA_MOTION).contains(&value) {
                return Err(SimError::Config(format!(
                    "setting camera_motion: {value} is outside 0..={MAX_CAMERA_MOTION} (a factor on the presets' camera motion)"
                )));
            }
            scale_camera_motion(&mut cfg.camera_trajectory, value)
        }
        "edge_supersampling" => {
            if value != 0.0 && value != 1.0 {
                return Err(SimError::Config(format!(
                    "setting edge_supersampling: {value} is neither 0 nor 1"
                )));
            }
            cfg.render.edge_supersampling = value == 1.0;
        }
        _ => {
            return Err(SimError::Config(format!(
                "unknown setting '{name}'; known settings: {}",
                setting_names()
            )));
        }
    }
    Ok(())
}

/// Scales every rate and amplitude of `traj` by `factor` (its constant offsets stay).
fn scale_camera_motion(traj: &mut RigidTrajectory, factor: f64) {
    for s in traj.position.iter_mut().chain(traj.angles.iter_mut()) {
        s.rate *= factor;
        for term in &mut s.terms {
            term.amplitude *= factor;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::preset;

    #[test]
    fn every_listed_setting_applies_and_changes_what_it_names() {
        let base = preset("one-object", 1).unwrap();
        for (name, _) in SETTINGS {
            let mut cfg = base.clone();
            // A switch takes 0 or 1: the opposite of the preset's.
            let value = match *name {
                "edge_supersampling" => f64::from(u8::from(!base.render.edge_supersampling)),
                _ => 3.0,
            };
            apply_setting(&mut cfg, name, value).unwrap();
            assert_ne!(cfg, base, "{name} changed nothing");
        }
        let mut cfg = base.clone();
        apply_setting(&mut cfg, "contrast", 0.3).unwrap();
        assert_eq!((cfg.esim.c_on, cfg.esim.c_off), (0.3, 0.3));
        apply_setting(&mut cfg, "gyro_bias", 0.01).unwrap();
        assert_eq!(cfg.imu.gyro_bias, [0.01, -0.01, 0.01]);
        apply_setting(&mut cfg, "camera_motion", 0.0).unwrap();
        let still = cfg.camera_trajectory.state(1.0);
        assert_eq!(still.velocity, [0.0; 3]);
    }

    #[test]
    fn unknown_names_and_bad_values_are_refused_with_the_setting_named() {
        let mut cfg = preset("one-object", 1).unwrap();
        let err = apply_setting(&mut cfg, "contrast_threshold", 0.3)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("contrast_threshold") && err.contains("noise_rate_hz"),
            "{err}"
        );
        let err = apply_setting(&mut cfg, "contrast", f64::NAN)
            .unwrap_err()
            .to_string();
        assert!(err.contains("contrast") && err.contains("finite"), "{err}");
        for bad in [-1.0, 2.5] {
            let err = apply_setting(&mut cfg, "hot_pixels", bad)
                .unwrap_err()
                .to_string();
            assert!(err.contains("hot_pixels"), "{err}");
        }
        let err = apply_setting(&mut cfg, "edge_supersampling", 0.5)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("edge_supersampling") && err.contains("neither 0 nor 1"),
            "{err}"
        );
        // A noise rate that would hold hundreds of millions of events per chunk.
        let err = apply_setting(&mut cfg, "noise_rate_hz", 1e12)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("setting noise_rate_hz = 1000000000000")
                && err.contains("esim.noise_rate_hz")
                && err.contains("above"),
            "{err}"
        );
        // Out of the simulator's range: named as the setting and as the field it changes.
        for bad in [0.0, -0.2] {
            let err = apply_setting(&mut cfg, "contrast", bad).unwrap_err().to_string();
            assert!(
                err.contains("setting contrast") && err.contains("esim.c_on"),
                "{err}"
            );
        }
        // Camera motion that would take minutes per packet.
        for bad in [-1.0, 1000.0] {
            let err = apply_setting(&mut cfg, "camera_motion", bad)
                .unwrap_err()
                .to_string();
            assert!(err.contains("camera_motion") && err.contains("0..=5"), "{err}");
        }
        // A refused setting leaves the configuration as it was (a valid one).
        assert!(crate::Simulator::new(cfg).is_ok());
    }
}
