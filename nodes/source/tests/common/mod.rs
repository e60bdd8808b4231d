//! Helpers shared by the source's integration tests.

#![allow(dead_code)]

use evseg_schemas::Events;
use evseg_source::EventSource;

/// Length of the batches [`read_batches`] asks for, seconds.
pub const BATCH_S: f64 = 0.01;

/// Every batch of `source` (10 ms each); panics if a batch holds an event at or after its end.
/// Returns the events and how many arrived before their batch's start (late).
pub fn read_batches(source: &mut impl EventSource) -> (Events, usize) {
    let mut all = Events::default();
    let mut late = 0;
    let mut k = 0;
    while let Some(batch) = source.next_batch((k + 1) as f64 * BATCH_S).unwrap() {
        let (start, end) = (k as f64 * BATCH_S, (k + 1) as f64 * BATCH_S);
        for &t in &batch.events.t {
            assert!(t < end, "batch {k} ends at {end} s but holds an event at {t} s");
            late += usize::from(t < start);
        }
        let n = batch.events.len();
        all.extend_from(&batch.events, 0..n);
        k += 1;
        assert!(k < 10_000, "source never ends");
    }
    (all, late)
}

/// The events as (t, x, y, p) tuples sorted, to compare sets whatever the order of equal times.
pub fn sorted(e: &Events) -> Vec<(u64, u16, u16, u8)> {
    let mut v: Vec<_> = (0..e.len())
        .map(|i| (e.t[i].to_bits(), e.x[i], e.y[i], e.p[i]))
        .collect();
    v.sort_unstable();
    v
}

/// A 64 x 48 camera (f 50 px, centred) with `distortion` and EVIMO2's IMU mapping.
pub fn camera_64x48(distortion: evseg_schemas::Distortion) -> evseg_schemas::CameraInfo {
    evseg_schemas::CameraInfo {
        width: 64,
        height: 48,
        fx: 50.0,
        fy: 50.0,
        cx: 31.5,
        cy: 23.5,
        distortion,
        imu_to_camera: evseg_evimo2::EVIMO2_IMU_TO_CAMERA,
        imu_time_offset_s: evseg_evimo2::EVIMO2_IMU_TIME_OFFSET_S,
        time_origin_us: 0,
        sensor: "test".into(),
    }
}
