//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;

use evseg_formats::{Chunk, DecodeError, EventDecoder, OpenOptions};

/// The real recordings directory (`$EVSEG_SHARED/data/real`, else `shared/data/real` beside the
/// repository). `None` (after printing why) when absent; under `CI=true` absence is a failure.
pub fn real_data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("EVSEG_SHARED") {
        Some(shared) => PathBuf::from(shared).join("data/real"),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/real"),
    };
    if dir.join("README.md").is_file() {
        return Some(dir);
    }
    if std::env::var("CI").as_deref() == Ok("true") {
        panic!(
            "real recordings not found at {} (CI=true: the golden tests must run)",
            dir.display()
        );
    }
    eprintln!(
        "SKIP: real recordings not found at {}; golden tests skipped",
        dir.display()
    );
    None
}

/// One event with its absolute time in µs.
pub type AbsEvent = (i64, u16, u16, u8);

/// One IMU sample: (t µs absolute, gyro rad/s, accel m/s²).
pub type AbsImu = (i64, [f64; 3], [f64; 3]);

/// Everything a decoder delivers, with absolute times.
#[derive(Debug, Default)]
pub struct Decoded {
    pub events: Vec<AbsEvent>,
    /// IMU samples.
    pub imu: Vec<AbsImu>,
    pub chunks: usize,
    pub error: Option<DecodeError>,
}

/// Absolute µs time of a relative time in seconds.
pub fn abs_us(origin: i64, t: f64) -> i64 {
    origin + (t * 1e6).round() as i64
}

/// Decodes with `decoder` in chunks of `max_events` until the end or an error, checking the
/// chunk invariants on the way.
pub fn decode_all(decoder: &mut dyn EventDecoder, max_events: usize) -> Decoded {
    let mut out = Decoded::default();
    let mut chunk = Chunk::default();
    loop {
        match decoder.decode_into(&mut chunk, max_events) {
            Ok(true) => {
                assert!(chunk.events.is_consistent());
                assert!(chunk.events.len() <= max_events.max(1), "chunk larger than asked");
                assert!(!chunk.is_empty(), "Ok(true) with an empty chunk");
                assert!(
                    decoder.stats().times_out_of_order > 0 || chunk.events.t.windows(2).all(|w| w[0] <= w[1]),
                    "chunk times decrease and the decoder did not count it"
                );
                let origin = decoder
                    .time_origin_us()
                    .expect("origin known once events were returned");
                out.chunks += 1;
                for i in 0..chunk.events.len() {
                    let e = &chunk.events;
                    out.events.push((abs_us(origin, e.t[i]), e.x[i], e.y[i], e.p[i]));
                }
                for s in &chunk.imu {
                    out.imu.push((abs_us(origin, s.t), s.gyro, s.accel));
                }
            }
            Ok(false) => break,
            Err(error) => {
                out.error = Some(error);
                // After an error the decoder is finished.
                assert!(matches!(decoder.decode_into(&mut chunk, max_events), Ok(false)));
                break;
            }
        }
    }
    out
}

/// Opens `path` with default options and decodes it whole.
pub fn decode_file(path: &std::path::Path, max_events: usize) -> Result<Decoded, DecodeError> {
    let mut decoder = evseg_formats::open(path, &OpenOptions::default())?;
    Ok(decode_all(decoder.as_mut(), max_events))
}

/// Like [`decode_file`], but an error at open (a fault before any event) becomes
/// `Decoded { events: [], error }`.
pub fn decode_file_lenient(path: &std::path::Path, max_events: usize) -> Decoded {
    decode_file(path, max_events).unwrap_or_else(|error| Decoded {
        error: Some(error),
        ..Decoded::default()
    })
}
