//! Ground-truth samples: camera motion, object poses and object masks.

use evseg_schemas::{CameraMotion, Mask, ObjectPose};

use crate::camera::Rays;
use crate::math;
use crate::render::FrameGeom;
use crate::scene::{BoxPose, Scene};
use crate::trajectory::RigidState;

/// Camera motion sample of a camera state at `t`: pose camera -> world, velocities in the
/// camera frame.
pub fn camera_motion(t: f64, cam: &RigidState) -> CameraMotion {
    CameraMotion {
        t,
        position: cam.position,
        orientation: math::quat_from_mat(&cam.rotation),
        linear_velocity: Some(math::mul_mtv(&cam.rotation, cam.velocity)),
        angular_velocity: Some(cam.omega_body),
    }
}

/// Poses (object -> camera) of every moving object at `t`.
pub fn object_poses(t: f64, scene: &Scene, cam: &RigidState, out: &mut Vec<ObjectPose>) {
    for b in scene.boxes.iter().filter(|b| b.id != 0) {
        let pose = BoxPose::new(cam, &b.trajectory.state(t));
        out.push(ObjectPose {
            id: b.id as u32,
            t,
            position: pose.center,
            orientation: math::quat_from_mat(&pose.r_cb),
        });
    }
}

/// Object id of the nearest surface at every pixel centre (0 = background), row-major.
pub fn mask(_scene: &Scene, rays: &Rays, geom: &FrameGeom) -> Mask {
    let (w, h) = (rays.width, rays.height);
    let mut ids = vec![0u16; w * h];
    let boxes: Vec<[i32; 4]> = geom.object_bboxes().map(|(_, bb)| bb).collect();
    for (v, row) in ids.chunks_mut(w).enumerate() {
        for (u, id) in row.iter_mut().enumerate() {
            let (ui, vi) = (u as i32, v as i32);
            if !boxes
                .iter()
                .any(|b| ui >= b[0] && ui <= b[2] && vi >= b[1] && vi <= b[3])
            {
                continue;
            }
            let i = v * w + u;
            *id = geom.locate(rays.x[i], rays.y[i], ui, vi, None).id;
        }
    }
    Mask {
        t: geom.t,
        width: w as u16,
        height: h as u16,
        ids,
    }
}
