use super::*;
use evseg_geometry::{EgomotionParams, translational_flow};

const F: f64 = 150.0;

/// A block of events: `(x0, x1, y0, y1, group, translation)`, pixels and normalized units/s.
type Block = (u16, u16, u16, u16, u32, [f64; 3]);

fn camera() -> CameraInfo {
    CameraInfo::pinhole(200, 150, F, "test")
}

/// Blocks of events `(x0, x1, y0, y1, group, t)` with flow of translation `t` at depth 1.
fn build(blocks: &[Block], groups: usize) -> (Events, NormalFlow, CoarseSegmentation) {
    let cam = camera();
    let mut ev = Events::default();
    let mut flow = NormalFlow::default();
    let mut coarse = CoarseSegmentation {
        map_overlap: vec![0.0; groups],
        ..CoarseSegmentation::default()
    };
    coarse.map_overlap[0] = 1.0;
    let mut k = 0u32;
    for &(x0, x1, y0, y1, g, t) in blocks {
        for v in (y0..y1).step_by(2) {
            for u in (x0..x1).step_by(2) {
                k += 1;
                let (x, y) = ((f64::from(u) - cam.cx) / F, (f64::from(v) - cam.cy) / F);
                let fl = translational_flow(x, y, t, 1.0);
                let ang = f64::from(k) * 2.399963;
                let (mut n0, mut nl) = ([ang.cos(), ang.sin()], 0.0);
                nl += fl[0] * n0[0] + fl[1] * n0[1];
                if nl < 0.0 {
                    nl = -nl;
                    n0 = [-n0[0], -n0[1]];
                }
                ev.push(f64::from(k) * 1e-6, u, v, 1);
                flow.nx.push((nl * n0[0]) as f32);
                flow.ny.push((nl * n0[1]) as f32);
                flow.confidence.push(1.0);
                coarse.group.push(g);
                coarse.residual.push(0.0);
            }
        }
    }
    (ev, flow, coarse)
}

fn merge(blocks: &[Block], groups: usize) -> HierResult {
    let (ev, flow, coarse) = build(blocks, groups);
    let mut m = HierarchicalMerger::new(HierParams::default()).unwrap();
    m.merge(&camera(), &ev, &flow, Some([0.0; 3].into()), &coarse)
        .unwrap()
}

const BG: [f64; 3] = [0.3, 0.0, 0.1];

#[test]
fn two_touching_clusters_with_equal_translation_merge() {
    let t = [-0.4, 0.3, 0.0];
    let r = merge(
        &[
            (0, 200, 0, 40, 0, BG),
            (100, 130, 60, 90, 1, t),
            (130, 160, 60, 90, 2, t),
        ],
        3,
    );
    assert_eq!(r.merges, 1);
    let s = &r.segmentation;
    assert_eq!(s.segments.len(), 2, "{:?}", s.segments);
    let obj = &s.segments[1];
    assert_eq!(obj.label, 1);
    for (got, want) in obj.translation.iter().zip(t) {
        assert!((got - want).abs() < 1e-3, "{:?}", obj.translation);
    }
    assert!((obj.bbox[0] - 100.0).abs() < 1e-3 && obj.bbox[2] >= 158.0);
    assert!(s.egomotion.valid);
}

#[test]
fn different_translations_or_separate_boxes_do_not_merge() {
    let r = merge(
        &[
            (0, 200, 0, 40, 0, BG),
            (100, 130, 60, 90, 1, [-0.4, 0.3, 0.0]),
            (130, 160, 60, 90, 2, [0.4, 0.3, 0.0]),
            // Same motion as group 1, but far away.
            (10, 40, 100, 130, 3, [-0.4, 0.3, 0.0]),
        ],
        4,
    );
    assert_eq!(r.merges, 0);
    assert_eq!(r.segmentation.segments.len(), 4);
    let labels: std::collections::BTreeSet<u32> = r.segmentation.label.iter().copied().collect();
    assert_eq!(labels.into_iter().collect::<Vec<_>>(), vec![0, 1, 2, 3]);
}

#[test]
fn the_background_penalty_keeps_an_object_with_background_like_motion_apart() {
    // The object moves like the background at depth 1.5 (motion term -0.04); only the map says
    // it is not background.
    let t_obj = [BG[0] * 1.5, BG[1] * 1.5, BG[2] * 1.5];
    let blocks = [(0, 200, 0, 62, 0, BG), (60, 100, 60, 100, 1, t_obj)];
    let (ev, flow, coarse) = build(&blocks, 2);
    let mut m = HierarchicalMerger::new(HierParams::default()).unwrap();
    let r = m.merge(&camera(), &ev, &flow, None, &coarse).unwrap();
    assert_eq!(r.merges, 0);
    let mut on_map = coarse.clone();
    on_map.map_overlap[1] = 1.0;
    let r = m.merge(&camera(), &ev, &flow, None, &on_map).unwrap();
    assert_eq!(r.merges, 1);
    assert!(r.segmentation.label.iter().all(|&l| l == 0));
}

#[test]
fn small_segments_become_background_and_unassigned_events_are_filled() {
    let (mut ev, mut flow, mut coarse) = build(
        &[(0, 200, 0, 150, 0, BG), (100, 104, 60, 64, 1, [-0.4, 0.3, 0.0])],
        2,
    );
    // An event without flow among the background.
    ev.push(1.0, 50, 50, 0);
    flow.nx.push(0.0);
    flow.ny.push(0.0);
    flow.confidence.push(0.0);
    coarse.group.push(CoarseSegmentation::UNASSIGNED);
    coarse.residual.push(f32::NAN);
    let mut m = HierarchicalMerger::new(HierParams::default()).unwrap();
    let r = m.merge(&camera(), &ev, &flow, None, &coarse).unwrap();
    assert_eq!(r.dropped_small, 1);
    assert!(r.segmentation.label.iter().all(|&l| l == 0));
    assert_eq!(r.segmentation.segments.len(), 1);
    assert_eq!(r.segmentation.segments[0].events as usize, ev.len());
}

#[test]
fn malformed_input_is_an_error() {
    let (ev, flow, coarse) = build(&[(0, 20, 0, 20, 0, BG)], 1);
    let mut m = HierarchicalMerger::new(HierParams::default()).unwrap();
    let mut bad = coarse.clone();
    bad.group[2] = 7;
    let e = m.merge(&camera(), &ev, &flow, None, &bad).unwrap_err();
    assert!(
        matches!(
            e,
            HierError::Group {
                index: 2,
                group: 7,
                ..
            }
        ),
        "{e}"
    );
    bad.residual.pop();
    let e = m.merge(&camera(), &ev, &flow, None, &bad).unwrap_err();
    assert!(
        matches!(
            e,
            HierError::Length {
                what: "coarse.residual",
                ..
            }
        ),
        "{e}"
    );
    let e = m
        .merge(
            &camera(),
            &ev,
            &flow,
            Some([f64::INFINITY, 0.0, 0.0].into()),
            &coarse,
        )
        .unwrap_err();
    assert!(matches!(e, HierError::Omega(_)), "{e}");
    let mut short = flow.clone();
    short.nx.pop();
    assert!(matches!(
        m.merge(&camera(), &ev, &short, None, &coarse),
        Err(HierError::Align(_))
    ));
    assert!(
        HierarchicalMerger::new(HierParams {
            lambda: -1.0,
            ..HierParams::default()
        })
        .is_err()
    );
}

#[test]
fn similarity_matches_the_paper() {
    let t = [1.0, 0.0, 0.0];
    assert_eq!(similarity(t, t, 0.1, 0.1, 0.5), 0.0);
    assert!((similarity(t, [2.0, 0.0, 0.0], 0.0, 0.0, 0.5) + 0.2).abs() < 1e-12);
    assert!((similarity(t, [0.0, 1.0, 0.0], 0.0, 0.0, 0.5) + 1.0).abs() < 1e-12);
    assert!((similarity(t, [-1.0, 0.0, 0.0], 0.2, 0.0, 0.5) + 2.0 + 0.02).abs() < 1e-12);
    assert!(boxes_touch([0.0, 0.0, 10.0, 10.0], [11.0, 5.0, 20.0, 8.0], 2.0));
    assert!(!boxes_touch([0.0, 0.0, 10.0, 10.0], [13.0, 5.0, 20.0, 8.0], 2.0));
}

/// Events at times `t0` and `t1` (seconds): a slice whose midpoint is their mean.
fn events_between(t0: f64, t1: f64) -> Events {
    let mut ev = Events::default();
    ev.push(t0, 1, 1, 1);
    ev.push(t1, 2, 2, 0);
    ev
}

fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    rigid::angle_between(a, b).to_degrees()
}

#[test]
fn a_slice_with_few_background_samples_leans_on_the_last_direction_turned_by_the_gyro() {
    let params = HierParams {
        direction_prior_samples: 300.0,
        ..HierParams::default()
    };
    let mut m = HierarchicalMerger::new(params).unwrap();
    let x = [1.0, 0.0, 0.0];
    let y = [0.0, 1.0, 0.0];
    // The first slice has no prior: its own direction.
    assert_eq!(m.with_direction_prior(x, &events_between(0.0, 0.03), None, 10), x);
    // Equal weights (n = 300) and no rotation: halfway between the two.
    let half = m.with_direction_prior(y, &events_between(0.03, 0.06), None, 300);
    assert!((angle(half, x) - 45.0).abs() < 1e-9, "{half:?}");
    // Many samples: nearly the slice's own.
    let own = m.with_direction_prior(y, &events_between(0.06, 0.09), None, 1_000_000);
    assert!(angle(own, y) < 0.02, "{own:?}");
    // No samples: the last direction, turned by -w dt in the camera frame (0.03 s at 1 rad/s
    // about z: 1.72 deg towards +x).
    let rate = RotationRate::from([0.0, 0.0, 1.0]);
    let held = m.with_direction_prior(x, &events_between(0.09, 0.12), Some(rate), 0);
    let (s, c) = 0.03f64.sin_cos();
    let turned = [c * own[0] + s * own[1], -s * own[0] + c * own[1], own[2]];
    assert!(angle(held, turned) < 0.01, "{held:?} vs {turned:?}");
    // A gap longer than PRIOR_MAX_GAP_S: the slice alone.
    let late = PRIOR_MAX_GAP_S + 0.2;
    assert_eq!(
        m.with_direction_prior(x, &events_between(late, late + 0.03), None, 0),
        x
    );
    // Off: every slice alone.
    let mut off = HierarchicalMerger::new(HierParams {
        direction_prior_samples: 0.0,
        ..HierParams::default()
    })
    .unwrap();
    off.with_direction_prior(x, &events_between(0.0, 0.03), None, 0);
    assert_eq!(
        off.with_direction_prior(y, &events_between(0.03, 0.06), None, 0),
        y
    );
}

#[test]
fn out_of_range_settings_are_refused_naming_the_parameter() {
    let bad = [
        (
            "direction_prior_samples",
            HierParams {
                direction_prior_samples: -1.0,
                ..HierParams::default()
            },
        ),
        (
            "direction_prior_samples",
            HierParams {
                direction_prior_samples: f64::NAN,
                ..HierParams::default()
            },
        ),
        (
            "depth_memory_restart_ratio",
            HierParams {
                egomotion: EgomotionParams {
                    depth_memory_restart_ratio: -0.1,
                    ..HierParams::default().egomotion
                },
                ..HierParams::default()
            },
        ),
    ];
    for (name, params) in bad {
        let err = HierarchicalMerger::new(params).expect_err(name);
        assert!(err.to_string().contains(name), "{err}");
    }
    assert!(HierarchicalMerger::new(HierParams::default()).is_ok());
}

#[test]
fn the_final_egomotion_takes_the_egomotion_flow_and_the_segmentation_does_not() {
    // One background with an object: `flow` moves the background by BG, `egomotion_flow` by
    // another translation (the same events and object flow).
    let other = [-0.1, 0.3, 0.2];
    let object = [-0.5, 0.0, 0.0];
    let blocks =
        |bg: [f64; 3]| -> Vec<Block> { vec![(0, 200, 0, 150, 0, bg), (90, 130, 60, 100, 1, object)] };
    let (ev, flow, coarse) = build(&blocks(BG), 2);
    let (ev2, ego_flow, _) = build(&blocks(other), 2);
    assert_eq!(ev, ev2);
    let rate = Some([0.0; 3].into());
    let mut plain = HierarchicalMerger::new(HierParams::default()).unwrap();
    let own = plain.merge(&camera(), &ev, &flow, rate, &coarse).unwrap();
    let mut m = HierarchicalMerger::new(HierParams::default()).unwrap();
    let r = m
        .merge_with_egomotion_flow(&camera(), &ev, &flow, Some(&ego_flow), rate, &coarse)
        .unwrap();
    assert_eq!(r.segmentation.label, own.segmentation.label);
    assert!(r.segmentation.label.iter().any(|&l| l != 0), "no object found");
    let (d_own, d) = (
        own.segmentation.egomotion.direction,
        r.segmentation.egomotion.direction,
    );
    assert!(angle(d_own, BG) < 2.0, "flow's direction {d_own:?}");
    assert!(angle(d, other) < 2.0, "egomotion flow's direction {d:?}");
    // An egomotion flow of another length is refused.
    let mut short = ego_flow.clone();
    short.confidence.pop();
    assert!(matches!(
        m.merge_with_egomotion_flow(&camera(), &ev, &flow, Some(&short), rate, &coarse),
        Err(HierError::Align(_))
    ));
}
