//! Prophesee EVT 3.0 decoder on arbitrary bytes (seeds: prefixes of a real IMX636 recording and
//! hand-made files with time loops, vectors past the edge, exposure rows). Without a geometry in
//! the header, the knob gives one or leaves it out (then `open` must fail cleanly).
#![no_main]

mod common;

use evseg_formats::{Format, OpenOptions, OutOfRange};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let knob = common::knob(data);
    let Some(path) = common::write_input("f.raw", data) else {
        return;
    };
    let options = OpenOptions {
        format: Some(Format::Evt3),
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
