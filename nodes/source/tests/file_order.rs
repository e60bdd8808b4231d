//! Text recordings stored out of time order (as a tool that writes each render interval pixel by
//! pixel stores them), read by the file source: the reorder window sorts late-stored events into
//! their batch across the decoder's read chunks, and the disorder is counted, not an error.

use std::io::Write;
use std::path::Path;

use evseg_source::EventSource;
use evseg_source::file::{FileSource, READ_CHUNK};

mod common;
use common::{read_batches, sorted};

/// Writes `events.txt` (microsecond times, so the text round-trips exactly) with the events in
/// `order`, and a pinhole `calib.txt` beside it.
fn write_text(dir: &Path, name: &str, t_us: &[u64], order: &[usize]) -> std::path::PathBuf {
    let sub = dir.join(name);
    std::fs::create_dir_all(&sub).unwrap();
    std::fs::write(sub.join("calib.txt"), "200 200 50 40\n").unwrap();
    let path = sub.join("events.txt");
    let mut f = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    for &i in order {
        let (x, y) = (i % 101, (i / 101) % 81);
        writeln!(f, "{:.6} {x} {y} {}", t_us[i] as f64 * 1e-6, i % 2).unwrap();
    }
    f.flush().unwrap();
    path
}

#[test]
fn text_events_stored_out_of_order_reach_their_batch() {
    // An event every 6.7 us over 0.6 s: 90 000 events, more than one read chunk, and the first
    // chunk ends (event 65 536, 439.1 ms) inside the block that straddles the batch end at
    // 440 ms, so the events of that batch are split between two reads.
    let n = 90_000usize;
    assert!(n > READ_CHUNK);
    let t_us: Vec<u64> = (0..n as u64).map(|i| i * 67 / 10).collect();
    let dir = tempfile::tempdir().unwrap();
    let in_order: Vec<usize> = (0..n).collect();
    // Reversed within blocks of 5 ms that straddle the batch boundaries (edges at 2.5 ms + k 5
    // ms): the first event stored is not the earliest, which the source's time origin must be.
    let block = |i: usize| (t_us[i] + 2_500) / 5_000;
    let mut shuffled: Vec<usize> = (0..n).collect();
    shuffled.sort_by_key(|&i| (block(i), std::cmp::Reverse(i)));
    assert_ne!(shuffled[0], 0);
    let sorted_path = write_text(dir.path(), "sorted", &t_us, &in_order);
    let shuffled_path = write_text(dir.path(), "shuffled", &t_us, &shuffled);
    let open = |p: &Path| FileSource::open(p, None, None).unwrap();

    let (want, late) = read_batches(&mut open(&sorted_path));
    assert_eq!((want.len(), late), (n, 0));
    let mut source = open(&shuffled_path);
    let origin_at_open = source.camera().time_origin_us;
    let (got, late) = read_batches(&mut source);
    // The first stored event is 6.7 us x (its index) after the earliest: the absolute origin
    // moved back by as much.
    let first_stored_us = t_us[shuffled[0]] as i64;
    assert_eq!(origin_at_open - source.camera().time_origin_us, first_stored_us);
    assert_eq!(late, 0, "events of the shuffled file arrived after their batch");
    // The same events at the same times: the shuffled file's times are counted from its first
    // stored event and then shifted to its earliest, so they may differ in the last bits.
    let (got, want) = (sorted(&got), sorted(&want));
    assert_eq!(got.len(), want.len());
    let worst = got
        .iter()
        .zip(&want)
        .map(|(a, b)| {
            assert_eq!(
                (a.1, a.2, a.3),
                (b.1, b.2, b.3),
                "the shuffled file's events differ"
            );
            (f64::from_bits(a.0) - f64::from_bits(b.0)).abs()
        })
        .fold(0.0, f64::max);
    assert!(worst < 1e-12, "times differ by up to {worst} s");
    let counters: std::collections::BTreeMap<_, _> = source.counters().into_iter().collect();
    assert!(counters["times_out_of_order_in_file"] > 1000, "{counters:?}");
    assert!(source.reordered() > 1000);

    // Without the window the same file hands events to later batches: the test can fail.
    let mut no_window = open(&shuffled_path);
    no_window.set_reorder_window(0.0).unwrap();
    let (_, late) = read_batches(&mut no_window);
    assert!(late > 100, "only {late} late events without the reorder window");
    let e = open(&shuffled_path)
        .set_reorder_window(-0.001)
        .err()
        .map(|e| e.to_string());
    assert_eq!(
        e.as_deref(),
        Some("reorder_window_ms: -1 ms must be finite and >= 0")
    );
}

/// An EVT 3.0 file whose header names no sensor size takes it from the camera file (as the
/// source node's `camera_file` gives it); without one the error says where to give it.
#[test]
fn a_recording_without_its_size_takes_the_camera_files() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = b"% evt 3.0\n".to_vec();
    // Time high 1, y 700, x 1000 (EVT 3.0 words: type << 12 | payload).
    for w in [0x8u16 << 12 | 1, 700, 0x2 << 12 | 1000] {
        bytes.extend_from_slice(&w.to_le_bytes());
    }
    let raw = dir.path().join("nosize.raw");
    std::fs::write(&raw, bytes).unwrap();
    let e = FileSource::open(&raw, None, None)
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("camera_file"), "{e}");
    let cam = dir.path().join("cam.json");
    std::fs::write(
        &cam,
        r#"{ "width": 1280, "height": 720, "fx": 1000, "fy": 1000, "cx": 639.5, "cy": 359.5, "distortion": { "model": "none" } }"#,
    )
    .unwrap();
    let mut source = FileSource::open(&raw, Some(&cam), None).unwrap();
    let camera = source.camera();
    assert_eq!((camera.width, camera.height), (1280, 720));
    let (events, late) = read_batches(&mut source);
    assert_eq!((events.len(), events.x[0], events.y[0], late), (1, 1000, 700, 0));
}
