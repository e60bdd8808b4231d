//! Text events with calib.txt and imu.txt beside them, malformed lines, and camera files.

mod common;

use std::path::{Path, PathBuf};

use common::{decode_all, decode_file_lenient};
use evseg_formats::{CameraFileError, DecodeError, Format, OpenOptions, build_camera_info};
use evseg_schemas::messages::{CameraInfo, Distortion};

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

const EVENTS: &str = "# Event Camera Dataset style\n0.000100 10 20 1\n0.000200 11 21 0\n\n0.000350 5 7 -1\n";
const IMU: &str =
    "0.00005 0.1 9.8 0.2 0.01 0.02 0.03\n0.00025 0.0 9.7 0.1 0.0 0.0 0.1\n0.00100 1 2 3 4 5 6\n";

#[test]
fn text_with_calibration_and_imu() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "events.txt", EVENTS);
    write(dir.path(), "imu.txt", IMU);
    write(
        dir.path(),
        "calib.txt",
        "200 201 120 90 -0.1 0.01 0.001 0.002 0.0001\n",
    );
    let options = OpenOptions {
        geometry: Some((240, 180)),
        ..Default::default()
    };
    let mut decoder = evseg_formats::open(&path, &options).unwrap();
    assert_eq!(decoder.format(), Format::Text);
    assert_eq!(decoder.geometry(), (240, 180));
    assert_eq!(decoder.time_origin_us(), Some(100));
    assert!(decoder.has_imu());
    // One event per chunk: each chunk carries the IMU samples up to its last event.
    let mut chunks = Vec::new();
    while let Some(chunk) = decoder.next_chunk(1).unwrap() {
        chunks.push(chunk);
    }
    assert_eq!(
        chunks.len(),
        4,
        "3 event chunks, then the IMU samples after the last event"
    );
    let times: Vec<f64> = chunks.iter().flat_map(|c| c.events.t.clone()).collect();
    let expected = [0.0, 100e-6, 250e-6];
    assert!(
        times.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-12),
        "{times:?}"
    );
    let polarities: Vec<u8> = chunks.iter().flat_map(|c| c.events.p.clone()).collect();
    assert_eq!(polarities, [1, 0, 0]);
    let imu_counts: Vec<usize> = chunks.iter().map(|c| c.imu.len()).collect();
    assert_eq!(imu_counts, [1, 0, 1, 1]);
    let first = chunks[0].imu[0];
    assert!((first.t + 50e-6).abs() < 1e-12);
    assert_eq!(first.accel, [0.1, 9.8, 0.2]);
    assert_eq!(first.gyro, [0.01, 0.02, 0.03]);
    let camera = build_camera_info(decoder.as_ref(), None).unwrap();
    assert_eq!(
        (camera.fx, camera.fy, camera.cx, camera.cy),
        (200.0, 201.0, 120.0, 90.0)
    );
    assert_eq!(
        camera.distortion,
        Distortion::RadTan {
            k1: -0.1,
            k2: 0.01,
            p1: 0.001,
            p2: 0.002,
            k3: 0.0001
        }
    );
    assert_eq!(
        (camera.width, camera.height, camera.time_origin_us),
        (240, 180, 100)
    );
    assert_eq!(camera.imu_to_camera, CameraInfo::IDENTITY);
}

#[test]
fn text_geometry_is_scanned_and_sidecars_can_be_ignored() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "events.txt", "t,x,y,p\n0.5,10,20,1\n0.6,11,3,0\n");
    write(dir.path(), "calib.txt", "not a calibration\n");
    let options = OpenOptions {
        text_sidecars: false,
        ..Default::default()
    };
    let mut decoder = evseg_formats::open(&path, &options).unwrap();
    assert_eq!(decoder.geometry(), (12, 21));
    assert!(!decoder.has_imu());
    assert!(decoder.calibration().is_none());
    let decoded = decode_all(decoder.as_mut(), 10);
    assert_eq!(decoded.events, vec![(500000, 10, 20, 1), (600000, 11, 3, 0)]);
    // With the sidecars, the bad calib.txt is an error naming it and its line.
    let error = evseg_formats::open(&path, &OpenOptions::default()).err().unwrap();
    assert!(matches!(&error, DecodeError::BadLine { line: 1, .. }), "{error}");
    assert!(error.path().ends_with("calib.txt"));
}

#[test]
fn text_events_stored_out_of_time_order_are_passed_on_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "events.txt",
        "0.010 1 1 1\n0.030 2 2 0\n0.020 3 3 1\n0.025 4 4 1\n0.040 5 5 0\n",
    );
    let options = OpenOptions {
        geometry: Some((10, 10)),
        ..Default::default()
    };
    let mut decoder = evseg_formats::open(&path, &options).unwrap();
    let decoded = decode_all(decoder.as_mut(), 100);
    assert!(decoded.error.is_none(), "{:?}", decoded.error);
    let xs: Vec<u16> = decoded.events.iter().map(|e| e.1).collect();
    assert_eq!(xs, vec![1, 2, 3, 4, 5], "events in file order");
    assert_eq!(decoder.stats().times_out_of_order, 2);
}

#[test]
fn malformed_text_lines_name_file_and_line_after_the_good_events() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("0.1 1 2\n", "expected 4 fields"),
        ("0.1 a 2 1\n", "field 2"),
        ("0.1 2.5 2 1\n", "x = 2.5"),
        ("0.1 1 2 2\n", "polarity 2"),
        ("0.1 1 500 1\n", "outside the 100x100 sensor"),
        ("0.1 1 2 nan\n", "field 4"),
    ];
    for (bad, needle) in cases {
        let text = format!("# header\n0.01 1 1 1\n0.02 2 2 0\n{bad}0.3 3 3 1\n");
        let path = write(dir.path(), "events.txt", &text);
        let options = OpenOptions {
            geometry: Some((100, 100)),
            ..Default::default()
        };
        let mut decoder = evseg_formats::open(&path, &options).unwrap();
        let decoded = decode_all(decoder.as_mut(), 100);
        assert_eq!(decoded.events.len(), 2, "{bad:?}");
        match decoded.error {
            Some(DecodeError::BadLine {
                ref path,
                line,
                ref what,
            }) => {
                assert_eq!(line, 4, "{bad:?}");
                assert!(path.ends_with("events.txt"));
                assert!(what.contains(needle), "{what} should contain {needle}");
            }
            ref other => panic!("{bad:?}: {other:?}"),
        }
    }
    // A malformed imu.txt line is named too.
    let path = write(dir.path(), "events.txt", "0.01 1 1 1\n0.02 2 2 0\n");
    write(dir.path(), "imu.txt", "0.005 0 0 9.8 0 0 0\n0.015 0 0 9.8 0 0\n");
    let decoded = decode_file_lenient(&path, 100);
    match decoded.error {
        Some(DecodeError::BadLine {
            ref path, line: 2, ..
        }) => assert!(path.ends_with("imu.txt")),
        ref other => panic!("{other:?}"),
    }
}

#[test]
fn camera_file_fills_what_the_event_file_lacks() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "events.txt", EVENTS);
    write(dir.path(), "imu.txt", IMU);
    let options = OpenOptions {
        geometry: Some((240, 180)),
        ..Default::default()
    };
    let decoder = evseg_formats::open(&path, &options).unwrap();
    // No calibration anywhere: every missing parameter is listed.
    match build_camera_info(decoder.as_ref(), None) {
        Err(CameraFileError::Missing { missing, hint }) => {
            assert_eq!(missing, ["fx", "fy", "cx", "cy", "imu_to_camera"]);
            assert!(hint.contains("text"), "{hint}");
        }
        other => panic!("{other:?}"),
    }
    let partial = write(dir.path(), "partial.json", r#"{"fx": 100, "cy": 90}"#);
    match build_camera_info(decoder.as_ref(), Some(&partial)) {
        Err(error @ CameraFileError::Missing { .. }) => {
            let text = error.to_string();
            assert!(
                text.contains("fy, cx, imu_to_camera") && text.contains("partial.json"),
                "{text}"
            );
        }
        other => panic!("{other:?}"),
    }
    let full = write(
        dir.path(),
        "camera.json",
        r#"{
            "sensor": "davis240c", "width": 240, "height": 180,
            "fx": 199.1, "fy": 198.2, "cx": 132.2, "cy": 110.8,
            "distortion": {"model": "equidistant", "k1": 0.1, "k2": 0.01, "k3": 0.001, "k4": 0.0001},
            "imu_to_camera": [0, -1, 0, 1, 0, 0, 0, 0, 1],
            "imu_time_offset_s": 0.0025
        }"#,
    );
    let camera = build_camera_info(decoder.as_ref(), Some(&full)).unwrap();
    assert_eq!(camera.sensor, "davis240c");
    assert_eq!(
        (camera.fx, camera.fy, camera.cx, camera.cy),
        (199.1, 198.2, 132.2, 110.8)
    );
    assert_eq!(
        camera.distortion,
        Distortion::Equidistant {
            k1: 0.1,
            k2: 0.01,
            k3: 0.001,
            k4: 0.0001
        }
    );
    assert_eq!(
        camera.imu_to_camera,
        [0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    );
    assert_eq!(camera.imu_time_offset_s, 0.0025);
    assert_eq!(camera.time_origin_us, 100);
}

#[test]
fn bad_camera_files_are_rejected_with_their_place() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "events.txt", EVENTS);
    let options = OpenOptions {
        geometry: Some((240, 180)),
        text_sidecars: false,
        ..Default::default()
    };
    let decoder = evseg_formats::open(&path, &options).unwrap();
    let base = r#""fx": 1, "fy": 1, "cx": 1, "cy": 1"#;
    let cases = [
        (format!("{{{base}, \"focal\": 3}}"), "unknown field"),
        (format!("{{{base},\n \"width\": 320}}"), "width 320 differs"),
        (
            format!("{{{base}, \"imu_to_camera\": [1,0,0, 0,1,0, 0,0,2]}}"),
            "not a rotation",
        ),
        (
            format!("{{{base}, \"imu_to_camera\": [1,0,0]}}"),
            "expected an array of length 9",
        ),
        (r#"{"fx": -1, "fy": 1, "cx": 1, "cy": 1}"#.to_string(), "positive"),
        (
            format!("{{{base}, \"distortion\": {{\"model\": \"fisheye\"}}}}"),
            "unknown variant",
        ),
        ("{\n\"fx\": 1,\n}".to_string(), "trailing comma"),
    ];
    for (json, needle) in cases {
        let file = write(dir.path(), "camera.json", &json);
        let error = build_camera_info(decoder.as_ref(), Some(&file)).unwrap_err();
        let text = error.to_string();
        assert!(
            text.contains(needle) && text.contains("camera.json"),
            "{text} should contain {needle}"
        );
    }
    let error = build_camera_info(decoder.as_ref(), Some(&dir.path().join("absent.json"))).unwrap_err();
    assert!(matches!(error, CameraFileError::Io { .. }));
    // Pinhole camera with only the required keys, and the radial-tangential k3 default.
    let file = write(
        dir.path(),
        "camera.json",
        &format!(
            "{{{base}, \"distortion\": {{\"model\": \"rad_tan\", \"k1\": 0.5, \"k2\": 0, \"p1\": 0, \"p2\": 0}}}}"
        ),
    );
    let camera = build_camera_info(decoder.as_ref(), Some(&file)).unwrap();
    assert_eq!(
        camera.distortion,
        Distortion::RadTan {
            k1: 0.5,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            k3: 0.0
        }
    );
    assert_eq!(camera.sensor, "text");
}
