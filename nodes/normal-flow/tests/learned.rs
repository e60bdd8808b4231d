//! The learned estimator: weights file checks, encoding invariances, and a known answer after a
//! small training on analytic straight edges.

use std::path::Path;

use evseg_normal_flow::learned::SplitMix64;
use evseg_normal_flow::train::{Dataset, TrainConfig, init_weights, train};
use evseg_normal_flow::{LearnedEstimator, LearnedParams, LearnedWeights, WeightsError};
use evseg_schemas::{CameraInfo, Events};

const W: u16 = 64;
const H: u16 = 64;

fn camera() -> CameraInfo {
    CameraInfo::pinhole(W, H, 100.0, "synthetic")
}

/// Events of a straight edge with unit normal at `angle_deg`, moving along it at `speed` px/s:
/// pixel `(x, y)` fires when the edge reaches its centre, `t = (n . x - d0) / speed`, rounded to
/// 1 µs; a second, parallel edge follows `gap_px` pixels behind (a stripe), each with its
/// polarity. Only events in `[t0, t1)`, time-ordered.
fn edge_events(angle_deg: f64, speed: f64, t0: f64, t1: f64) -> Events {
    let (nx, ny) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
    let proj = |x: f64, y: f64| nx * x + ny * y;
    let d0 = [(0.0, 0.0), (W as f64, 0.0), (0.0, H as f64), (W as f64, H as f64)]
        .iter()
        .map(|&(x, y)| proj(x, y))
        .fold(f64::INFINITY, f64::min)
        - 1.0;
    let mut list = Vec::new();
    for (lag_px, p) in [(0.0, 1u8), (12.0, 0u8)] {
        for y in 0..H {
            for x in 0..W {
                let t = (proj(x as f64, y as f64) - d0 + lag_px) / speed;
                let t = (t * 1e6).round() * 1e-6;
                if t >= t0 && t < t1 {
                    list.push((t, x, y, p));
                }
            }
        }
    }
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut ev = Events::with_capacity(list.len());
    for (t, x, y, p) in list {
        ev.push(t, x, y, p);
    }
    ev
}

fn small_config(seed: u64) -> TrainConfig {
    TrainConfig {
        seed,
        d: 24,
        hidden: vec![48, 48],
        radius_px: 5,
        alpha_xy: 3.0,
        alpha_t: 6.0,
        epochs: 12,
        batch: 128,
        lr: 3e-3,
        threads: 2,
    }
}

#[test]
fn weights_round_trip_and_bad_files_name_the_file() {
    let w = init_weights(&small_config(3));
    let bytes = w.to_bytes();
    let p = Path::new("some/dir/w.bin");
    assert_eq!(LearnedWeights::from_bytes(&bytes, p).expect("round trip"), w);
    // Truncated anywhere: an error naming the file, never a panic.
    for cut in [0, 7, 12, 30, bytes.len() / 2, bytes.len() - 1] {
        let e = LearnedWeights::from_bytes(&bytes[..cut], p).expect_err("truncated");
        assert!(e.to_string().contains("some/dir/w.bin"), "{e}");
        assert!(
            matches!(e, WeightsError::Truncated { .. } | WeightsError::Magic { .. }),
            "{cut}: {e}"
        );
    }
    let mut bad = bytes.clone();
    bad[0] = b'X';
    assert!(matches!(
        LearnedWeights::from_bytes(&bad, p),
        Err(WeightsError::Magic { .. })
    ));
    let mut bad = bytes.clone();
    let mid = bytes.len() - 100;
    bad[mid] ^= 0x40;
    assert!(matches!(
        LearnedWeights::from_bytes(&bad, p),
        Err(WeightsError::Checksum { .. })
    ));
    let mut bad = bytes.clone();
    bad.push(0);
    assert!(matches!(
        LearnedWeights::from_bytes(&bad, p),
        Err(WeightsError::Trailing { .. })
    ));
    let mut bad = bytes.clone();
    bad[8] = 9;
    assert!(matches!(
        LearnedWeights::from_bytes(&bad, p),
        Err(WeightsError::Version { version: 9, .. })
    ));
    let missing = LearnedWeights::load("/nonexistent/evseg/weights.bin").expect_err("missing file");
    assert!(
        missing.to_string().contains("/nonexistent/evseg/weights.bin"),
        "{missing}"
    );
}

/// Largest difference between the feature rows of the same events in two encodings.
fn largest_difference(ia: &[u32], fa: &[f32], ib: &[u32], fb: &[f32], dim: usize) -> f32 {
    assert_eq!(ia.len(), ib.len());
    let mut a_rows: Vec<(u32, &[f32])> = ia.iter().copied().zip(fa.chunks(dim)).collect();
    let mut b_rows: Vec<(u32, &[f32])> = ib.iter().copied().zip(fb.chunks(dim)).collect();
    a_rows.sort_by_key(|r| r.0);
    b_rows.sort_by_key(|r| r.0);
    let mut worst = 0.0f32;
    for ((ea, ra), (eb, rb)) in a_rows.iter().zip(&b_rows) {
        assert_eq!(ea, eb);
        for (x, y) in ra.iter().zip(*rb) {
            worst = worst.max((x - y).abs());
        }
    }
    worst
}

#[test]
fn encoding_is_translation_invariant_and_time_scales_the_flow() {
    let w = init_weights(&small_config(5));
    let params = LearnedParams {
        threads: 2,
        ..LearnedParams::default()
    };
    let cam = CameraInfo::pinhole(96, 96, 100.0, "synthetic");
    let mut est = LearnedEstimator::new(&cam, w.clone(), params).expect("estimator");
    let ev = edge_events(30.0, 800.0, 0.01, 0.04);
    assert!(ev.len() > 500);
    // Shift every event by (+17, +9) px and 0.25 s, and the slice with it.
    let mut shifted = Events::with_capacity(ev.len());
    for i in 0..ev.len() {
        shifted.push(ev.t[i] + 0.25, ev.x[i] + 17, ev.y[i] + 9, ev.p[i]);
    }
    let all = |_: usize| true;
    let (ia, fa) = est.features(&ev, 0.01, 0.04, 0, &all).expect("features");
    let (ib, fb) = est.features(&shifted, 0.26, 0.29, 0, &all).expect("features");
    let dim = 2 * w.d();
    // The time shift may move an event to the next 1/2048 time bin (float rounding of the bin
    // boundaries): a phase change of at most |At| / 2048 per neighbour, so a loose bound.
    assert!(largest_difference(&ia, &fa, &ib, &fb, dim) < 0.1);
    // Shifted in space only: equal up to f32 rounding (|feature| <= sqrt(D) ~ 4.9).
    let mut moved = Events::with_capacity(ev.len());
    for i in 0..ev.len() {
        moved.push(ev.t[i], ev.x[i] + 17, ev.y[i] + 9, ev.p[i]);
    }
    let (ib, fb) = est.features(&moved, 0.01, 0.04, 0, &all).expect("features");
    let worst = largest_difference(&ia, &fa, &ib, &fb, dim);
    assert!(worst < 2e-3, "largest feature difference {worst}");

    // Twice as long in time (events and slice): the same encoding, half the flow in px/s.
    let mut slow = Events::with_capacity(ev.len());
    for i in 0..ev.len() {
        slow.push(ev.t[i] * 2.0, ev.x[i], ev.y[i], ev.p[i]);
    }
    let fast_est = est.process_pixels(&ev, 0.01, 0.04).expect("process");
    let slow_est = est.process_pixels(&slow, 0.02, 0.08).expect("process");
    let mut compared = 0;
    for (a, b) in fast_est.iter().zip(&slow_est) {
        assert_eq!(a.confidence > 0.0, b.confidence > 0.0);
        if a.confidence > 0.0 {
            let na = a.flow_px[0].hypot(a.flow_px[1]);
            for j in 0..2 {
                assert!(
                    (a.flow_px[j] - 2.0 * b.flow_px[j]).abs() < 1e-2 * na + 1e-6,
                    "{a:?} {b:?}"
                );
            }
            compared += 1;
        }
    }
    assert!(compared > 500, "{compared}");
}

#[test]
fn trained_on_edges_gives_the_normal_direction_of_unseen_edges() {
    let cfg = small_config(11);
    let mut w = init_weights(&cfg);
    let mut est = LearnedEstimator::new(&camera(), w.clone(), LearnedParams::default()).expect("estimator");
    let mut data = Dataset::new(2 * cfg.d);
    let mut rng = SplitMix64(7);
    // A 30 ms slice around the time the first edge is in the middle of the sensor.
    let slice_of = |speed: f64| (45.0 / speed - 0.015, 45.0 / speed + 0.015);
    for a in (0..360).step_by(10) {
        for speed in [400.0, 900.0, 1600.0] {
            let slice = slice_of(speed);
            let ev = edge_events(a as f64, speed, slice.0, slice.1);
            let n = [(a as f32).to_radians().cos(), (a as f32).to_radians().sin()];
            let fx = vec![n[0] * speed as f32; ev.len()];
            let fy = vec![n[1] * speed as f32; ev.len()];
            data.add_slice(
                &mut est, &ev, &fx, &fy, slice.0, slice.1, 0.3, 1.0, 0, false, &mut rng,
            )
            .expect("encode");
        }
    }
    assert!(data.len() > 5000, "{}", data.len());
    train(&mut w, &data, &cfg, &mut |_, _, _| {});
    let mut est = LearnedEstimator::new(&camera(), w, LearnedParams::default()).expect("estimator");
    // Unseen angles (5 degrees off the training ones) and an unseen speed.
    let mut errors = Vec::new();
    let (mut sign_ok, mut scored) = (0, 0);
    for a in (5..360).step_by(30) {
        let speed = 1200.0;
        let slice = slice_of(speed);
        let ev = edge_events(a as f64, speed, slice.0, slice.1);
        let n = [(a as f64).to_radians().cos(), (a as f64).to_radians().sin()];
        let est_px = est.process_pixels(&ev, slice.0, slice.1).expect("process");
        for (i, e) in est_px.iter().enumerate() {
            // Away from the sensor border (full window).
            let (x, y) = (ev.x[i], ev.y[i]);
            if e.confidence <= 0.0 || x < 6 || y < 6 || x >= W - 6 || y >= H - 6 {
                continue;
            }
            let f = e.flow_px;
            scored += 1;
            sign_ok += usize::from(f[0] * n[0] + f[1] * n[1] > 0.0);
            let cross = f[0] * n[1] - f[1] * n[0];
            let dot = f[0] * n[0] + f[1] * n[1];
            errors.push(cross.abs().atan2(dot).to_degrees());
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors[errors.len() / 2];
    let sign = sign_ok as f64 / scored as f64;
    assert!(scored > 1000, "{scored}");
    assert!(sign > 0.95, "sign-correct {sign}");
    assert!(median < 10.0, "median direction error {median} deg");
}

#[test]
fn encoding_matches_its_definition() {
    // Random events on a small sensor; times at the centres of the 1/2048 tau bins.
    let w = init_weights(&small_config(9));
    let (width, height) = (40u16, 30u16);
    let cam = CameraInfo::pinhole(width, height, 50.0, "synthetic");
    let mut est = LearnedEstimator::new(&cam, w.clone(), LearnedParams::default()).expect("estimator");
    let (t0, t1) = (0.5, 0.53);
    let mut rng = SplitMix64(99);
    let mut list: Vec<(f64, u16, u16)> = (0..600)
        .map(|_| {
            let q = (rng.next_u64() % 4096) as f64;
            let t = t0 + (q + 0.5) * (t1 - t0) / 4096.0;
            let x = (rng.next_u64() % u64::from(width)) as u16;
            let y = (rng.next_u64() % u64::from(height)) as u16;
            (t, x, y)
        })
        .collect();
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut ev = Events::with_capacity(list.len());
    for &(t, x, y) in &list {
        ev.push(t, x, y, 1);
    }
    let (idx, feats) = est.features(&ev, t0, t1, 0, &|_| true).expect("features");
    let d = w.d();
    let r = f64::from(w.radius_px);
    let rad = w.radius_px as i32;
    // tau = 2 (t - t0) / T in [0, 2), quantised to 1/2048: bin q = floor(2048 tau / ... ) = floor(4096 (t - t0) / T).
    let tau = |t: f64| ((t - t0) / (t1 - t0) * 4096.0).floor() / 2048.0;
    let mut checked = 0;
    let mut worst = 0.0f64;
    for (row, &i) in idx.iter().enumerate() {
        let i = i as usize;
        let mut sum = vec![(0.0f64, 0.0f64); d];
        let mut n = 0;
        for j in 0..ev.len() {
            let (dx, dy) = (
                i32::from(ev.x[j]) - i32::from(ev.x[i]),
                i32::from(ev.y[j]) - i32::from(ev.y[i]),
            );
            if dx.abs() > rad || dy.abs() > rad {
                continue;
            }
            n += 1;
            for (k, s) in sum.iter_mut().enumerate() {
                let ph = (tau(ev.t[j]) - tau(ev.t[i])) * f64::from(w.at[k])
                    + f64::from(dx) / r * f64::from(w.ax[k])
                    + f64::from(dy) / r * f64::from(w.ay[k]);
                s.0 += ph.cos();
                s.1 += ph.sin();
            }
        }
        let scale = (d as f64).sqrt() / f64::from(n);
        for (k, s) in sum.iter().enumerate() {
            worst = worst.max((s.0 * scale - f64::from(feats[row * 2 * d + k])).abs());
            worst = worst.max((s.1 * scale - f64::from(feats[row * 2 * d + d + k])).abs());
        }
        checked += 1;
    }
    assert!(checked > 300, "{checked}");
    assert!(worst < 1e-3, "largest difference from the definition {worst}");
}
