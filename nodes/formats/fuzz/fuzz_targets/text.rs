//! Text decoder on arbitrary bytes, with its sidecars: the input is split at NUL bytes into
//! `events.txt`, `calib.txt` and `imu.txt` (a sidecar is absent when its part is missing). The
//! knob decides whether the geometry is given or scanned from the file.
#![no_main]

mod common;

use evseg_formats::{Format, OpenOptions, OutOfRange};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let knob = common::knob(data);
    let mut parts = data.splitn(3, |&b| b == 0);
    let events = parts.next().unwrap_or_default();
    for name in ["calib.txt", "imu.txt"] {
        match parts.next() {
            Some(part) => {
                if common::write_input(name, part).is_none() {
                    return;
                }
            }
            None => common::remove_input(name),
        }
    }
    let Some(path) = common::write_input("events.txt", events) else {
        return;
    };
    let options = OpenOptions {
        format: Some(Format::Text),
        geometry: (knob & 2 != 0).then_some((64, 48)),
        out_of_range: if knob & 1 == 0 {
            OutOfRange::Error
        } else {
            OutOfRange::Drop
        },
        ..Default::default()
    };
    common::decode_twice(&path, &options, knob);
});
