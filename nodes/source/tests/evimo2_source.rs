//! The EVIMO2 source on a small folder written by the project's own EVIMO2 writer: every event
//! once, in order, IMU and masks delivered in the batches whose span holds them.

mod common;

use evseg_evimo2::{FrameTruth, SequenceData, write_sequence};
use evseg_schemas::{CameraMotion, Distortion, Events, ImuSample, Mask, ObjectPose};
use evseg_source::EventSource;
use evseg_source::evimo2::Evimo2Source;

pub fn small_sequence() -> SequenceData {
    let mut events = Events::default();
    for i in 0..5000u32 {
        events.push(
            f64::from(i) * 1e-4,
            (i % 64) as u16,
            (i / 64 % 48) as u16,
            (i % 3 == 0) as u8,
        );
    }
    let camera = common::camera_64x48(Distortion::RadTan {
        k1: -0.1,
        k2: 0.01,
        p1: 0.001,
        p2: -0.001,
        k3: 0.0,
    });
    let imu = (0..100)
        .map(|i| ImuSample {
            t: f64::from(i) * 0.005,
            gyro: [0.1, 0.2, 0.3],
            accel: [0.0, -9.8, 0.0],
        })
        .collect();
    let mut frames = Vec::new();
    let mut masks = Vec::new();
    let mut poses = Vec::new();
    for k in 0..3u64 {
        let t = 0.05 + k as f64 / 60.0;
        let cam = CameraMotion {
            t,
            position: [k as f64 * 0.01, 0.0, 0.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
            ..Default::default()
        };
        poses.push(cam);
        let obj = ObjectPose {
            id: 1,
            t,
            position: [0.0, 0.0, 2.0],
            orientation: [0.0, 0.0, 0.0, 1.0],
        };
        frames.push(FrameTruth {
            id: k,
            t,
            camera: Some(cam),
            objects: vec![obj],
        });
        let mut ids = vec![0u16; 64 * 48];
        ids[..100].fill(1);
        masks.push(Mask {
            t,
            width: 64,
            height: 48,
            ids,
        });
    }
    SequenceData {
        events,
        t_start_s: 1000.0,
        camera,
        imu_topic: evseg_evimo2::DEFAULT_IMU_TOPIC.into(),
        imu,
        camera_poses: poses,
        frames,
        masks,
        depth_mm: None,
    }
}

#[test]
fn reads_back_everything_in_time_batches() {
    let dir = tempfile::tempdir().unwrap();
    let data = small_sequence();
    write_sequence(dir.path(), &data).unwrap();
    let mut src = Evimo2Source::open(dir.path(), &Default::default(), None).unwrap();
    assert_eq!(src.camera().width, 64);
    assert!(matches!(src.camera().distortion, Distortion::RadTan { .. }));
    let mut all = Events::default();
    let (mut imu, mut masks, mut k) = (0, 0, 0);
    while let Some(b) = src.next_batch((k + 1) as f64 * 0.01).unwrap() {
        let end = (k + 1) as f64 * 0.01;
        assert!(b.events.t.iter().all(|&t| t < end && t >= end - 0.01 - 1e-12));
        let n = b.events.len();
        all.extend_from(&b.events, 0..n);
        imu += b.imu.len();
        let truth = b.truth.unwrap();
        assert!(truth.masks.iter().all(|m| m.t < end));
        masks += truth.masks.len();
        k += 1;
        assert!(k < 1000, "source never ends");
    }
    // Times go through absolute seconds (t_start_s = 1000) in the file: equal to ~1e-13 s.
    assert_eq!(all.len(), data.events.len());
    assert!(
        all.x == data.events.x && all.y == data.events.y && all.p == data.events.p,
        "coordinates differ"
    );
    let worst = all
        .t
        .iter()
        .zip(&data.events.t)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst < 1e-9, "times differ by up to {worst} s");
    assert_eq!(masks, 3);
    // IMU samples are delivered on the camera clock (t + offset) within the event span.
    assert!(imu > 0 && imu <= 100);
}

#[test]
fn a_missing_folder_is_named() {
    let err = Evimo2Source::open(
        std::path::Path::new("/nonexistent/seq"),
        &Default::default(),
        None,
    )
    .err()
    .unwrap();
    assert!(err.to_string().contains("/nonexistent/seq"), "{err}");
}

/// A folder with a few events out of time order: the source sorts them back and says how many
/// (its counters, which the node logs and writes to its summary), instead of changing the
/// stream without a word; a clean folder counts nothing.
#[test]
fn events_sorted_back_into_order_are_counted() {
    let clean = tempfile::tempdir().unwrap();
    let mut data = small_sequence();
    write_sequence(clean.path(), &data).unwrap();
    let drain = |src: &mut Evimo2Source| {
        let mut k = 0;
        while src.next_batch((k + 1) as f64 * 0.01).unwrap().is_some() {
            k += 1;
            assert!(k < 1000, "source never ends");
        }
    };
    let mut src = Evimo2Source::open(clean.path(), &Default::default(), None).unwrap();
    drain(&mut src);
    assert!(
        src.counters().iter().all(|(_, n)| *n == 0),
        "{:?}",
        src.counters()
    );

    // Swap the times of three pairs of neighbouring events within one 10 ms batch.
    for i in [1000usize, 2000, 3000] {
        data.events.t.swap(i, i + 1);
    }
    let shuffled = tempfile::tempdir().unwrap();
    write_sequence(shuffled.path(), &data).unwrap();
    let mut src = Evimo2Source::open(shuffled.path(), &Default::default(), None).unwrap();
    drain(&mut src);
    let counters: std::collections::HashMap<_, _> = src.counters().into_iter().collect();
    assert_eq!(counters["events_reordered"], 3, "{counters:?}");
    assert_eq!(counters["times_not_increasing"], 3, "{counters:?}");
    assert_eq!(counters["masks_read_with_raw_ids"], 0, "{counters:?}");
}
