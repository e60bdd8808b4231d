//! Write a synthetic sequence, read it back, compare everything.

mod common;

use evseg_evimo2::{
    MetaForm, ReadOptions, Sequence, SequenceData, WriteOptions, write_sequence, write_sequence_with,
};
use evseg_schemas::Events;

fn written(form: MetaForm, compress: bool) -> (tempfile::TempDir, SequenceData) {
    let dir = tempfile::tempdir().unwrap();
    let data = common::sequence();
    let opts = WriteOptions {
        meta_form: form,
        compress,
        ..WriteOptions::default()
    };
    write_sequence_with(dir.path(), &data, &opts).unwrap();
    (dir, data)
}

#[test]
fn round_trip_is_exact() {
    let (dir, data) = written(MetaForm::Pickle, true);
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    assert_eq!(seq.t0_s, common::T_START);
    assert_eq!(seq.camera, data.camera);
    assert_eq!(seq.event_count, common::N_EVENTS as u64);
    assert_eq!(seq.imu_topic.as_deref(), Some("/prophesee/left/imu"));
    assert_eq!(seq.imu_topics, vec!["/prophesee/left/imu".to_string()]);
    assert_eq!(seq.imu, data.imu);
    assert_eq!(seq.camera_poses, data.camera_poses);
    assert_eq!(seq.frames, data.frames);
    assert_eq!(seq.object_poses().len(), 5);
    assert_eq!(seq.ros_time_offset_s, None);

    let mut events = seq.events().unwrap();
    assert_eq!(events.read_all().unwrap(), data.events);
    assert_eq!(events.non_monotonic(), 0);

    let mut masks = seq.masks().unwrap();
    assert_eq!(masks.len(), 3);
    let read: Vec<_> = masks.iter().collect::<Result<_, _>>().unwrap();
    assert_eq!(read, data.masks);
    // Two objects, and object 2 is absent from frame 1 as written.
    assert!(read[0].ids.contains(&2) && !read[1].ids.contains(&2) && read[1].ids.contains(&1));

    let mut depth = seq.depth().unwrap().expect("depth written");
    let expected = data.depth_mm.as_ref().unwrap();
    assert_eq!(depth.len(), expected.len());
    for (i, want) in expected.iter().enumerate() {
        let d = depth.read(i).unwrap();
        assert_eq!(d.t, data.frames[i].t);
        assert_eq!(&d.depth_mm, want);
    }
}

#[test]
fn both_meta_forms_and_compressions_read_the_same() {
    let (pickled, _) = written(MetaForm::Pickle, false);
    let (literal, _) = written(MetaForm::Literal, true);
    let a = Sequence::open(pickled.path(), &ReadOptions::default()).unwrap();
    let b = Sequence::open(literal.path(), &ReadOptions::default()).unwrap();
    assert_eq!(
        Sequence {
            folder: b.folder.clone(),
            ..a.clone()
        },
        b
    );
    let ma: Vec<_> = a.masks().unwrap().iter().collect::<Result<_, _>>().unwrap();
    let mb: Vec<_> = b.masks().unwrap().iter().collect::<Result<_, _>>().unwrap();
    assert_eq!(ma, mb);
}

#[test]
fn options_override_the_imu_convention() {
    let (dir, _) = written(MetaForm::Pickle, true);
    let r = [1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0];
    let opts = ReadOptions {
        imu_to_camera: Some(r),
        imu_time_offset_s: Some(0.005),
        sensor: Some("x".into()),
        imu_topic: Some("/prophesee/left/imu".into()),
        max_time_gap_s: None,
    };
    let seq = Sequence::open(dir.path(), &opts).unwrap();
    assert_eq!(seq.camera.imu_to_camera, r);
    assert_eq!(seq.camera.imu_time_offset_s, 0.005);
    assert_eq!(seq.camera.sensor, "x");
}

fn concat(parts: Vec<Events>) -> Events {
    let mut all = Events::default();
    for p in parts {
        all.extend_from(&p, 0..p.len());
    }
    all
}

#[test]
fn chunked_reading_equals_one_read() {
    let (dir, data) = written(MetaForm::Pickle, true);
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();

    let mut r = seq.events().unwrap();
    r.set_scan_block(3);
    let mut parts = Vec::new();
    while let Some(chunk) = r.next_chunk(7).unwrap() {
        assert!(chunk.len() <= 7 && chunk.is_consistent());
        parts.push(chunk);
    }
    assert_eq!(parts.len(), common::N_EVENTS.div_ceil(7));
    assert_eq!(concat(parts), data.events);
    assert_eq!(r.position(), common::N_EVENTS as u64);

    // Time windows of 10 ms, with a tiny scan block, mixed with chunk reads.
    let mut r = seq.events().unwrap();
    r.set_scan_block(5);
    let mut parts = Vec::new();
    let mut t_end = 0.0;
    let mut windows = 0;
    while r.position() < r.len() {
        t_end += 0.01;
        let w = r.read_until(t_end).unwrap();
        assert!(
            w.t.iter().all(|&t| t < t_end && t >= t_end - 0.01 - 1e-12),
            "window ending {t_end}"
        );
        parts.push(w);
        windows += 1;
        if windows % 10 == 0 {
            parts.push(r.next_chunk(3).unwrap().unwrap_or_default());
        }
    }
    assert_eq!(concat(parts), data.events);
    assert_eq!(r.read_until(1e9).unwrap().len(), 0);
    assert!(r.next_chunk(10).unwrap().is_none());

    // read_until at the first event's time returns nothing and does not advance.
    let mut r = seq.events().unwrap();
    assert_eq!(r.read_until(0.0).unwrap().len(), 0);
    assert_eq!(r.position(), 0);
}

#[test]
fn non_monotonic_times_are_counted_not_fatal() {
    let dir = tempfile::tempdir().unwrap();
    let mut data = common::sequence();
    data.events.t[100] = data.events.t[99] - 0.001; // one step back, then forward again
    data.events.t[2000] = 0.0; // a big step back, then forward again
    write_sequence(dir.path(), &data).unwrap();
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    let mut r = seq.events().unwrap();
    let mut n = 0;
    while let Some(c) = r.next_chunk(333).unwrap() {
        n += c.len();
    }
    assert_eq!(n, common::N_EVENTS);
    assert_eq!(r.non_monotonic(), 2);
}

/// The reader's count of events dropped for their time, and the row and time of the first.
type TimeOutliers = (u64, Option<(u64, f64)>);

/// Reads every event of `dir` in chunks of 333; returns them with the reader's outlier count and
/// first outlier, or the error.
fn read_all_chunked(dir: &std::path::Path) -> evseg_evimo2::Result<(Events, TimeOutliers)> {
    let seq = Sequence::open(dir, &ReadOptions::default())?;
    let mut r = seq.events()?;
    let mut all = Events::default();
    while let Some(c) = r.next_chunk(333)? {
        all.extend_from(&c, 0..c.len());
    }
    Ok((all, r.time_outliers()))
}

#[test]
fn corrupt_event_times_are_dropped_and_counted_not_a_gap_of_empty_slices() {
    let dir = tempfile::tempdir().unwrap();
    let mut data = common::sequence();
    // (Not farther: the writer's event index holds an entry per 10 ms of the span.)
    data.events.t[4999] = 5000.0; // far in the future (the last event)
    data.events.t[10] = -3000.0; // far in the past, inside the first block (t0 must not take it)
    let finite = data.clone();
    data.events.t[300] = f64::NAN;
    assert!(
        write_sequence(dir.path(), &data)
            .unwrap_err()
            .to_string()
            .contains("event 300 has time NaN s"),
        "the writer refuses what it could not index"
    );
    write_sequence(dir.path(), &finite).unwrap();
    // Not-finite times written into the file as another tool might.
    let path = dir.path().join(evseg_evimo2::EVENTS_T);
    let mut bytes = std::fs::read(&path).unwrap();
    let data_offset = bytes.len() - 8 * common::N_EVENTS;
    for (i, t) in [(300, f64::NAN), (301, f64::INFINITY)] {
        bytes[data_offset + 8 * i..data_offset + 8 * i + 8]
            .copy_from_slice(&(t + common::T_START).to_le_bytes());
    }
    std::fs::write(&path, bytes).unwrap();
    data = finite;
    data.events.t[300] = f64::NAN;
    data.events.t[301] = f64::INFINITY;
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    assert_eq!(seq.t0_s, common::T_START, "t0 from the kept events");
    let (events, (dropped, first)) = read_all_chunked(dir.path()).unwrap();
    assert_eq!(events.len(), common::N_EVENTS - 4);
    assert_eq!(dropped, 4);
    assert_eq!(first, Some((10, -3000.0 + common::T_START)));
    assert!(
        events.t.iter().all(|t| (0.0..2.0).contains(t)),
        "every kept time is near the others"
    );
    // The kept events are the others, in order, with their pixels and polarities.
    let keep: Vec<usize> = (0..common::N_EVENTS)
        .filter(|i| ![10, 300, 301, 4999].contains(i))
        .collect();
    for (k, &i) in keep.iter().enumerate() {
        assert_eq!(
            (events.t[k], events.x[k], events.y[k], events.p[k]),
            (
                data.events.t[i],
                data.events.x[i],
                data.events.y[i],
                data.events.p[i]
            ),
            "event {i}"
        );
    }
}

/// A recording that pauses for longer than the default largest gap loses its second part
/// (counted) unless `max_time_gap_s` covers the pause; a gap outside the allowed range is
/// refused naming the events file.
#[test]
fn a_long_pause_is_kept_with_a_larger_time_gap() {
    let dir = tempfile::tempdir().unwrap();
    let mut data = common::sequence();
    let half = common::N_EVENTS / 2;
    for t in &mut data.events.t[half..] {
        *t += 20.0;
    }
    write_sequence(dir.path(), &data).unwrap();
    let read = |gap: Option<f64>| -> evseg_evimo2::Result<(usize, u64)> {
        let options = ReadOptions {
            max_time_gap_s: gap,
            ..Default::default()
        };
        let mut r = Sequence::open(dir.path(), &options)?.events()?;
        let mut n = 0;
        while let Some(c) = r.next_chunk(333)? {
            n += c.len();
        }
        Ok((n, r.time_outliers().0))
    };
    let after = (common::N_EVENTS - half) as u64;
    assert_eq!(
        read(None).unwrap(),
        (half, after),
        "the default drops the second part"
    );
    assert_eq!(read(Some(30.0)).unwrap(), (common::N_EVENTS, 0));
    for bad in [0.0, -1.0, f64::NAN, 1e9] {
        let e = read(Some(bad)).unwrap_err().to_string();
        assert!(
            e.contains("dataset_events_t.npy") && e.contains("largest time gap"),
            "{bad}: {e}"
        );
    }
}

#[test]
fn a_jump_in_event_times_is_an_error_naming_the_file_and_the_first_event() {
    let dir = tempfile::tempdir().unwrap();
    let mut data = common::sequence();
    // 70 000 more events in order (so that the events before the jump are most of the first
    // scan block, whose median is the first reference), then more than
    // MAX_CONSECUTIVE_TIME_OUTLIERS events shifted by a day: a block, not stray values.
    let last = data.events.t[common::N_EVENTS - 1];
    let copy = |d: &mut SequenceData, k: usize, t: f64| {
        let (x, y, p) = (d.events.x[k % 100], d.events.y[k % 100], d.events.p[k % 100]);
        d.events.push(t, x, y, p);
    };
    for k in 0..70_000 {
        copy(&mut data, k, last + (k + 1) as f64 * 1e-5);
    }
    let jump_at = data.events.len();
    let last = data.events.t[jump_at - 1];
    for k in 0..evseg_evimo2::reader::MAX_CONSECUTIVE_TIME_OUTLIERS as usize + 10 {
        copy(&mut data, k, last + 86_400.0 + k as f64 * 1e-6);
    }
    write_sequence(dir.path(), &data).unwrap();
    let err = read_all_chunked(dir.path()).map(|r| r.1).unwrap_err().to_string();
    assert!(
        err.contains("dataset_events_t.npy") && err.contains(&format!("from event {jump_at} on")),
        "{err}"
    );
}

#[test]
fn a_sequence_written_as_it_arrives_equals_one_written_whole() {
    let data = common::sequence();
    let whole = tempfile::tempdir().unwrap();
    write_sequence(whole.path(), &data).unwrap();
    let streamed = tempfile::tempdir().unwrap();
    let opts = WriteOptions {
        block_events: 1000,
        ..WriteOptions::default()
    };
    let mut w =
        evseg_evimo2::SequenceWriter::create(streamed.path(), &data.camera, data.t_start_s, &opts).unwrap();
    for (a, b) in [(0, 1), (1, 2345), (2345, common::N_EVENTS)] {
        let mut part = Events::default();
        part.extend_from(&data.events, a..b);
        w.push_events(&part).unwrap();
    }
    for (f, m) in data.frames.iter().zip(&data.masks) {
        w.push_mask(f.id, m).unwrap();
    }
    let n = w
        .finish(&data.imu_topic, &data.imu, &data.camera_poses, &data.frames)
        .unwrap();
    assert_eq!(n, common::N_EVENTS as u64);
    for file in [
        "dataset_events_t.npy",
        "dataset_events_xy.npy",
        "dataset_events_p.npy",
        "dataset_mask.npz",
        "dataset_info.npz",
    ] {
        assert_eq!(
            std::fs::read(whole.path().join(file)).unwrap(),
            std::fs::read(streamed.path().join(file)).unwrap(),
            "{file}"
        );
    }
}

#[test]
fn the_streaming_writer_names_a_bad_time_by_its_row_and_frames_that_do_not_match_the_masks() {
    let data = common::sequence();
    let dir = tempfile::tempdir().unwrap();
    let mut w = evseg_evimo2::SequenceWriter::create(dir.path(), &data.camera, 0.0, &WriteOptions::default())
        .unwrap();
    let mut part = Events::default();
    part.extend_from(&data.events, 0..10);
    w.push_events(&part).unwrap();
    part.t[3] = f64::INFINITY;
    let e = w.push_events(&part).unwrap_err().to_string();
    assert!(
        e.contains("dataset_events_t.npy") && e.contains("event 13 has time inf"),
        "{e}"
    );
    w.push_mask(data.frames[0].id, &data.masks[0]).unwrap();
    let e = w
        .finish(&data.imu_topic, &data.imu, &data.camera_poses, &data.frames)
        .unwrap_err()
        .to_string();
    assert!(e.contains("dataset_mask.npz") && e.contains("1 masks for"), "{e}");
}

#[test]
fn index_matches_pydvs_definition() {
    // t = 0, 0.004, ..., 0.1 (26 events), w = 0.01.
    let t: Vec<f64> = (0..26).map(|i| i as f64 * 0.004).collect();
    let idx = evseg_evimo2::writer::event_index(t.iter().copied(), t.len(), 0.01);
    // Reference: the pydvs get_index loop run by python3 on the same floats (float rounding moves
    // some entries by one from an exact-decimal reasoning).
    assert_eq!(idx, vec![0, 3, 6, 8, 10, 13, 16, 18, 21, 23, 25, 25]);
    assert_eq!(
        evseg_evimo2::writer::event_index([1.0].into_iter(), 1, 0.01),
        vec![0]
    );
}

#[cfg(unix)]
#[test]
fn links_back_into_the_tree_do_not_list_a_sequence_twice() {
    let dir = tempfile::tempdir().unwrap();
    let root = dir.path().join("fan");
    write_sequence(&root.join("seq"), &common::sequence()).unwrap();
    // Links to the root itself, to its parent (which holds it) and a second name of the sequence.
    for (name, target) in [("l1", "."), ("l2", ".."), ("again", "seq")] {
        std::os::unix::fs::symlink(target, root.join(name)).unwrap();
    }
    let (found, complete) = evseg_evimo2::find_sequence_folders(&root);
    assert!(complete);
    assert_eq!(
        found,
        vec![root.join("again")],
        "one of the two names, the first in order"
    );
}
