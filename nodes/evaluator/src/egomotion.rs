//! Ground-truth camera velocity over a window and the egomotion figures.
//!
//! The true linear velocity is in the camera frame, m/s: the mean of the samples'
//! `linear_velocity` inside the window when the source gives velocities (the simulator), else
//! from the poses (EVIMO2): `v = R_wc(t0)^T (p(t1) - p(t0)) / (t1 - t0)`, position interpolated
//! linearly and rotation by slerp between the bracketing samples (METHOD_NOTES section 5).
//!
//! Only the direction of translation is observable from normal flow, so the predicted unit
//! direction is **multiplied by the true speed** before the per-axis error is taken (the public
//! EVIMO2 evaluation's convention, and the paper's m/s figures). The angle between the predicted
//! direction and the true velocity is reported beside it.

use evseg_schemas::{CameraMotion, Egomotion};
use serde::Serialize;

use crate::error::EvalError;
use crate::outcome::{Outcome, Skip};
use evseg_geometry::rigid::{self, Quat, Vec3};

/// A rigid pose at one instant: `position` in metres and `orientation` a unit quaternion
/// `[x, y, z, w]`, both in the convention of the message it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseSample {
    /// Time, seconds.
    pub t: f64,
    /// Position, metres.
    pub position: Vec3,
    /// Unit quaternion `[x, y, z, w]`.
    pub orientation: Quat,
}

/// Why a pose could not be interpolated.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum InterpolationGap {
    /// No sample at or before, or none at or after, the requested time.
    Missing,
    /// The bracketing samples are `gap_s` seconds apart, more than allowed.
    TooFar {
        /// Requested time, s.
        t: f64,
        /// Gap between the bracketing samples, s.
        gap_s: f64,
    },
}

/// The pose at `t` (seconds) from time-sorted `samples`: linear interpolation of the position and
/// slerp of the orientation between the bracketing samples, which may be at most `max_gap_s`
/// apart. No extrapolation.
pub fn interpolate_pose(
    samples: &[PoseSample],
    t: f64,
    max_gap_s: f64,
) -> Result<(Vec3, Quat), InterpolationGap> {
    let i = samples.partition_point(|s| s.t <= t);
    if i == 0 {
        return Err(InterpolationGap::Missing);
    }
    let a = &samples[i - 1];
    if a.t == t {
        return Ok((a.position, a.orientation));
    }
    let b = samples.get(i).ok_or(InterpolationGap::Missing)?;
    let gap_s = b.t - a.t;
    if gap_s > max_gap_s {
        return Err(InterpolationGap::TooFar { t, gap_s });
    }
    let s = (t - a.t) / gap_s;
    Ok((
        rigid::lerp(a.position, b.position, s),
        rigid::slerp(a.orientation, b.orientation, s),
    ))
}

/// Where a true velocity came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum VelocitySource {
    /// Mean of the source's velocity samples inside the window.
    VelocitySamples,
    /// Velocity samples bracketing the window's midpoint, linearly interpolated.
    InterpolatedVelocity,
    /// Finite difference of interpolated poses at the window's ends.
    Poses,
}

/// True camera linear velocity over a window.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrueVelocity {
    /// Velocity, m/s, camera frame (at the window start for the pose form).
    pub velocity_mps: Vec3,
    /// How it was obtained.
    pub source: VelocitySource,
}

fn gap_skip(g: InterpolationGap) -> Skip {
    match g {
        InterpolationGap::Missing => Skip::NoCameraTruth,
        InterpolationGap::TooFar { t, gap_s } => Skip::TruthGap { t, gap_s },
    }
}

/// The true camera velocity over `[t0, t1)` seconds from time-sorted camera samples whose
/// quaternions are unit (see the module docs for the rules). `max_gap_s` bounds the distance
/// between samples that may be interpolated.
pub fn true_camera_velocity(
    samples: &[CameraMotion],
    t0: f64,
    t1: f64,
    max_gap_s: f64,
) -> Result<TrueVelocity, Skip> {
    let inside: Vec<Vec3> = samples
        .iter()
        .filter(|s| s.t >= t0 && s.t < t1)
        .filter_map(|s| s.linear_velocity)
        .collect();
    if !inside.is_empty() {
        let sum = inside.iter().fold([0.0; 3], |a, &v| rigid::add(a, v));
        return Ok(TrueVelocity {
            velocity_mps: rigid::scale(sum, 1.0 / inside.len() as f64),
            source: VelocitySource::VelocitySamples,
        });
    }
    let mid = 0.5 * (t0 + t1);
    let with_v: Vec<(f64, Vec3)> = samples
        .iter()
        .filter_map(|s| s.linear_velocity.map(|v| (s.t, v)))
        .collect();
    let i = with_v.partition_point(|(t, _)| *t <= mid);
    if i > 0 && i < with_v.len() {
        let ((ta, va), (tb, vb)) = (with_v[i - 1], with_v[i]);
        if tb - ta <= max_gap_s {
            return Ok(TrueVelocity {
                velocity_mps: rigid::lerp(va, vb, (mid - ta) / (tb - ta)),
                source: VelocitySource::InterpolatedVelocity,
            });
        }
    }
    let poses: Vec<PoseSample> = samples
        .iter()
        .map(|s| PoseSample {
            t: s.t,
            position: s.position,
            orientation: s.orientation,
        })
        .collect();
    let (p0, q0) = interpolate_pose(&poses, t0, max_gap_s).map_err(gap_skip)?;
    let (p1, _) = interpolate_pose(&poses, t1, max_gap_s).map_err(gap_skip)?;
    let r_wc0 = rigid::quat_to_mat(q0);
    let v = rigid::scale(rigid::mul_mtv(&r_wc0, rigid::sub(p1, p0)), 1.0 / (t1 - t0));
    Ok(TrueVelocity {
        velocity_mps: v,
        source: VelocitySource::Poses,
    })
}

/// Egomotion figures of one slice.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EgomotionScore {
    /// True camera velocity, m/s, camera frame.
    pub true_velocity_mps: Vec3,
    /// True speed, m/s.
    pub true_speed_mps: f64,
    /// Where the true velocity came from.
    pub truth_source: VelocitySource,
    /// Predicted unit direction of translation, camera frame.
    pub predicted_direction: Vec3,
    /// Angle between predicted direction and true velocity, degrees (skipped when the camera
    /// is slower than the threshold: the direction is then undefined).
    pub direction_error_deg: Outcome<f64>,
    /// Predicted direction times the true speed, m/s, camera frame.
    pub scaled_velocity_mps: Vec3,
    /// `scaled_velocity_mps - true_velocity_mps`, m/s per axis.
    pub scaled_error_mps: Vec3,
}

/// Scores a predicted egomotion against the true velocity of its window. `valid: false` is
/// skipped (never replaced by a value); a valid prediction with a zero or non-finite direction
/// is an error. `min_speed_mps` is the speed below which the direction error is skipped.
pub fn score_egomotion(
    seq: u64,
    predicted: &Egomotion,
    truth: Result<TrueVelocity, Skip>,
    min_speed_mps: f64,
) -> Result<Outcome<EgomotionScore>, EvalError> {
    if !predicted.valid {
        return Ok(Outcome::Skipped(Skip::NoPrediction));
    }
    let d = predicted.direction;
    let n = rigid::norm(d);
    if !(n.is_finite() && n > 0.0) {
        return Err(EvalError::BadDirection { seq, direction: d });
    }
    let truth = match truth {
        Ok(t) => t,
        Err(skip) => return Ok(Outcome::Skipped(skip)),
    };
    let unit = rigid::scale(d, 1.0 / n);
    let v = truth.velocity_mps;
    let speed = rigid::norm(v);
    let scaled = rigid::scale(unit, speed);
    let direction_error_deg = if speed >= min_speed_mps && speed > 0.0 {
        Outcome::Scored(rigid::angle_between(unit, v).to_degrees())
    } else {
        Outcome::Skipped(Skip::SlowCamera { speed_mps: speed })
    };
    Ok(Outcome::Scored(EgomotionScore {
        true_velocity_mps: v,
        true_speed_mps: speed,
        truth_source: truth.source,
        predicted_direction: unit,
        direction_error_deg,
        scaled_velocity_mps: scaled,
        scaled_error_mps: rigid::sub(scaled, v),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_geometry::rigid::{mul_mv, quat_from_axis_angle, quat_to_mat};

    fn ego(direction: Vec3) -> Egomotion {
        Egomotion {
            direction,
            omega: [0.0; 3],
            valid: true,
        }
    }

    fn truth(v: Vec3) -> Result<TrueVelocity, Skip> {
        Ok(TrueVelocity {
            velocity_mps: v,
            source: VelocitySource::VelocitySamples,
        })
    }

    #[test]
    fn direction_rotated_by_ten_degrees_gives_ten_degrees_and_known_error() {
        let speed = 0.5;
        let a = 10f64.to_radians();
        // True velocity along x at 0.5 m/s; prediction rotated 10 degrees about z (unnormalized).
        let s = score_egomotion(
            0,
            &ego([3.0 * a.cos(), 3.0 * a.sin(), 0.0]),
            truth([speed, 0.0, 0.0]),
            0.01,
        )
        .unwrap();
        let s = s.scored().unwrap();
        assert!((s.direction_error_deg.scored().unwrap() - 10.0).abs() < 1e-9);
        let e = s.scaled_error_mps;
        assert!((e[0] - speed * (a.cos() - 1.0)).abs() < 1e-12);
        assert!((e[1] - speed * a.sin()).abs() < 1e-12);
        assert_eq!(e[2], 0.0);
        // |error| = 2 v sin(a/2), the chord.
        assert!((rigid::norm(e) - 2.0 * speed * (a / 2.0).sin()).abs() < 1e-12);
    }

    #[test]
    fn invalid_prediction_is_skipped_and_bad_direction_is_an_error() {
        let mut e = ego([0.0; 3]);
        e.valid = false;
        assert_eq!(
            score_egomotion(0, &e, truth([1.0, 0.0, 0.0]), 0.01).unwrap(),
            Outcome::Skipped(Skip::NoPrediction)
        );
        assert!(matches!(
            score_egomotion(4, &ego([0.0; 3]), truth([1.0, 0.0, 0.0]), 0.01),
            Err(EvalError::BadDirection { seq: 4, .. })
        ));
        assert!(score_egomotion(4, &ego([f64::NAN, 0.0, 1.0]), truth([1.0, 0.0, 0.0]), 0.01).is_err());
    }

    #[test]
    fn slow_camera_skips_only_the_direction() {
        let s = score_egomotion(0, &ego([0.0, 0.0, 1.0]), truth([0.001, 0.0, 0.0]), 0.01).unwrap();
        let s = s.scored().unwrap();
        assert!(matches!(
            s.direction_error_deg,
            Outcome::Skipped(Skip::SlowCamera { .. })
        ));
        assert!((s.scaled_error_mps[0] + 0.001).abs() < 1e-15);
        assert!((s.scaled_error_mps[2] - 0.001).abs() < 1e-15);
    }

    fn pose(t: f64, position: Vec3, q: Quat) -> CameraMotion {
        CameraMotion {
            t,
            position,
            orientation: q,
            linear_velocity: None,
            angular_velocity: None,
        }
    }

    #[test]
    fn velocity_from_poses_on_a_rotating_constant_velocity_trajectory() {
        // World velocity (1, 2, 0.5) m/s; camera yawing about world z at 0.5 rad/s, 100 Hz poses.
        let vw = [1.0, 2.0, 0.5];
        let rate = 0.5;
        let samples: Vec<CameraMotion> = (0..50)
            .map(|k| {
                let t = k as f64 * 0.01;
                let q = quat_from_axis_angle([0.0, 0.0, 1.0], 0.3 + rate * t);
                pose(t, rigid::scale(vw, t), q)
            })
            .collect();
        // Window not aligned with samples: both ends interpolated.
        let (t0, t1) = (0.123, 0.153);
        let v = true_camera_velocity(&samples, t0, t1, 0.05).unwrap();
        assert_eq!(v.source, VelocitySource::Poses);
        // Expected: R_wc(t0)^T vw, with the slerped rotation exact for a constant-rate yaw.
        let r0 = quat_to_mat(quat_from_axis_angle([0.0, 0.0, 1.0], 0.3 + rate * t0));
        let want = rigid::mul_mtv(&r0, vw);
        assert!(
            rigid::norm(rigid::sub(v.velocity_mps, want)) < 1e-9,
            "{v:?} vs {want:?}"
        );
        // And back in the world frame it is the world velocity.
        let back = mul_mv(&r0, v.velocity_mps);
        assert!(rigid::norm(rigid::sub(back, vw)) < 1e-9);
    }

    #[test]
    fn velocity_samples_are_preferred_and_gaps_are_reported() {
        let q = [0.0, 0.0, 0.0, 1.0];
        let mut a = pose(0.0, [0.0; 3], q);
        let mut b = pose(0.01, [0.0; 3], q);
        a.linear_velocity = Some([1.0, 0.0, 0.0]);
        b.linear_velocity = Some([3.0, 0.0, 0.0]);
        let v = true_camera_velocity(&[a, b], 0.0, 0.02, 0.1).unwrap();
        assert_eq!(v.source, VelocitySource::VelocitySamples);
        assert_eq!(v.velocity_mps, [2.0, 0.0, 0.0]);
        // Window between the samples: interpolated at the midpoint 0.005 s.
        let v = true_camera_velocity(&[a, b], 0.004, 0.006, 0.1).unwrap();
        assert_eq!(v.source, VelocitySource::InterpolatedVelocity);
        assert!((v.velocity_mps[0] - 2.0).abs() < 1e-12);
        // Poses only, too far apart.
        let c = pose(0.0, [0.0; 3], q);
        let d = pose(1.0, [1.0, 0.0, 0.0], q);
        assert!(matches!(
            true_camera_velocity(&[c, d], 0.1, 0.2, 0.1),
            Err(Skip::TruthGap { .. })
        ));
        assert_eq!(
            true_camera_velocity(&[c], 0.1, 0.2, 0.1),
            Err(Skip::NoCameraTruth)
        );
        assert!((true_camera_velocity(&[c, d], 0.1, 0.2, 2.0).unwrap().velocity_mps[0] - 1.0).abs() < 1e-12);
    }
}
