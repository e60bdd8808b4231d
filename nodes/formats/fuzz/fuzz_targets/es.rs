//! Event Stream decoder on arbitrary bytes (seeds: a prefix of a real DVS recording, hand-made
//! DVS and ATIS files with overflows, resets and exposure events).
#![no_main]

mod common;

use evseg_formats::{Format, OpenOptions, OutOfRange};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let knob = common::knob(data);
    let Some(path) = common::write_input("f.es", data) else {
        return;
    };
    let options = OpenOptions {
        format: Some(Format::EventStream),
        out_of_range: if knob & 1 == 0 {
            OutOfRange::Error
        } else {
            OutOfRange::Drop
        },
        ..Default::default()
    };
    common::decode_twice(&path, &options, knob);
});
