use super::*;
use evseg_geometry::Camera;
use evseg_geometry::{planar_flow, rotational_flow, translational_flow};
use evseg_schemas::align::AlignError;

fn camera() -> CameraInfo {
    CameraInfo::pinhole(320, 240, 250.0, "test")
}

/// SplitMix64 (tests only): uniform in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

const T: [f64; 3] = [0.3, -0.1, 0.5];
const W: [f64; 3] = [0.05, -0.1, 0.2];
/// Plane `1/Z = (alpha x + beta y + gamma) / d`.
const PLANE: (f64, f64, f64, f64) = (0.1, -0.2, 1.0, 3.0);

fn plane_inv_z(x: f64, y: f64) -> f64 {
    (PLANE.0 * x + PLANE.1 * y + PLANE.2) / PLANE.3
}

/// Expected translational model `a` (crate docs, w = 0).
fn expected_a() -> [f64; 8] {
    let (al, be, ga, d) = PLANE;
    [
        T[2] * al,
        T[2] * be,
        T[2] * ga - T[0] * al,
        -T[0] * be,
        -T[0] * ga,
        T[2] * ga - T[1] * be,
        -T[1] * al,
        -T[1] * ga,
    ]
    .map(|v| v / d)
}

/// `n` events at random pixels; flow `u(x, y, in_object)`; a random gradient direction n0 per
/// event gives the normal flow vector `(u . n0) n0`, plus Gaussian-ish noise of `noise` along n0.
/// Events in the 60x60 px square at (200, 60) are "object" when `object` is set.
fn scene(
    n: usize,
    object: bool,
    noise: f64,
    u: impl Fn(f64, f64, bool) -> [f64; 2],
) -> (Events, NormalFlow, Vec<bool>) {
    let cam = Camera::new(&camera());
    let mut rng = Rng(42);
    let (mut ev, mut fl, mut truth) = (Events::with_capacity(n), NormalFlow::default(), vec![]);
    for i in 0..n {
        let (pu, pv) = ((rng.next() * 320.0) as u16, (rng.next() * 240.0) as u16);
        let in_obj = object && (200..260).contains(&pu) && (60..120).contains(&pv);
        let [x, y] = cam.pixel_to_normalized(f64::from(pu), f64::from(pv));
        let flow = u(x, y, in_obj);
        let th = rng.next() * std::f64::consts::TAU;
        let n0 = [th.cos(), th.sin()];
        // Sum of 4 uniforms: roughly Gaussian, standard deviation `noise`.
        let e = noise * ((0..4).map(|_| rng.next()).sum::<f64>() - 2.0) * 3f64.sqrt();
        let len = flow[0] * n0[0] + flow[1] * n0[1] + e;
        ev.push(i as f64 * 1e-6, pu, pv, 1);
        fl.nx.push((len * n0[0]) as f32);
        fl.ny.push((len * n0[1]) as f32);
        fl.confidence.push(1.0);
        truth.push(in_obj);
    }
    (ev, fl, truth)
}

fn camera_flow(x: f64, y: f64, _: bool) -> [f64; 2] {
    let tr = translational_flow(x, y, T, plane_inv_z(x, y));
    let ro = rotational_flow(x, y, W);
    [tr[0] + ro[0], tr[1] + ro[1]]
}

/// The camera's flow on the plane, except inside the object: a box 1.5 m away moving with
/// (-1, 0.4, 0) m/s relative to the camera, seen with the same camera rotation.
fn flow_with_object(x: f64, y: f64, obj: bool) -> [f64; 2] {
    if !obj {
        return camera_flow(x, y, false);
    }
    let tr = translational_flow(x, y, [T[0] + 1.0, T[1] - 0.4, T[2]], 1.0 / 1.5);
    let ro = rotational_flow(x, y, W);
    [tr[0] + ro[0], tr[1] + ro[1]]
}

/// Huber weights in every slice.
fn huber() -> PlanarParams {
    PlanarParams {
        fit: FitParams {
            robust: Robust::Huber { k: 1.345 },
            ..Default::default()
        },
        robust_needs_previous: false,
        fit_memory: 0.0,
        start_centre_weight: 1.0,
        ..Default::default()
    }
}

/// Plain least squares, smoothing with `sigma_px` itself on the small test camera (these
/// tests measure the split against the smoothing's ramp at the default 16 px).
fn ls() -> PlanarParams {
    PlanarParams {
        fit: FitParams {
            robust: Robust::LeastSquares,
            ..Default::default()
        },
        sigma_reference_focal_px: 0.0,
        // Each slice fitted alone and alike: these tests segment one slice several times.
        fit_memory: 0.0,
        start_centre_weight: 1.0,
        ..Default::default()
    }
}

/// The smoothing keeps its angle: `sigma_px` at the reference focal length, scaled on others.
#[test]
fn the_smoothing_scales_with_the_focal_length() {
    let p = PlanarParams::default();
    let cam = |f: f64| CameraInfo::pinhole(640, 480, f, "test");
    assert_eq!(p.sigma_on(&cam(550.0)), 16.0);
    assert!((p.sigma_on(&cam(275.0)) - 8.0).abs() < 1e-12);
    assert!((p.sigma_on(&cam(1100.0)) - 32.0).abs() < 1e-12);
    let fixed = PlanarParams {
        sigma_reference_focal_px: 0.0,
        ..p
    };
    assert_eq!(fixed.sigma_on(&cam(275.0)), 16.0);
    // A focal length that is not a positive number leaves sigma as given.
    assert_eq!(p.sigma_on(&cam(f64::NAN)), 16.0);
    let bad = PlanarParams {
        sigma_reference_focal_px: -1.0,
        ..p
    };
    assert!(PlanarSegmenter::new(bad).is_err());
}

#[test]
fn plane_gives_zero_residuals_the_expected_model_and_all_background() {
    let (ev, fl, _) = scene(3000, false, 0.0, camera_flow);
    for params in [ls(), huber()] {
        let mut s = PlanarSegmenter::new(params).unwrap();
        let r = s.segment(&camera(), &ev, &fl, Some(W.into())).unwrap();
        assert!(r.derotated);
        assert_eq!(r.fitted_events, 3000);
        let max_r = r.residuals.residual.iter().fold(0f32, |m, v| m.max(v.abs()));
        assert!(max_r < 1e-5, "max residual {max_r}");
        for (a, e) in r.residuals.model.iter().zip(expected_a()) {
            assert!(
                (a - e).abs() < 1e-5,
                "{:?} vs {:?}",
                r.residuals.model,
                expected_a()
            );
        }
        assert!(!r.has_foreground);
        assert!(r.residuals.background.iter().all(|&b| b));
    }
}

#[test]
fn noisy_plane_is_still_all_background() {
    // 0.005 normalized units/s = 1.25 px/s at f = 250.
    let (ev, fl, _) = scene(3000, false, 0.005, camera_flow);
    let r = PlanarSegmenter::new(PlanarParams::default())
        .unwrap()
        .segment(&camera(), &ev, &fl, Some(W.into()))
        .unwrap();
    let bg = r.residuals.background.iter().filter(|&&b| b).count();
    assert_eq!(bg, 3000, "split {:?}", r.split);
}

fn check_object_found(params: PlanarParams, noise: f64) {
    let (ev, fl, truth) = scene(6000, true, noise, flow_with_object);
    let r = PlanarSegmenter::new(params)
        .unwrap()
        .segment(&camera(), &ev, &fl, Some(W.into()))
        .unwrap();
    let obj = truth.iter().filter(|&&t| t).count();
    let fg_hit = (0..ev.len())
        .filter(|&i| truth[i] && !r.residuals.background[i])
        .count();
    let bg_hit = (0..ev.len())
        .filter(|&i| !truth[i] && r.residuals.background[i])
        .count();
    let (fg_rate, bg_rate) = (
        fg_hit as f64 / obj as f64,
        bg_hit as f64 / (ev.len() - obj) as f64,
    );
    assert!(obj > 150, "object has {obj} events");
    assert!(r.has_foreground);
    assert!(fg_rate > 0.9, "object events called foreground: {fg_rate}");
    assert!(bg_rate > 0.9, "background events called background: {bg_rate}");
    // The object's raw residuals are far larger than the background's.
    let mean_abs = |want: bool| {
        let v: Vec<f64> = (0..ev.len())
            .filter(|&i| truth[i] == want)
            .map(|i| f64::from(r.residuals.residual[i]).abs())
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    assert!(
        mean_abs(true) > 5.0 * mean_abs(false),
        "{} {}",
        mean_abs(true),
        mean_abs(false)
    );
}

#[test]
fn moving_object_is_foreground_with_robust_fit() {
    check_object_found(huber(), 0.01);
}

#[test]
fn moving_object_is_foreground_with_plain_least_squares() {
    check_object_found(ls(), 0.01);
}

#[test]
fn robust_fit_recovers_the_background_model_despite_the_object() {
    let (ev, fl, _) = scene(6000, true, 0.0, flow_with_object);
    let r = PlanarSegmenter::new(huber())
        .unwrap()
        .segment(&camera(), &ev, &fl, Some(W.into()))
        .unwrap();
    let a = &r.residuals.model;
    assert!(model_error(a) < 0.01, "model {a:?} vs {:?}", expected_a());
}

/// Distance of a fitted model from [`expected_a`].
fn model_error(a: &[f64]) -> f64 {
    a.iter()
        .zip(expected_a())
        .map(|(a, e)| (a - e).powi(2))
        .sum::<f64>()
        .sqrt()
}

#[test]
fn the_previous_foreground_is_left_out_of_the_plain_fit() {
    let (ev, fl, truth) = scene(6000, true, 0.0, flow_with_object);
    let labels: Vec<u32> = truth.iter().map(|&o| u32::from(o)).collect();
    // The paper's linear split, whose midpoint bounds how far the smoothing's ramp past the
    // object counts as foreground (a compressed split_power lowers the threshold, see
    // `a_compressed_split_spreads_further_past_a_clean_object`).
    let mut seg = PlanarSegmenter::new(PlanarParams {
        split_power: 1.0,
        ..ls()
    })
    .unwrap();
    // No previous slice yet: the labels cannot be placed and are not used.
    let first = seg
        .segment_with_previous(&camera(), &ev, &fl, Some(W.into()), Some(&labels))
        .unwrap();
    assert!(!first.previous_applied);
    let pulled = model_error(&first.residuals.model);
    assert!(pulled > 1e-3, "the plain fit is pulled by the object: {pulled}");
    // The same slice again with its labels: the object's equations are out, the plane exact.
    let second = seg
        .segment_with_previous(&camera(), &ev, &fl, Some(W.into()), Some(&labels))
        .unwrap();
    assert!(second.previous_applied);
    let clean = model_error(&second.residuals.model);
    assert!(clean < 1e-5, "model error {clean} (f32 flow), pulled {pulled}");
    // Every object event is foreground; the smoothing (sigma_px) spreads a little past it.
    let spread = spread_past_object(&second, &truth);
    assert!(
        spread * 20 < truth.len(),
        "{spread} background events called foreground"
    );
    // Labels of another slice's length are ignored, not a crash; weight 1 turns it off.
    let third = seg
        .segment_with_previous(&camera(), &ev, &fl, Some(W.into()), Some(&labels[1..]))
        .unwrap();
    assert!(!third.previous_applied);
    let mut off = PlanarSegmenter::new(PlanarParams {
        previous: PreviousParams {
            weight: 1.0,
            ..PreviousParams::default()
        },
        ..ls()
    })
    .unwrap();
    off.segment(&camera(), &ev, &fl, Some(W.into())).unwrap();
    let r = off
        .segment_with_previous(&camera(), &ev, &fl, Some(W.into()), Some(&labels))
        .unwrap();
    assert!(!r.previous_applied);
    assert!((model_error(&r.residuals.model) - pulled).abs() < 1e-12);
}

#[test]
fn rotation_is_removed_with_omega_and_absorbed_without() {
    let rot = |x: f64, y: f64, _: bool| rotational_flow(x, y, W);
    let (ev, fl, _) = scene(2000, false, 0.0, rot);
    let mut s = PlanarSegmenter::new(ls()).unwrap();
    let r = s.segment(&camera(), &ev, &fl, Some(W.into())).unwrap();
    assert!(r.residuals.residual.iter().all(|v| v.abs() < 1e-5));
    assert!(
        r.residuals.model.iter().all(|v| v.abs() < 1e-5),
        "{:?}",
        r.residuals.model
    );
    // Without the IMU the plane model takes the rotation: a = (-wy, wx, 0, wz, -wy, 0, -wz, wx).
    let r = s.segment(&camera(), &ev, &fl, None).unwrap();
    assert!(!r.derotated);
    let want = [-W[1], W[0], 0.0, W[2], -W[1], 0.0, -W[2], W[0]];
    for (a, e) in r.residuals.model.iter().zip(want) {
        assert!((a - e).abs() < 1e-5, "{:?}", r.residuals.model);
    }
    // And planar_flow of that model is the rotational flow.
    let f = planar_flow(0.2, -0.1, &want);
    let g = rotational_flow(0.2, -0.1, W);
    assert!((f[0] - g[0]).abs() < 1e-12 && (f[1] - g[1]).abs() < 1e-12);
}

#[test]
fn invalid_flow_gives_nan_and_too_few_events_give_no_model() {
    let (ev, mut fl, _) = scene(500, false, 0.0, camera_flow);
    for i in (0..500).step_by(2) {
        fl.confidence[i] = 0.0;
    }
    let mut s = PlanarSegmenter::new(PlanarParams::default()).unwrap();
    let r = s.segment(&camera(), &ev, &fl, Some(W.into())).unwrap();
    assert_eq!(r.fitted_events, 250);
    for i in 0..500 {
        assert_eq!(r.residuals.residual[i].is_nan(), i % 2 == 0);
    }
    assert_eq!(r.residuals.model.len(), 8);
    let few = 5;
    let mut ev5 = Events::default();
    ev5.extend_from(&ev, 0..few);
    let fl5 = NormalFlow {
        nx: fl.nx[..few].to_vec(),
        ny: fl.ny[..few].to_vec(),
        confidence: vec![1.0; few],
    };
    let r = s.segment(&camera(), &ev5, &fl5, Some(W.into())).unwrap();
    assert!(r.residuals.model.is_empty());
    assert!(r.residuals.background.iter().all(|&b| b));
    let r = s
        .segment(&camera(), &Events::default(), &NormalFlow::default(), None)
        .unwrap();
    assert!(r.residuals.residual.is_empty() && r.residuals.model.is_empty());
}

#[test]
fn malformed_input_is_an_error() {
    let (mut ev, mut fl, _) = scene(20, false, 0.0, camera_flow);
    let mut s = PlanarSegmenter::new(PlanarParams::default()).unwrap();
    assert!(matches!(
        s.segment(&camera(), &ev, &fl, Some([f64::NAN, 0.0, 0.0].into())),
        Err(PlanarError::Omega(_))
    ));
    fl.nx.push(0.0);
    assert!(matches!(
        s.segment(&camera(), &ev, &fl, None),
        Err(PlanarError::Input(AlignError::FlowLength {
            nx: 21,
            events: 20,
            ..
        }))
    ));
    fl.nx.pop();
    ev.y[7] = 240;
    assert!(matches!(
        s.segment(&camera(), &ev, &fl, None),
        Err(PlanarError::Input(AlignError::EventOutside {
            index: 7,
            y: 240,
            ..
        }))
    ));
    ev.t.pop();
    assert_eq!(
        s.segment(&camera(), &ev, &fl, None),
        Err(PlanarError::Input(AlignError::EventColumns))
    );
    let (ev, fl, _) = scene(20, false, 0.0, camera_flow);
    assert_eq!(
        s.segment_weighted(&camera(), &ev, &fl, None, Some(&[1.0; 19])),
        Err(PlanarError::EventWeights {
            weights: 19,
            events: 20
        })
    );
    let previous = |q: PreviousParams| PlanarParams {
        previous: q,
        ..Default::default()
    };
    for p in [
        previous(PreviousParams {
            weight: 1.5,
            ..Default::default()
        }),
        previous(PreviousParams {
            weight: f64::NAN,
            ..Default::default()
        }),
        previous(PreviousParams {
            min_free_share: -0.1,
            ..Default::default()
        }),
        previous(PreviousParams {
            cell_px: 0,
            ..Default::default()
        }),
        PlanarParams {
            cell_px: 0,
            ..Default::default()
        },
        PlanarParams {
            sigma_px: -1.0,
            ..Default::default()
        },
        PlanarParams {
            residual_length_k: -1.0,
            ..Default::default()
        },
        PlanarParams {
            residual_length_k: f64::NAN,
            ..Default::default()
        },
        PlanarParams {
            split_power: 1.5,
            ..Default::default()
        },
        PlanarParams {
            split_power: -0.5,
            ..Default::default()
        },
        PlanarParams {
            split_power: f64::NAN,
            ..Default::default()
        },
        PlanarParams {
            fit_memory: -1.0,
            ..Default::default()
        },
        PlanarParams {
            start_centre_weight: 1.5,
            ..Default::default()
        },
        PlanarParams {
            start_centre_weight: f64::NAN,
            ..Default::default()
        },
        PlanarParams {
            fit_memory: f64::INFINITY,
            ..Default::default()
        },
        PlanarParams {
            fit_memory_gap_s: f64::NAN,
            ..Default::default()
        },
        PlanarParams {
            fit: FitParams {
                robust: Robust::Huber { k: 0.0 },
                ..Default::default()
            },
            ..Default::default()
        },
    ] {
        assert!(matches!(PlanarSegmenter::new(p), Err(PlanarError::Param(_))));
    }
}

#[test]
fn long_flows_residuals_are_discounted_relative_to_the_median_length() {
    let sample = |n: f64| FlowSample {
        index: 0,
        x: 0.0,
        y: 0.0,
        n0: [1.0, 0.0],
        n,
        n_derot: n,
        confidence: 1.0,
    };
    let samples: Vec<FlowSample> = [0.5, 1.0, 1.0, 2.0, 8.0].into_iter().map(sample).collect();
    // Median length 1: the median sample keeps its residual, k = 6.
    let d = length_discount(&samples, 6.0);
    assert!((d(1) - 1.0).abs() < 1e-12);
    assert!((d(0) - 7.0 / 6.5).abs() < 1e-12, "shorter: a little more");
    assert!((d(3) - 7.0 / 8.0).abs() < 1e-12);
    assert!((d(4) - 7.0 / 14.0).abs() < 1e-12, "8x the median: half");
    // Off, and no samples.
    let off = length_discount(&samples, 0.0);
    assert!((0..5).all(|i| off(i) == 1.0));
    let none = length_discount(&[], 6.0);
    assert_eq!(none(0), 1.0);
}

/// Background events `r` calls foreground, after checking that it calls every object event
/// (`truth`) foreground.
fn spread_past_object(r: &PlanarResult, truth: &[bool]) -> usize {
    let mut spread = 0;
    for (i, &o) in truth.iter().enumerate() {
        let background = r.residuals.background[i];
        assert!(!(o && background), "object event {i}");
        spread += usize::from(!o && !background);
    }
    spread
}

/// The result of segmenting the slice `(ev, fl)` a second time with `labels` as the previous
/// slice's (the first time they cannot be placed), which must then be applied.
fn with_previous(params: PlanarParams, ev: &Events, fl: &NormalFlow, labels: &[u32]) -> PlanarResult {
    let mut seg = PlanarSegmenter::new(params).unwrap();
    seg.segment_with_previous(&camera(), ev, fl, Some(W.into()), Some(labels))
        .unwrap();
    let second = seg
        .segment_with_previous(&camera(), ev, fl, Some(W.into()), Some(labels))
        .unwrap();
    assert!(second.previous_applied);
    second
}

/// With an exact background model the only foreground past the object is the smoothing's ramp;
/// the default compressed split takes more of it than the linear one, but stays bounded.
#[test]
fn a_compressed_split_spreads_further_past_a_clean_object() {
    let (ev, fl, truth) = scene(6000, true, 0.0, flow_with_object);
    let labels: Vec<u32> = truth.iter().map(|&o| u32::from(o)).collect();
    let spread = |split_power: f64| {
        let r = with_previous(PlanarParams { split_power, ..ls() }, &ev, &fl, &labels);
        spread_past_object(&r, &truth)
    };
    let (linear, default) = (spread(1.0), spread(PlanarParams::default().split_power));
    assert!(linear < default, "{linear} {default}");
    assert!(
        default * 10 < truth.len(),
        "{default} background events called foreground"
    );
}

/// The default robust fit waits for the previous foreground: the first slice gets the plain
/// fit, the next one (with its mask) the robust one.
#[test]
fn the_robust_fit_is_used_only_with_the_previous_foreground() {
    let (ev, fl, truth) = scene(6000, true, 0.0, flow_with_object);
    let labels: Vec<u32> = truth.iter().map(|&o| u32::from(o)).collect();
    let d = PlanarParams {
        fit_memory: 0.0,
        start_centre_weight: 1.0,
        ..PlanarParams::default()
    };
    assert!(d.robust_needs_previous && d.fit.robust != Robust::LeastSquares);
    let model = |params: PlanarParams, labels: Option<&[u32]>| {
        let mut seg = PlanarSegmenter::new(params).unwrap();
        let first = seg
            .segment_with_previous(&camera(), &ev, &fl, Some(W.into()), labels)
            .unwrap();
        assert!(!first.previous_applied);
        first.residuals.model
    };
    // No previous slice: exactly the plain fit, not the robust one.
    assert_eq!(model(d, Some(&labels)), model(ls(), None));
    assert_ne!(model(d, Some(&labels)), model(huber(), None));
    // The second slice, with the first one's labels (half the object's equations left in):
    // the robust fit.
    let half: Vec<u32> = labels
        .iter()
        .enumerate()
        .map(|(i, &l)| l * (i % 2) as u32)
        .collect();
    let masked = |params: PlanarParams| with_previous(params, &ev, &fl, &half).residuals.model;
    assert_eq!(masked(d), masked(huber()));
    assert_ne!(masked(d), masked(ls()));
}

/// The robust scale comes from the equations in the fit: equations weighted 0 (the previous
/// foreground) with large residuals must not loosen the Huber weights of the fitted ones. The
/// fit with them weighted 0 is the fit without them; with the scale over every equation (the
/// code before 2026-11-28) the zero-weight half raised the median residual tenfold, the Huber
/// weights of the fitted outliers stayed near 1 and the fit followed them.
#[test]
fn equations_weighted_zero_do_not_set_the_robust_scale() {
    let a_true = expected_a();
    let mut rng = Rng(7);
    let eq = |off: f64, rng: &mut Rng| {
        let (x, y) = (rng.next() - 0.5, rng.next() - 0.5);
        let th = rng.next() * std::f64::consts::TAU;
        let e = Equation::new(x, y, [th.cos(), th.sin()], 0.0);
        let b = e.g.iter().zip(&a_true).map(|(g, a)| g * a).sum::<f64>() + off + 0.002 * (rng.next() - 0.5);
        Equation { b, ..e }
    };
    // 300 fitted equations, a fifth of them off by +0.3 (another motion), then 400 left out
    // (weight 0) off by +1.
    let mut eqs: Vec<Equation> = (0..300)
        .map(|i| eq(if i % 5 == 0 { 0.3 } else { 0.0 }, &mut rng))
        .collect();
    let fitted = eqs.clone();
    eqs.extend((0..400).map(|_| eq(1.0, &mut rng)));
    let base: Vec<f64> = (0..eqs.len()).map(|i| if i < 300 { 1.0 } else { 0.0 }).collect();
    let huber = FitParams {
        robust: Robust::Huber { k: 1.345 },
        ..FitParams::default()
    };
    let with_zeros = fit_planar_weighted(&eqs, Some(&base), &huber).unwrap();
    assert_eq!(with_zeros, fit_planar(&fitted, &huber).unwrap());
    // And the robust fit is closer to the model than plain least squares on the same equations.
    let err = |a: &[f64; 8]| {
        a.iter()
            .zip(&a_true)
            .map(|(a, t)| (a - t).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let plain = fit_planar(&fitted, &FitParams::default()).unwrap();
    assert!(
        err(&with_zeros) < 0.5 * err(&plain),
        "{} vs {}",
        err(&with_zeros),
        err(&plain)
    );
}

/// Noisy equations of `a_true` at `count` random points with `x` in `x_range` (normalized
/// units); a random gradient direction each.
fn strip_equations(
    a_true: &[f64; 8],
    count: usize,
    x_range: (f64, f64),
    noise: f64,
    rng: &mut Rng,
) -> Vec<Equation> {
    (0..count)
        .map(|_| {
            let x = x_range.0 + (x_range.1 - x_range.0) * rng.next();
            let y = rng.next() - 0.5;
            let th = rng.next() * std::f64::consts::TAU;
            let e = Equation::new(x, y, [th.cos(), th.sin()], 0.0);
            let b = e.g.iter().zip(a_true).map(|(g, a)| g * a).sum::<f64>() + noise * (rng.next() - 0.5);
            Equation { b, ..e }
        })
        .collect()
}

/// The largest error of the flow a model predicts over the whole view (normalized units/s).
fn worst_flow_error(a: &[f64; 8], a_true: &[f64; 8]) -> f64 {
    let mut worst: f64 = 0.0;
    for i in 0..=10 {
        for j in 0..=10 {
            let (x, y) = (f64::from(i) * 0.1 - 0.5, f64::from(j) * 0.1 - 0.5);
            let (f, g) = (planar_flow(x, y, a), planar_flow(x, y, a_true));
            worst = worst.max((f[0] - g[0]).hypot(f[1] - g[1]));
        }
    }
    worst
}

/// The background seen only in a strip at the image's left edge (an object covering the
/// rest): fitted alone, the 8-parameter model extrapolates the strip's noise over the view;
/// with the previous slice's fit over the whole view as a prior it stays close. A prior of
/// weight 0 is the plain fit, to the bit.
#[test]
fn the_previous_fit_holds_the_model_where_the_equations_leave_it_open() {
    let a_true = expected_a();
    let mut rng = Rng(11);
    let full = strip_equations(&a_true, 2000, (-0.5, 0.5), 0.01, &mut rng);
    let strip = strip_equations(&a_true, 300, (-0.5, -0.4), 0.01, &mut rng);
    let p = FitParams::default();
    let prior = fit_planar_with_prior(&full, None, &p, None).unwrap();
    let alone = fit_planar(&strip, &p).unwrap();
    let held = fit_planar_with_prior(&strip, None, &p, Some((&prior, 1.0)))
        .unwrap()
        .a;
    let (e_alone, e_held) = (
        worst_flow_error(&alone, &a_true),
        worst_flow_error(&held, &a_true),
    );
    assert!(e_held < 0.01, "with the prior: {e_held}");
    assert!(
        e_alone > 10.0 * e_held,
        "alone {e_alone}, with the prior {e_held}"
    );
    let zero = fit_planar_with_prior(&strip, None, &p, Some((&prior, 0.0)))
        .unwrap()
        .a;
    assert_eq!(zero, alone);
}

/// The segmenter carries its fit to the next slice only when that slice follows within
/// `fit_memory_gap_s` and its flow is derotated alike; otherwise the fit is the fit of a fresh
/// segmenter.
#[test]
fn the_fit_memory_reaches_only_the_next_slice_in_the_same_space() {
    let (ev_a, fl_a, _) = scene(3000, true, 0.0, flow_with_object);
    let (mut ev_b, fl_b, _) = scene(3000, false, 0.02, camera_flow);
    let params = PlanarParams {
        fit_memory: 1.0,
        ..ls()
    };
    let model = |first: Option<&Events>, b: &Events, w: Option<RotationRate>| {
        let mut seg = PlanarSegmenter::new(params).unwrap();
        if let Some(a) = first {
            seg.segment(&camera(), a, &fl_a, Some(W.into())).unwrap();
        }
        seg.segment(&camera(), b, &fl_b, w).unwrap().residuals.model
    };
    let fresh = model(None, &ev_b, Some(W.into()));
    // Slice b right after a (its events from 0 s, a's up to 3 ms): a's fit is its prior.
    assert_ne!(model(Some(&ev_a), &ev_b, Some(W.into())), fresh);
    // Raw flow after derotated flow: no prior.
    assert_eq!(model(Some(&ev_a), &ev_b, None), model(None, &ev_b, None));
    // Slice b a second later: no prior.
    for t in &mut ev_b.t {
        *t += 1.0;
    }
    assert_eq!(
        model(Some(&ev_a), &ev_b, Some(W.into())),
        model(None, &ev_b, Some(W.into()))
    );
    // Memory 0: no prior.
    let off = PlanarParams {
        fit_memory: 0.0,
        ..params
    };
    let mut seg = PlanarSegmenter::new(off).unwrap();
    seg.segment(&camera(), &ev_a, &fl_a, Some(W.into())).unwrap();
    ev_b.t.iter_mut().for_each(|t| *t -= 1.0);
    let r = seg.segment(&camera(), &ev_b, &fl_b, Some(W.into())).unwrap();
    assert_eq!(r.residuals.model, fresh);
}

/// The first slice's centre ramp: `f` at the centre, 1 at the border, linear between; a slice
/// with the previous fit as its prior is not weighted, and `start_centre_weight` 1 is the plain
/// first fit.
#[test]
fn the_first_fit_weighs_the_view_border_more() {
    assert!((centre_ramp(160, 120, 320, 240, 0.25) - (0.25 + 0.75 * (0.5 / 120.0))).abs() < 1e-12);
    assert!((centre_ramp(0, 120, 320, 240, 0.25) - (0.25 + 0.75 * (159.5 / 160.0))).abs() < 1e-12);
    assert!((centre_ramp(240, 120, 320, 240, 0.25) - (0.25 + 0.75 * (80.5 / 160.0))).abs() < 1e-12);
    assert_eq!(centre_ramp(10, 10, 320, 240, 1.0), 1.0);
    let (ev, fl, _) = scene(6000, true, 0.0, flow_with_object);
    // The models of the same slice segmented twice in a row by one segmenter.
    let twice = |start_centre_weight: f64, fit_memory: f64| {
        let mut seg = PlanarSegmenter::new(PlanarParams {
            start_centre_weight,
            fit_memory,
            ..ls()
        })
        .unwrap();
        let mut model = || {
            seg.segment(&camera(), &ev, &fl, Some(W.into()))
                .unwrap()
                .residuals
                .model
        };
        (model(), model())
    };
    let first = |start_centre_weight: f64| twice(start_centre_weight, 1.0);
    let (plain, plain_next) = first(1.0);
    let (ramped, ramped_next) = first(0.25);
    // The object (a square right of the centre) pulls the ramped fit less.
    assert_ne!(plain, ramped);
    assert!(
        model_error(&ramped) < model_error(&plain),
        "{} {}",
        model_error(&ramped),
        model_error(&plain)
    );
    let fresh = twice(1.0, 0.0).0;
    assert_eq!(plain, fresh);
    // The second slices differ only through their priors (the first fits).
    assert_ne!(plain_next, ramped_next);
    // Without the memory the ramp still weighs the first slice only.
    let (a, b) = twice(0.25, 0.0);
    assert_eq!(a, ramped);
    assert_eq!(b, fresh);
}

#[test]
fn iteration_counts_beyond_their_bounds_are_refused_naming_the_parameter() {
    let d = PlanarParams::default();
    let mut many_rounds = d;
    many_rounds.fit.iterations = MAX_ROBUST_ITERATIONS + 1;
    let mut no_iterations = d;
    no_iterations.two_means_iter = 0;
    let mut many_iterations = d;
    many_iterations.two_means_iter = MAX_TWO_MEANS_ITER + 1;
    for (p, name) in [
        (many_rounds, "robust_iterations"),
        (no_iterations, "two_means_iter"),
        (many_iterations, "two_means_iter"),
    ] {
        let e = PlanarSegmenter::new(p)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default();
        assert!(e.contains(name), "{name}: {e}");
    }
    let mut at_bounds = d;
    at_bounds.fit.iterations = MAX_ROBUST_ITERATIONS;
    at_bounds.two_means_iter = MAX_TWO_MEANS_ITER;
    assert!(PlanarSegmenter::new(at_bounds).is_ok());
}
