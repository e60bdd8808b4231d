//! Known-answer check of the frame conventions end to end, simulator -> slicer -> the method's
//! motion field (the first rungs of `examples/oracle_ladder.rs`): the slicer's rotation rate
//! (IMU axes mapped to the camera) matches the simulator's true camera rate, and the true flow of
//! static background events, derotated with `B(x) w`, points along `A(x) t` of the true camera
//! velocity (camera frame). A sign, axis, unit or frame error in any of these breaks it.

use evseg_geometry::motion::{a_matrix, b_matrix};
use evseg_geometry::{Camera, TableCache};
use evseg_schemas::EventPacket;
use evseg_slicer::{Slicer, SlicerParams};
use evseg_source::EventSource;
use evseg_source::synthetic::SyntheticSource;

fn mul(m: &[[f64; 3]; 2], v: [f64; 3]) -> [f64; 2] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
    ]
}

#[test]
fn background_flow_follows_the_true_camera_twist_and_the_imu_rate_matches_it() {
    let mut src = SyntheticSource::new("camera-only", 1, Some(0.2)).unwrap();
    let camera = src.camera();
    let cam = Camera::new(&camera);
    let mut table = TableCache::default();
    let table = table.get(&camera).clone();
    let mut slicer = Slicer::new(SlicerParams::default()).unwrap();
    let (mut angles, mut omega_err, mut slices) = (Vec::new(), Vec::new(), 0);
    let mut t = 0.0;
    loop {
        t += 0.01;
        let Some(b) = src.next_batch(t).unwrap() else {
            break;
        };
        let packet = EventPacket {
            camera: camera.clone(),
            events: b.events,
            imu: b.imu,
        };
        for s in slicer.push(packet, b.truth, t).unwrap() {
            let truth = s.truth.unwrap();
            let n = truth.camera.len() as f64;
            assert!(n > 0.0);
            let (mut w, mut v) = ([0.0; 3], [0.0; 3]);
            for c in &truth.camera {
                let (cw, cv) = (c.angular_velocity.unwrap(), c.linear_velocity.unwrap());
                for k in 0..3 {
                    w[k] += cw[k] / n;
                    v[k] += cv[k] / n;
                }
            }
            let imu = s.slice.omega.unwrap();
            omega_err.push((0..3).map(|k| (imu[k] - w[k]).powi(2)).sum::<f64>().sqrt());
            let ev = &s.slice.events;
            for i in (0..ev.len()).step_by(7) {
                if truth.event_object[i] != 0 {
                    continue;
                }
                let (px, py) = (ev.x[i], ev.y[i]);
                let [x, y] = table.get(px, py).unwrap();
                let (x, y) = (f64::from(x), f64::from(y));
                let u = cam.pixel_flow_to_normalized(
                    f64::from(px),
                    f64::from(py),
                    f64::from(truth.flow_x[i]),
                    f64::from(truth.flow_y[i]),
                );
                let r = mul(&b_matrix(x, y), w);
                let d = [u[0] - r[0], u[1] - r[1]];
                let a = mul(&a_matrix(x, y), v);
                let (dn, an) = (d[0].hypot(d[1]), a[0].hypot(a[1]));
                if dn > 1e-3 && an > 1e-3 {
                    let c = (d[0] * a[0] + d[1] * a[1]) / (dn * an);
                    angles.push(c.clamp(-1.0, 1.0).acos().to_degrees());
                }
            }
            slices += 1;
        }
    }
    assert!(slices >= 3, "{slices} slices");
    omega_err.sort_by(f64::total_cmp);
    angles.sort_by(f64::total_cmp);
    assert!(angles.len() > 1000, "{} samples", angles.len());
    let med_omega = omega_err[omega_err.len() / 2];
    // IMU noise 0.005 rad/s per sample and a 0.002 rad/s bias: the slice mean is within 0.02.
    assert!(med_omega < 0.02, "|omega_imu - w_true| median {med_omega} rad/s");
    // Measured 1.6 deg (oracle_ladder R1); an error in sign, axes or frame gives tens of degrees.
    let med = angles[angles.len() / 2];
    let p90 = angles[angles.len() * 9 / 10];
    assert!(
        med < 5.0 && p90 < 30.0,
        "median {med} deg, 90th percentile {p90} deg"
    );
}
