//! IMU model: gyroscope and accelerometer in the IMU frame, with white noise and constant bias.
//!
//! The IMU frame follows the EVIMO2 (Prophesee) convention: camera-frame angular rate
//! `w_cam = (w_imu.y, -w_imu.x, w_imu.z)`, i.e. `v_cam = R * v_imu` with
//! `R = [[0, 1, 0], [-1, 0, 0], [0, 0, 1]]` ([`IMU_TO_CAMERA`]). The IMU sits at the camera
//! centre and shares its clock (time offset 0).

use evseg_schemas::ImuSample;
use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::math::{self, Mat3};
use crate::rng::Rng;
use crate::trajectory::RigidState;

/// Rotation taking IMU-frame vectors to the camera frame (EVIMO2 convention), row-major.
pub const IMU_TO_CAMERA: Mat3 = [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]];

/// IMU noise and rate parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImuConfig {
    /// Sample rate, Hz (1000: the rate of the IMUs in DAVIS/Prophesee cameras).
    pub rate_hz: f64,
    /// Gyroscope white-noise standard deviation per sample, rad/s (0.005: MEMS gyro at 1 kHz).
    pub gyro_noise_std: f64,
    /// Constant gyroscope bias, rad/s, IMU frame (0.002 rad/s per axis, signs varied).
    pub gyro_bias: [f64; 3],
    /// Accelerometer white-noise standard deviation per sample, m/s² (0.05: MEMS at 1 kHz).
    pub accel_noise_std: f64,
    /// Constant accelerometer bias, m/s², IMU frame.
    pub accel_bias: [f64; 3],
    /// Gravity magnitude, m/s² (world z is up).
    pub gravity: f64,
}

impl Default for ImuConfig {
    fn default() -> Self {
        Self {
            rate_hz: 1000.0,
            gyro_noise_std: 0.005,
            gyro_bias: [0.002, -0.002, 0.002],
            accel_noise_std: 0.05,
            accel_bias: [0.02, -0.01, 0.015],
            gravity: 9.81,
        }
    }
}

impl ImuConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(self.rate_hz.is_finite() && self.rate_hz > 0.0 && self.rate_hz <= 100_000.0) {
            return Err(SimError::Config(format!(
                "imu.rate_hz = {} must be in (0, 1e5]",
                self.rate_hz
            )));
        }
        let finite = [self.gyro_noise_std, self.accel_noise_std, self.gravity]
            .iter()
            .chain(&self.gyro_bias)
            .chain(&self.accel_bias)
            .all(|v| v.is_finite());
        if !finite || self.gyro_noise_std < 0.0 || self.accel_noise_std < 0.0 {
            return Err(SimError::Config(
                "imu: noise levels must be finite and >= 0, biases finite".into(),
            ));
        }
        Ok(())
    }
}

/// Noise-free IMU reading of a camera state: (angular rate, specific force), IMU frame.
pub fn ideal_reading(cam: &RigidState, gravity: f64) -> ([f64; 3], [f64; 3]) {
    let gyro_cam = cam.omega_body;
    // Specific force = acceleration - gravity vector, world (z up), then into the camera frame.
    let f_world = math::add(cam.acceleration, [0.0, 0.0, gravity]);
    let accel_cam = math::mul_mtv(&cam.rotation, f_world);
    (
        math::mul_mtv(&IMU_TO_CAMERA, gyro_cam),
        math::mul_mtv(&IMU_TO_CAMERA, accel_cam),
    )
}

/// Produces IMU samples on a fixed time grid `k / rate_hz`.
#[derive(Debug, Clone)]
pub struct ImuSampler {
    cfg: ImuConfig,
    rng: Rng,
    next_index: u64,
}

impl ImuSampler {
    /// A sampler with its own noise stream.
    pub fn new(cfg: ImuConfig, seed: u64) -> Self {
        Self {
            cfg,
            rng: Rng::new(seed, 0x1a0),
            next_index: 0,
        }
    }

    /// Samples with `t < t_end` not produced yet, using `state(t)` for the camera state.
    pub fn until(&mut self, t_end: f64, state: impl Fn(f64) -> RigidState, out: &mut Vec<ImuSample>) {
        loop {
            let t = self.next_index as f64 / self.cfg.rate_hz;
            if t >= t_end {
                break;
            }
            let (g, a) = ideal_reading(&state(t), self.cfg.gravity);
            let mut gyro = [0.0; 3];
            let mut accel = [0.0; 3];
            for k in 0..3 {
                gyro[k] = g[k] + self.cfg.gyro_bias[k] + self.cfg.gyro_noise_std * self.rng.normal();
                accel[k] = a[k] + self.cfg.accel_bias[k] + self.cfg.accel_noise_std * self.rng.normal();
            }
            out.push(ImuSample { t, gyro, accel });
            self.next_index += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::{RigidTrajectory, Signal};

    #[test]
    fn resting_imu_reads_gravity_and_axis_mapping_matches_evimo2() {
        // Camera looking along world +y, x right, y down (world -z).
        let base = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];
        let tr = RigidTrajectory::fixed([0.0, 0.0, 1.0], base);
        let (g, a) = ideal_reading(&tr.state(0.0), 9.81);
        assert!(g.iter().all(|v| v.abs() < 1e-12));
        // Specific force points up = camera -y; in IMU frame: v_imu = R^T v_cam.
        let a_cam = math::mul_mv(&IMU_TO_CAMERA, a);
        assert!(
            (a_cam[1] + 9.81).abs() < 1e-9 && a_cam[0].abs() < 1e-9,
            "{a_cam:?}"
        );
        // A yaw rate about camera x shows up as imu y (w_cam.x = w_imu.y).
        let mut spin = tr.clone();
        spin.axes = [0, 1, 2];
        spin.angles[0] = Signal::linear(0.0, 0.7);
        let (g, _) = ideal_reading(&spin.state(0.3), 9.81);
        assert!((g[1] - 0.7).abs() < 1e-12 && g[0].abs() < 1e-12, "{g:?}");
    }
}
