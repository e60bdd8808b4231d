//! EVIMO2 folders written by other tools, read by the source.
//!
//! - Events stored out of time order (as a simulator that writes each render interval pixel by
//!   pixel would) read back batch by batch as the sorted folder does: the source's reorder
//!   window sorts late-stored events into their batch, and the time origin is the earliest
//!   event, not the first stored one.
//! - Events outside the sensor are dropped and counted, so no stage gets a pixel it cannot
//!   index.

use std::path::Path;

use evseg_evimo2::npy::encode_array;
use evseg_evimo2::{EventReader, ReadOptions, Sequence};
use evseg_source::EventSource;
use evseg_source::evimo2::Evimo2Source;
use evseg_source::synthetic::write_evimo2;

mod common;
use common::{read_batches, sorted};

/// Copies `from` into `to` with the events stored reversed within blocks of 5 ms that straddle
/// the 10 ms batch boundaries (block edges at 2.5 ms + k 5 ms).
fn write_shuffled_copy(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), to.join(entry.file_name())).unwrap();
    }
    let t0 = Sequence::open(from, &ReadOptions::default()).unwrap().t0_s;
    let ev = EventReader::open(from).unwrap().read_all().unwrap();
    let block = |i: usize| ((ev.t[i] + 0.0025) / 0.005).floor() as i64;
    let mut order: Vec<usize> = (0..ev.len()).collect();
    order.sort_by_key(|&i| (block(i), std::cmp::Reverse(i)));
    let t: Vec<u8> = order.iter().flat_map(|&i| (ev.t[i] + t0).to_le_bytes()).collect();
    let xy: Vec<u8> = order
        .iter()
        .flat_map(|&i| [ev.x[i].to_le_bytes(), ev.y[i].to_le_bytes()].concat())
        .collect();
    let p: Vec<u8> = order.iter().map(|&i| ev.p[i]).collect();
    let n = order.len();
    std::fs::write(to.join("dataset_events_t.npy"), encode_array("<f8", &[n], &t)).unwrap();
    std::fs::write(
        to.join("dataset_events_xy.npy"),
        encode_array("<u2", &[n, 2], &xy),
    )
    .unwrap();
    std::fs::write(to.join("dataset_events_p.npy"), encode_array("|u1", &[n], &p)).unwrap();
}

#[test]
fn events_stored_out_of_order_reach_their_batch() {
    let dir = tempfile::tempdir().unwrap();
    let (sorted_dir, shuffled_dir) = (dir.path().join("sorted"), dir.path().join("shuffled"));
    let n = write_evimo2("two-objects", 5, Some(0.2), 0.25, &sorted_dir).unwrap();
    assert!(n > 1000, "only {n} events");
    write_shuffled_copy(&sorted_dir, &shuffled_dir);
    let open = |d: &Path| Evimo2Source::open(d, &ReadOptions::default(), None).unwrap();

    let (want, late) = read_batches(&mut open(&sorted_dir));
    assert_eq!((want.len(), late), (n as usize, 0));
    let (got, late) = read_batches(&mut open(&shuffled_dir));
    assert_eq!(late, 0, "events of the shuffled folder arrived after their batch");
    assert_eq!(sorted(&got), sorted(&want), "the shuffled folder's events differ");

    // Without the window the same folder hands events to later batches: the test can fail.
    let mut no_window = open(&shuffled_dir);
    no_window.set_reorder_window(0.0).unwrap();
    let (_, late) = read_batches(&mut no_window);
    assert!(late > 100, "only {late} late events without the reorder window");
    assert!(open(&shuffled_dir).set_reorder_window(f64::NAN).is_err());
}

#[test]
fn events_outside_the_sensor_are_dropped_and_counted() {
    let dir = tempfile::tempdir().unwrap();
    let n = write_evimo2("one-object", 2, Some(0.05), 0.25, dir.path()).unwrap();
    let camera = Sequence::open(dir.path(), &ReadOptions::default())
        .unwrap()
        .camera;
    // Three events one past the last column or row (a writer's off-by-one).
    let path = dir.path().join("dataset_events_xy.npy");
    let ev = EventReader::open(dir.path()).unwrap().read_all().unwrap();
    let mut xy: Vec<[u16; 2]> = (0..ev.len()).map(|i| [ev.x[i], ev.y[i]]).collect();
    xy[10][0] = camera.width;
    xy[20][1] = camera.height;
    xy[30] = [camera.width + 5, 0];
    let bytes: Vec<u8> = xy
        .iter()
        .flat_map(|p| [p[0].to_le_bytes(), p[1].to_le_bytes()].concat())
        .collect();
    std::fs::write(&path, encode_array("<u2", &[xy.len(), 2], &bytes)).unwrap();

    let mut source = Evimo2Source::open(dir.path(), &ReadOptions::default(), None).unwrap();
    let (got, _) = read_batches(&mut source);
    assert_eq!(got.len(), n as usize - 3);
    assert!(
        (0..got.len()).all(|i| got.x[i] < camera.width && got.y[i] < camera.height),
        "an event outside the sensor reached a batch"
    );
    let mut source = Evimo2Source::open(dir.path(), &ReadOptions::default(), None).unwrap();
    while source.next_batch(1.0).unwrap().is_some() {}
    assert!(source.counters().contains(&("events_outside_sensor", 3)));
}
