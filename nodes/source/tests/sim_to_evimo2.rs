//! `evseg sim --out`: the simulator written as an EVIMO2 v2 folder reads back through the EVIMO2
//! source to the same events and ground truth as the simulator itself gives.

use evseg_schemas::Events;
use evseg_source::EventSource;
use evseg_source::evimo2::Evimo2Source;
use evseg_source::synthetic::{SyntheticSource, write_evimo2};

#[test]
fn simulated_sequence_round_trips_through_an_evimo2_folder() {
    let dir = tempfile::tempdir().unwrap();
    let n = write_evimo2("two-objects", 3, Some(0.15), 0.25, dir.path()).unwrap();
    assert!(n > 1000, "only {n} events");
    for f in [
        "dataset_events_t.npy",
        "dataset_events_xy.npy",
        "dataset_events_p.npy",
        "dataset_mask.npz",
        "dataset_info.npz",
    ] {
        assert!(dir.path().join(f).is_file(), "{f} missing");
    }

    let mut from_folder = Evimo2Source::open(dir.path(), &Default::default(), None).unwrap();
    // The simulator itself, same scene, seed, length and resolution.
    let mut cfg = evseg_sim::preset("two-objects", 3).unwrap();
    cfg.duration_s = 0.15;
    let cfg = cfg.with_resolution_scale(0.25);
    let mut direct = evseg_sim::Simulator::new(cfg).unwrap();
    let _ = SyntheticSource::new("two-objects", 3, Some(0.15)).unwrap();

    let (mut a, mut b) = (Events::default(), Events::default());
    let (mut masks_a, mut masks_b, mut imu_a, mut imu_b) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut k = 0;
    loop {
        let t_end = (k + 1) as f64 * 0.01;
        k += 1;
        let fa = from_folder.next_batch(t_end).unwrap();
        let fb = if direct.is_finished() {
            None
        } else {
            Some(direct.next_chunk(t_end.min(direct.duration())))
        };
        if fa.is_none() && fb.is_none() {
            break;
        }
        if let Some(x) = fa {
            let n = x.events.len();
            a.extend_from(&x.events, 0..n);
            masks_a.extend(x.truth.unwrap().masks);
            imu_a.extend(x.imu);
        }
        if let Some(x) = fb {
            let n = x.events.len();
            b.extend_from(&x.events, 0..n);
            masks_b.extend(x.truth.masks);
            imu_b.extend(x.imu);
        }
        assert!(k < 10_000);
    }
    assert_eq!(a.len(), b.len());
    assert!(
        a.x == b.x && a.y == b.y && a.p == b.p,
        "event coordinates or polarities differ"
    );
    // The folder's clock starts at its first event (the schema's convention); the simulator's at
    // the start of rendering, `t0` earlier.
    let t0 = b.t[0];
    assert!(a.t[0] == 0.0 && t0 > 0.0);
    let worst =
        a.t.iter()
            .zip(&b.t)
            .map(|(x, y)| (x - (y - t0)).abs())
            .fold(0.0, f64::max);
    assert!(worst < 1e-9, "event times differ by {worst} s");
    // Masks from t0 on come back identical (a mask before the first event has a negative time
    // on the folder's clock).
    let masks_b: Vec<_> = masks_b.into_iter().filter(|m| m.t >= t0).collect();
    let masks_a: Vec<_> = masks_a.into_iter().filter(|m| m.t >= 0.0).collect();
    assert_eq!(masks_a.len(), masks_b.len());
    assert!(
        masks_a
            .iter()
            .zip(&masks_b)
            .all(|(x, y)| x.ids == y.ids && (x.t - (y.t - t0)).abs() < 1e-9),
        "masks differ"
    );
    assert_eq!(imu_a.len(), imu_b.len());
    assert!(
        imu_a
            .iter()
            .zip(&imu_b)
            .all(|(x, y)| x.gyro == y.gyro && x.accel == y.accel),
        "IMU differs"
    );
    // The camera description survives, IMU convention included.
    assert_eq!(
        from_folder.camera().imu_to_camera,
        direct.camera_info().imu_to_camera
    );
    assert_eq!(from_folder.camera().width, direct.camera_info().width);
}

/// The IMU check on a simulated folder: the simulator's own mapping agrees with its camera
/// trajectory; a wrong one (the IMU read as if in the camera frame) is found out, kept when set
/// explicitly and replaced by the simulator's with `auto`.
#[test]
fn the_imu_check_finds_a_wrong_axis_convention() {
    use evseg_evimo2::imu_check::ImuVerdict;
    use evseg_source::evimo2::ImuCheckMode;
    let dir = tempfile::tempdir().unwrap();
    write_evimo2("fast-rotation", 5, Some(1.0), 0.25, dir.path()).unwrap();
    let mut right = Evimo2Source::open(dir.path(), &Default::default(), None).unwrap();
    let sim_map = right.camera().imu_to_camera;
    let sim_offset = right.camera().imu_time_offset_s;
    match right.check_imu(ImuCheckMode::Auto, false) {
        ImuVerdict::Consistent(a) => assert!(a.relative_error() < 0.3, "{a:?}"),
        other => panic!("the simulator's own mapping should agree: {other:?}"),
    }
    let identity = evseg_schemas::CameraInfo::IDENTITY;
    assert_ne!(
        sim_map, identity,
        "the test needs an IMU frame other than the camera's"
    );
    let wrong = evseg_evimo2::ReadOptions {
        imu_to_camera: Some(identity),
        ..Default::default()
    };
    let mut kept = Evimo2Source::open(dir.path(), &wrong, None).unwrap();
    assert!(matches!(
        kept.check_imu(ImuCheckMode::Auto, true),
        ImuVerdict::Mismatch { .. }
    ));
    assert_eq!(
        kept.camera().imu_to_camera,
        identity,
        "an explicit mapping is kept"
    );
    let mut fixed = Evimo2Source::open(dir.path(), &wrong, None).unwrap();
    fixed.check_imu(ImuCheckMode::Auto, false);
    assert_eq!(fixed.camera().imu_to_camera, sim_map);
    assert!((fixed.camera().imu_time_offset_s - sim_offset).abs() < 0.0051);
}
