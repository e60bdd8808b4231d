//! The tracker on simulated sequences segmented by the ground truth ("oracle" segmentation whose
//! labels are scrambled every slice, as a segmenter's per-slice cluster numbers are): every
//! object must keep one track id for the whole sequence, different objects different ids, and
//! background events must stay 0. An object's events are unconfirmed (moving, no id) only in
//! its track's first `min_hits - 1` slices.

use std::collections::{BTreeMap, BTreeSet};

use evseg_schemas::{Egomotion, EventPacket, Events, Segment, Segmentation, Tracks, Truth};
use evseg_slicer::{SliceOut, Slicer, SlicerParams};
use evseg_tracker::{Tracker, TrackerParams};

/// The segmentation of a slice by its true object ids, each object's label scrambled with the
/// slice number so that the segmenter's labels carry no identity across slices.
fn oracle_segmentation(events: &Events, truth: &Truth, seq: u64) -> Segmentation {
    let scramble = |id: u16| (u32::from(id) * 7 + seq as u32 * 3) % 101 + 1;
    let mut stats: BTreeMap<u16, ([f32; 4], [f64; 2], u32)> = BTreeMap::new();
    for i in 0..events.len() {
        let id = truth.event_object[i];
        if id == 0 {
            continue;
        }
        let (x, y) = (f32::from(events.x[i]), f32::from(events.y[i]));
        let st = stats
            .entry(id)
            .or_insert(([f32::MAX, f32::MAX, f32::MIN, f32::MIN], [0.0; 2], 0));
        st.0 = [st.0[0].min(x), st.0[1].min(y), st.0[2].max(x), st.0[3].max(y)];
        st.1[0] += f64::from(x);
        st.1[1] += f64::from(y);
        st.2 += 1;
    }
    Segmentation {
        label: truth
            .event_object
            .iter()
            .map(|&id| if id == 0 { 0 } else { scramble(id) })
            .collect(),
        segments: stats
            .iter()
            .map(|(&id, &(bbox, sum, n))| Segment {
                label: scramble(id),
                translation: [0.0; 3],
                centroid: [sum[0] / f64::from(n), sum[1] / f64::from(n)],
                bbox,
                events: n,
            })
            .collect(),
        egomotion: Egomotion::default(),
    }
}

/// Track ids seen per ground-truth object id.
type IdsPerObject = BTreeMap<u16, BTreeSet<u32>>;

/// Runs `preset` through the slicer and the tracker. Returns, per object, the set of track ids
/// its events got in slices where it had at least `min_events` events, and the number of slices
/// where such an object's events were not all labelled with one non-zero id, not counting the
/// first `min_hits - 1` slices in which they were all unconfirmed.
fn track_preset(
    preset: &str,
    seconds: f64,
    scale: f64,
) -> Result<(IdsPerObject, usize), Box<dyn std::error::Error>> {
    let mut cfg = evseg_sim::preset(preset, 1)?.with_resolution_scale(scale);
    cfg.duration_s = cfg.duration_s.min(seconds);
    let mut sim = evseg_sim::Simulator::new(cfg)?;
    let camera = sim.camera_info();
    let mut slicer = Slicer::new(SlicerParams::default())?;
    let params = TrackerParams::default();
    let min_events = params.min_events;
    let tentative_slices = params.min_hits as usize - 1;
    let mut unconfirmed: BTreeMap<u16, usize> = BTreeMap::new();
    let mut tracker = Tracker::new(params)?;
    let mut ids = IdsPerObject::new();
    let mut bad_slices = 0;
    let mut feed = |slices: Vec<SliceOut>| -> Result<(), Box<dyn std::error::Error>> {
        for s in slices {
            let truth = s.truth.ok_or("slice without truth")?;
            let n = s.slice.events.len();
            assert_eq!(truth.event_object.len(), n, "simulator truth must be per event");
            let seg = oracle_segmentation(&s.slice.events, &truth, s.seq);
            let out = tracker.update((s.t_start, s.t_end), n, &seg)?;
            assert_eq!(out.label.len(), n);
            let mut per_object: BTreeMap<u16, BTreeSet<u32>> = BTreeMap::new();
            for (&obj, &id) in truth.event_object.iter().zip(&out.label) {
                if obj == 0 {
                    assert_eq!(id, 0, "slice {}: a background event got a track id", s.seq);
                } else {
                    per_object.entry(obj).or_default().insert(id);
                }
            }
            for (obj, set) in per_object {
                let count = truth.event_object.iter().filter(|&&o| o == obj).count();
                if count < min_events as usize {
                    continue;
                }
                if set.len() == 1 && set.contains(&Tracks::UNCONFIRMED) {
                    let n = unconfirmed.entry(obj).or_default();
                    *n += 1;
                    if *n > tentative_slices {
                        bad_slices += 1;
                    }
                    continue;
                }
                if set.len() != 1 || set.contains(&0) || set.contains(&Tracks::UNCONFIRMED) {
                    bad_slices += 1;
                }
                ids.entry(obj).or_default().extend(set);
            }
        }
        Ok(())
    };
    while !sim.is_finished() {
        let t_end = sim.time() + 0.01;
        let chunk = sim.next_chunk(t_end);
        let packet = EventPacket {
            camera: camera.clone(),
            events: chunk.events,
            imu: chunk.imu,
        };
        feed(slicer.push(packet, Some(chunk.truth), sim.time())?)?;
    }
    feed(slicer.finish())?;
    Ok((ids, bad_slices))
}

fn assert_one_id_per_object(
    preset: &str,
    seconds: f64,
    scale: f64,
    objects: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    let (ids, bad) = track_preset(preset, seconds, scale)?;
    eprintln!("{preset}: ids per object {ids:?}, slices with split or missing ids {bad}");
    assert_eq!(ids.len(), objects, "{preset}: objects seen");
    assert_eq!(
        bad, 0,
        "{preset}: slices where an object's events were not one track"
    );
    let all: BTreeSet<u32> = ids.values().flatten().copied().collect();
    assert!(
        ids.values().all(|s| s.len() == 1),
        "{preset}: an object changed id: {ids:?}"
    );
    assert_eq!(all.len(), objects, "{preset}: two objects share an id: {ids:?}");
    Ok(())
}

#[test]
fn two_objects_keep_one_id_each_over_the_sequence() -> Result<(), Box<dyn std::error::Error>> {
    // Full resolution (640x480) for the first 1.5 s, which include object 2 occluding most of
    // object 1 (0.4-0.5 s).
    assert_one_id_per_object("two-objects", 1.5, 1.0, 2)
}

#[test]
fn objects_entering_and_leaving_get_one_id_each() -> Result<(), Box<dyn std::error::Error>> {
    // Half resolution to keep the 5 s sequence quick.
    assert_one_id_per_object("enter-leave", 5.0, 0.5, 2)
}
