use super::*;
use crate::rng::SplitMix64;
use evseg_schemas::align::AlignError;

fn camera() -> CameraInfo {
    CameraInfo::pinhole(320, 240, 250.0, "test")
}

/// `n` events at random pixels of the central 200x160 px, with flow from `flow_of(i)`.
fn slice(n: usize, flow_of: impl Fn(usize) -> (f32, f32, f32)) -> (Events, NormalFlow) {
    let mut rng = SplitMix64::new(11);
    let mut ev = Events::with_capacity(n);
    let mut fl = NormalFlow::default();
    for i in 0..n {
        let u = 60 + rng.below(200) as u16;
        let v = 40 + rng.below(160) as u16;
        ev.push(i as f64 * 1e-6, u, v, 1);
        let (nx, ny, c) = flow_of(i);
        fl.nx.push(nx);
        fl.ny.push(ny);
        fl.confidence.push(c);
    }
    (ev, fl)
}

#[test]
fn separates_interleaved_events_by_their_flow() {
    // Same region, two motions: +-2 normalized units/s (+-500 px/s) along x.
    let (ev, fl) = slice(4000, |i| {
        if i % 2 == 0 {
            (2.0, 0.0, 1.0)
        } else {
            (-2.0, 0.0, 1.0)
        }
    });
    let mut s = Oversegmenter::new(OversegParams {
        k: 2,
        ..Default::default()
    })
    .unwrap();
    let c = s.segment(&camera(), &ev, &fl).unwrap();
    assert_eq!(c.count, 2);
    for i in 0..ev.len() {
        assert_eq!(c.id[i] == c.id[0], i % 2 == 0, "event {i}");
    }
}

#[test]
fn with_no_flow_weight_splits_by_position() {
    let (ev, fl) = slice(4000, |i| {
        if i % 2 == 0 {
            (2.0, 0.0, 1.0)
        } else {
            (-2.0, 0.0, 1.0)
        }
    });
    let mut s = Oversegmenter::new(OversegParams {
        k: 2,
        lambda: 0.0,
        ..Default::default()
    })
    .unwrap();
    let c = s.segment(&camera(), &ev, &fl).unwrap();
    // Two halves of a 200x160 rectangle: split along x near the centre column 160.
    let left = c.id[(0..ev.len()).find(|&i| ev.x[i] < 100).unwrap()];
    let wrong = (0..ev.len())
        .filter(|&i| ev.x[i] < 140 && c.id[i] != left || ev.x[i] > 180 && c.id[i] == left)
        .count();
    assert_eq!(wrong, 0);
}

#[test]
fn invalid_flow_is_unassigned_and_all_invalid_gives_no_clusters() {
    let (ev, fl) = slice(500, |i| match i % 3 {
        0 => (1.0, 0.0, 0.0),
        1 => (f32::NAN, 0.0, 1.0),
        _ => (0.5, 0.5, 0.8),
    });
    let mut s = Oversegmenter::new(OversegParams::default()).unwrap();
    let c = s.segment(&camera(), &ev, &fl).unwrap();
    assert_eq!(c.count, 30);
    for i in 0..ev.len() {
        assert_eq!(c.id[i] == UNASSIGNED, i % 3 != 2, "event {i}");
        assert!(c.id[i] == UNASSIGNED || c.id[i] < 30);
    }
    let (ev, fl) = slice(100, |_| (0.0, 0.0, 0.0));
    let c = s.segment(&camera(), &ev, &fl).unwrap();
    assert_eq!(c.count, 0);
    assert!(c.id.iter().all(|&i| i == UNASSIGNED));
    let c = s
        .segment(&camera(), &Events::default(), &NormalFlow::default())
        .unwrap();
    assert_eq!((c.count, c.id.len()), (0, 0));
}

#[test]
fn fewer_events_than_clusters() {
    let (ev, fl) = slice(5, |i| (i as f32, 0.0, 1.0));
    let mut s = Oversegmenter::new(OversegParams::default()).unwrap();
    let c = s.segment(&camera(), &ev, &fl).unwrap();
    assert_eq!(c.count, 5);
    let mut ids = c.id.clone();
    ids.sort_unstable();
    ids.dedup();
    assert_eq!(ids.len(), 5, "five distinct events, five clusters");
}

#[test]
fn malformed_input_is_an_error() {
    let (ev, mut fl) = slice(10, |_| (1.0, 0.0, 1.0));
    fl.confidence.pop();
    let mut s = Oversegmenter::new(OversegParams::default()).unwrap();
    assert!(matches!(
        s.segment(&camera(), &ev, &fl),
        Err(OversegError::Input(AlignError::FlowLength {
            confidence: 9,
            events: 10,
            ..
        }))
    ));
    let (mut ev, fl) = slice(10, |_| (1.0, 0.0, 1.0));
    ev.x[3] = 320;
    let e = s.segment(&camera(), &ev, &fl).unwrap_err();
    assert_eq!(
        e,
        OversegError::Input(AlignError::EventOutside {
            index: 3,
            x: 320,
            y: ev.y[3],
            width: 320,
            height: 240
        })
    );
    ev.p.pop();
    assert_eq!(
        s.segment(&camera(), &ev, &fl),
        Err(OversegError::Input(AlignError::EventColumns))
    );
    for p in [
        OversegParams {
            k: 0,
            ..Default::default()
        },
        OversegParams {
            lambda: f64::NAN,
            ..Default::default()
        },
        OversegParams {
            max_samples: 0,
            ..Default::default()
        },
    ] {
        assert!(matches!(Oversegmenter::new(p), Err(OversegError::Param(_))));
    }
}
