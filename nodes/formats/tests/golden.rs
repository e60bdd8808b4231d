//! Golden values of the four real recordings (shared/data/real/README.md, decoded by faery 0.7.1
//! and the `aedat` package): every figure must match exactly.

mod common;

use common::{AbsEvent, Decoded, decode_all, real_data_dir};
use evseg_formats::{Format, OpenOptions};

struct Golden {
    file: &'static str,
    format: Format,
    geometry: (u16, u16),
    count: usize,
    on: usize,
    first: [AbsEvent; 3],
    last: AbsEvent,
    sum_x: u64,
    sum_y: u64,
}

const GOLDEN: [Golden; 4] = [
    Golden {
        file: "davis346.aedat4",
        format: Format::Aedat4,
        geometry: (346, 260),
        count: 78_830,
        on: 41_257,
        first: [
            (1589163147368868, 215, 164, 1),
            (1589163147368950, 226, 160, 1),
            (1589163147368974, 40, 236, 1),
        ],
        last: (1589163149728813, 233, 205, 1),
        sum_x: 14_861_513,
        sum_y: 15_061_593,
    },
    Golden {
        file: "dvs.es",
        format: Format::EventStream,
        geometry: (320, 240),
        count: 473_225,
        on: 270_001,
        first: [(0, 0, 0, 1), (0, 1, 0, 1), (0, 2, 0, 1)],
        last: (999000, 38, 193, 1),
        sum_x: 72_946_016,
        sum_y: 56_007_796,
    },
    Golden {
        file: "evt3.raw",
        format: Format::Evt3,
        geometry: (1280, 720),
        count: 1_218_618,
        on: 553_295,
        first: [
            (11200224, 484, 315, 1),
            (11200225, 474, 231, 0),
            (11200225, 450, 309, 1),
        ],
        last: (21968221, 471, 350, 0),
        sum_x: 606_868_036,
        sum_y: 367_486_055,
    },
    Golden {
        file: "evt2.raw",
        format: Format::Evt2,
        geometry: (640, 480),
        count: 521_252,
        on: 185_861,
        first: [
            (913716224, 35, 443, 1),
            (913716224, 36, 443, 1),
            (913716224, 74, 443, 1),
        ],
        last: (913812095, 12, 471, 0),
        sum_x: 128_979_953,
        sum_y: 216_346_680,
    },
];

fn check(golden: &Golden, decoded: &Decoded) {
    let name = golden.file;
    assert!(decoded.error.is_none(), "{name}: {:?}", decoded.error);
    let ev = &decoded.events;
    assert_eq!(ev.len(), golden.count, "{name}: event count");
    assert_eq!(
        ev.iter().filter(|e| e.3 == 1).count(),
        golden.on,
        "{name}: ON count"
    );
    assert_eq!(ev[..3], golden.first, "{name}: first events");
    assert_eq!(ev[ev.len() - 1], golden.last, "{name}: last event");
    assert_eq!(
        ev.iter().map(|e| e.1 as u64).sum::<u64>(),
        golden.sum_x,
        "{name}: sum of x"
    );
    assert_eq!(
        ev.iter().map(|e| e.2 as u64).sum::<u64>(),
        golden.sum_y,
        "{name}: sum of y"
    );
}

#[test]
fn real_files_match_golden_values() {
    let Some(dir) = real_data_dir() else { return };
    for golden in &GOLDEN {
        let path = dir.join(golden.file);
        let mut decoder = evseg_formats::open(&path, &OpenOptions::default()).expect(golden.file);
        assert_eq!(decoder.format(), golden.format, "{}", golden.file);
        assert_eq!(
            decoder.geometry(),
            golden.geometry,
            "{}: sensor size",
            golden.file
        );
        assert_eq!(
            decoder.time_origin_us(),
            Some(golden.first[0].0),
            "{}: time origin",
            golden.file
        );
        let decoded = decode_all(decoder.as_mut(), 10_000);
        check(golden, &decoded);
        let stats = decoder.stats();
        assert_eq!(stats.events, golden.count as u64);
        assert_eq!(stats.out_of_range, 0, "{}", golden.file);
        assert_eq!(stats.time_regressions, 0, "{}", golden.file);
    }
}

#[test]
fn chunk_size_does_not_change_the_events() {
    let Some(dir) = real_data_dir() else { return };
    for golden in &GOLDEN {
        let path = dir.join(golden.file);
        let reference = common::decode_file(&path, 1 << 20).unwrap();
        for max in [1, 5, 4093] {
            let small = common::decode_file(&path, max).unwrap();
            assert!(small.error.is_none());
            assert_eq!(
                small.events, reference.events,
                "{} in chunks of {max}",
                golden.file
            );
            assert_eq!(
                small.imu.len(),
                reference.imu.len(),
                "{} in chunks of {max}",
                golden.file
            );
        }
        check(golden, &reference);
    }
}

#[test]
fn davis346_imu_matches_golden_values() {
    let Some(dir) = real_data_dir() else { return };
    let path = dir.join("davis346.aedat4");
    let mut decoder = evseg_formats::open(&path, &OpenOptions::default()).unwrap();
    assert!(decoder.has_imu());
    let decoded = decode_all(decoder.as_mut(), 10_000);
    let imu = &decoded.imu;
    assert_eq!(imu.len(), 2_363);
    assert_eq!(imu[0].0, 1589163147369190);
    assert_eq!(imu[imu.len() - 1].0, 1589163149728420);
    assert!(imu.windows(2).all(|w| w[0].0 <= w[1].0), "IMU times decrease");
    // Back to the file's units: deg/s and g.
    let deg = 180.0 / std::f64::consts::PI;
    let g = evseg_formats::STANDARD_GRAVITY;
    let close = |a: f64, b: f64, rel: f64| (a - b).abs() <= rel * b.abs().max(1e-6);
    let (_, gyro, accel) = imu[0];
    for (got, want) in gyro
        .iter()
        .map(|v| v * deg)
        .zip([0.7781982, -0.5187988, -0.015258788])
    {
        assert!(close(got, want, 1e-6), "first gyro {got} vs {want}");
    }
    for (got, want) in accel
        .iter()
        .map(|v| v / g)
        .zip([0.02758789, -0.9951172, 0.2590332])
    {
        assert!(close(got, want, 1e-6), "first accel {got} vs {want}");
    }
    let sum = |f: &dyn Fn(&common::AbsImu) -> f64| imu.iter().map(f).sum::<f64>();
    assert!(close(sum(&|s| s.1[0] * deg), 1747.0245, 1e-3));
    assert!(close(sum(&|s| s.1[1] * deg), -1164.3829, 1e-3));
    assert!(close(sum(&|s| s.1[2] * deg), 269.1040, 1e-3));
    assert!(close(sum(&|s| s.2[0] / g), 62.6272, 1e-3));
    // The camera is almost still: gyro below about 1 deg/s.
    assert!(imu.iter().all(|s| s.1.iter().all(|w| (w * deg).abs() < 5.0)));
    // 59 frame and 236 trigger packets... at least the frame/trigger packets were skipped.
    assert!(decoder.stats().skipped_packets > 0);
}
