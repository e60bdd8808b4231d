//! What every fuzz target checks: a file decodes without panicking, the events obey the
//! documented invariants, errors name the file and stop the decoder, and the events do not
//! depend on the chunk size or the read block size.
//!
//! Inputs are written to a per-process scratch file (the decoders read paths), in `/dev/shm` when
//! it exists so that the fuzzer does not wear the disk.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use evseg_formats::{DecodeError, EventDecoder, OpenOptions};
use evseg_schemas::messages::ImuSample;

/// A per-process directory for the fuzzed files.
pub fn scratch_dir() -> PathBuf {
    let base = Path::new("/dev/shm");
    let base = if base.is_dir() {
        base.to_path_buf()
    } else {
        std::env::temp_dir()
    };
    let dir = base.join(format!("evseg-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    dir
}

/// Writes `bytes` to `name` in the scratch directory; `None` if the write fails (not a decoder
/// bug, so the input is skipped).
pub fn write_input(name: &str, bytes: &[u8]) -> Option<PathBuf> {
    let path = scratch_dir().join(name);
    std::fs::write(&path, bytes).ok()?;
    Some(path)
}

/// Removes `name` from the scratch directory if it is there.
pub fn remove_input(name: &str) {
    let _ = std::fs::remove_file(scratch_dir().join(name));
}

/// Everything one pass over a file produced.
#[derive(Debug, PartialEq)]
pub struct Decoded {
    /// (t bits, x, y, p) of every event.
    pub events: Vec<(u64, u16, u16, u8)>,
    /// (t, gyro, accel) bits of every IMU sample.
    pub imu: Vec<[u64; 7]>,
    /// The error that ended the pass, as text.
    pub error: Option<String>,
}

fn imu_bits(s: &ImuSample) -> [u64; 7] {
    [
        s.t.to_bits(),
        s.gyro[0].to_bits(),
        s.gyro[1].to_bits(),
        s.gyro[2].to_bits(),
        s.accel[0].to_bits(),
        s.accel[1].to_bits(),
        s.accel[2].to_bits(),
    ]
}

/// An error must name the file it is about: the event file, or one of the text sidecars
/// (`calib.txt`, `imu.txt`) beside it.
pub fn check_error(error: &DecodeError, path: &Path) {
    let named = error.path();
    let sidecar = named.parent() == path.parent()
        && named
            .file_name()
            .is_some_and(|n| n == "calib.txt" || n == "imu.txt");
    assert!(named == path || sidecar, "error names another file: {error}");
    let text = error.to_string();
    assert!(
        text.contains(&named.display().to_string()),
        "error text lacks the file: {text}"
    );
}

/// Decodes `path` whole in chunks of `chunk` events, checking the invariants of
/// [`evseg_formats::EventDecoder`] on the way. `None` when `open` fails (checked too).
pub fn decode_checked(path: &Path, options: &OpenOptions, chunk: usize) -> Option<Decoded> {
    let mut decoder = match evseg_formats::open(path, options) {
        Ok(decoder) => decoder,
        Err(error) => {
            check_error(&error, path);
            return None;
        }
    };
    Some(drain_checked(decoder.as_mut(), path, chunk))
}

/// Reads every chunk of an opened decoder, checking the invariants.
pub fn drain_checked(decoder: &mut dyn EventDecoder, path: &Path, chunk: usize) -> Decoded {
    let (width, height) = decoder.geometry();
    let mut out = Decoded {
        events: Vec::new(),
        imu: Vec::new(),
        error: None,
    };
    let mut last_t = f64::NEG_INFINITY;
    loop {
        match decoder.next_chunk(chunk) {
            Ok(Some(c)) => {
                let e = &c.events;
                assert!(e.is_consistent(), "columns of different lengths");
                assert!(
                    e.len() <= chunk.max(1),
                    "chunk of {} events for a limit of {chunk}",
                    e.len()
                );
                assert!(!c.is_empty(), "an empty chunk returned as data");
                for i in 0..e.len() {
                    let (t, x, y, p) = (e.t[i], e.x[i], e.y[i], e.p[i]);
                    // A text file stored out of time order is passed on as stored and counted
                    // (times before the first event's are then negative).
                    let disorder = decoder.stats().times_out_of_order > 0;
                    assert!(t.is_finite() && (t >= 0.0 || disorder), "event time {t} s");
                    assert!(t >= last_t || disorder, "event time went back from {last_t} to {t}");
                    last_t = last_t.max(t);
                    assert!(
                        x < width && y < height,
                        "event ({x}, {y}) outside {width}x{height}"
                    );
                    assert!(p <= 1, "polarity {p}");
                    out.events.push((t.to_bits(), x, y, p));
                }
                for s in &c.imu {
                    assert!(s.t.is_finite(), "IMU time {}", s.t);
                    out.imu.push(imu_bits(s));
                }
            }
            Ok(None) => break,
            Err(error) => {
                check_error(&error, path);
                out.error = Some(error.to_string());
                // After an error the decoder is finished.
                assert!(
                    matches!(decoder.next_chunk(chunk), Ok(None)),
                    "decoder went on after {error}"
                );
                break;
            }
        }
    }
    let stats = decoder.stats();
    assert_eq!(stats.events, out.events.len() as u64, "stats count other events");
    assert_eq!(
        stats.imu_samples,
        out.imu.len() as u64,
        "stats count other IMU samples"
    );
    if !out.events.is_empty() {
        assert!(decoder.time_origin_us().is_some(), "events without a time origin");
    }
    out
}

/// Decodes `path` twice (small read blocks and chunks picked by `knob`, then the defaults) and
/// checks that both passes agree. The error texts may differ only if both are present (the
/// small-block pass can meet the fault at another read), so only their presence is compared.
pub fn decode_twice(path: &Path, options: &OpenOptions, knob: u8) -> Option<Decoded> {
    let small = OpenOptions {
        read_block_bytes: 16 + (knob as usize & 0x3F),
        ..options.clone()
    };
    let first = decode_checked(path, &small, 1 + (knob as usize >> 3));
    let second = decode_checked(path, options, 65_536);
    match (&first, &second) {
        (Some(a), Some(b)) => {
            assert_eq!(a.events, b.events, "events depend on the block or chunk size");
            assert_eq!(a.imu, b.imu, "IMU samples depend on the block or chunk size");
            assert_eq!(
                a.error.is_some(),
                b.error.is_some(),
                "errors depend on the block size"
            );
        }
        (None, None) => {}
        _ => panic!("open succeeded with one block size only"),
    }
    second
}

/// A knob derived from the input (its length and first byte), so that seeds taken verbatim from
/// real files still exercise several option settings, deterministically.
pub fn knob(data: &[u8]) -> u8 {
    (data.len() as u8) ^ data.first().copied().unwrap_or(0)
}
