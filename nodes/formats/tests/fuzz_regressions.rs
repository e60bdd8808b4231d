//! Inputs that made a fuzz target (`nodes/formats/fuzz`) fail, kept in `tests/fuzz-regressions/`
//! and decoded here the way the target decoded them, with the answer the decoder must give.
//! File names start with the fuzz target's name.

mod common;

use std::path::{Path, PathBuf};

use common::{Decoded, decode_all};
use evseg_formats::{DecodeError, Format, OpenOptions};

fn regression(name: &str) -> Vec<u8> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fuzz-regressions")
        .join(name);
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The `text` target's input layout: NUL bytes separate `events.txt`, `calib.txt`, `imu.txt`.
fn text_files(dir: &Path, data: &[u8]) -> PathBuf {
    let mut parts = data.splitn(3, |&b| b == 0);
    let events = dir.join("events.txt");
    std::fs::write(&events, parts.next().unwrap_or_default()).unwrap();
    for name in ["calib.txt", "imu.txt"] {
        if let Some(part) = parts.next() {
            std::fs::write(dir.join(name), part).unwrap();
        }
    }
    events
}

/// Decodes `path` with `options` but read blocks of `block` bytes, in chunks of `chunk` events.
fn decode(path: &Path, options: &OpenOptions, block: usize, chunk: usize) -> Decoded {
    let options = OpenOptions {
        read_block_bytes: block,
        ..options.clone()
    };
    let mut decoder = evseg_formats::open(path, &options).unwrap();
    decode_all(decoder.as_mut(), chunk)
}

/// Found by the `text` target: a malformed `imu.txt` line stopped the events at a place that
/// depended on the chunk size (the IMU was read ahead once per chunk, so a chunk of 1 event
/// stopped after the first event and a large chunk after the third). Now the IMU is read per
/// event: the events stop at the first event at or after the last good IMU sample (1.0 s),
/// whatever the chunk size.
#[test]
fn text_imu_error_stops_the_events_at_the_same_place_for_every_chunk_size() {
    let dir = tempfile::tempdir().unwrap();
    let events = text_files(
        dir.path(),
        &regression("text-imu-error-depends-on-chunk-size.bin"),
    );
    let options = OpenOptions {
        format: Some(Format::Text),
        ..Default::default()
    };
    for (block, chunk) in [(20, 1), (64, 2), (1 << 20, 65_536)] {
        let decoded = decode(&events, &options, block, chunk);
        // 0.0001 10 20 1 is delivered; 1.0002 11 20 01 needs the IMU sample after the one at
        // 1.0 s, whose line (imu.txt line 3) is malformed.
        assert_eq!(
            decoded.events,
            vec![(100, 10, 20, 1)],
            "block {block}, chunk {chunk}"
        );
        assert_eq!(decoded.imu.len(), 1, "the sample at 1.0 s");
        assert_eq!(decoded.imu[0].0, 1_000_000);
        match &decoded.error {
            Some(DecodeError::BadLine { path, line, .. }) => {
                assert_eq!(path, &dir.path().join("imu.txt"));
                assert_eq!(*line, 3);
            }
            other => panic!("block {block}, chunk {chunk}: {other:?}"),
        }
    }
}
