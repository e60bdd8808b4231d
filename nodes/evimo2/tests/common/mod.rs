//! A small synthetic EVIMO2 sequence shared by the integration tests.
#![allow(dead_code)]

use evseg_evimo2::{
    DEFAULT_IMU_TOPIC, EVIMO2_IMU_TIME_OFFSET_S, EVIMO2_IMU_TO_CAMERA, FrameTruth, SequenceData,
};
use evseg_schemas::{CameraInfo, CameraMotion, Distortion, Events, ImuSample, Mask, ObjectPose};

/// Absolute start time. Event, frame, pose and IMU times below are multiples of 2^-20 s and
/// below 1 s, so `t + T_START - T_START == t` exactly in f64 and round trips are bit-exact.
pub const T_START: f64 = 8.0;
pub const WIDTH: u16 = 64;
pub const HEIGHT: u16 = 48;
pub const N_EVENTS: usize = 5000;

/// Deterministic pseudo-random numbers (64-bit LCG, Knuth's MMIX constants).
pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 33
    }
}

pub fn camera() -> CameraInfo {
    CameraInfo {
        width: WIDTH,
        height: HEIGHT,
        fx: 50.5,
        fy: 51.25,
        cx: 31.5,
        cy: 23.75,
        distortion: Distortion::RadTan {
            k1: -0.117189,
            k2: 0.069793,
            p1: -0.000327,
            p2: 0.005909,
            k3: 0.0125,
        },
        imu_to_camera: EVIMO2_IMU_TO_CAMERA,
        imu_time_offset_s: EVIMO2_IMU_TIME_OFFSET_S,
        time_origin_us: 8_000_000,
        sensor: "synthetic 'test' cam".into(),
    }
}

pub fn events() -> Events {
    let mut rng = Lcg(7);
    let mut ev = Events::with_capacity(N_EVENTS);
    let mut tick: u64 = 0;
    for _ in 0..N_EVENTS {
        ev.push(
            tick as f64 / (1u64 << 20) as f64,
            (rng.next() % WIDTH as u64) as u16,
            (rng.next() % HEIGHT as u64) as u16,
            (rng.next() % 2) as u8,
        );
        tick += rng.next() % 200; // mean 100 ticks ≈ 95 µs, so ~0.48 s in all; some ties
    }
    ev
}

fn rect_mask(t: f64, rects: &[(u16, u16, u16, u16, u16)]) -> Mask {
    let mut ids = vec![0u16; WIDTH as usize * HEIGHT as usize];
    for &(id, x0, y0, x1, y1) in rects {
        for y in y0..y1 {
            for x in x0..x1 {
                ids[y as usize * WIDTH as usize + x as usize] = id;
            }
        }
    }
    Mask {
        t,
        width: WIDTH,
        height: HEIGHT,
        ids,
    }
}

/// Dyadic quaternion components (exact in binary and in decimal text); not normalised — the
/// reader must return exactly what was written either way.
fn quat(i: usize) -> [f64; 4] {
    let a = 0.0625 * i as f64;
    [a, -a / 2.0, 0.125, 1.0 - a]
}

pub fn sequence() -> SequenceData {
    let frame_t = [0.0625, 0.125, 0.1875];
    let mut frames = Vec::new();
    let mut masks = Vec::new();
    for (i, &t) in frame_t.iter().enumerate() {
        let mut objects = vec![ObjectPose {
            id: 1,
            t,
            position: [0.25 * i as f64, -0.5, 1.5],
            orientation: quat(i),
        }];
        let mut rects = vec![(1u16, 4 + 4 * i as u16, 5, 20 + 4 * i as u16, 17)];
        if i != 1 {
            objects.push(ObjectPose {
                id: 2,
                t,
                position: [-0.75, 0.125, 2.0 + i as f64],
                orientation: quat(i + 3),
            });
            rects.push((2, 40, 30, 60, 46));
        }
        frames.push(FrameTruth {
            id: i as u64,
            t,
            camera: Some(CameraMotion {
                t,
                position: [0.001 * i as f64, 0.0, -0.5],
                orientation: quat(i + 1),
                linear_velocity: None,
                angular_velocity: None,
            }),
            objects,
        });
        masks.push(rect_mask(t, &rects));
    }
    let imu = (0..120)
        .map(|k| {
            let t = k as f64 / 256.0;
            ImuSample {
                t,
                gyro: [0.5 - t, 0.25 * t, -1.0 + t * t],
                accel: [9.75, -0.125 * t, 0.03125],
            }
        })
        .collect();
    let camera_poses = (0..60)
        .map(|k| {
            let t = k as f64 / 128.0;
            CameraMotion {
                t,
                position: [t, 2.0 * t, -t],
                orientation: [0.0, 0.0, t / 4.0, 1.0],
                linear_velocity: None,
                angular_velocity: None,
            }
        })
        .collect();
    let depth = masks
        .iter()
        .map(|m| {
            m.ids
                .iter()
                .map(|&id| if id == 0 { 0 } else { 1000 + 17 * id })
                .collect()
        })
        .collect();
    SequenceData {
        events: events(),
        t_start_s: T_START,
        camera: camera(),
        imu_topic: DEFAULT_IMU_TOPIC.to_string(),
        imu,
        camera_poses,
        frames,
        masks,
        depth_mm: Some(depth),
    }
}
