//! `rotation_source`: a folder without an IMU gets its rotation rate from the camera trajectory
//! when asked, and only then.

mod common;

use evseg_evimo2::{SequenceData, write_sequence};
use evseg_schemas::{CameraMotion, Distortion, Events};
use evseg_source::EventSource;
use evseg_source::evimo2::{Evimo2Source, RotationSource};

/// The camera's constant rotation rate, rad/s, camera frame.
const RATE: [f64; 3] = [0.2, -0.1, 0.3];

/// A folder with events over 0.5 s, no IMU, and (with `poses`) a camera turning at [`RATE`]
/// recorded at 200 Hz.
fn sequence(poses: bool) -> SequenceData {
    let mut events = Events::default();
    for i in 0..5000u32 {
        events.push(f64::from(i) * 1e-4, (i % 64) as u16, (i / 64 % 48) as u16, 1);
    }
    let camera = common::camera_64x48(Distortion::None);
    let speed = RATE.iter().map(|r| r * r).sum::<f64>().sqrt();
    let axis = RATE.map(|r| r / speed);
    // Constant body rate: R(t) = exp([RATE] t), camera -> world, as the quaternion [x, y, z, w].
    let camera_poses = (0..if poses { 100 } else { 0 })
        .map(|k| {
            let t = f64::from(k) * 0.005;
            let half = 0.5 * speed * t;
            CameraMotion {
                t,
                position: [0.0; 3],
                orientation: [
                    axis[0] * half.sin(),
                    axis[1] * half.sin(),
                    axis[2] * half.sin(),
                    half.cos(),
                ],
                ..Default::default()
            }
        })
        .collect();
    SequenceData {
        events,
        t_start_s: 1000.0,
        camera,
        imu_topic: evseg_evimo2::DEFAULT_IMU_TOPIC.into(),
        imu: Vec::new(),
        camera_poses,
        frames: Vec::new(),
        masks: Vec::new(),
        depth_mm: None,
    }
}

/// The IMU samples of every 10 ms batch.
fn samples(src: &mut Evimo2Source) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    let mut k = 0;
    while let Some(b) = src.next_batch((k + 1) as f64 * 0.01).unwrap() {
        out.extend(b.imu.iter().map(|s| s.gyro));
        k += 1;
        assert!(k < 1000, "source never ends");
    }
    out
}

#[test]
fn the_trajectory_gives_the_rotation_rate_when_asked() {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), &sequence(true)).unwrap();
    let open = || Evimo2Source::open(dir.path(), &Default::default(), None).unwrap();

    // Default: the folder's IMU, which is empty, so no sample (and a warning).
    let mut imu = open();
    assert_eq!(
        imu.set_rotation_source(RotationSource::Imu, dir.path()).unwrap(),
        0
    );
    assert!(samples(&mut imu).is_empty());

    let mut traj = open();
    let made = traj
        .set_rotation_source(RotationSource::Trajectory, dir.path())
        .unwrap();
    assert!(made > 15, "only {made} samples from 0.5 s of trajectory");
    let camera = traj.camera();
    assert_eq!(
        camera.imu_to_camera,
        [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    );
    assert_eq!(camera.imu_time_offset_s, 0.0);
    let got = samples(&mut traj);
    assert!(got.len() > 15, "{} samples delivered", got.len());
    for g in &got {
        for (a, b) in g.iter().zip(RATE) {
            assert!((a - b).abs() < 1e-6, "rate {g:?}, want {RATE:?}");
        }
    }
}

#[test]
fn a_folder_without_trajectory_cannot_give_the_rate() {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), &sequence(false)).unwrap();
    let mut src = Evimo2Source::open(dir.path(), &Default::default(), None).unwrap();
    let e = src
        .set_rotation_source(RotationSource::Trajectory, dir.path())
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(
        e.contains("rotation_source: trajectory") && e.contains("no camera trajectory"),
        "{e}"
    );
    let bad = "gyro".parse::<RotationSource>().err().unwrap_or_default();
    assert_eq!(bad, "rotation_source must be imu or trajectory, got `gyro`");
}
