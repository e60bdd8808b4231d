//! Does the IMU's rotation rate, mapped into the camera frame, agree with the camera trajectory's?
//!
//! EVIMO2's IMU axes differ from the camera's and its clock is offset (METHOD_NOTES section 4:
//! `w_cam = (w_imu.y, -w_imu.x, w_imu.z)`, -0.02 s). A folder written by another tool may follow
//! another convention (IMU already in the camera frame, no offset), and the method, which
//! derotates every normal flow with the IMU, then fails without any error. Where the folder has
//! a camera trajectory, this module measures the agreement of the configured mapping with the
//! rotation rate the trajectory implies, and finds the best of the 24 axis permutations with
//! signs that are rotations, over a range of time offsets. Only the calibration (a discrete axis
//! convention and one offset) is taken from the trajectory; no per-frame ground truth reaches
//! the method.

use evseg_schemas::{CameraInfo, CameraMotion, ImuSample};
use nalgebra::{Quaternion, UnitQuaternion};

/// Shortest interval over which the trajectory is differentiated, seconds: at the Vicon's
/// 200 Hz, 4 samples, so that the pose noise (sub-millimetre, about 0.1 deg) is not amplified
/// into rates of several degrees per second.
pub const MIN_RATE_INTERVAL_S: f64 = 0.02;

/// Longest interval over which the trajectory is differentiated, seconds (a gap in the
/// trajectory, e.g. a Vicon dropout, is not bridged).
pub const MAX_RATE_INTERVAL_S: f64 = 0.1;

/// The camera's mean rotation rate over an interval of its trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrajectoryRate {
    /// Start of the interval, seconds (sequence clock).
    pub t0: f64,
    /// End of the interval, seconds.
    pub t1: f64,
    /// Mean rotation rate, rad/s, camera frame (at the interval's start).
    pub rate: [f64; 3],
}

/// How well an IMU mapping agrees with the trajectory.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuAgreement {
    /// IMU-to-camera rotation, row-major: `w_cam = M w_imu`.
    pub imu_to_camera: [f64; 9],
    /// Added to IMU times to get camera times, seconds.
    pub time_offset_s: f64,
    /// Root-mean-square difference between the trajectory's and the mapped IMU's rates, rad/s.
    pub rms_error_rad_s: f64,
    /// Root-mean-square of the trajectory's rates, rad/s (the scale of `rms_error_rad_s`).
    pub rms_rate_rad_s: f64,
    /// Intervals compared.
    pub intervals: usize,
}

impl ImuAgreement {
    /// `rms_error_rad_s / rms_rate_rad_s`: 0 for perfect agreement, about 1.4 for unrelated rates
    /// of equal size, 2 for opposite ones.
    pub fn relative_error(&self) -> f64 {
        self.rms_error_rad_s / self.rms_rate_rad_s.max(f64::MIN_POSITIVE)
    }
}

/// The camera's rotation rate over successive intervals of at least [`MIN_RATE_INTERVAL_S`] of
/// its (time-sorted, camera -> world) trajectory; intervals longer than [`MAX_RATE_INTERVAL_S`]
/// and poses with a non-finite or zero quaternion are skipped.
pub fn trajectory_rates(poses: &[CameraMotion]) -> Vec<TrajectoryRate> {
    let rotation = |p: &CameraMotion| {
        let [x, y, z, w] = p.orientation;
        let q = Quaternion::new(w, x, y, z);
        (q.norm().is_finite() && q.norm() > 0.0).then(|| UnitQuaternion::from_quaternion(q))
    };
    let mut out = Vec::new();
    let mut i = 0;
    while i < poses.len() {
        let Some(ra) = rotation(&poses[i]) else {
            i += 1;
            continue;
        };
        let t0 = poses[i].t;
        let Some(j) = (i + 1..poses.len()).find(|&j| poses[j].t - t0 >= MIN_RATE_INTERVAL_S) else {
            break;
        };
        let t1 = poses[j].t;
        if let Some(rb) = rotation(&poses[j])
            && t1 - t0 <= MAX_RATE_INTERVAL_S
        {
            // R_a^T R_b: the rotation from a to b in the camera frame at a.
            let v = (ra.inverse() * rb).scaled_axis() / (t1 - t0);
            out.push(TrajectoryRate {
                t0,
                t1,
                rate: [v.x, v.y, v.z],
            });
        }
        i = j;
    }
    out
}

/// The agreement of the IMU samples `imu` (time-sorted, IMU frame and clock), mapped with
/// `imu_to_camera` and shifted by `time_offset_s`, with the trajectory `rates`: each interval's
/// rate against the mean of the IMU samples inside it (samples with a non-finite reading left
/// out). `None` when no interval holds a usable sample.
pub fn agreement(
    rates: &[TrajectoryRate],
    imu: &[ImuSample],
    imu_to_camera: &[f64; 9],
    time_offset_s: f64,
) -> Option<ImuAgreement> {
    let (mut err2, mut rate2, mut n) = (0.0, 0.0, 0usize);
    for r in rates {
        let start = imu.partition_point(|s| s.t + time_offset_s < r.t0);
        let end = imu.partition_point(|s| s.t + time_offset_s < r.t1);
        if end <= start {
            continue;
        }
        // Non-finite gyro readings (a corrupt sample) are left out of the mean rather than
        // making the whole interval unusable.
        let (mut mean, mut count) = ([0.0; 3], 0.0);
        for s in imu[start..end]
            .iter()
            .filter(|s| s.gyro.iter().all(|v| v.is_finite()))
        {
            let w = CameraInfo::rotate(imu_to_camera, s.gyro);
            for (slot, wk) in mean.iter_mut().zip(w) {
                *slot += wk;
            }
            count += 1.0;
        }
        if count == 0.0 {
            continue;
        }
        let d: f64 = (0..3).map(|k| (r.rate[k] - mean[k] / count).powi(2)).sum();
        if !d.is_finite() {
            continue;
        }
        err2 += d;
        rate2 += r.rate.iter().map(|v| v * v).sum::<f64>();
        n += 1;
    }
    (n > 0).then(|| ImuAgreement {
        imu_to_camera: *imu_to_camera,
        time_offset_s,
        rms_error_rad_s: (err2 / n as f64).sqrt(),
        rms_rate_rad_s: (rate2 / n as f64).sqrt(),
        intervals: n,
    })
}

/// The 24 signed axis permutations that are rotations (determinant +1), row-major.
pub fn axis_rotations() -> Vec<[f64; 9]> {
    const PERMUTATIONS: [[usize; 3]; 6] = [[0, 1, 2], [0, 2, 1], [1, 0, 2], [1, 2, 0], [2, 0, 1], [2, 1, 0]];
    let mut out = Vec::with_capacity(24);
    for p in PERMUTATIONS {
        for signs in 0..8u8 {
            let mut m = [0.0; 9];
            for (row, &col) in p.iter().enumerate() {
                m[3 * row + col] = if signs & (1 << row) != 0 { -1.0 } else { 1.0 };
            }
            let det = m[0] * (m[4] * m[8] - m[5] * m[7]) - m[1] * (m[3] * m[8] - m[5] * m[6])
                + m[2] * (m[3] * m[7] - m[4] * m[6]);
            if det > 0.0 {
                out.push(m);
            }
        }
    }
    out
}

/// The mapping among [`axis_rotations`] and `offsets_s` (seconds) that agrees best with the
/// trajectory `rates` (smallest `rms_error_rad_s`); `None` when none can be compared.
pub fn best_agreement(
    rates: &[TrajectoryRate],
    imu: &[ImuSample],
    offsets_s: &[f64],
) -> Option<ImuAgreement> {
    let mut best: Option<ImuAgreement> = None;
    for m in axis_rotations() {
        for &offset in offsets_s {
            if let Some(a) = agreement(rates, imu, &m, offset)
                && best.is_none_or(|b| a.rms_error_rad_s < b.rms_error_rad_s)
            {
                best = Some(a);
            }
        }
    }
    best
}

/// Offsets [`best_agreement`] tries by default: -0.1 to 0.1 s in 5 ms steps (EVIMO2's -0.02 s
/// and no offset included).
pub fn default_offsets_s() -> Vec<f64> {
    (-20..=20).map(|k| f64::from(k) * 0.005).collect()
}

/// What the check concludes about a configured mapping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ImuVerdict {
    /// Too little rotation, IMU or trajectory to tell (fewer than `min_intervals` intervals, or
    /// the camera's rms rate below `min_rate_rad_s`).
    Inconclusive,
    /// The configured mapping agrees with the trajectory (or no other does much better).
    Consistent(ImuAgreement),
    /// The configured mapping disagrees and `better` agrees: its rms error is at most `ratio`
    /// times the configured one's, and the configured one's relative error is above
    /// `max_relative_error`.
    Mismatch {
        /// The configured mapping's agreement.
        configured: ImuAgreement,
        /// The best mapping's agreement.
        better: ImuAgreement,
    },
}

/// Thresholds of [`check`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImuCheckParams {
    /// Fewest trajectory intervals (default 20: 0.4 s of trajectory at the shortest interval).
    pub min_intervals: usize,
    /// The camera's rms rotation rate below which nothing is concluded, rad/s (default 0.05,
    /// about 3 deg/s: below it the gyro's noise and bias are comparable to the rate).
    pub min_rate_rad_s: f64,
    /// A configured mapping whose rms error is at most this fraction of the camera's rms rate
    /// is consistent whatever else does (default 0.5: a wrong axis convention gives about 1 to
    /// 2, a right one with the gyro's noise and the trajectory's differentiation well under 0.3).
    pub max_relative_error: f64,
    /// Another mapping counts as better only when its rms error is at most this fraction of the
    /// configured one's (default 0.5).
    pub ratio: f64,
}

impl Default for ImuCheckParams {
    fn default() -> Self {
        Self {
            min_intervals: 20,
            min_rate_rad_s: 0.05,
            max_relative_error: 0.5,
            ratio: 0.5,
        }
    }
}

/// Checks the configured `imu_to_camera` / `time_offset_s` against the trajectory `poses`
/// (see the module docs).
pub fn check(
    poses: &[CameraMotion],
    imu: &[ImuSample],
    imu_to_camera: &[f64; 9],
    time_offset_s: f64,
    p: &ImuCheckParams,
) -> ImuVerdict {
    let rates = trajectory_rates(poses);
    let Some(configured) = agreement(&rates, imu, imu_to_camera, time_offset_s) else {
        return ImuVerdict::Inconclusive;
    };
    if configured.intervals < p.min_intervals || configured.rms_rate_rad_s < p.min_rate_rad_s {
        return ImuVerdict::Inconclusive;
    }
    if configured.relative_error() <= p.max_relative_error {
        return ImuVerdict::Consistent(configured);
    }
    match best_agreement(&rates, imu, &default_offsets_s()) {
        Some(better)
            if better.rms_error_rad_s <= p.ratio * configured.rms_error_rad_s
                && better.relative_error() <= p.max_relative_error =>
        {
            ImuVerdict::Mismatch { configured, better }
        }
        _ => ImuVerdict::Consistent(configured),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::EVIMO2_IMU_TO_CAMERA as EVIMO2;

    const IDENTITY: [f64; 9] = CameraInfo::IDENTITY;

    /// The camera's rate at time `t`, rad/s, camera frame: turning about every axis, varying.
    fn rate(t: f64) -> [f64; 3] {
        [
            0.8 * (2.1 * t).sin(),
            0.5 * (1.3 * t + 1.0).cos(),
            0.3 * (3.0 * t).sin(),
        ]
    }

    /// A 200 Hz trajectory integrating [`rate`] for `seconds`, and a 1 kHz gyro reading it in
    /// the IMU frame `m^T w_cam`, on a clock `offset` behind the camera's (camera = IMU + offset).
    fn sequence(m: &[f64; 9], offset: f64, seconds: f64) -> (Vec<CameraMotion>, Vec<ImuSample>) {
        let mut poses = Vec::new();
        let mut q = UnitQuaternion::identity();
        let dt = 1e-4;
        let mut t = 0.0;
        for k in 0..=(seconds / dt) as usize {
            if k % 50 == 0 {
                poses.push(CameraMotion {
                    t,
                    position: [0.0; 3],
                    orientation: [q.i, q.j, q.k, q.w],
                    linear_velocity: None,
                    angular_velocity: None,
                });
            }
            let w = rate(t + 0.5 * dt);
            q *= UnitQuaternion::from_scaled_axis(nalgebra::Vector3::new(w[0], w[1], w[2]) * dt);
            t += dt;
        }
        let imu = (0..(seconds * 1000.0) as usize)
            .map(|k| {
                let t_imu = k as f64 * 1e-3;
                let w = rate(t_imu + offset);
                // gyro = M^T w_cam
                let gyro = [0, 1, 2].map(|c| m[c] * w[0] + m[3 + c] * w[1] + m[6 + c] * w[2]);
                ImuSample {
                    t: t_imu,
                    gyro,
                    accel: [0.0; 3],
                }
            })
            .collect();
        (poses, imu)
    }

    #[test]
    fn the_right_mapping_agrees_and_a_wrong_one_is_found_out() {
        let (poses, imu) = sequence(&EVIMO2, -0.02, 4.0);
        let p = ImuCheckParams::default();
        match check(&poses, &imu, &EVIMO2, -0.02, &p) {
            ImuVerdict::Consistent(a) => assert!(a.relative_error() < 0.05, "{a:?}"),
            other => panic!("expected consistent, got {other:?}"),
        }
        // Read as if the IMU were in the camera frame on the camera's clock.
        match check(&poses, &imu, &IDENTITY, 0.0, &p) {
            ImuVerdict::Mismatch { configured, better } => {
                assert!(configured.relative_error() > 0.5, "{configured:?}");
                assert_eq!(better.imu_to_camera, EVIMO2);
                assert!((better.time_offset_s + 0.02).abs() < 1e-9, "{better:?}");
            }
            other => panic!("expected a mismatch, got {other:?}"),
        }
    }

    #[test]
    fn a_camera_in_the_imu_frame_is_found_too() {
        let (poses, imu) = sequence(&IDENTITY, 0.0, 4.0);
        match check(&poses, &imu, &EVIMO2, -0.02, &ImuCheckParams::default()) {
            ImuVerdict::Mismatch { better, .. } => {
                assert_eq!(better.imu_to_camera, IDENTITY);
                assert!(better.time_offset_s.abs() < 1e-9, "{better:?}");
            }
            other => panic!("expected a mismatch, got {other:?}"),
        }
    }

    #[test]
    fn too_little_trajectory_or_rotation_concludes_nothing() {
        let (poses, imu) = sequence(&IDENTITY, 0.0, 0.2);
        let p = ImuCheckParams::default();
        assert_eq!(check(&poses, &imu, &EVIMO2, 0.0, &p), ImuVerdict::Inconclusive);
        assert_eq!(check(&[], &imu, &EVIMO2, 0.0, &p), ImuVerdict::Inconclusive);
        let (poses, imu) = sequence(&IDENTITY, 0.0, 4.0);
        let still: Vec<ImuSample> = imu.iter().map(|s| ImuSample { gyro: [0.0; 3], ..*s }).collect();
        let still_poses: Vec<CameraMotion> = poses
            .iter()
            .map(|q| CameraMotion {
                orientation: [0.0, 0.0, 0.0, 1.0],
                ..*q
            })
            .collect();
        assert_eq!(
            check(&still_poses, &still, &EVIMO2, 0.0, &p),
            ImuVerdict::Inconclusive
        );
    }

    #[test]
    fn malformed_poses_and_samples_are_skipped_without_a_panic() {
        let (mut poses, mut imu) = sequence(&EVIMO2, -0.02, 4.0);
        // Zero and non-finite quaternions, non-finite gyro readings, a pose out of order.
        for (k, p) in poses.iter_mut().enumerate() {
            match k % 17 {
                3 => p.orientation = [0.0; 4],
                7 => p.orientation = [f64::NAN, 0.0, 0.0, 1.0],
                11 => p.t = -1.0,
                _ => {}
            }
        }
        for (k, s) in imu.iter_mut().enumerate() {
            if k % 13 == 5 {
                s.gyro = [f64::NAN, f64::INFINITY, 0.0];
            }
        }
        let rates = trajectory_rates(&poses);
        assert!(rates.iter().all(|r| r.rate.iter().all(|v| v.is_finite())));
        // Intervals holding a bad gyro reading are left out; the rest still agree.
        match check(&poses, &imu, &EVIMO2, -0.02, &ImuCheckParams::default()) {
            ImuVerdict::Consistent(a) => {
                assert!(a.rms_error_rad_s.is_finite() && a.relative_error() < 0.1, "{a:?}")
            }
            other => panic!("expected consistent, got {other:?}"),
        }
        // Every sample unusable: nothing to conclude.
        let bad: Vec<ImuSample> = imu
            .iter()
            .map(|s| ImuSample {
                gyro: [f64::NAN; 3],
                ..*s
            })
            .collect();
        assert_eq!(
            check(&poses, &bad, &EVIMO2, -0.02, &ImuCheckParams::default()),
            ImuVerdict::Inconclusive
        );
    }

    #[test]
    fn there_are_24_axis_rotations() {
        let all = axis_rotations();
        assert_eq!(all.len(), 24);
        assert!(all.contains(&EVIMO2) && all.contains(&IDENTITY));
    }
}
