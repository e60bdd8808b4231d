//! Object image-plane motion: ground truth from the object's poses relative to the camera, and
//! its comparison with a predicted track.
//!
//! **Truth.** From the object poses (object -> camera) interpolated at the window's ends, the
//! relative motion `dT = T_co(t1) T_co(t0)^-1` gives the twist `(v, w)` (m/s, rad/s, camera frame)
//! by the SE(3) logarithm divided by `t1 - t0`; every point `P` of the object then moves as
//! `dP/dt = v + w x P`. The evaluation point is the object's origin `P` at the window's midpoint,
//! projected to `x = (P.x / P.z, P.y / P.z)` (normalized coordinates) at depth `Z = P.z`.
//! An object moving with `(v, w)` is equivalent to the camera moving with `(-v, -w)`, so in the
//! motion-field model of METHOD_NOTES section 1 (`u = (1/Z) A(x) t + B(x) w`):
//! - true **translational image motion** = `(1/Z) A(x) (-v)` = `((v_x - x v_z)/Z, (v_y - y v_z)/Z)`,
//!   normalized image units per second (the paper's ΔX, ΔY: translation only, depth motion
//!   excluded);
//! - true **image velocity** of the point = `(dx/dt, dy/dt)` with `dP/dt = v + w x P`, converted
//!   to pixels per second with the pinhole focal lengths (lens distortion's Jacobian ignored).
//!
//! **Prediction.** A track's `translation` (depth 1, normalized units per second, the camera
//! translation relative to the segment in the same model) gives the predicted translational
//! image motion `A(x) t` at the same point `x`; its `velocity` (pixels per second, the filtered
//! image velocity of its centroid) is compared with the true image velocity. Without a matched
//! track the predictions and errors are NaN (null in JSON), never invented.

use evseg_schemas::Track;
use serde::Serialize;

use crate::egomotion::{InterpolationGap, PoseSample, interpolate_pose};
use crate::outcome::Skip;
use evseg_geometry::rigid::{self, Vec3};

/// Relative twist of an object over a window, camera frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ObjectTwist {
    /// Linear part of the twist, m/s (velocity of the point at the camera origin moving with
    /// the object).
    pub v_mps: Vec3,
    /// Angular velocity, rad/s.
    pub w_radps: Vec3,
    /// Object origin at the window's midpoint, metres, camera frame.
    pub position_m: Vec3,
}

/// The object's relative twist over `[t0, t1]` from its time-sorted poses (object -> camera,
/// unit quaternions), interpolated at both ends (bracketing samples at most `max_gap_s` apart).
pub fn object_twist(
    poses: &[PoseSample],
    t0: f64,
    t1: f64,
    max_gap_s: f64,
) -> Result<ObjectTwist, InterpolationGap> {
    let (p0, q0) = interpolate_pose(poses, t0, max_gap_s)?;
    let (p1, q1) = interpolate_pose(poses, t1, max_gap_s)?;
    let (pm, _) = interpolate_pose(poses, 0.5 * (t0 + t1), max_gap_s)?;
    let (r0, r1) = (rigid::quat_to_mat(q0), rigid::quat_to_mat(q1));
    let r = rigid::mul_mm(&r1, &rigid::transpose(&r0));
    let t = rigid::sub(p1, rigid::mul_mv(&r, p0));
    let (rho, phi) = rigid::se3_log(&r, t);
    let dt = t1 - t0;
    Ok(ObjectTwist {
        v_mps: rigid::scale(rho, 1.0 / dt),
        w_radps: rigid::scale(phi, 1.0 / dt),
        position_m: pm,
    })
}

/// Motion figures of one ground-truth object in one slice (see the module docs for units).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectMotionScore {
    /// Ground-truth object id.
    pub object: u32,
    /// Matched predicted label / track id, if any.
    pub label: Option<u32>,
    /// Evaluation point: the object's origin projected, normalized coordinates.
    pub point_normalized: [f64; 2],
    /// Depth of the object's origin, metres.
    pub depth_m: f64,
    /// True translational image motion `(1/Z) A(x) (-v)`, normalized units per second.
    pub true_translational_flow: [f64; 2],
    /// Predicted translational image motion `A(x) t_track`, normalized units per second (NaN
    /// without a matched track).
    pub predicted_translational_flow: [f64; 2],
    /// Predicted minus true translational image motion, normalized units per second (NaN
    /// without a prediction).
    pub translational_flow_error: [f64; 2],
    /// True image velocity of the evaluation point, pixels per second.
    pub true_image_velocity_px: [f64; 2],
    /// The matched track's image velocity, pixels per second (NaN without one).
    pub predicted_image_velocity_px: [f64; 2],
    /// Predicted minus true image velocity, pixels per second (NaN without a prediction).
    pub image_velocity_error_px: [f64; 2],
}

impl ObjectMotionScore {
    /// True when a prediction was available (a matched track with finite values).
    pub fn has_prediction(&self) -> bool {
        self.translational_flow_error.iter().all(|e| e.is_finite())
    }
}

/// Scores one object: `twist` from its poses, `track` the matched track (if any), `fx`, `fy` the
/// focal lengths in pixels (for pixel velocities).
pub fn score_object_motion(
    object: u32,
    label: Option<u32>,
    track: Option<&Track>,
    twist: &ObjectTwist,
    fx: f64,
    fy: f64,
) -> Result<ObjectMotionScore, Skip> {
    let p = twist.position_m;
    let z = p[2];
    if z.is_nan() || z <= 0.0 {
        return Err(Skip::ObjectBehindCamera { id: object });
    }
    let (x, y) = (p[0] / z, p[1] / z);
    let v = twist.v_mps;
    let true_tr = [(v[0] - x * v[2]) / z, (v[1] - y * v[2]) / z];
    let pdot = rigid::add(v, rigid::cross(twist.w_radps, p));
    let true_img = [fx * (pdot[0] - x * pdot[2]) / z, fy * (pdot[1] - y * pdot[2]) / z];
    let nan = [f64::NAN; 2];
    let (pred_tr, pred_img) = match track {
        Some(tr) => {
            let t = tr.translation;
            ([-t[0] + x * t[2], -t[1] + y * t[2]], tr.velocity)
        }
        None => (nan, nan),
    };
    let diff = |a: [f64; 2], b: [f64; 2]| [a[0] - b[0], a[1] - b[1]];
    Ok(ObjectMotionScore {
        object,
        label,
        point_normalized: [x, y],
        depth_m: z,
        true_translational_flow: true_tr,
        predicted_translational_flow: pred_tr,
        translational_flow_error: diff(pred_tr, true_tr),
        true_image_velocity_px: true_img,
        predicted_image_velocity_px: pred_img,
        image_velocity_error_px: diff(pred_img, true_img),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_geometry::rigid::{quat_from_axis_angle, quat_to_mat};

    fn track(translation: Vec3, velocity: [f64; 2]) -> Track {
        Track {
            id: 3,
            centroid: [0.0; 2],
            velocity,
            bbox: [0.0; 4],
            translation,
            age: 1,
            events: 10,
        }
    }

    fn poses(f: impl Fn(f64) -> PoseSample) -> Vec<PoseSample> {
        (0..20).map(|k| f(k as f64 * 0.005)).collect()
    }

    #[test]
    fn pure_translation_known_image_motion_and_perfect_track() {
        // Object at 2 m straight ahead moving right at 0.2 m/s: flow (0.1, 0) normalized/s.
        let ps = poses(|t| PoseSample {
            t,
            position: [0.2 * t, 0.0, 2.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
        });
        let tw = object_twist(&ps, 0.02, 0.05, 0.01).unwrap();
        assert!(rigid::norm(rigid::sub(tw.v_mps, [0.2, 0.0, 0.0])) < 1e-12);
        // The camera-equivalent translation with depth 1 is -v / Z.
        let good = track([-0.1, 0.0, 0.0], [20.0, 0.0]);
        let s = score_object_motion(1, Some(3), Some(&good), &tw, 200.0, 200.0).unwrap();
        assert!((s.true_translational_flow[0] - 0.1).abs() < 1e-12);
        assert!(s.true_translational_flow[1].abs() < 1e-12);
        assert!((s.true_image_velocity_px[0] - 20.0).abs() < 1e-9);
        assert!(s.translational_flow_error.iter().all(|e| e.abs() < 1e-12));
        assert!(s.image_velocity_error_px.iter().all(|e| e.abs() < 1e-9));
        assert!(s.has_prediction());
        // No track: NaN, never a value.
        let none = score_object_motion(1, None, None, &tw, 200.0, 200.0).unwrap();
        assert!(none.translational_flow_error.iter().all(|e| e.is_nan()));
        assert!(!none.has_prediction());
    }

    #[test]
    fn rotating_object_image_velocity_matches_finite_difference_of_projection() {
        // Origin on a screw path: rotating about the camera y axis through (0, 0, 3).
        let w = 0.8;
        let ps = poses(|t| {
            let q = quat_from_axis_angle([0.0, 1.0, 0.0], w * t);
            let r = quat_to_mat(q);
            let c = [0.0, 0.0, 3.0];
            let arm = rigid::mul_mv(&r, [0.5, 0.1, 0.0]);
            PoseSample {
                t,
                position: rigid::add(rigid::add(c, arm), [0.0, 0.05 * t, 0.0]),
                orientation: q,
            }
        });
        let (t0, t1) = (0.03, 0.035);
        let tw = object_twist(&ps, t0, t1, 0.01).unwrap();
        assert!(rigid::norm(rigid::sub(tw.w_radps, [0.0, w, 0.0])) < 1e-9);
        let s = score_object_motion(2, None, None, &tw, 100.0, 100.0).unwrap();
        let proj = |t: f64| {
            let (p, _) = interpolate_pose(&ps, t, 0.01).unwrap();
            [100.0 * p[0] / p[2], 100.0 * p[1] / p[2]]
        };
        // Central difference around the midpoint of the window (positions are interpolated
        // linearly between 5 ms samples, so stay inside one sample interval).
        let (a, b) = (proj(0.0325 - 1e-4), proj(0.0325 + 1e-4));
        let fd = [(b[0] - a[0]) / 2e-4, (b[1] - a[1]) / 2e-4];
        for k in 0..2 {
            assert!(
                (s.true_image_velocity_px[k] - fd[k]).abs() < 0.05,
                "{:?} vs {fd:?}",
                s.true_image_velocity_px
            );
        }
    }

    #[test]
    fn object_behind_the_camera_is_skipped() {
        let tw = ObjectTwist {
            v_mps: [0.0; 3],
            w_radps: [0.0; 3],
            position_m: [0.0, 0.0, -1.0],
        };
        assert_eq!(
            score_object_motion(5, None, None, &tw, 1.0, 1.0),
            Err(Skip::ObjectBehindCamera { id: 5 })
        );
    }
}
