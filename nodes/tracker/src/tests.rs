//! Scenario tests of the tracker with known answers.

use evseg_schemas::{Egomotion, Segment, Segmentation, Tracks};

use crate::{TentativeEvents, Tracker, TrackerError, TrackerParams};

/// The default parameters but `min_hits` 1: a track is confirmed, and its events carry its id,
/// from its first slice, for the tests of matching, merging and splitting.
fn confirmed_at_once() -> TrackerParams {
    TrackerParams {
        min_hits: 1,
        ..TrackerParams::default()
    }
}

/// Slice length used by the scenarios, seconds (the slicer's default).
const DT: f64 = 0.03;

/// One object seen in a slice: segmentation label, centroid (pixels), event count.
#[derive(Clone, Copy)]
struct Obj {
    label: u32,
    centroid: [f64; 2],
    events: u32,
}

/// A segmentation of `background` background events followed by each object's events, boxes
/// 20x20 px around the centroids. Returns it with the slice's event count.
fn frame(objs: &[Obj], background: usize) -> (usize, Segmentation) {
    let mut label = vec![0u32; background];
    let mut segments = Vec::new();
    for o in objs {
        label.extend(std::iter::repeat_n(o.label, o.events as usize));
        let [x, y] = o.centroid;
        segments.push(Segment {
            label: o.label,
            translation: [0.1 * f64::from(o.label), 0.0, 0.0],
            centroid: o.centroid,
            bbox: [
                (x - 10.0) as f32,
                (y - 10.0) as f32,
                (x + 10.0) as f32,
                (y + 10.0) as f32,
            ],
            events: o.events,
        });
    }
    let n = label.len();
    (
        n,
        Segmentation {
            label,
            segments,
            egomotion: Egomotion::default(),
        },
    )
}

fn span(k: usize) -> (f64, f64) {
    (k as f64 * DT, (k + 1) as f64 * DT)
}

/// The single track id carried by the events of segmentation label `label` (panics if they
/// disagree, which the tracker must never produce).
fn id_of(seg: &Segmentation, out: &evseg_schemas::Tracks, label: u32) -> u32 {
    let ids: Vec<u32> = seg
        .label
        .iter()
        .zip(&out.label)
        .filter(|(l, _)| **l == label)
        .map(|(_, id)| *id)
        .collect();
    assert!(!ids.is_empty(), "no events of label {label}");
    assert!(
        ids.iter().all(|&i| i == ids[0]),
        "events of one segment got different ids"
    );
    ids[0]
}

/// Grows the box of `seg`'s segment `k` by `by` pixels on every side.
fn widen(seg: &mut Segmentation, k: usize, by: f32) {
    let b = &mut seg.segments[k].bbox;
    *b = [b[0] - by, b[1] - by, b[2] + by, b[3] + by];
}

/// A slice with a large object (label 1, 300 events, a 40 x 40 px box) at `large` and a small
/// one (label 2, a 20 x 20 px box) at `small`, besides 50 background events.
fn large_and_small(large: [f64; 2], small: [f64; 2], small_events: u32) -> (usize, Segmentation) {
    let (n, mut seg) = frame(
        &[
            Obj {
                label: 1,
                centroid: large,
                events: 300,
            },
            Obj {
                label: 2,
                centroid: small,
                events: small_events,
            },
        ],
        50,
    );
    widen(&mut seg, 0, 10.0);
    (n, seg)
}

fn position(start: [f64; 2], velocity: [f64; 2], k: usize) -> [f64; 2] {
    let t = k as f64 * DT;
    [start[0] + velocity[0] * t, start[1] + velocity[1] * t]
}

/// Label 1, 60 events, moving down at 150 px/s from (200, 100), as seen in slice `k`: the
/// object of the tentative-track tests.
fn obj(k: usize) -> Obj {
    Obj {
        label: 1,
        centroid: position([200.0, 100.0], [0.0, 150.0], k),
        events: 60,
    }
}

#[test]
fn two_objects_on_straight_lines_keep_their_ids() -> Result<(), TrackerError> {
    let mut tracker = Tracker::new(confirmed_at_once())?;
    let (va, vb) = ([300.0, 0.0], [-200.0, 100.0]);
    let (mut id_a, mut id_b) = (0, 0);
    for k in 0..20 {
        // The segmenter's labels change from slice to slice (they are per-slice cluster numbers),
        // and the segment order flips: the tracker must not rely on either.
        let (la, lb) = if k % 2 == 0 { (3, 7) } else { (9, 2) };
        let a = Obj {
            label: la,
            centroid: position([50.0, 50.0], va, k),
            events: 200,
        };
        let b = Obj {
            label: lb,
            centroid: position([300.0, 200.0], vb, k),
            events: 150,
        };
        let objs = if k % 3 == 0 { vec![b, a] } else { vec![a, b] };
        let (n, seg) = frame(&objs, 500);
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!(out.label.len(), n);
        assert!(
            out.label[..500].iter().all(|&l| l == 0),
            "background events must stay 0"
        );
        let (ia, ib) = (id_of(&seg, &out, la), id_of(&seg, &out, lb));
        if k == 0 {
            // New ids in segment order, starting at 1 (slice 0 lists B first).
            assert_eq!((ia, ib), (2, 1));
            (id_a, id_b) = (ia, ib);
        }
        assert_eq!((ia, ib), (id_a, id_b), "slice {k}");
        assert_eq!(out.tracks.len(), 2);
        // Tracks come sorted by id: B (1) then A (2).
        let ta = &out.tracks[1];
        assert_eq!(ta.id, id_a);
        assert_eq!(ta.age, k as u32);
        assert_eq!(ta.events, 200);
        assert_eq!(ta.translation, [0.1 * f64::from(la), 0.0, 0.0]);
        assert_eq!(
            ta.bbox,
            seg.segments
                .iter()
                .find(|s| s.label == la)
                .map(|s| s.bbox)
                .unwrap_or_default()
        );
    }
    // After 20 noise-free slices the filtered velocities are the true ones.
    let out_v: Vec<[f64; 2]> = {
        let k = 20;
        let a = Obj {
            label: 1,
            centroid: position([50.0, 50.0], va, k),
            events: 200,
        };
        let b = Obj {
            label: 2,
            centroid: position([300.0, 200.0], vb, k),
            events: 150,
        };
        let (n, seg) = frame(&[a, b], 0);
        tracker
            .update(span(k), n, &seg)?
            .tracks
            .iter()
            .map(|t| t.velocity)
            .collect()
    };
    for (v, truth) in out_v.iter().zip([vb, va]) {
        assert!(
            (v[0] - truth[0]).abs() < 5.0 && (v[1] - truth[1]).abs() < 5.0,
            "{v:?} vs {truth:?}"
        );
    }
    Ok(())
}

#[test]
fn crossing_objects_with_different_velocities_do_not_swap() -> Result<(), TrackerError> {
    // A moves right and B left at 400 px/s on rows 8 px apart: 12 px per slice each. At the
    // crossing, each object's new centroid is nearer to the *other* object's previous centroid,
    // so matching to last positions would swap them; the velocity prediction must not.
    let mut tracker = Tracker::new(confirmed_at_once())?;
    let (va, vb) = ([400.0, 0.0], [-400.0, 0.0]);
    let (a0, b0) = ([-2.0, 100.0], [202.0, 108.0]);
    let mut swapped_for_nearest_neighbour = false;
    for k in 0..17 {
        let (pa, pb) = (position(a0, va, k), position(b0, vb, k));
        if k > 0 {
            let (qa, qb) = (position(a0, va, k - 1), position(b0, vb, k - 1));
            let d = |p: [f64; 2], q: [f64; 2]| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt();
            swapped_for_nearest_neighbour |= d(pb, qa) < d(pa, qa) && d(pa, qb) < d(pb, qb);
        }
        let a = Obj {
            label: 1 + (k as u32 % 2),
            centroid: pa,
            events: 100,
        };
        let b = Obj {
            label: 2 - (k as u32 % 2),
            centroid: pb,
            events: 100,
        };
        let (n, seg) = frame(&[a, b], 50);
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!(id_of(&seg, &out, a.label), 1, "slice {k}: object A");
        assert_eq!(id_of(&seg, &out, b.label), 2, "slice {k}: object B");
    }
    assert!(
        swapped_for_nearest_neighbour,
        "the scenario must be one that fools nearest-neighbour matching"
    );
    Ok(())
}

/// Object moving at (100, 50) px/s, seen in slices `0..10`, hidden for `gap` slices, then seen
/// for 5 more slices on the same line. Returns the ids it got before and after the gap.
fn ids_around_gap(gap: usize, params: TrackerParams) -> Result<(u32, u32), TrackerError> {
    let mut tracker = Tracker::new(params)?;
    let v = [100.0, 50.0];
    let mut ids = (0, 0);
    for k in 0..10 + gap + 5 {
        let visible = !(10..10 + gap).contains(&k);
        let objs = if visible {
            vec![Obj {
                label: 4,
                centroid: position([100.0, 100.0], v, k),
                events: 80,
            }]
        } else {
            vec![]
        };
        let (n, seg) = frame(&objs, 30);
        let out = tracker.update(span(k), n, &seg)?;
        if visible {
            let id = id_of(&seg, &out, 4);
            if k < 10 {
                ids.0 = id;
            } else {
                ids.1 = id;
                assert_eq!(out.tracks.len(), 1);
            }
        } else {
            // A missing track is not reported.
            assert!(out.tracks.is_empty(), "slice {k}");
        }
    }
    Ok(ids)
}

#[test]
fn a_short_gap_keeps_the_id_and_a_long_one_gives_a_new_id() -> Result<(), TrackerError> {
    // 30 ms slices, max_missing_s 0.5 s. Gap of 10 slices: 0.33 s since the last match when the
    // object reappears -> same id. Gap of 20 slices: 0.63 s -> dropped, new id 2 (1 is not reused).
    let params = confirmed_at_once();
    assert_eq!(ids_around_gap(10, params.clone())?, (1, 1));
    assert_eq!(ids_around_gap(20, params.clone())?, (1, 2));
    // The limit is the parameter: with 1 s, a 20-slice gap is bridged.
    let lenient = TrackerParams {
        max_missing_s: 1.0,
        ..params
    };
    assert_eq!(ids_around_gap(20, lenient)?, (1, 1));
    Ok(())
}

#[test]
fn small_segments_are_background_unless_they_continue_a_track() -> Result<(), TrackerError> {
    let params = TrackerParams {
        min_events: 30,
        ..confirmed_at_once()
    };
    let mut tracker = Tracker::new(params)?;
    // Slice 0: a big object (label 1) and a small blob (label 2, 10 events) far away.
    let big = |k: usize, events| Obj {
        label: 1,
        centroid: position([100.0, 100.0], [50.0, 0.0], k),
        events,
    };
    let small = Obj {
        label: 2,
        centroid: [400.0, 300.0],
        events: 10,
    };
    let (n, seg) = frame(&[big(0, 100), small], 20);
    let out = tracker.update(span(0), n, &seg)?;
    assert_eq!(id_of(&seg, &out, 1), 1);
    assert_eq!(id_of(&seg, &out, 2), 0, "a small unmatched segment is background");
    assert_eq!(out.tracks.len(), 1);
    assert_eq!(out.label.iter().filter(|&&l| l == 0).count(), 30);
    // Slice 1: the object shrinks to 10 events but continues its track: it keeps id 1.
    let (n, seg) = frame(&[big(1, 10)], 20);
    let out = tracker.update(span(1), n, &seg)?;
    assert_eq!(id_of(&seg, &out, 1), 1);
    assert_eq!(out.tracks[0].events, 10);
    // Slice 2: exactly min_events in a new place: a new track, id 2.
    let (n, seg) = frame(
        &[
            big(2, 100),
            Obj {
                label: 5,
                centroid: [500.0, 50.0],
                events: 30,
            },
        ],
        0,
    );
    let out = tracker.update(span(2), n, &seg)?;
    assert_eq!((id_of(&seg, &out, 1), id_of(&seg, &out, 5)), (1, 2));
    Ok(())
}

#[test]
fn tentative_tracks_can_label_their_events_with_their_id_but_are_listed_only_when_confirmed()
-> Result<(), TrackerError> {
    let params = TrackerParams {
        min_hits: 3,
        tentative_events: TentativeEvents::Id,
        ..TrackerParams::default()
    };
    let mut tracker = Tracker::new(params)?;
    for k in 0..4 {
        let (n, seg) = frame(&[obj(k)], 10);
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!(id_of(&seg, &out, 1), 1, "slice {k}");
        let listed: Vec<u32> = out.tracks.iter().map(|t| t.id).collect();
        assert_eq!(listed, if k < 2 { vec![] } else { vec![1] }, "slice {k}");
    }
    // A new tentative object seen once, missed once, seen again in place: it was dropped at its
    // first miss and comes back with a new id.
    let other = Obj {
        label: 2,
        centroid: [50.0, 50.0],
        events: 60,
    };
    let (n, seg) = frame(&[obj(4), other], 0);
    assert_eq!(id_of(&seg, &tracker.update(span(4), n, &seg)?, 2), 2);
    let (n, seg) = frame(&[obj(5)], 0);
    tracker.update(span(5), n, &seg)?;
    let (n, seg) = frame(&[obj(6), other], 0);
    let out = tracker.update(span(6), n, &seg)?;
    assert_eq!((id_of(&seg, &out, 1), id_of(&seg, &out, 2)), (1, 3));
    Ok(())
}

/// With `tentative_events: background` a track's events are background until it is
/// confirmed, and a segment seen in one slice only (a phantom) never labels anything.
#[test]
fn tentative_tracks_can_leave_their_events_background_until_confirmed() -> Result<(), TrackerError> {
    let params = TrackerParams {
        min_hits: 2,
        tentative_events: TentativeEvents::Background,
        ..TrackerParams::default()
    };
    let mut tracker = Tracker::new(params)?;
    let phantom = Obj {
        label: 2,
        centroid: [50.0, 50.0],
        events: 60,
    };
    let (n, seg) = frame(&[obj(0), phantom], 10);
    let out = tracker.update(span(0), n, &seg)?;
    assert_eq!((id_of(&seg, &out, 1), id_of(&seg, &out, 2)), (0, 0));
    assert!(out.tracks.is_empty());
    for k in 1..4 {
        let (n, seg) = frame(&[obj(k)], 10);
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!(id_of(&seg, &out, 1), 1, "slice {k}");
        assert_eq!(out.tracks.iter().map(|t| t.id).collect::<Vec<_>>(), vec![1]);
    }
    Ok(())
}

/// By default a tentative track's events are moving without an id ([`Tracks::UNCONFIRMED`])
/// until its `min_hits`-th match, then carry the id the track had from its first slice; a
/// phantom seen in one slice only is moving in that slice and never gets an id. With
/// `tentative_events: id` the events carry the id from the first slice.
#[test]
fn tentative_tracks_label_their_events_unconfirmed_until_confirmed() -> Result<(), TrackerError> {
    let phantom = Obj {
        label: 2,
        centroid: [50.0, 50.0],
        events: 60,
    };
    let run = |tentative_events| -> Result<Vec<(u32, u32, Vec<u32>)>, TrackerError> {
        let params = TrackerParams {
            min_hits: 3,
            tentative_events,
            ..TrackerParams::default()
        };
        let mut tracker = Tracker::new(params)?;
        let mut seen = Vec::new();
        for k in 0..4 {
            let objs: Vec<Obj> = if k == 0 {
                vec![obj(0), phantom]
            } else {
                vec![obj(k)]
            };
            let (n, seg) = frame(&objs, 10);
            let out = tracker.update(span(k), n, &seg)?;
            let listed = out.tracks.iter().map(|t| t.id).collect();
            let phantom_label = if k == 0 { id_of(&seg, &out, 2) } else { 0 };
            seen.push((id_of(&seg, &out, 1), phantom_label, listed));
        }
        Ok(seen)
    };
    let u = Tracks::UNCONFIRMED;
    assert_eq!(
        run(TentativeEvents::Unconfirmed)?,
        vec![(u, u, vec![]), (u, 0, vec![]), (1, 0, vec![1]), (1, 0, vec![1])]
    );
    assert_eq!(
        run(TentativeEvents::Id)?,
        vec![(1, 2, vec![]), (1, 0, vec![]), (1, 0, vec![1]), (1, 0, vec![1])]
    );
    Ok(())
}

#[test]
fn egomotion_is_passed_through_and_an_empty_slice_is_fine() -> Result<(), TrackerError> {
    let mut tracker = Tracker::new(confirmed_at_once())?;
    let (n, mut seg) = frame(&[], 0);
    seg.egomotion = Egomotion {
        direction: [0.0, 0.6, 0.8],
        omega: [0.1, -0.2, 0.3],
        valid: true,
    };
    let out = tracker.update(span(0), n, &seg)?;
    assert_eq!(out.egomotion, seg.egomotion);
    assert!(out.label.is_empty() && out.tracks.is_empty());
    Ok(())
}

#[test]
fn malformed_input_gives_errors_and_leaves_the_tracker_unchanged() -> Result<(), TrackerError> {
    let mut tracker = Tracker::new(confirmed_at_once())?;
    let obj = |k| Obj {
        label: 1,
        centroid: position([100.0, 100.0], [100.0, 0.0], k),
        events: 50,
    };
    let (n, seg) = frame(&[obj(0)], 10);
    tracker.update(span(0), n, &seg)?;

    let (n, good) = frame(&[obj(1)], 10);
    // Label vector shorter than the slice.
    assert_eq!(
        tracker.update(span(1), n + 1, &good).err(),
        Some(TrackerError::LabelCount {
            labels: n,
            events: n + 1
        })
    );
    // An event label that no segment describes.
    let mut bad = good.clone();
    bad.label[3] = 9;
    assert_eq!(
        tracker.update(span(1), n, &bad).err(),
        Some(TrackerError::UnknownLabel { index: 3, label: 9 })
    );
    // Two segments with one label.
    let mut bad = good.clone();
    bad.segments.push(bad.segments[0].clone());
    assert_eq!(
        tracker.update(span(1), n, &bad).err(),
        Some(TrackerError::DuplicateSegment { label: 1 })
    );
    // Non-finite centroid.
    let mut bad = good.clone();
    bad.segments[0].centroid[1] = f64::NAN;
    assert!(matches!(
        tracker.update(span(1), n, &bad),
        Err(TrackerError::NonFiniteCentroid { label: 1, .. })
    ));
    // Inverted or infinite box.
    let mut bad = good.clone();
    bad.segments[0].bbox = [10.0, 10.0, 5.0, 20.0];
    assert!(matches!(
        tracker.update(span(1), n, &bad),
        Err(TrackerError::InvalidBbox { label: 1, .. })
    ));
    bad.segments[0].bbox = [10.0, 10.0, f32::INFINITY, 20.0];
    assert!(matches!(
        tracker.update(span(1), n, &bad),
        Err(TrackerError::InvalidBbox { label: 1, .. })
    ));
    // Bad windows: non-finite, reversed, and not after the previous slice.
    assert!(matches!(
        tracker.update((f64::NAN, 1.0), n, &good),
        Err(TrackerError::InvalidSpan { .. })
    ));
    assert!(matches!(
        tracker.update((1.0, 0.5), n, &good),
        Err(TrackerError::InvalidSpan { .. })
    ));
    assert!(matches!(
        tracker.update(span(0), n, &good),
        Err(TrackerError::TimeNotIncreasing { .. })
    ));
    // A huge label value is fine (sparse index) when it is declared.
    let mut big_label = good.clone();
    big_label.segments[0].label = 4_000_000_000;
    big_label
        .label
        .iter_mut()
        .filter(|l| **l == 1)
        .for_each(|l| *l = 4_000_000_000);
    let mut probe = tracker.clone();
    assert_eq!(
        id_of(&big_label, &probe.update(span(1), n, &big_label)?, 4_000_000_000),
        1
    );

    // None of the errors changed anything: the next good slice continues track 1 at age 1.
    let out = tracker.update(span(1), n, &good)?;
    assert_eq!(id_of(&good, &out, 1), 1);
    assert_eq!(out.tracks[0].age, 1);
    assert_eq!(tracker.live_tracks(), 1);
    Ok(())
}

#[test]
fn background_segment_entries_are_ignored_even_if_malformed() -> Result<(), TrackerError> {
    // A segment with label 0 describes the background: it is never tracked and its centroid is
    // not checked (a producer may leave it NaN).
    let mut tracker = Tracker::new(confirmed_at_once())?;
    let (n, mut seg) = frame(
        &[Obj {
            label: 3,
            centroid: [10.0, 10.0],
            events: 40,
        }],
        100,
    );
    seg.segments.push(Segment {
        label: 0,
        translation: [0.0; 3],
        centroid: [f64::NAN, f64::NAN],
        bbox: [0.0; 4],
        events: 100,
    });
    let out = tracker.update(span(0), n, &seg)?;
    assert_eq!(out.tracks.len(), 1);
    assert_eq!(out.label.iter().filter(|&&l| l == 0).count(), 100);
    Ok(())
}

#[test]
fn invalid_parameters_are_refused() {
    let bad = [
        TrackerParams {
            measurement_std_px: 0.0,
            ..Default::default()
        },
        TrackerParams {
            gate_chi2: f64::NAN,
            ..Default::default()
        },
        TrackerParams {
            accel_std_px_s2: -1.0,
            ..Default::default()
        },
        TrackerParams {
            max_missing_s: f64::INFINITY,
            ..Default::default()
        },
        TrackerParams {
            min_hits: 0,
            ..Default::default()
        },
        TrackerParams {
            max_distance_px: -5.0,
            ..Default::default()
        },
        TrackerParams {
            merge_inside: 1.5,
            ..Default::default()
        },
        TrackerParams {
            merge_inside: f64::NAN,
            ..Default::default()
        },
        TrackerParams {
            split_gap_px: -1.0,
            ..Default::default()
        },
        TrackerParams {
            split_gap_px: f64::NAN,
            ..Default::default()
        },
        TrackerParams {
            split_min_share: -0.5,
            ..Default::default()
        },
        TrackerParams {
            split_min_share: f64::INFINITY,
            ..Default::default()
        },
        TrackerParams {
            split_yield_min_share: 1.5,
            ..Default::default()
        },
        TrackerParams {
            split_yield_min_share: f64::NAN,
            ..Default::default()
        },
        // Finite but so large that the filter's variances overflow (NaN tracks), or the split
        // grouping's cell search would run for minutes per slice.
        TrackerParams {
            accel_std_px_s2: 1e200,
            ..Default::default()
        },
        TrackerParams {
            initial_velocity_std_px_s: 1e200,
            ..Default::default()
        },
        TrackerParams {
            measurement_std_box_fraction: 1e300,
            ..Default::default()
        },
        TrackerParams {
            split_gap_px: 1e30,
            ..Default::default()
        },
        TrackerParams {
            split_cell_px: 1,
            split_gap_px: 300.0,
            ..Default::default()
        },
    ];
    for p in bad {
        assert!(
            matches!(Tracker::new(p.clone()), Err(TrackerError::InvalidParam { .. })),
            "{p:?} accepted"
        );
    }
    // The same gap with coarser cells is a small search, and accepted.
    let coarse = TrackerParams {
        split_cell_px: 10,
        split_gap_px: 300.0,
        ..Default::default()
    };
    assert!(Tracker::new(coarse).is_ok());
}

#[test]
fn fragments_of_a_tracked_object_take_its_id_and_a_distant_segment_does_not() -> Result<(), TrackerError> {
    let run =
        |absorb_overlap: f64, merge_inside: f64| -> Result<(u32, u32, u32, Vec<u32>, u32), TrackerError> {
            let mut tracker = Tracker::new(TrackerParams {
                absorb_overlap,
                merge_inside,
                ..confirmed_at_once()
            })?;
            let mut id = 0;
            for k in 0..4 {
                let (n, seg) = frame(
                    &[Obj {
                        label: 1,
                        centroid: [100.0 + k as f64, 100.0],
                        events: 200,
                    }],
                    50,
                );
                id = id_of(&seg, &tracker.update(span(k), n, &seg)?, 1);
            }
            // The object comes in two pieces, 4 px either side of where it is expected, and a
            // separate object appears far away.
            let (n, seg) = frame(
                &[
                    Obj {
                        label: 1,
                        centroid: [100.0, 100.0],
                        events: 120,
                    },
                    Obj {
                        label: 2,
                        centroid: [108.0, 100.0],
                        events: 80,
                    },
                    Obj {
                        label: 3,
                        centroid: [300.0, 200.0],
                        events: 100,
                    },
                ],
                50,
            );
            let out = tracker.update(span(4), n, &seg)?;
            let ids = out.tracks.iter().map(|t| t.id).collect();
            let listed_events = out.tracks.iter().find(|t| t.id == id).map_or(0, |t| t.events);
            Ok((
                id_of(&seg, &out, 1),
                id_of(&seg, &out, 2),
                id_of(&seg, &out, 3),
                ids,
                listed_events,
            ))
        };
    let (a, b, c, ids, events) = run(0.5, 0.0)?;
    assert_eq!(a, b, "both pieces carry the object's id");
    assert!(c != a && c != 0, "the distant object has its own track");
    assert_eq!(ids.len(), 2, "one listed track per id: {ids:?}");
    assert_eq!(events, 200, "the listed track counts both pieces");
    // Off: the second piece opens a track of its own...
    let (a, b, _, ids, _) = run(0.0, 0.0)?;
    assert!(a != b && b != 0);
    assert_eq!(ids.len(), 3);
    // ...which the containment merge joins to the object at once (its box lies 13/21 inside).
    let (a, b, c, ids, _) = run(0.0, 0.5)?;
    assert_eq!(a, b, "merged by containment");
    assert!(c != a && c != 0);
    assert_eq!(ids.len(), 2, "{ids:?}");
    Ok(())
}

/// Two pieces of 150 events each on the row y = 100, label 1 at x = `xa` and label 2 at `xb`
/// (20 x 20 px boxes), besides 50 background events.
fn two_pieces(xa: f64, xb: f64) -> (usize, Segmentation) {
    frame(
        &[
            Obj {
                label: 1,
                centroid: [xa, 100.0],
                events: 150,
            },
            Obj {
                label: 2,
                centroid: [xb, 100.0],
                events: 150,
            },
        ],
        50,
    )
}

#[test]
fn touching_tracks_that_move_alike_become_one_and_others_stay_apart() -> Result<(), TrackerError> {
    // Two pieces 20 px apart (their 20 px boxes touch), moving at `va` and `vb` px/s.
    let run = |va: f64, vb: f64| -> Result<Vec<(u32, u32)>, TrackerError> {
        let mut tracker = Tracker::new(confirmed_at_once())?;
        let mut ids = Vec::new();
        for k in 0..8 {
            let t = k as f64 * DT;
            let (n, seg) = two_pieces(200.0 + va * t, 220.0 + vb * t);
            let out = tracker.update(span(k), n, &seg)?;
            ids.push((id_of(&seg, &out, 1), id_of(&seg, &out, 2)));
        }
        Ok(ids)
    };
    let alike = run(150.0, 150.0)?;
    assert!(
        confirmed_at_once().min_hits_to_merge == 3,
        "the assertions below count on it"
    );
    // Separate until both tracks have three matches, then one id from there on.
    assert!(alike[0].0 != alike[0].1, "{alike:?}");
    assert!(
        alike[3..].iter().all(|&(a, b)| a == b && a == alike[0].0),
        "{alike:?}"
    );
    // Moving apart at 100 px/s relative: never merged (they touch only at first).
    let apart = run(150.0, 250.0)?;
    assert!(apart.iter().all(|&(a, b)| a != b), "{apart:?}");
    Ok(())
}

#[test]
fn long_tracked_neighbours_that_come_to_touch_merge_only_without_a_hit_limit() -> Result<(), TrackerError> {
    // Two objects moving alike at 150 px/s with boxes 10 px apart for 12 slices, then 1 px
    // apart (touching within `merge_gap_px`).
    let run = |merge_velocity_max_hits: u32| -> Result<Vec<(u32, u32)>, TrackerError> {
        let mut tracker = Tracker::new(TrackerParams {
            merge_velocity_max_hits,
            ..confirmed_at_once()
        })?;
        let mut ids = Vec::new();
        for k in 0..16 {
            let t = k as f64 * DT;
            let offset = if k < 12 { 30.0 } else { 21.0 };
            let (n, seg) = two_pieces(200.0 + 150.0 * t, 200.0 + offset + 150.0 * t);
            let out = tracker.update(span(k), n, &seg)?;
            ids.push((id_of(&seg, &out, 1), id_of(&seg, &out, 2)));
        }
        Ok(ids)
    };
    let unlimited = run(0)?;
    assert!(unlimited[..12].iter().all(|&(a, b)| a != b), "{unlimited:?}");
    assert!(unlimited[12..].iter().all(|&(a, b)| a == b), "{unlimited:?}");
    // Each track has 12 matches when they touch: above a limit of 10, so they stay apart.
    let limited = run(10)?;
    assert!(limited.iter().all(|&(a, b)| a == 1 && b == 2), "{limited:?}");
    Ok(())
}

#[test]
fn a_piece_inside_another_tracks_box_is_merged_whatever_its_velocity() -> Result<(), TrackerError> {
    // A large piece (40 x 40 px box) and a small one (20 x 20) inside it whose centroid swings
    // 10 px either way from slice to slice (a fragment's centroid jumps with the pieces): their
    // filtered velocities differ by far more than `merge_velocity_px_s`.
    let run = |merge_inside: f64| -> Result<Vec<(u32, u32)>, TrackerError> {
        let mut tracker = Tracker::new(TrackerParams {
            merge_inside,
            absorb_overlap: 0.0,
            ..confirmed_at_once()
        })?;
        let mut ids = Vec::new();
        for k in 0..6 {
            let swing = if k % 2 == 0 { -10.0 } else { 10.0 };
            let x = 200.0 + 3.0 * k as f64;
            let (n, seg) = large_and_small([x, 100.0], [x + swing, 100.0], 100);
            let out = tracker.update(span(k), n, &seg)?;
            ids.push((id_of(&seg, &out, 1), id_of(&seg, &out, 2)));
        }
        Ok(ids)
    };
    let on = run(0.5)?;
    assert!(on.iter().all(|&(a, b)| a == b && a == on[0].0), "{on:?}");
    // Off: two tracks until the velocity rule may look at them (three matches each).
    let off = run(0.0)?;
    assert!(off[..2].iter().all(|&(a, b)| a != b), "{off:?}");
    Ok(())
}

#[test]
fn two_objects_tracked_apart_stay_apart_when_one_passes_inside_the_others_box() -> Result<(), TrackerError> {
    // A large object (40 x 40 px box) still, a small one coming from 200 px away at 300 px/s
    // and passing across it: tracked apart for longer than `merge_inside_max_hits` before
    // their boxes overlap.
    let p = confirmed_at_once();
    let mut tracker = Tracker::new(p.clone())?;
    let mut overlapped = 0;
    for k in 0..30 {
        let small = [100.0 + 300.0 * k as f64 * DT, 300.0];
        let (n, seg) = large_and_small([300.0, 300.0], small, 100);
        overlapped += usize::from((small[0] - 300.0).abs() <= 10.0);
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!((id_of(&seg, &out, 1), id_of(&seg, &out, 2)), (1, 2), "slice {k}");
    }
    assert!(
        overlapped >= 2 && p.merge_inside_max_hits < 20,
        "the small box must lie inside the large one in some slices after both are established"
    );
    Ok(())
}

#[test]
fn objects_joined_while_overlapping_are_split_once_apart() -> Result<(), TrackerError> {
    // A large object (40 x 40 px box) still; a second one (20 x 20) starts inside its box, so
    // the two are one track from the first slice, then moves away at 400 px/s.
    let run = |split_gap_px: f64, split_after_slices: u32| -> Result<Vec<(u32, u32)>, TrackerError> {
        let mut tracker = Tracker::new(TrackerParams {
            split_gap_px,
            split_after_slices,
            ..confirmed_at_once()
        })?;
        let mut ids = Vec::new();
        for k in 0..15 {
            let second = [300.0 + 400.0 * k as f64 * DT, 300.0];
            let (n, seg) = large_and_small([300.0, 300.0], second, 150);
            let out = tracker.update(span(k), n, &seg)?;
            ids.push((id_of(&seg, &out, 1), id_of(&seg, &out, 2)));
        }
        Ok(ids)
    };
    // Off: the track's box grows over both objects and keeps absorbing the second one.
    let d = confirmed_at_once();
    let off = run(0.0, d.split_after_slices)?;
    assert!(off.iter().all(|&(a, b)| a == 1 && b == 1), "{off:?}");
    // On: one track while the boxes are within the gap, two once the second one is clear of
    // it (its box 17 px away from slice 4 on) for `split_after_slices` slices in a row; the
    // first keeps its id.
    let mut aparts = Vec::new();
    for after in [1, d.split_after_slices] {
        let on = run(d.split_gap_px, after)?;
        assert_eq!(on[0], (1, 1), "{on:?}");
        assert!(on.iter().all(|&(a, _)| a == 1), "{on:?}");
        let apart = on.iter().position(|&(a, b)| a != b).unwrap_or(on.len());
        let late = after.max(1) as usize - 1;
        assert!((3 + late..=5 + late).contains(&apart), "after {after}: {on:?}");
        assert!(on[apart..].iter().all(|&(_, b)| b == on[apart].1), "{on:?}");
        aparts.push(apart);
    }
    // The default waits `split_after_slices - 1` slices longer than an immediate split.
    assert_eq!(
        aparts[1],
        aparts[0] + d.split_after_slices as usize - 1,
        "{aparts:?}"
    );
    Ok(())
}

/// Event pixels for `seg`: the events of each label spread row by row over the box
/// `area(label)` (`[x_min, y_min, x_max, y_max]`, pixels), background events at (0, 0).
fn pixels(seg: &Segmentation, area: impl Fn(u32) -> [f64; 4]) -> (Vec<u16>, Vec<u16>) {
    let mut seen = std::collections::HashMap::new();
    seg.label
        .iter()
        .map(|&l| {
            if l == 0 {
                return (0, 0);
            }
            let j = seen.entry(l).or_insert(0usize);
            let [x0, y0, x1, y1] = area(l);
            let w = (x1 - x0) as usize + 1;
            let h = (y1 - y0) as usize + 1;
            let p = (x0 as usize + *j % w, y0 as usize + (*j / w) % h);
            *j += 1;
            (p.0 as u16, p.1 as u16)
        })
        .unzip()
}

#[test]
fn segments_whose_boxes_touch_but_whose_events_lie_apart_split_when_grouped_by_events()
-> Result<(), TrackerError> {
    // As `objects_joined_while_overlapping_are_split_once_apart`, but the second object's box
    // always reaches back to the first one's (a stray event), while its events lie in its 20 x
    // 20 px core moving away at 400 px/s.
    let run = |split_cell_px: u16| -> Result<Vec<(u32, u32)>, TrackerError> {
        let mut tracker = Tracker::new(TrackerParams {
            split_cell_px,
            ..confirmed_at_once()
        })?;
        let mut ids = Vec::new();
        for k in 0..15 {
            let sx = 300.0 + 400.0 * k as f64 * DT;
            let (_, mut seg) = large_and_small([300.0, 300.0], [sx, 300.0], 150);
            seg.segments[1].bbox[0] = seg.segments[1].bbox[0].min(321.0);
            let (x, y) = pixels(&seg, |l| {
                if l == 1 {
                    [280.0, 280.0, 320.0, 320.0]
                } else {
                    [sx - 10.0, 290.0, sx + 10.0, 310.0]
                }
            });
            let out = tracker.update_with_pixels(span(k), &x, &y, &seg)?;
            ids.push((id_of(&seg, &out, 1), id_of(&seg, &out, 2)));
        }
        Ok(ids)
    };
    // By boxes (the default): the boxes touch in every slice, so the two stay one track.
    let boxes = run(0)?;
    assert!(boxes.iter().all(|&(a, b)| a == 1 && b == 1), "{boxes:?}");
    // By 8 px cells: events within 3 cells of each other join. The first object's events reach
    // x = 320 (cell 40); the second one's start at x = 350 (cell 43) in slice 5, still joined,
    // and at x = 362 (cell 45) in slice 6, apart; split after `split_after_slices` 3 slices
    // apart, in slice 8.
    let cells = run(8)?;
    assert!(cells.iter().all(|&(a, _)| a == 1), "{cells:?}");
    let apart = cells.iter().position(|&(a, b)| a != b).unwrap_or(cells.len());
    assert_eq!(apart, 8, "{cells:?}");
    assert!(
        cells[apart..].iter().all(|&(_, b)| b == cells[apart].1),
        "{cells:?}"
    );
    // Pixels that do not fit the labels are refused.
    let mut tracker = Tracker::new(confirmed_at_once())?;
    let (_, seg) = large_and_small([300.0, 300.0], [300.0, 300.0], 150);
    let (x, y) = pixels(&seg, |_| [280.0, 280.0, 320.0, 320.0]);
    let n = seg.label.len();
    assert_eq!(
        tracker.update_with_pixels(span(0), &x[1..], &y[1..], &seg),
        Err(TrackerError::LabelCount {
            labels: n,
            events: n - 1
        })
    );
    assert_eq!(
        tracker.update_with_pixels(span(0), &x, &y[1..], &seg),
        Err(TrackerError::PixelCount { x: n, y: n - 1 })
    );
    Ok(())
}

/// A still object (label 1, 500 events, a 60 x 60 px box at (300, 300)).
fn still_object() -> (usize, Segmentation) {
    let (n, mut seg) = frame(
        &[Obj {
            label: 1,
            centroid: [300.0, 300.0],
            events: 500,
        }],
        50,
    );
    widen(&mut seg, 0, 20.0);
    (n, seg)
}

/// The object of [`still_object`] segmented in two groups 19 px apart: a small piece (label 1,
/// 120 events, a 20 x 20 px box at (285, 300)) nearest its predicted centroid, and the bulk
/// (label 2, 400 events, a 40 x 40 px box at (335, 300)).
fn piece_and_bulk() -> (usize, Segmentation) {
    let (n, mut seg) = frame(
        &[
            Obj {
                label: 1,
                centroid: [285.0, 300.0],
                events: 120,
            },
            Obj {
                label: 2,
                centroid: [335.0, 300.0],
                events: 400,
            },
        ],
        50,
    );
    widen(&mut seg, 1, 10.0);
    (n, seg)
}

#[test]
fn a_split_track_stays_with_its_larger_group() -> Result<(), TrackerError> {
    // A still object with a 60 x 60 px box for three slices; then its segmentation comes in
    // two groups 19 px apart: a small piece (120 events) nearest the predicted centroid, which
    // the association matches, and the bulk (400 events) absorbed through the box; split at
    // once (`split_after_slices` 1).
    let mut tracker = Tracker::new(TrackerParams {
        split_after_slices: 1,
        ..confirmed_at_once()
    })?;
    for k in 0..3 {
        let (n, seg) = still_object();
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!(id_of(&seg, &out, 1), 1);
    }
    let (n, seg) = piece_and_bulk();
    let out = tracker.update(span(3), n, &seg)?;
    assert_eq!((id_of(&seg, &out, 2), id_of(&seg, &out, 1)), (1, 2));
    // The track was corrected with the bulk, which it keeps following.
    let (n, mut seg) = frame(
        &[Obj {
            label: 1,
            centroid: [335.0, 300.0],
            events: 400,
        }],
        50,
    );
    widen(&mut seg, 0, 10.0);
    let out = tracker.update(span(4), n, &seg)?;
    assert_eq!(id_of(&seg, &out, 1), 1);
    Ok(())
}

/// Runs `params` over a stationary object (label 1 at (100, 100)) tracked for ten slices while a
/// track opened in slice 0 on a stray segment at (120, 100) is missed; in slice 10 the object's
/// segment appears at (112, 100). Returns the object's id before and in slice 10.
fn stale_track_scenario(params: TrackerParams) -> Result<(u32, u32), TrackerError> {
    let mut tracker = Tracker::new(params)?;
    let object = |centroid| Obj {
        label: 1,
        centroid,
        events: 200,
    };
    let stray = Obj {
        label: 2,
        centroid: [120.0, 100.0],
        events: 100,
    };
    let (n, seg) = frame(&[object([100.0, 100.0]), stray], 50);
    let first = tracker.update(span(0), n, &seg)?;
    let id = id_of(&seg, &first, 1);
    for k in 1..10 {
        let (n, seg) = frame(&[object([100.0, 100.0])], 50);
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!(id_of(&seg, &out, 1), id);
    }
    let (n, seg) = frame(&[object([112.0, 100.0])], 50);
    let out = tracker.update(span(10), n, &seg)?;
    Ok((id, id_of(&seg, &out, 1)))
}

#[test]
fn a_missed_track_does_not_take_the_segment_of_the_track_that_follows_the_object() -> Result<(), TrackerError>
{
    // The stray track, missed for nine slices, is closer to the segment in Mahalanobis distance
    // (its position has grown uncertain) and in box overlap: without the cascade it wins.
    let (before, after) = stale_track_scenario(confirmed_at_once())?;
    assert_eq!(after, before, "the object's id must not change");
    let plain = TrackerParams {
        matching_cascade: false,
        ..confirmed_at_once()
    };
    let (before, after) = stale_track_scenario(plain)?;
    assert_ne!(
        after, before,
        "the scenario must show the plain association's failure"
    );
    Ok(())
}

/// An object (label 1, a 40 x 40 px box at (100, 100)) tracked from slice 0 beside a stray
/// segment at (160, 100) whose track is opened first in slice 0 and then missed; in slice 6 a small segment at
/// (104, 100), inside the object's box, is matched to the stray track, and the two merge.
/// Returns the object's id in slice 5 and in slice 6.
fn merge_scenario(params: TrackerParams) -> Result<(u32, u32), TrackerError> {
    let mut tracker = Tracker::new(params)?;
    let object = Obj {
        label: 1,
        centroid: [100.0, 100.0],
        events: 300,
    };
    // The object's segment is widened wherever it is in the list.
    let slice = |objs: &[Obj]| {
        let (n, mut seg) = frame(objs, 50);
        if let Some(k) = seg.segments.iter().position(|s| s.label == 1) {
            widen(&mut seg, k, 10.0);
        }
        (n, seg)
    };
    let stray = Obj {
        label: 2,
        centroid: [160.0, 100.0],
        events: 100,
    };
    // The stray segment first: its track gets the smaller (older) id.
    let (n, seg) = slice(&[stray, object]);
    tracker.update(span(0), n, &seg)?;
    let mut id = 0;
    for k in 1..6 {
        let (n, seg) = slice(&[object]);
        let out = tracker.update(span(k), n, &seg)?;
        id = id_of(&seg, &out, 1);
    }
    let piece = Obj {
        label: 2,
        centroid: [104.0, 100.0],
        events: 60,
    };
    let (n, seg) = slice(&[object, piece]);
    let out = tracker.update(span(6), n, &seg)?;
    assert_eq!(
        id_of(&seg, &out, 1),
        id_of(&seg, &out, 2),
        "the piece inside the object's box must merge with it"
    );
    Ok((id, id_of(&seg, &out, 1)))
}

#[test]
fn of_two_merged_tracks_the_one_matched_more_often_keeps_its_id() -> Result<(), TrackerError> {
    let (before, after) = merge_scenario(confirmed_at_once())?;
    assert_eq!(after, before, "the object's id must not change");
    let oldest = TrackerParams {
        merge_keeps_most_hits: false,
        ..confirmed_at_once()
    };
    let (before, after) = merge_scenario(oldest)?;
    assert_ne!(
        after, before,
        "with the older id kept, the stray track's id takes over"
    );
    Ok(())
}

/// An object seen in two pieces moving alike at 100 px/s: a 60-event leading piece (label 1)
/// tracked from the first slice and the 400-event bulk (label 2) 32 px behind it (boxes 12 px
/// apart), tracked from slice 3; after `apart` slices the bulk closes to 22 px (boxes 2 px
/// apart) and the two tracks merge. Returns the bulk's id before and after the merge, and the
/// piece's id before it.
fn pieces_rejoin(params: TrackerParams, apart: usize) -> Result<(u32, u32, u32), TrackerError> {
    let mut tracker = Tracker::new(params)?;
    let at = |k: usize, gap: f64| {
        let x = 100.0 + 3.0 * k as f64;
        let piece = Obj {
            label: 1,
            centroid: [x, 100.0],
            events: 60,
        };
        let bulk = Obj {
            label: 2,
            centroid: [x + gap, 100.0],
            events: 400,
        };
        if k < 3 {
            frame(&[piece], 50)
        } else {
            frame(&[piece, bulk], 50)
        }
    };
    let (mut bulk_id, mut piece_id) = (0, 0);
    for k in 0..apart {
        let (n, seg) = at(k, 32.0);
        let out = tracker.update(span(k), n, &seg)?;
        if k >= 3 {
            bulk_id = id_of(&seg, &out, 2);
            piece_id = id_of(&seg, &out, 1);
        }
    }
    let (n, seg) = at(apart, 22.0);
    let out = tracker.update(span(apart), n, &seg)?;
    assert_eq!(
        id_of(&seg, &out, 1),
        id_of(&seg, &out, 2),
        "the touching pieces must merge"
    );
    Ok((bulk_id, id_of(&seg, &out, 2), piece_id))
}

#[test]
fn of_two_established_tracks_merged_the_one_with_more_events_keeps_its_id() -> Result<(), TrackerError> {
    // Both tracks matched more than `merge_inside_max_hits` (10) times: the bulk's id stays.
    let (bulk, after, piece) = pieces_rejoin(confirmed_at_once(), 18)?;
    assert_ne!(bulk, piece, "the pieces were tracked apart");
    assert_eq!(after, bulk, "the bulk of the object keeps its id");
    // Without the rule the piece, matched more often, keeps its.
    let hits_only = TrackerParams {
        merge_keeps_most_events: false,
        ..confirmed_at_once()
    };
    let (bulk, after, piece) = pieces_rejoin(hits_only, 18)?;
    assert_eq!((after, bulk == piece), (piece, false));
    // A young track (here 5 matches) does not take the id by its events alone.
    let (bulk, after, piece) = pieces_rejoin(confirmed_at_once(), 8)?;
    assert_eq!((after, bulk == piece), (piece, false));
    Ok(())
}

#[test]
fn a_group_smaller_than_split_min_share_stays_with_its_track() -> Result<(), TrackerError> {
    // The scene of `a_split_track_stays_with_its_larger_group`: a 120-event piece 19 px from
    // the 400-event bulk. It splits off at the default share (0) but not at 0.5 (120 / 400).
    let run = |split_min_share: f64| -> Result<(u32, u32), TrackerError> {
        let mut tracker = Tracker::new(TrackerParams {
            split_min_share,
            split_after_slices: 1,
            ..confirmed_at_once()
        })?;
        for k in 0..3 {
            let (n, seg) = still_object();
            tracker.update(span(k), n, &seg)?;
        }
        let (n, seg) = piece_and_bulk();
        let out = tracker.update(span(3), n, &seg)?;
        Ok((id_of(&seg, &out, 2), id_of(&seg, &out, 1)))
    };
    assert_eq!(run(0.0)?, (1, 2));
    assert_eq!(run(0.5)?, (1, 1));
    assert_eq!(run(0.25)?, (1, 2));
    Ok(())
}

#[test]
fn tentative_events_names_round_trip_and_a_bad_one_lists_the_valid_ones() {
    for name in TentativeEvents::NAMES {
        let v: TentativeEvents = name.parse().unwrap();
        assert_eq!(v.name(), name);
    }
    let err = "label".parse::<TentativeEvents>().unwrap_err().to_string();
    assert!(
        err.contains("tentative_events") && err.contains("`label`") && err.contains("unconfirmed"),
        "{err}"
    );
}

/// Object A (label 1, still at (145, 300), box x 130-160) and object B (label 2, still at
/// (300, 300), wide box x 170-435) for three slices, then a slice in which B's track gets
/// its own segment (150 events, box x 280-320) and, through its wide predicted box, a larger
/// piece P (label 3, 400 events, box x 158-188) lying apart from it but overlapping A's
/// segment. Returns the ids of A's, B's and P's events in that slice and the live tracks, with
/// `split_yields_to_tracks` = `yields` and `split_yield_min_share` = `yield_min_share`.
fn piece_beside_another_track(
    yields: bool,
    yield_min_share: f64,
) -> Result<(u32, u32, u32, usize), TrackerError> {
    let mut tracker = Tracker::new(TrackerParams {
        split_after_slices: 1,
        merge_velocity_px_s: 0.0,
        split_yields_to_tracks: yields,
        split_yield_min_share: yield_min_share,
        ..confirmed_at_once()
    })?;
    let set_box = |seg: &mut Segmentation, k: usize, x0: f32, x1: f32| {
        let b = &mut seg.segments[k].bbox;
        (b[0], b[2]) = (x0, x1);
    };
    let a = |events| Obj {
        label: 1,
        centroid: [145.0, 300.0],
        events,
    };
    let b = |events| Obj {
        label: 2,
        centroid: [300.0, 300.0],
        events,
    };
    for k in 0..3 {
        let (n, mut seg) = frame(&[a(200), b(300)], 50);
        set_box(&mut seg, 0, 130.0, 160.0);
        set_box(&mut seg, 1, 170.0, 435.0);
        let out = tracker.update(span(k), n, &seg)?;
        assert_eq!((id_of(&seg, &out, 1), id_of(&seg, &out, 2)), (1, 2));
    }
    let piece = Obj {
        label: 3,
        centroid: [173.0, 300.0],
        events: 400,
    };
    let (n, mut seg) = frame(&[a(200), b(150), piece], 50);
    set_box(&mut seg, 0, 130.0, 160.0);
    set_box(&mut seg, 1, 280.0, 320.0);
    set_box(&mut seg, 2, 158.0, 188.0);
    let out = tracker.update(span(3), n, &seg)?;
    Ok((
        id_of(&seg, &out, 1),
        id_of(&seg, &out, 2),
        id_of(&seg, &out, 3),
        tracker.live_tracks(),
    ))
}

#[test]
fn a_group_apart_that_touches_another_track_goes_to_it() -> Result<(), TrackerError> {
    // With the rule the piece is A's and B keeps its own segment; without it B's track keeps
    // the larger group (the piece beside A) and B's own segment splits off under a new id.
    let share = TrackerParams::default().split_yield_min_share;
    assert_eq!(piece_beside_another_track(true, share)?, (1, 2, 1, 2));
    assert_eq!(piece_beside_another_track(false, share)?, (1, 3, 2, 3));
    // B's own segment holds 150 / 400 of the largest group's events: below a share of 0.5
    // nothing is handed over.
    assert_eq!(piece_beside_another_track(true, 0.5)?, (1, 3, 2, 3));
    Ok(())
}
