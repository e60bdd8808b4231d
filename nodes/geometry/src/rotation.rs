//! The camera's rotation rate over one slice as a function of time, from the slice's gyro
//! samples: what every stage derotates the normal flow with.
//!
//! A slice's mean rate (`Slice::omega`) leaves a rotational flow of `B(x) (w(t) - w_mean)` in
//! every event when the rate changes within the window. Under fast rotation that is as large as
//! the translational flow itself: on the simulator's `fast-rotation` preset (yaw up to about
//! 1 rad/s, angular accelerations up to about 5 rad/s^2, so the rate moves by up to 0.15 rad/s
//! across a 30 ms slice) the *true* flow derotated with the true mean rate lies a median 8.4 deg
//! from the translational flow direction on the background, against 1.6 deg on the slower
//! presets (hierarchical merger's `examples/oracle_ladder.rs`, rung R1). A straight line fitted
//! to the gyro samples of the window follows the rate to first order; the fit averages the gyro
//! noise over all samples like the mean does.

use evseg_schemas::{CameraInfo, ImuSample, Slice};

/// The rotation rate `w(t) = mean + slope (t - t_ref)`, rad/s, camera frame, `t` in seconds on
/// the camera clock. A constant rate has `slope` zero.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RotationRate {
    /// Rate at `t_ref`, rad/s, camera frame.
    pub mean: [f64; 3],
    /// Change of the rate per second, rad/s^2, camera frame.
    pub slope: [f64; 3],
    /// Reference time, seconds (camera clock).
    pub t_ref: f64,
}

impl From<[f64; 3]> for RotationRate {
    /// A constant rate (rad/s, camera frame).
    fn from(mean: [f64; 3]) -> Self {
        Self {
            mean,
            slope: [0.0; 3],
            t_ref: 0.0,
        }
    }
}

/// Fewest gyro samples for a fitted slope; with fewer the rate is taken as constant.
pub const MIN_SAMPLES_FOR_SLOPE: usize = 3;

/// Node parameter of every stage that derotates: fit the slope of the rate within the slice
/// ([`RotationRate::of_slice`]'s `linear`).
pub const SLOPE_PARAM: &str = "derotate_slope";

/// Default of [`SLOPE_PARAM`]: on. Measured on `evseg bench` (evseg-bench-v1); see the
/// project's `docs/scoreboard-history.md`.
pub const SLOPE_DEFAULT: bool = true;

/// `--describe` text of [`SLOPE_PARAM`].
pub const SLOPE_PARAM_DOC: &str = "derotate each event with the rotation rate at its time (a line fitted to the slice's gyro samples) instead of the slice's mean rate";

impl RotationRate {
    /// The rate at time `t` (seconds, camera clock), rad/s, camera frame.
    #[inline]
    pub fn at(&self, t: f64) -> [f64; 3] {
        let dt = t - self.t_ref;
        [
            self.mean[0] + self.slope[0] * dt,
            self.mean[1] + self.slope[1] * dt,
            self.mean[2] + self.slope[2] * dt,
        ]
    }

    /// True when every component is finite.
    pub fn is_finite(&self) -> bool {
        self.mean.iter().chain(&self.slope).all(|v| v.is_finite()) && self.t_ref.is_finite()
    }

    /// The slice's rate: `mean` (the slice's mean rate, `Slice::omega`, rad/s, camera frame)
    /// with, when `linear` and at least [`MIN_SAMPLES_FOR_SLOPE`] of the `imu` samples have
    /// finite rates spread over at least half of the window `span` (seconds, camera clock), the
    /// least-squares slope of those samples (turned into the camera frame and clock with
    /// `camera`'s `imu_to_camera` and `imu_time_offset_s`). The line passes through `mean` at
    /// the samples' mean time, so a slice whose samples fit no slope keeps the constant `mean`.
    /// `None` when `mean` is `None`.
    pub fn from_gyro(
        mean: Option<[f64; 3]>,
        imu: &[ImuSample],
        camera: &CameraInfo,
        span: (f64, f64),
        linear: bool,
    ) -> Option<Self> {
        let mean = mean?;
        let constant = Self::from(mean);
        if !linear {
            return Some(constant);
        }
        let usable = || {
            imu.iter()
                .filter(|s| s.t.is_finite() && s.gyro.iter().all(|g| g.is_finite()))
        };
        let k = usable().count();
        if k < MIN_SAMPLES_FOR_SLOPE {
            return Some(constant);
        }
        let offset = camera.imu_time_offset_s;
        let t_mean = usable().map(|s| s.t + offset).sum::<f64>() / k as f64;
        let (t_min, t_max) = usable().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
            (lo.min(s.t + offset), hi.max(s.t + offset))
        });
        if t_max - t_min < 0.5 * (span.1 - span.0) {
            return Some(constant);
        }
        let (mut stt, mut stw) = (0.0, [0.0; 3]);
        for s in usable() {
            let dt = s.t + offset - t_mean;
            let w = camera.imu_vector_to_camera(s.gyro);
            stt += dt * dt;
            for (a, wi) in stw.iter_mut().zip(w) {
                *a += dt * wi;
            }
        }
        if stt <= 0.0 {
            return Some(constant);
        }
        Some(Self {
            mean,
            slope: stw.map(|v| v / stt),
            t_ref: t_mean,
        })
    }

    /// [`RotationRate::from_gyro`] of a slice with window `span` (seconds): its mean rate
    /// `omega`, gyro samples and camera.
    pub fn of_slice(slice: &Slice, span: (f64, f64), linear: bool) -> Option<Self> {
        Self::from_gyro(slice.omega, &slice.imu, &slice.camera, span, linear)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn imu(ts: &[f64], rate: impl Fn(f64) -> [f64; 3]) -> Vec<ImuSample> {
        ts.iter()
            .map(|&t| ImuSample {
                t,
                gyro: rate(t),
                accel: [0.0; 3],
            })
            .collect()
    }

    #[test]
    fn a_rate_changing_linearly_is_followed_in_the_camera_frame_and_clock() {
        // IMU x = camera y, IMU y = camera -x, IMU z = camera z; IMU clock 2 ms behind.
        let mut cam = CameraInfo::pinhole(640, 480, 320.0, "test");
        cam.imu_to_camera = [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        cam.imu_time_offset_s = 0.002;
        let rate_imu = |t: f64| [0.5 + 4.0 * t, -1.0, 2.0 * t];
        let ts: Vec<f64> = (0..6).map(|k| 0.1 + 0.005 * k as f64).collect();
        let samples = imu(&ts, rate_imu);
        let mean_imu = ts.iter().map(|&t| rate_imu(t)).fold([0.0; 3], |a, w| {
            [a[0] + w[0] / 6.0, a[1] + w[1] / 6.0, a[2] + w[2] / 6.0]
        });
        let mean = cam.imu_vector_to_camera(mean_imu);
        let r = RotationRate::from_gyro(Some(mean), &samples, &cam, (0.1, 0.13), true).unwrap();
        for t_imu in [0.1, 0.117, 0.13] {
            let want = cam.imu_vector_to_camera(rate_imu(t_imu));
            let got = r.at(t_imu + 0.002);
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-9, "t {t_imu}: {got:?} vs {want:?}");
            }
        }
        // Constant when asked, or with too few samples, or when they cover too little time.
        let c = RotationRate::from_gyro(Some(mean), &samples, &cam, (0.1, 0.13), false).unwrap();
        assert_eq!(c.at(0.5), mean);
        let c = RotationRate::from_gyro(Some(mean), &samples[..2], &cam, (0.1, 0.13), true).unwrap();
        assert_eq!(c.at(0.5), mean);
        let c = RotationRate::from_gyro(Some(mean), &samples, &cam, (0.1, 0.2), true).unwrap();
        assert_eq!(c.at(0.5), mean);
        assert!(RotationRate::from_gyro(None, &samples, &cam, (0.1, 0.13), true).is_none());
    }

    #[test]
    fn non_finite_samples_are_left_out_of_the_slope() {
        let cam = CameraInfo::pinhole(64, 48, 32.0, "test");
        let mut samples = imu(&[0.0, 0.01, 0.02, 0.03], |t| [t, 0.0, 0.0]);
        samples[1].gyro[0] = f64::NAN;
        let r = RotationRate::from_gyro(Some([0.02, 0.0, 0.0]), &samples, &cam, (0.0, 0.03), true).unwrap();
        assert!(r.is_finite());
        assert!((r.slope[0] - 1.0).abs() < 1e-9, "{r:?}");
    }
}
