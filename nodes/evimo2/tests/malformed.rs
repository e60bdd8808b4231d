//! Bad inputs give errors that name the file (and member), never a panic.

mod common;

use std::path::Path;

use evseg_evimo2::npy;
use evseg_evimo2::{
    EventReader, MetaForm, ReadOptions, Sequence, WriteOptions, write_sequence, write_sequence_with,
};

fn folder() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    write_sequence(dir.path(), &common::sequence()).unwrap();
    dir
}

fn open_err(dir: &Path) -> String {
    match Sequence::open(dir, &ReadOptions::default()) {
        Ok(_) => panic!("opening {} should fail", dir.display()),
        Err(e) => e.to_string(),
    }
}

/// Rewrites `dataset_info.npz` with `meta` replaced by the given `.npy` image.
fn replace_meta(dir: &Path, meta_npy: &[u8]) {
    let path = dir.join("dataset_info.npz");
    let mut old = evseg_evimo2::npz::NpzReader::open(&path).unwrap();
    let k = old.read_key("K").unwrap();
    drop(old);
    let mut w = evseg_evimo2::npz::NpzWriter::create(&path, true).unwrap();
    w.add("K", &npy::encode_array(&k.header.descr, &k.header.shape, &k.data))
        .unwrap();
    w.add("meta", meta_npy).unwrap();
    w.finish().unwrap();
}

fn unicode_npy(text: &str) -> Vec<u8> {
    let n = text.chars().count().max(1);
    let mut data: Vec<u8> = text.chars().flat_map(|c| (c as u32).to_le_bytes()).collect();
    data.resize(4 * n, 0);
    npy::encode_array(&format!("<U{n}"), &[], &data)
}

#[test]
fn truncated_event_file() {
    let dir = folder();
    let path = dir.path().join("dataset_events_t.npy");
    let len = std::fs::metadata(&path).unwrap().len();
    let f = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    f.set_len(len - 3).unwrap();
    let e = open_err(dir.path());
    assert!(
        e.contains("dataset_events_t.npy") && e.contains("truncated"),
        "{e}"
    );
    assert!(e.contains(&format!("byte {}", len - 3)), "{e}");

    // Cut inside the header.
    f.set_len(40).unwrap();
    let e = EventReader::open(dir.path()).unwrap_err().to_string();
    assert!(
        e.contains("dataset_events_t.npy: byte 40") && e.contains("header"),
        "{e}"
    );
    f.set_len(0).unwrap();
    let e = EventReader::open(dir.path()).unwrap_err().to_string();
    assert!(e.contains("dataset_events_t.npy: byte 0"), "{e}");
}

#[test]
fn wrong_dtype_and_shape() {
    let dir = folder();
    let n = common::N_EVENTS;
    std::fs::write(
        dir.path().join("dataset_events_xy.npy"),
        npy::encode_array("<f8", &[n, 2], &vec![0u8; n * 16]),
    )
    .unwrap();
    let e = open_err(dir.path());
    assert!(e.contains("dataset_events_xy.npy") && e.contains("'<f8'"), "{e}");

    std::fs::write(
        dir.path().join("dataset_events_xy.npy"),
        npy::encode_array("<u2", &[n, 3], &vec![0u8; n * 6]),
    )
    .unwrap();
    let e = open_err(dir.path());
    assert!(
        e.contains("dataset_events_xy.npy") && e.contains("shape [5000, 3]"),
        "{e}"
    );

    std::fs::write(
        dir.path().join("dataset_events_t.npy"),
        npy::encode_array("<c16", &[n], &vec![0u8; n * 16]),
    )
    .unwrap();
    let e = open_err(dir.path());
    assert!(
        e.contains("dataset_events_t.npy") && e.contains("unsupported dtype '<c16'"),
        "{e}"
    );

    // Out-of-range coordinates in a wider integer type are reported with the event number.
    let dir = folder();
    let mut xy: Vec<u8> = Vec::new();
    for i in 0..n as i64 {
        let x = if i == 1234 { 70_000 } else { i % 64 };
        xy.extend_from_slice(&x.to_le_bytes());
        xy.extend_from_slice(&(i % 48).to_le_bytes());
    }
    std::fs::write(
        dir.path().join("dataset_events_xy.npy"),
        npy::encode_array("<i8", &[n, 2], &xy),
    )
    .unwrap();
    let mut r = EventReader::open(dir.path()).unwrap();
    assert_eq!(r.next_chunk(1000).unwrap().unwrap().x[999], 999 % 64);
    let e = r.next_chunk(1000).unwrap_err().to_string();
    assert!(
        e.contains("dataset_events_xy.npy") && e.contains("event 1234"),
        "{e}"
    );
}

/// Polarity columns of floats are read (value > 0 is ON), but a NaN is an error naming the file
/// and the event, and a column of strings is refused at open naming the file.
#[test]
fn bad_polarity_columns() {
    let n = common::N_EVENTS;
    let dir = folder();
    let p: Vec<u8> = (0..n)
        .flat_map(|i| {
            let v = if i == 1500 {
                f32::NAN
            } else if i % 2 == 0 {
                -1.0
            } else {
                1.0
            };
            v.to_le_bytes()
        })
        .collect();
    std::fs::write(
        dir.path().join("dataset_events_p.npy"),
        npy::encode_array("<f4", &[n], &p),
    )
    .unwrap();
    let mut r = EventReader::open(dir.path()).unwrap();
    let first = r.next_chunk(1000).unwrap().unwrap();
    assert_eq!(first.p[..4], [0, 1, 0, 1]);
    let e = r.next_chunk(1000).unwrap_err().to_string();
    assert!(
        e.contains("dataset_events_p.npy") && e.contains("event 1500") && e.contains("NaN"),
        "{e}"
    );

    let dir = folder();
    std::fs::write(
        dir.path().join("dataset_events_p.npy"),
        npy::encode_array("<U1", &[n], &vec![0u8; 4 * n]),
    )
    .unwrap();
    let e = open_err(dir.path());
    assert!(
        e.contains("dataset_events_p.npy") && e.contains("bool, integer or float"),
        "{e}"
    );
}

#[test]
fn mismatched_event_counts() {
    let dir = folder();
    let n = common::N_EVENTS - 1;
    std::fs::write(
        dir.path().join("dataset_events_p.npy"),
        npy::encode_array("|u1", &[n], &vec![1u8; n]),
    )
    .unwrap();
    let e = open_err(dir.path());
    for name in [
        "dataset_events_t.npy",
        "dataset_events_xy.npy",
        "dataset_events_p.npy",
    ] {
        assert!(e.contains(name), "{e}");
    }
    assert!(e.contains("5000") && e.contains("4999"), "{e}");
}

#[test]
fn missing_files() {
    for name in ["dataset_events_p.npy", "dataset_info.npz"] {
        let dir = folder();
        std::fs::remove_file(dir.path().join(name)).unwrap();
        let e = open_err(dir.path());
        assert!(e.contains(name), "{e}");
    }
    let dir = folder();
    std::fs::remove_file(dir.path().join("dataset_mask.npz")).unwrap();
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    let e = seq.masks().unwrap_err().to_string();
    assert!(e.contains("dataset_mask.npz"), "{e}");
    std::fs::remove_file(dir.path().join("dataset_depth.npz")).unwrap();
    assert!(seq.depth().unwrap().is_none());
}

#[test]
fn a_folder_that_is_not_a_sequence_names_the_sequences_below_it() {
    // A dataset's layout: <camera>/<category>/<split>/<sequence>/, two sequences.
    let root = tempfile::tempdir().unwrap();
    let split = root.path().join("samsung_mono/imo/eval");
    for name in ["scene13_dyn_test_00_000000", "scene14_dyn_test_03_000000"] {
        write_sequence(&split.join(name), &common::sequence()).unwrap();
    }
    let e = open_err(&split);
    assert!(e.contains("not an EVIMO2 v2 sequence folder"), "{e}");
    assert!(
        e.contains("scene13_dyn_test_00_000000, scene14_dyn_test_03_000000; pass one"),
        "{e}"
    );
    // From the dataset's root the names carry the path below it.
    let e = open_err(root.path());
    assert!(
        e.contains("samsung_mono/imo/eval/scene13_dyn_test_00_000000"),
        "{e}"
    );
    // A folder with no sequence below it, and a path that does not exist.
    let empty = tempfile::tempdir().unwrap();
    let e = open_err(empty.path());
    assert!(
        e.contains("none of the folders up to 4 levels below it is one"),
        "{e}"
    );
    let e = open_err(&empty.path().join("nowhere"));
    assert!(e.contains("no such folder") && e.contains("nowhere"), "{e}");
    // The sequence folder itself opens.
    Sequence::open(&split.join("scene13_dyn_test_00_000000"), &ReadOptions::default()).unwrap();
}

#[test]
fn camera_fields_missing_from_meta_come_from_k_and_the_masks() {
    let dir = folder();
    let full = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    assert!(full.camera_fallbacks.is_empty());
    // A writer that keeps the calibration in K and the masks only.
    replace_meta(dir.path(), &unicode_npy("{'meta': {'dist_model': 'none'}}"));
    let s = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    let c = (&s.camera, &full.camera);
    assert_eq!((c.0.fx, c.0.fy, c.0.cx, c.0.cy), (c.1.fx, c.1.fy, c.1.cx, c.1.cy));
    assert_eq!((c.0.width, c.0.height), (c.1.width, c.1.height));
    assert_eq!(
        s.camera_fallbacks,
        [
            "fx, fy, cx, cy from dataset_info.npz[K]",
            "res_x, res_y from dataset_mask.npz"
        ]
    );
    // Without masks, the resolution has no source: the error names the fields and the file.
    std::fs::remove_file(dir.path().join("dataset_mask.npz")).unwrap();
    let e = open_err(dir.path());
    assert!(
        e.contains("res_x or res_y") && e.contains("dataset_mask.npz"),
        "{e}"
    );
    // Without K (and without fx), the intrinsics have none either.
    let path = dir.path().join("dataset_info.npz");
    let mut w = evseg_evimo2::npz::NpzWriter::create(&path, true).unwrap();
    w.add(
        "meta",
        &unicode_npy("{'meta': {'fy': 1.0, 'res_x': 8, 'res_y': 6}}"),
    )
    .unwrap();
    w.finish().unwrap();
    let e = open_err(dir.path());
    assert!(
        e.contains("missing fx, cx, cy") && e.contains("no usable K"),
        "{e}"
    );
}

#[test]
fn npz_that_is_not_a_zip_or_is_corrupt() {
    let dir = folder();
    std::fs::write(
        dir.path().join("dataset_mask.npz"),
        b"\x93NUMPY this is an npy, not a zip",
    )
    .unwrap();
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    let e = seq.masks().unwrap_err().to_string();
    assert!(e.contains("dataset_mask.npz") && e.contains("zip"), "{e}");

    std::fs::write(dir.path().join("dataset_info.npz"), b"garbage").unwrap();
    let e = open_err(dir.path());
    assert!(e.contains("dataset_info.npz") && e.contains("zip"), "{e}");

    // Corrupt the deflated data of the mask members (keep the zip directory intact): every read
    // fails with an error naming the member, or (if the flip lands in padding) succeeds.
    let dir = folder();
    let path = dir.path().join("dataset_mask.npz");
    let original = std::fs::read(&path).unwrap();
    let mut failures = 0;
    for pos in (40..original.len().saturating_sub(200)).step_by(37) {
        let mut bytes = original.clone();
        bytes[pos] ^= 0x5a;
        std::fs::write(&path, &bytes).unwrap();
        let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
        let result = seq
            .masks()
            .and_then(|mut m| m.iter().collect::<Result<Vec<_>, _>>());
        if let Err(e) = result {
            let e = e.to_string();
            assert!(e.contains("dataset_mask.npz"), "{e}");
            failures += 1;
        }
    }
    assert!(
        failures > 0,
        "flipping bytes of deflated data never produced an error"
    );
}

#[test]
fn meta_garbage() {
    let dir = folder();
    replace_meta(dir.path(), &unicode_npy("{'meta': {'fx': 1.0, "));
    let e = open_err(dir.path());
    assert!(
        e.contains("dataset_info.npz[meta.npy]") && e.contains("not a Python literal"),
        "{e}"
    );

    let mut pickle_garbage = npy::encode_header("|O", false, &[]);
    pickle_garbage.extend_from_slice(b"\x80\x03this is not a pickle");
    replace_meta(dir.path(), &pickle_garbage);
    let e = open_err(dir.path());
    assert!(
        e.contains("dataset_info.npz[meta.npy]") && e.contains("pickle"),
        "{e}"
    );

    replace_meta(dir.path(), &npy::encode_array("<f8", &[1], &1.0f64.to_le_bytes()));
    let e = open_err(dir.path());
    assert!(e.contains("meta has dtype '<f8'"), "{e}");

    // Without 'fx' the four intrinsics come from K; without K it is an error
    // (`camera_fields_missing_from_meta_come_from_k_and_the_masks`).
    replace_meta(
        dir.path(),
        &unicode_npy("{'meta': {'fy': 1.0, 'cx': 2, 'cy': 3, 'res_x': 64, 'res_y': 48}}"),
    );
    let s = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    assert_eq!(s.camera_fallbacks, ["fx, fy, cx, cy from dataset_info.npz[K]"]);

    replace_meta(
        dir.path(),
        &unicode_npy(
            "{'meta': {'fx': 1.0, 'fy': 1.0, 'cx': 2, 'cy': 3, 'res_x': 64, 'res_y': 48}, 'frames': [{'ts': 'soon'}]}",
        ),
    );
    let e = open_err(dir.path());
    assert!(
        e.contains("meta['frames'][0]['ts']") && e.contains("expected a number, found str"),
        "{e}"
    );

    replace_meta(dir.path(), &unicode_npy("[1, 2]"));
    let e = open_err(dir.path());
    assert!(e.contains("expected a dict, found list"), "{e}");

    std::fs::remove_file(dir.path().join("dataset_info.npz")).unwrap();
    let mut w = evseg_evimo2::npz::NpzWriter::create(&dir.path().join("dataset_info.npz"), false).unwrap();
    w.add("K", &npy::encode_array("<f8", &[1], &1.0f64.to_le_bytes()))
        .unwrap();
    w.finish().unwrap();
    let e = open_err(dir.path());
    assert!(e.contains("no member 'meta.npy'") && e.contains("K.npy"), "{e}");
}

#[test]
fn every_corruption_of_the_pickled_meta_is_an_error_or_a_value() {
    // Flip each byte of the pickle in turn (and truncate at each length): the reader must return
    // an error or some value, never panic.
    let dir = tempfile::tempdir().unwrap();
    let mut data = common::sequence();
    data.imu.truncate(3);
    data.camera_poses.truncate(3);
    write_sequence_with(
        dir.path(),
        &data,
        &WriteOptions {
            meta_form: MetaForm::Pickle,
            ..WriteOptions::default()
        },
    )
    .unwrap();
    let mut info = evseg_evimo2::npz::NpzReader::open(&dir.path().join("dataset_info.npz")).unwrap();
    let arr = info.read_key("meta").unwrap();
    let mut errors = 0;
    for pos in 0..arr.data.len() {
        for variant in 0..2 {
            let mut a = arr.clone();
            if variant == 0 {
                a.data[pos] ^= 0xff;
            } else {
                a.data.truncate(pos);
            }
            if let Ok(v) = evseg_evimo2::meta::meta_from_npy(&a, "m") {
                if evseg_evimo2::meta::convert(&v, 0.0, &ReadOptions::default(), "m").is_err() {
                    errors += 1;
                }
            } else {
                errors += 1;
            }
        }
    }
    assert!(errors > arr.data.len(), "only {errors} errors");
}

#[test]
fn imu_topic_missing_lists_available() {
    let dir = folder();
    let opts = ReadOptions {
        imu_topic: Some("/nope/imu".into()),
        ..ReadOptions::default()
    };
    let e = Sequence::open(dir.path(), &opts).unwrap_err().to_string();
    assert!(
        e.contains("/nope/imu") && e.contains("/prophesee/left/imu"),
        "{e}"
    );
}

#[test]
fn mask_without_frame_or_with_wrong_shape() {
    let dir = folder();
    let path = dir.path().join("dataset_mask.npz");
    let mut w = evseg_evimo2::npz::NpzWriter::create(&path, false).unwrap();
    w.add(
        "mask_0000000007",
        &npy::encode_array("<u2", &[48, 64], &vec![0u8; 48 * 64 * 2]),
    )
    .unwrap();
    w.finish().unwrap();
    let seq = Sequence::open(dir.path(), &ReadOptions::default()).unwrap();
    let e = seq.masks().unwrap_err().to_string();
    assert!(
        e.contains("dataset_mask.npz[mask_0000000007.npy]") && e.contains("id 7"),
        "{e}"
    );

    let mut w = evseg_evimo2::npz::NpzWriter::create(&path, false).unwrap();
    w.add(
        "mask_0000000001",
        &npy::encode_array("<u2", &[64, 48], &vec![0u8; 48 * 64 * 2]),
    )
    .unwrap();
    w.finish().unwrap();
    let mut masks = seq.masks().unwrap();
    let e = masks.read(0).unwrap_err().to_string();
    assert!(e.contains("mask_0000000001.npy") && e.contains("[64, 48]"), "{e}");
    assert!(masks.read(5).is_err());
}

#[test]
fn writer_rejects_inconsistent_data() {
    let dir = tempfile::tempdir().unwrap();
    let mut data = common::sequence();
    data.masks.pop();
    let e = write_sequence(dir.path(), &data).unwrap_err().to_string();
    assert!(
        e.contains("dataset_mask.npz") && e.contains("2 masks for 3 frames"),
        "{e}"
    );
    let mut data = common::sequence();
    data.masks[1].ids[0] = 70;
    let e = write_sequence(dir.path(), &data).unwrap_err().to_string();
    assert!(e.contains("object id 70"), "{e}");
    let mut data = common::sequence();
    data.events.p.pop();
    assert!(write_sequence(dir.path(), &data).is_err());
}
