//! Reading speed: events in chunks and in 1 ms windows, and one 640x480 mask.
//! Run: `CARGO_TARGET_DIR=/work/target-evimo2 cargo bench -p evseg-evimo2 --bench read`.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use evseg_evimo2::{FrameTruth, ReadOptions, Sequence, SequenceData, write_sequence};
use evseg_schemas::{CameraInfo, Distortion, Events, Mask};

const N: usize = 2_000_000;

fn folder() -> tempfile::TempDir {
    let (w, h) = (640u16, 480u16);
    let mut events = Events::with_capacity(N);
    let mut s = 1u64;
    for i in 0..N {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        // 2 M events over 1 s (a typical EVIMO2 Samsung rate).
        events.push(
            i as f64 * 5e-7,
            ((s >> 33) % 640) as u16,
            ((s >> 13) % 480) as u16,
            (s >> 7) as u8 & 1,
        );
    }
    let mut ids = vec![0u16; w as usize * h as usize];
    for y in 100..300 {
        for x in 200..400 {
            ids[y * w as usize + x] = 3;
        }
    }
    let frames = vec![FrameTruth {
        id: 0,
        t: 0.5,
        camera: None,
        objects: vec![],
    }];
    let data = SequenceData {
        events,
        t_start_s: 10.0,
        camera: CameraInfo {
            width: w,
            height: h,
            fx: 500.0,
            fy: 500.0,
            cx: 320.0,
            cy: 240.0,
            distortion: Distortion::None,
            imu_to_camera: CameraInfo::IDENTITY,
            imu_time_offset_s: 0.0,
            time_origin_us: 0,
            sensor: "bench".into(),
        },
        imu_topic: "/imu".into(),
        imu: vec![],
        camera_poses: vec![],
        frames,
        masks: vec![Mask {
            t: 0.5,
            width: w,
            height: h,
            ids,
        }],
        depth_mm: None,
    };
    let dir = tempfile::tempdir().expect("temp dir");
    write_sequence(dir.path(), &data).expect("write");
    dir
}

fn bench(c: &mut Criterion) {
    let dir = folder();
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).expect("open");
    let mut g = c.benchmark_group("events");
    g.sample_size(10);
    g.throughput(Throughput::Elements(N as u64));
    g.bench_function("next_chunk_65536", |b| {
        b.iter(|| {
            let mut r = seq.events().expect("events");
            let mut n = 0;
            while let Some(chunk) = r.next_chunk(65536).expect("chunk") {
                n += black_box(chunk).len();
            }
            assert_eq!(n, N);
        })
    });
    g.bench_function("read_until_1ms_windows", |b| {
        b.iter(|| {
            let mut r = seq.events().expect("events");
            let (mut n, mut t) = (0, 0.0);
            while r.position() < r.len() {
                t += 1e-3;
                n += black_box(r.read_until(t).expect("window")).len();
            }
            assert_eq!(n, N);
        })
    });
    g.finish();
    let mut g = c.benchmark_group("masks");
    g.bench_function("read_640x480_deflated", |b| {
        let mut masks = seq.masks().expect("masks");
        b.iter(|| black_box(masks.read(0).expect("mask")))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
