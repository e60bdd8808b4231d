//! Ground-truth samples: camera motion, object poses and object masks.

use evseg_schemas::{CameraMotion, Mask, ObjectPose};

use crate::camera::Rays;
use crate::math;
use crate::render::FrameGeom;
use crate::scene::{BoxPose, Scene};
use crate::trajectory::RigidState;

/// Pixels located together by [`mask`] (a multiple of the SIMD width).
const MASK_LANES: usize = crate::texture::LANES;

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
/// Only pixels inside a moving object's bounding box are located, a group of
/// `MASK_LANES` along the row at a time (see `FrameGeom::locate_lanes`).
pub fn mask(_scene: &Scene, rays: &Rays, geom: &FrameGeom) -> Mask {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is available (checked just above).
        return unsafe { mask_avx2(rays, geom) };
    }
    mask_with(rays, geom)
}

/// [`mask`] compiled with AVX2 (the lane search inlined).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn mask_avx2(rays: &Rays, geom: &FrameGeom) -> Mask {
    mask_with(rays, geom)
}

/// The body of [`mask`].
#[inline(always)]
fn mask_with(rays: &Rays, geom: &FrameGeom) -> Mask {
    let (w, h) = (rays.width, rays.height);
    let mut ids = vec![0u16; w * h];
    for (_, b) in geom.object_bboxes() {
        // Inclusive pixel bounding box [u0, v0, u1, v1], inside the image.
        let (u0, u1) = (b[0].max(0) as usize, (b[2].max(-1) + 1) as usize);
        let (v0, v1) = (b[1].max(0) as usize, (b[3].max(-1) + 1) as usize);
        for v in v0..v1.min(h) {
            let row = v * w;
            let mut u = u0;
            while u < u1.min(w) {
                let i = row + u;
                if u + MASK_LANES <= u1.min(w) {
                    let x: &[f32; MASK_LANES] = rays.x[i..i + MASK_LANES].try_into().expect("lane slice");
                    let y: &[f32; MASK_LANES] = rays.y[i..i + MASK_LANES].try_into().expect("lane slice");
                    let px = std::array::from_fn(|l| (u + l) as i32);
                    let found = geom.object_ids_lanes(x, y, &px, &[v as i32; MASK_LANES]);
                    ids[i..i + MASK_LANES].copy_from_slice(&found);
                    u += MASK_LANES;
                } else {
                    ids[i] = geom.locate(rays.x[i], rays.y[i], u as i32, v as i32, None).id;
                    u += 1;
                }
            }
        }
    }
    Mask {
        t: geom.t,
        width: w as u16,
        height: h as u16,
        ids,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn masks_match_locating_every_pixel() {
        let cfg = crate::presets::preset("two-objects", 2).unwrap();
        let scene = Scene::new(&cfg.scene, cfg.camera_trajectory.clone(), 2, 0.01);
        let rays = Rays::new(&cfg.camera);
        let w = rays.width;
        let mut covered = 0;
        for t in [0.0, 0.4, 1.3] {
            let geom = FrameGeom::new(&scene, &cfg.camera, t);
            let m = mask(&scene, &rays, &geom);
            for (i, &id) in m.ids.iter().enumerate() {
                let (u, v) = ((i % w) as i32, (i / w) as i32);
                let inside = geom
                    .object_bboxes()
                    .any(|(_, b)| u >= b[0] && u <= b[2] && v >= b[1] && v <= b[3]);
                let expected = if inside {
                    geom.locate(rays.x[i], rays.y[i], u, v, None).id
                } else {
                    0
                };
                assert_eq!(id, expected, "t {t} pixel {u} {v}");
                covered += usize::from(id != 0);
            }
        }
        assert!(covered > 1000, "{covered}");
    }
}
