//! Hand-made EVT 2.0, EVT 3.0 and Event Stream files exercising what the real recordings do not:
//! time loops, vector events past the sensor edge, exposure-measurement rows, out-of-range
//! policies, ATIS exposure events, trailing partial words.

mod common;

use std::path::PathBuf;

use common::{decode_all, decode_file_lenient};
use evseg_formats::{DecodeError, Format, OpenOptions, OutOfRange};

fn write(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn evt3(words: &[u16]) -> Vec<u8> {
    let mut bytes = b"% evt 3.0\n% format EVT3;height=8;width=16\n".to_vec();
    for w in words {
        bytes.extend_from_slice(&w.to_le_bytes());
    }
    bytes
}

const fn w3(kind: u16, payload: u16) -> u16 {
    kind << 12 | payload
}

#[test]
fn evt3_time_loops_vectors_and_rows() {
    let dir = tempfile::tempdir().unwrap();
    let words = [
        w3(0x0, 1),                // before the first time high: skipped
        w3(0x2, 2),                // skipped
        w3(0x8, 5),                // time high 5
        w3(0x6, 7),                // t = 5 * 4096 + 7 = 20487
        w3(0x0, 3),                // y = 3
        w3(0x2, 1 << 11 | 4),      // ON event at x = 4
        w3(0x3, 10),               // vector base x = 10, OFF
        w3(0x4, 0b1111_0000_0101), // x = 10, 12; 18..21 past the 16-pixel width: dropped
        w3(0x5, 0xFF),             // base 22: all 8 past the width, dropped
        w3(0xA, 0x101),            // trigger
        w3(0x8, 4095),             // time high 4095, time low reset
        w3(0x6, 1),                // t = 4095 * 4096 + 1
        w3(0x2, 5),                // OFF event at x = 5
        w3(0x8, 0),                // loop: t = 2^24
        w3(0x2, 6),
        w3(0x1, 2), // exposure-measurement row: its X events are not CD events
        w3(0x2, 7),
        w3(0x0, 2),
        w3(0xE, 0x123), // OTHERS and CONTINUED words are skipped
        w3(0xF, 0x456),
        w3(0x7, 0x1),
        w3(0x6, 9), // t = 2^24 + 9
        w3(0x2, 1 << 11 | 15),
    ];
    let path = write(&dir, "a.raw", &evt3(&words));
    let mut decoder = evseg_formats::open(&path, &OpenOptions::default()).unwrap();
    assert_eq!(decoder.format(), Format::Evt3);
    assert_eq!(decoder.geometry(), (16, 8));
    assert_eq!(decoder.time_origin_us(), Some(20487));
    let decoded = decode_all(decoder.as_mut(), 3);
    assert!(decoded.error.is_none(), "{:?}", decoded.error);
    let expected = vec![
        (20487, 4, 3, 1),
        (20487, 10, 3, 0),
        (20487, 12, 3, 0),
        (4095 * 4096 + 1, 5, 3, 0),
        (1 << 24, 6, 3, 0),
        ((1 << 24) + 9, 15, 2, 1),
    ];
    assert_eq!(decoded.events, expected);
    // Asking for everything at once works too.
    let mut decoder = evseg_formats::open(&path, &OpenOptions::default()).unwrap();
    let chunk = decoder.next_chunk(usize::MAX).unwrap().unwrap();
    assert_eq!(chunk.events.len(), 6);
    assert!(decoder.next_chunk(usize::MAX).unwrap().is_none());
    let stats = decoder.stats();
    assert_eq!(stats.words_before_time_base, 2);
    assert_eq!(stats.out_of_range, 4 + 8);
    assert_eq!(stats.triggers, 1);
    assert_eq!(stats.events, 6);
}

#[test]
fn evt3_out_of_range_policies_and_partial_word() {
    let dir = tempfile::tempdir().unwrap();
    let words = [
        w3(0x8, 1),
        w3(0x0, 2),
        w3(0x2, 3),
        w3(0x0, 9),
        w3(0x2, 4),
        w3(0x0, 1),
        w3(0x2, 16),
        w3(0x2, 5),
    ];
    let bytes = evt3(&words);
    let header = bytes.len() - 2 * words.len();
    let path = write(&dir, "b.raw", &bytes);
    // Error: the event before the bad row, then the error at the bad row's word.
    let decoded = decode_file_lenient(&path, 100);
    assert_eq!(decoded.events, vec![(4096, 3, 2, 0)]);
    match decoded.error {
        Some(DecodeError::Corrupt { offset, ref what, .. }) => {
            assert_eq!(offset, (header + 6) as u64);
            assert!(what.contains("y=9"), "{what}");
        }
        ref other => panic!("{other:?}"),
    }
    // Drop: x = 4 on row 9 and x = 16 on row 1 are dropped and counted.
    let options = OpenOptions {
        out_of_range: OutOfRange::Drop,
        ..Default::default()
    };
    let mut decoder = evseg_formats::open(&path, &options).unwrap();
    let decoded = decode_all(decoder.as_mut(), 100);
    assert!(decoded.error.is_none());
    assert_eq!(decoded.events, vec![(4096, 3, 2, 0), (4096, 5, 1, 0)]);
    assert_eq!(decoder.stats().out_of_range, 2);
    // A trailing odd byte: the events, then a truncation at that byte.
    let mut odd = evt3(&[w3(0x8, 1), w3(0x0, 2), w3(0x2, 3)]);
    odd.push(0x20);
    let path = write(&dir, "c.raw", &odd);
    let decoded = decode_file_lenient(&path, 100);
    assert_eq!(decoded.events, vec![(4096, 3, 2, 0)]);
    assert!(
        matches!(decoded.error, Some(DecodeError::Truncated { offset, .. }) if offset == odd.len() as u64 - 1)
    );
}

#[test]
fn evt3_without_geometry_needs_a_size() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = b"% evt 3.0\n".to_vec();
    for w in [w3(0x8, 1), w3(0x0, 700), w3(0x2, 1000)] {
        bytes.extend_from_slice(&w.to_le_bytes());
    }
    let path = write(&dir, "d.raw", &bytes);
    let error = evseg_formats::open(&path, &OpenOptions::default()).err().unwrap();
    assert!(matches!(error, DecodeError::Unsupported { .. }), "{error}");
    assert!(error.to_string().contains("geometry"));
    let options = OpenOptions {
        geometry: Some((1280, 720)),
        ..Default::default()
    };
    let mut decoder = evseg_formats::open(&path, &options).unwrap();
    assert_eq!(decoder.geometry(), (1280, 720));
    assert_eq!(
        decode_all(decoder.as_mut(), 10).events,
        vec![(4096, 1000, 700, 0)]
    );
}

fn evt2(header: &[u8], words: &[u32]) -> Vec<u8> {
    let mut bytes = header.to_vec();
    for w in words {
        bytes.extend_from_slice(&w.to_le_bytes());
    }
    bytes
}

const fn cd(on: u32, t_low: u32, x: u32, y: u32) -> u32 {
    on << 28 | t_low << 22 | x << 11 | y
}

#[test]
fn evt2_time_loop_default_geometry_and_partial_word() {
    let dir = tempfile::tempdir().unwrap();
    let words = [
        cd(1, 1, 1, 1),          // before the first time high: skipped
        0x8 << 28 | 0x0FFF_FFFF, // time high = (2^28 - 1) * 64
        cd(1, 63, 639, 479),     // t = 2^34 - 64 + 63
        0xA << 28,               // trigger
        0x8 << 28,               // loop
        cd(0, 5, 0, 0),          // t = 2^34 + 5
    ];
    let path = write(&dir, "e.raw", &evt2(b"% evt 2.0\n", &words));
    let mut decoder = evseg_formats::open(&path, &OpenOptions::default()).unwrap();
    assert_eq!(decoder.format(), Format::Evt2);
    assert_eq!(decoder.geometry(), (640, 480), "Gen3 default");
    let decoded = decode_all(decoder.as_mut(), 1);
    assert!(decoded.error.is_none());
    assert_eq!(
        decoded.events,
        vec![((1 << 34) - 1, 639, 479, 1), ((1 << 34) + 5, 0, 0, 0)]
    );
    assert_eq!(decoder.stats().words_before_time_base, 1);
    assert_eq!(decoder.stats().triggers, 1);
    // A geometry line wins over the default; x = 639 is then outside a 320-pixel sensor.
    let path = write(&dir, "f.raw", &evt2(b"% evt 2.0\n% geometry 320x240\n", &words));
    let decoded = decode_file_lenient(&path, 10);
    assert!(decoded.events.is_empty());
    assert!(matches!(decoded.error, Some(DecodeError::Corrupt { offset, .. }) if offset == 29 + 8));
    // Three trailing bytes: a truncation at the partial word.
    let mut bytes = evt2(
        b"% format EVT2;width=640;height=480\n",
        &[0x8 << 28, cd(1, 0, 2, 3)],
    );
    let n = bytes.len();
    bytes.extend_from_slice(&[1, 2, 3]);
    let path = write(&dir, "g.raw", &bytes);
    let decoded = decode_file_lenient(&path, 10);
    assert_eq!(decoded.events, vec![(0, 2, 3, 1)]);
    assert!(matches!(decoded.error, Some(DecodeError::Truncated { offset, .. }) if offset == n as u64));
}

#[test]
fn raw_without_version_and_wrong_version() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(&dir, "h.raw", &evt2(b"% geometry 640x480\n", &[0x8 << 28]));
    let error = evseg_formats::open(&path, &OpenOptions::default()).err().unwrap();
    assert!(error.to_string().contains("OpenOptions::format"), "{error}");
    let options = OpenOptions {
        format: Some(Format::Evt2),
        ..Default::default()
    };
    assert!(evseg_formats::open(&path, &options).is_ok());
    let path = write(&dir, "i.raw", &evt2(b"% evt 2.1\n", &[0x8 << 28]));
    let error = evseg_formats::open(&path, &OpenOptions::default()).err().unwrap();
    assert!(error.to_string().contains("2.1"), "{error}");
    // A header longer than the first 4 KiB still names the format.
    let mut long = "% comment line that is long enough to fill a lot of bytes\n".repeat(200);
    long.push_str("% evt 2.0\n");
    let path = write(
        &dir,
        "long.raw",
        &evt2(long.as_bytes(), &[0x8 << 28, cd(1, 0, 2, 3)]),
    );
    let decoded = decode_file_lenient(&path, 10);
    assert_eq!(decoded.events, vec![(0, 2, 3, 1)]);
    // Forcing EVT 3.0 on a file whose header says EVT 2.0 is refused.
    let path = write(&dir, "j.raw", &evt2(b"% evt 2.0\n", &[0x8 << 28]));
    let options = OpenOptions {
        format: Some(Format::Evt3),
        geometry: Some((640, 480)),
        ..Default::default()
    };
    assert!(matches!(
        evseg_formats::open(&path, &options),
        Err(DecodeError::Unsupported { .. })
    ));
}

fn es(kind: u8, version: u8, body: &[u8]) -> Vec<u8> {
    let mut bytes = b"Event Stream".to_vec();
    bytes.extend_from_slice(&[version, 0, 0, kind]);
    bytes.extend_from_slice(&4u16.to_le_bytes());
    bytes.extend_from_slice(&3u16.to_le_bytes());
    bytes.extend_from_slice(body);
    bytes
}

#[test]
fn event_stream_atis_skips_exposure_events_and_flips_y() {
    let dir = tempfile::tempdir().unwrap();
    let body = [
        5 << 2 | 1 << 1,
        1,
        0,
        0,
        0, // CD ON at t = 5, x = 1, y_file = 0
        2 << 2 | 1,
        2,
        0,
        1,
        0,    // threshold crossing at t = 7: skipped
        0xFD, // overflow x1: +63
        0xFC, // reset (overflow x0)
        0,
        3,
        0,
        2,
        0, // CD OFF at t = 70, x = 3, y_file = 2
    ];
    let path = write(&dir, "a.es", &es(2, 2, &body));
    let mut decoder = evseg_formats::open(&path, &OpenOptions::default()).unwrap();
    assert_eq!(decoder.format(), Format::EventStream);
    assert_eq!(decoder.geometry(), (4, 3));
    let decoded = decode_all(decoder.as_mut(), 10);
    assert!(decoded.error.is_none());
    assert_eq!(decoded.events, vec![(5, 1, 2, 1), (70, 3, 0, 0)]);
    assert_eq!(decoder.stats().exposure_events, 1);
}

#[test]
fn event_stream_dvs_overflow_reset_and_bad_files() {
    let dir = tempfile::tempdir().unwrap();
    let body = [0xFF, 0xFE, 3 << 1 | 1, 3, 0, 2, 0, 0, 9, 0, 0, 0];
    let path = write(&dir, "b.es", &es(1, 2, &body));
    let decoded = decode_file_lenient(&path, 10);
    assert_eq!(decoded.events, vec![(130, 3, 0, 1)]);
    // x = 9 on a 4-pixel sensor: error at that event's first byte.
    assert!(matches!(decoded.error, Some(DecodeError::Corrupt { offset, .. }) if offset == 20 + 7));
    for (kind, version, needle) in [
        (1, 1, "version 1"),
        (0, 2, "generic"),
        (4, 2, "color"),
        (9, 2, "type 9"),
    ] {
        let path = write(&dir, "c.es", &es(kind, version, &[]));
        let error = evseg_formats::open(&path, &OpenOptions::default()).err().unwrap();
        assert!(error.to_string().contains(needle), "{error}");
    }
    let path = write(&dir, "d.es", b"Event Stream\x02");
    assert!(matches!(
        evseg_formats::open(&path, &OpenOptions::default()),
        Err(DecodeError::Truncated { .. })
    ));
}
