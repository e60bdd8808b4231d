//! Known answers: straight edges moving at known velocities, generated analytically (a pixel
//! fires when the edge line, moving along its unit normal `n` at `s` px/s, reaches its centre:
//! `t = (n . x - d0) / s`, rounded to 1 µs like a sensor clock).

use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams, WideFitParams};
use evseg_schemas::{CameraInfo, Events, NormalFlow};

const W: u16 = 64;
const H: u16 = 64;
const F: f64 = 100.0;

fn camera() -> CameraInfo {
    CameraInfo::pinhole(W, H, F, "synthetic")
}

/// Events of an edge with unit normal at `angle_deg` moving at `speed` px/s, starting outside
/// the sensor so that every pixel fires once, polarity `p`, time-ordered.
fn edge_events(angle_deg: f64, speed: f64, p: u8) -> Events {
    let (nx, ny) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
    let proj = |x: f64, y: f64| nx * x + ny * y;
    let corners = [(0.0, 0.0), (W as f64, 0.0), (0.0, H as f64), (W as f64, H as f64)];
    let d0 = corners
        .iter()
        .map(|&(x, y)| proj(x, y))
        .fold(f64::INFINITY, f64::min)
        - 1.0;
    let mut list = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let t = (proj(x as f64, y as f64) - d0) / speed;
            list.push(((t * 1e6).round() * 1e-6, x, y));
        }
    }
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut ev = Events::with_capacity(list.len());
    for (t, x, y) in list {
        ev.push(t, x, y, p);
    }
    ev
}

/// True when pixel `(x, y)` has a full window inside the sensor and the edge had passed at
/// least `r + 1` pixels of the sensor before reaching it (so that the window behind it is filled).
fn checkable(x: u16, y: u16, r: u16, angle_deg: f64) -> bool {
    let m = r + 1;
    if x < m || y < m || x + m >= W || y + m >= H {
        return false;
    }
    let (nx, ny) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
    // Behind the pixel along -n, r + 1 pixels are inside the sensor.
    let bx = x as f64 - nx * (r as f64 + 1.5);
    let by = y as f64 - ny * (r as f64 + 1.5);
    bx >= 0.0 && by >= 0.0 && bx < W as f64 && by < H as f64
}

/// Runs the estimator over an edge and checks every checkable event: valid, sign-correct and
/// within 5% of `speed * n` (pixels and, through the pinhole camera, normalized units).
fn check_edge(angle_deg: f64, speed: f64, radius: usize) {
    let params = PlaneFitParams {
        radius,
        ..PlaneFitParams::default()
    };
    let events = edge_events(angle_deg, speed, 1);
    let mut est = PlaneFitEstimator::new(&camera(), params).expect("valid");
    let mut norm = est.clone();
    let px = est.process_pixels(&events).expect("consistent");
    let flow = norm.process(&events).expect("consistent");
    let (nx, ny) = (angle_deg.to_radians().cos(), angle_deg.to_radians().sin());
    let truth = [speed * nx, speed * ny];
    let mut checked = 0;
    for (i, &e) in px.iter().enumerate() {
        if !checkable(events.x[i], events.y[i], radius as u16, angle_deg) {
            continue;
        }
        checked += 1;
        assert!(
            e.confidence > 0.5,
            "angle {angle_deg}: event {i} confidence {}",
            e.confidence
        );
        let [vx, vy] = e.flow_px;
        assert!(
            vx * truth[0] + vy * truth[1] > 0.0,
            "angle {angle_deg}: sign wrong at {i}"
        );
        let err = (vx - truth[0]).hypot(vy - truth[1]);
        assert!(
            err < 0.05 * speed,
            "angle {angle_deg}: flow ({vx:.1}, {vy:.1}) vs true ({:.1}, {:.1})",
            truth[0],
            truth[1]
        );
        // Normalized output: pinhole, so pixel flow / focal length.
        let (fx, fy) = (f64::from(flow.nx[i]) * F, f64::from(flow.ny[i]) * F);
        assert!((fx - vx).abs() < 1e-3 * speed && (fy - vy).abs() < 1e-3 * speed);
        assert_eq!(flow.confidence[i], e.confidence as f32);
    }
    assert!(
        checked > 1500,
        "only {checked} events checked at angle {angle_deg}"
    );
}

#[test]
fn vertical_edge_moving_right_gives_its_speed() {
    check_edge(0.0, 200.0, 2);
}

#[test]
fn diagonal_edge_gives_its_speed_along_the_normal() {
    check_edge(45.0, 500.0, 2);
}

#[test]
fn every_direction_is_sign_correct_and_within_5_percent() {
    for k in 0..12 {
        check_edge(15.0 + 30.0 * k as f64, 300.0, 2);
    }
}

#[test]
fn radius_one_window_works_too() {
    for angle in [0.0, 120.0, 250.0] {
        check_edge(angle, 800.0, 1);
    }
}

#[test]
fn surfaces_persist_across_slices() {
    let events = edge_events(30.0, 400.0, 0);
    let camera = camera();
    // Causal: the look-ahead stays inside a slice, so only the causal fit is independent of
    // where the slices are cut.
    let causal = PlaneFitParams {
        lookahead_s: 0.0,
        ..PlaneFitParams::default()
    };
    let mut whole = PlaneFitEstimator::new(&camera, causal).expect("valid");
    let all = whole.process(&events).expect("consistent");
    let mut split = PlaneFitEstimator::new(&camera, causal).expect("valid");
    let mid = events.len() / 2;
    let mut first = Events::default();
    first.extend_from(&events, 0..mid);
    let mut second = Events::default();
    second.extend_from(&events, mid..events.len());
    let a = split.process(&first).expect("consistent");
    let valid_first = split.stats().valid;
    let b = split.process(&second).expect("consistent");
    let valid_second = split.stats().valid - valid_first;
    assert_eq!([a.nx.clone(), b.nx.clone()].concat(), all.nx);
    assert_eq!(
        [a.confidence.clone(), b.confidence.clone()].concat(),
        all.confidence
    );
    assert_eq!(whole.stats(), split.stats());
    // A fresh estimator on the second half alone lacks the history for its first events.
    let mut fresh = PlaneFitEstimator::new(&camera, causal).expect("valid");
    let c = fresh.process(&second).expect("consistent");
    assert!(
        fresh.stats().valid < valid_second,
        "{} vs {valid_second}",
        fresh.stats().valid
    );
    assert_ne!(c.confidence, b.confidence);
}

#[test]
fn polarities_do_not_mix() {
    // ON edge only: OFF events at the same pixels later see no OFF neighbours.
    let on = edge_events(0.0, 200.0, 1);
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    est.process(&on).expect("consistent");
    let mut off = Events::default();
    off.push(10.0, 30, 30, 0);
    let out = est.process(&off).expect("consistent");
    assert_eq!(out.confidence, vec![0.0]);
    assert_eq!((out.nx[0], out.ny[0]), (0.0, 0.0));
}

#[test]
fn too_few_points_are_invalid_not_guessed() {
    let mut ev = Events::default();
    // Four isolated events and a pair of neighbours: never 5 same-polarity points in a window.
    for (i, (x, y)) in [(5, 5), (20, 20), (40, 10), (10, 50), (30, 30), (31, 30)]
        .into_iter()
        .enumerate()
    {
        ev.push(0.001 * i as f64, x, y, 1);
    }
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let out = est.process(&ev).expect("consistent");
    assert!(out.confidence.iter().all(|&c| c == 0.0));
    assert!(out.nx.iter().chain(&out.ny).all(|&v| v == 0.0));
    assert_eq!(est.stats().valid, 0);
    assert_eq!(est.stats().events, 6);
}

#[test]
fn neighbours_older_than_dt_max_are_not_used() {
    // 1 px/s: the pixels behind the edge are 1 s old, beyond dt_max = 0.3 s; only the pixels of
    // the edge itself (a line) remain, which span no plane.
    let slow = edge_events(0.0, 1.0, 1);
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    est.process(&slow).expect("consistent");
    assert_eq!(est.stats().valid, 0);
    // With dt_max above 1 s the same stream is measured.
    let params = PlaneFitParams {
        dt_max_s: 3.5,
        ..PlaneFitParams::default()
    };
    let mut est = PlaneFitEstimator::new(&camera(), params).expect("valid");
    let px = est.process_pixels(&slow).expect("consistent");
    let i = (0..slow.len())
        .find(|&i| slow.x[i] == 32 && slow.y[i] == 32)
        .expect("pixel");
    assert!((px[i].flow_px[0] - 1.0).abs() < 0.05 && px[i].flow_px[1].abs() < 0.05);
}

#[test]
fn faster_than_max_speed_is_invalid() {
    let fast = edge_events(0.0, 50_000.0, 1);
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    est.process(&fast).expect("consistent");
    assert_eq!(est.stats().valid, 0);
    let params = PlaneFitParams {
        max_speed_px_s: 100_000.0,
        ..PlaneFitParams::default()
    };
    let mut est = PlaneFitEstimator::new(&camera(), params).expect("valid");
    est.process(&fast).expect("consistent");
    assert!(est.stats().valid > 1000);
}

#[test]
fn malformed_events_are_counted_and_ignored() {
    let mut ev = edge_events(0.0, 200.0, 1);
    let n = ev.len();
    let last = ev.t[n - 1];
    ev.push(last, W, 3, 1);
    ev.push(last, 3, u16::MAX, 1);
    ev.push(f64::NAN, 3, 3, 1);
    ev.push(last - 0.1, 40, 40, 1);
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let out = est.process(&ev).expect("consistent");
    assert_eq!(out.nx.len(), n + 4);
    assert_eq!(&out.confidence[n..n + 3], &[0.0, 0.0, 0.0]);
    let s = est.stats();
    assert_eq!((s.out_of_sensor, s.bad_time, s.out_of_order), (2, 1, 1));
    // Column lengths that disagree are an error, not a panic.
    ev.p.pop();
    assert!(est.process(&ev).is_err());
}

#[test]
fn a_malformed_next_slice_is_skipped_or_refused_never_a_panic() {
    let events = jittered_edge_events(150.0, 0.4);
    let (first, second) = split_at(&events, 0.2);
    let t = first.t[first.len() - 1];
    // Events outside the sensor and without a time in the next slice are not written ahead and
    // not counted: the same flow as with the clean next slice.
    let mut bad = Events::default();
    bad.push(t + 0.001, W, 3, 1);
    bad.push(t + 0.001, 3, u16::MAX, 1);
    bad.push(f64::NAN, 3, 3, 1);
    for i in 0..second.len() {
        bad.push(second.t[i], second.x[i], second.y[i], second.p[i]);
    }
    let mut clean_est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let mut clean = evseg_schemas::NormalFlow::default();
    clean_est
        .process_with_next_into(&first, Some(&second), &mut clean)
        .expect("consistent");
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let mut out = evseg_schemas::NormalFlow::default();
    est.process_with_next_into(&first, Some(&bad), &mut out)
        .expect("consistent");
    let s = est.stats();
    assert_eq!(
        (s.events, s.out_of_sensor, s.bad_time),
        (first.len() as u64, 0, 0)
    );
    assert!(out.nx == clean.nx && out.confidence == clean.confidence);
    // And the next slice did change the fits (so the comparison above says something).
    let mut alone = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let alone_flow = alone.process(&first).expect("consistent");
    assert!(clean.nx != alone_flow.nx, "the clean next slice changed nothing");
    // A next slice whose columns disagree is an error, not a panic.
    bad.p.pop();
    assert!(est.process_with_next_into(&first, Some(&bad), &mut out).is_err());
}

#[test]
fn bad_parameters_are_refused() {
    let cam = camera();
    for params in [
        PlaneFitParams {
            radius: 0,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            radius: 9,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            min_points: 2,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            radius: 1,
            min_points: 10,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            dt_max_s: f64::NAN,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            outlier_s: -1.0,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            min_confidence: 1.0,
            ..PlaneFitParams::default()
        },
        // The check window must be larger than the fit's and at most MAX_RADIUS.
        PlaneFitParams {
            check_radius: 2,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            check_radius: 5,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            check_max_angle_rad: 0.0,
            ..PlaneFitParams::default()
        },
        PlaneFitParams {
            check_max_speed_diff: f64::NAN,
            ..PlaneFitParams::default()
        },
    ] {
        assert!(
            PlaneFitEstimator::new(&cam, params).is_err(),
            "{params:?} accepted"
        );
    }
    let empty = CameraInfo::pinhole(0, 10, 100.0, "empty");
    assert!(PlaneFitEstimator::new(&empty, PlaneFitParams::default()).is_err());
}

/// The edge of [`edge_events`] with every timestamp shifted by a pseudo-random jitter of up to
/// `jitter_px / speed` seconds (a fixed hash per pixel, as a per-pixel threshold mismatch would).
fn jittered_edge_events(speed: f64, jitter_px: f64) -> Events {
    let clean = edge_events(0.0, speed, 1);
    let mut list: Vec<(f64, u16, u16)> = (0..clean.len())
        .map(|i| {
            let (x, y) = (clean.x[i], clean.y[i]);
            let h = ((u64::from(x) * 73_856_093) ^ (u64::from(y) * 19_349_663)) % 1000;
            let j = (h as f64 / 999.0 * 2.0 - 1.0) * jitter_px / speed;
            (clean.t[i] + j, x, y)
        })
        .collect();
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut ev = Events::with_capacity(list.len());
    for (t, x, y) in list {
        ev.push(t, x, y, 1);
    }
    ev
}

/// Median of `|p| / speed` over the checkable valid events.
fn median_speed_ratio(events: &Events, params: PlaneFitParams, speed: f64) -> f64 {
    let mut est = PlaneFitEstimator::new(&camera(), params).expect("valid");
    let px = est.process_pixels(events).expect("consistent");
    let mut ratios: Vec<f64> = px
        .iter()
        .enumerate()
        .filter(|(i, e)| e.confidence > 0.0 && checkable(events.x[*i], events.y[*i], 2, 0.0))
        .map(|(_, e)| e.flow_px[0].hypot(e.flow_px[1]) / speed)
        .collect();
    assert!(ratios.len() > 1000, "only {} valid events", ratios.len());
    ratios.sort_by(f64::total_cmp);
    ratios[ratios.len() / 2]
}

#[test]
fn causal_fit_overestimates_jittered_speed_and_lookahead_removes_it() {
    // Jitter of +-0.4 px of travel: the causal fit keeps only the early-firing pixels at the
    // edge front, so the surface looks compressed along the motion.
    let speed = 150.0;
    let events = jittered_edge_events(speed, 0.4);
    let causal_params = PlaneFitParams {
        lookahead_s: 0.0,
        ..PlaneFitParams::default()
    };
    let causal = median_speed_ratio(&events, causal_params, speed);
    let lookahead = PlaneFitParams {
        lookahead_s: 0.03,
        ..PlaneFitParams::default()
    };
    let non_causal = median_speed_ratio(&events, lookahead, speed);
    println!("jittered edge: median speed ratio causal {causal:.4}, lookahead {non_causal:.4}");
    assert!(causal > 1.01, "causal median ratio {causal}");
    assert!(
        (non_causal - 1.0).abs() < 0.5 * (causal - 1.0),
        "lookahead median ratio {non_causal}, causal {causal}"
    );
}

#[test]
fn lookahead_keeps_clean_edges_exact() {
    let events = edge_events(30.0, 200.0, 1);
    let params = PlaneFitParams {
        lookahead_s: 0.03,
        ..PlaneFitParams::default()
    };
    let ratio = median_speed_ratio(&events, params, 200.0);
    assert!((ratio - 1.0).abs() < 0.01, "ratio {ratio}");
}

#[test]
fn direction_test_drops_uncertain_fits_only() {
    let speed = 150.0;
    let events = jittered_edge_events(speed, 0.4);
    let mut all = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    all.process(&events).expect("consistent");
    let strict = PlaneFitParams {
        max_direction_sd_rad: 1f64.to_radians(),
        ..PlaneFitParams::default()
    };
    let mut some = PlaneFitEstimator::new(&camera(), strict).expect("valid");
    some.process(&events).expect("consistent");
    assert!(some.stats().valid < all.stats().valid);
    // A clean edge has an exact direction: nothing dropped.
    let clean = edge_events(0.0, speed, 1);
    let mut a = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let mut b = PlaneFitEstimator::new(&camera(), strict).expect("valid");
    a.process(&clean).expect("consistent");
    b.process(&clean).expect("consistent");
    assert_eq!(a.stats().valid, b.stats().valid);
}

/// Events of a vertical edge moving right whose time surface bends: within `inner` columns of
/// column `x_c` it crosses a pixel every `1 / fast` s, farther out every `1 / slow` s (a surface
/// that is a plane in a small window and not in a larger one).
fn kinked_edge_events(x_c: u16, inner: u16, fast: f64, slow: f64) -> Events {
    let mut list = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let d = f64::from(x) - f64::from(x_c);
            let k = f64::from(inner);
            let t = if d.abs() <= k {
                d / fast
            } else {
                d.signum() * (k / fast + (d.abs() - k) / slow)
            };
            list.push((0.1 + (t * 1e6).round() * 1e-6, x, y));
        }
    }
    list.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut ev = Events::with_capacity(list.len());
    for (t, x, y) in list {
        ev.push(t, x, y, 1);
    }
    ev
}

#[test]
fn a_surface_that_bends_outside_the_window_fails_the_scale_check() {
    // Plane at 400 px/s over the 5 x 5 window, 100 px/s beyond it: the 7 x 7 plane says about
    // 240 px/s, 40 % slower, so the check leaves the estimate out; without the check it is
    // the 5 x 5 window's 400 px/s.
    let events = kinked_edge_events(32, 2, 400.0, 100.0);
    let centre: Vec<usize> = (0..events.len())
        .filter(|&i| events.x[i] == 32 && (8..H - 8).contains(&events.y[i]))
        .collect();
    assert!(centre.len() > 40);
    let unchecked = PlaneFitParams {
        check_radius: 0,
        ..PlaneFitParams::default()
    };
    let mut plain = PlaneFitEstimator::new(&camera(), unchecked).expect("valid");
    let px = plain.process_pixels(&events).expect("consistent");
    for &i in &centre {
        let [vx, vy] = px[i].flow_px;
        assert!(px[i].confidence > 0.5, "event {i} invalid without the check");
        assert!((vx - 400.0).abs() < 20.0 && vy.abs() < 20.0, "({vx}, {vy})");
    }
    assert_eq!(plain.stats().disagreed, 0);
    // The synthetic 5 x 5 surface is an exact plane, so its fit is confident enough to skip the
    // check by default; every fit is checked when no confidence is high enough to skip it.
    let always = PlaneFitParams {
        check_skip_confidence: 2.0,
        ..PlaneFitParams::default()
    };
    let mut checked = PlaneFitEstimator::new(&camera(), always).expect("valid");
    let px = checked.process_pixels(&events).expect("consistent");
    for &i in &centre {
        assert_eq!(px[i].confidence, 0.0, "event {i} kept despite the bend");
    }
    assert!(checked.stats().disagreed >= centre.len() as u64);
    let mut skipping = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let px = skipping.process_pixels(&events).expect("consistent");
    for &i in &centre {
        assert!(px[i].confidence > 0.5, "confident exact fit {i} was not skipped");
    }
    // A gentler bend (400 -> 340 px/s) stays within the 20 % the check allows.
    let gentle = kinked_edge_events(32, 2, 400.0, 340.0);
    let mut checked = PlaneFitEstimator::new(&camera(), always).expect("valid");
    let px = checked.process_pixels(&gentle).expect("consistent");
    let kept = (0..gentle.len())
        .filter(|&i| gentle.x[i] == 32 && (8..H - 8).contains(&gentle.y[i]) && px[i].confidence > 0.5)
        .count();
    assert_eq!(kept, centre.len());
}

/// `events` split at time `t_split`: (before, from then on).
fn split_at(events: &Events, t_split: f64) -> (Events, Events) {
    let (mut a, mut b) = (Events::default(), Events::default());
    for i in 0..events.len() {
        let part = if events.t[i] < t_split { &mut a } else { &mut b };
        part.push(events.t[i], events.x[i], events.y[i], events.p[i]);
    }
    (a, b)
}

#[test]
fn lookahead_across_slices_fits_a_slice_end_like_its_middle() {
    // The jittered edge of the look-ahead test, cut into two slices while it crosses the sensor.
    let speed = 150.0;
    let events = jittered_edge_events(speed, 0.4);
    let t_split = 0.2;
    let (first, second) = split_at(&events, t_split);
    assert!(first.len() > 1000 && second.len() > 1000);
    let params = PlaneFitParams::default();
    let la = params.lookahead_s;

    // Each slice on its own: the first slice's last events see less of the future.
    let mut alone = PlaneFitEstimator::new(&camera(), params).expect("valid");
    let mut flow_alone = evseg_schemas::NormalFlow::default();
    alone.process_into(&first, &mut flow_alone).expect("consistent");
    let mut second_alone = evseg_schemas::NormalFlow::default();
    alone
        .process_into(&second, &mut second_alone)
        .expect("consistent");

    // The first slice fitted with the second's first events on the surfaces.
    let mut across = PlaneFitEstimator::new(&camera(), params).expect("valid");
    let mut flow_across = evseg_schemas::NormalFlow::default();
    across
        .process_with_next_into(&first, Some(&second), &mut flow_across)
        .expect("consistent");
    assert_eq!(
        across.stats().events,
        first.len() as u64,
        "the next slice's events are not counted yet"
    );
    let mut second_across = evseg_schemas::NormalFlow::default();
    across
        .process_into(&second, &mut second_across)
        .expect("consistent");
    assert_eq!(across.stats().events, events.len() as u64);
    assert_eq!(across.stats().out_of_order, 0, "{:?}", across.stats());

    // The tail of the first slice: biased alone, like the middle across slices.
    let tail_from = t_split - 0.5 * la;
    let (ratio_alone, n_alone) = median_ratio_between(&first, &flow_alone, speed, tail_from, f64::INFINITY);
    let (ratio_across, n_across) =
        median_ratio_between(&first, &flow_across, speed, tail_from, f64::INFINITY);
    let (ratio_middle, _) = median_ratio_between(&first, &flow_across, speed, 0.05, t_split - la);
    println!(
        "tail of the first slice: median speed ratio alone {ratio_alone:.4} ({n_alone}), across {ratio_across:.4} ({n_across}); middle {ratio_middle:.4}"
    );
    assert!(n_alone > 100 && n_across > 100);
    assert!(ratio_alone > 1.01, "alone {ratio_alone}");
    assert!(
        (ratio_across - ratio_middle).abs() < 0.5 * (ratio_alone - ratio_middle).abs(),
        "across {ratio_across}, alone {ratio_alone}, middle {ratio_middle}"
    );

    // The first slice across slices is exactly the two slices fitted as one, cut back.
    let mut whole = PlaneFitEstimator::new(&camera(), params).expect("valid");
    let both = whole.process(&events).expect("consistent");
    let n = first.len();
    assert_eq!(flow_across.nx[..], both.nx[..n]);
    assert_eq!(flow_across.ny[..], both.ny[..n]);
    assert_eq!(flow_across.confidence[..], both.confidence[..n]);
    // And the second slice comes out the same either way: its own look-ahead covers what the
    // first slice's fits wrote ahead.
    assert_eq!(second_across.nx, second_alone.nx);
    assert_eq!(second_across.confidence, second_alone.confidence);
}

/// Median of `|p| / speed` over the valid, checkable events with times in `[t0, t1)` (the
/// flow's normalized lengths back to pixels through the pinhole camera), and their count.
fn median_ratio_between(
    events: &Events,
    flow: &evseg_schemas::NormalFlow,
    speed: f64,
    t0: f64,
    t1: f64,
) -> (f64, usize) {
    let mut ratios: Vec<f64> = (0..events.len())
        .filter(|&i| {
            flow.confidence[i] > 0.0
                && events.t[i] >= t0
                && events.t[i] < t1
                && checkable(events.x[i], events.y[i], 2, 0.0)
        })
        .map(|i| F * f64::from(flow.nx[i]).hypot(f64::from(flow.ny[i])) / speed)
        .collect();
    ratios.sort_by(f64::total_cmp);
    (
        ratios.get(ratios.len() / 2).copied().unwrap_or(f64::NAN),
        ratios.len(),
    )
}

/// Own and wide flow (pixels/s along x and y from the normalized flow of the pinhole camera) of
/// every event of `events`, with the wide fit `wide` on; and the estimator's counters.
fn own_and_wide(
    events: &Events,
    wide: WideFitParams,
) -> (NormalFlow, NormalFlow, evseg_normal_flow::EstimatorStats) {
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default())
        .and_then(|e| e.with_wide_fit(wide))
        .expect("valid");
    let (mut own, mut wide_flow) = (NormalFlow::default(), NormalFlow::default());
    est.process_wide_into(events, None, &mut own, Some(&mut wide_flow))
        .expect("consistent");
    (own, wide_flow, est.stats())
}

/// Speed in pixels/s of event `i`'s estimate in `flow` (normalized units through the pinhole
/// camera of focal length `F`), `None` when invalid.
fn speed_px(flow: &NormalFlow, i: usize) -> Option<f64> {
    (flow.confidence[i] > 0.0).then(|| f64::from(flow.nx[i]).hypot(f64::from(flow.ny[i])) * F)
}

#[test]
fn the_wide_flow_refits_fast_edges_and_keeps_slow_ones() {
    let wide = WideFitParams::default();
    // A clean edge faster than the threshold: every checkable event gets the wide window's
    // estimate, which is its true speed.
    let fast = 2.0 * wide.min_speed_px_s;
    let events = edge_events(30.0, fast, 1);
    let (own, wide_flow, stats) = own_and_wide(&events, wide);
    let mut checked = 0;
    for i in 0..events.len() {
        if !checkable(events.x[i], events.y[i], wide.radius as u16, 30.0) {
            continue;
        }
        let s = speed_px(&wide_flow, i).expect("valid wide estimate");
        assert!(
            (s / fast - 1.0).abs() < 0.02,
            "event {i}: wide speed {s}, true {fast}"
        );
        checked += 1;
    }
    assert!(checked > 1000, "{checked} events checked");
    assert!(stats.wide_fits > 1000 && stats.wide_valid > 1000, "{stats:?}");
    assert!(
        own.nx != wide_flow.nx || own.ny != wide_flow.ny,
        "the wide fits changed nothing"
    );
    // A slow edge: no wide fit, the wide flow is the own flow.
    let events = edge_events(30.0, 0.5 * wide.min_speed_px_s, 1);
    let (own, wide_flow, stats) = own_and_wide(&events, wide);
    assert_eq!(stats.wide_fits, 0);
    assert_eq!(own, wide_flow);
}

#[test]
fn the_wide_window_narrows_the_length_spread_of_a_jittered_fast_edge() {
    // Per-pixel timing jitter of +-0.4 px of travel on an edge at 600 px/s: the 5 x 5 window
    // has few distinct timestamps across the edge and its lengths scatter; the 7 x 7 window's
    // scatter less. Spread: the median absolute deviation of the speed ratio (measured 0.022
    // for the 5 x 5 window, 0.011 for the 7 x 7).
    let speed = 600.0;
    let events = jittered_edge_events(speed, 0.4);
    let (own, wide_flow, _) = own_and_wide(&events, WideFitParams::default());
    let spread = |flow: &NormalFlow| {
        let mut r: Vec<f64> = (0..events.len())
            .filter(|&i| checkable(events.x[i], events.y[i], 3, 0.0))
            .filter_map(|i| speed_px(flow, i))
            .map(|s| s / speed)
            .collect();
        assert!(r.len() > 1000, "only {} valid", r.len());
        r.sort_by(f64::total_cmp);
        let med = r[r.len() / 2];
        let mut dev: Vec<f64> = r.iter().map(|x| (x - med).abs()).collect();
        dev.sort_by(f64::total_cmp);
        (med, dev[dev.len() / 2])
    };
    let ((own_med, own_mad), (wide_med, wide_mad)) = (spread(&own), spread(&wide_flow));
    println!(
        "jittered 600 px/s edge: own median {own_med:.4} MAD {own_mad:.4}, wide {wide_med:.4} MAD {wide_mad:.4}"
    );
    assert!(wide_mad < 0.7 * own_mad, "wide MAD {wide_mad}, own {own_mad}");
    assert!((wide_med - 1.0).abs() < 0.03, "wide median ratio {wide_med}");
}

#[test]
fn without_the_wide_fit_the_wide_flow_is_the_flow() {
    let events = jittered_edge_events(600.0, 0.4);
    let mut est = PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let (mut own, mut wide) = (NormalFlow::default(), NormalFlow::default());
    est.process_wide_into(&events, None, &mut own, Some(&mut wide))
        .expect("consistent");
    assert_eq!(own, wide);
    assert_eq!(est.stats().wide_fits, 0);
}

#[test]
fn bad_wide_fit_settings_are_refused_by_name() {
    let est = || PlaneFitEstimator::new(&camera(), PlaneFitParams::default()).expect("valid");
    let d = WideFitParams::default();
    for (wide, name) in [
        // Not larger than the fit's 5 x 5 window, or above MAX_RADIUS.
        (WideFitParams { radius: 2, ..d }, "wide_radius"),
        (WideFitParams { radius: 5, ..d }, "wide_radius"),
        // A check not larger than the wide window.
        (WideFitParams { check_radius: 3, ..d }, "wide_check_radius"),
        (WideFitParams { check_radius: 5, ..d }, "wide_check_radius"),
        (
            WideFitParams {
                min_speed_px_s: f64::NAN,
                ..d
            },
            "wide_min_speed",
        ),
        (
            WideFitParams {
                min_speed_px_s: -1.0,
                ..d
            },
            "wide_min_speed",
        ),
    ] {
        let err = est().with_wide_fit(wide).expect_err("refused").to_string();
        assert!(err.contains(name), "{wide:?}: {err}");
    }
    assert!(
        est()
            .with_wide_fit(WideFitParams { check_radius: 4, ..d })
            .is_ok()
    );
}
