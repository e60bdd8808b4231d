//! Prophesee EVT 2.0 decoder on arbitrary bytes (seeds: prefixes of a real Gen3 recording and
//! hand-made files). The header may or may not give the geometry; without one the 640 x 480
//! default or the `geometry` option applies, as the knob picks.
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
        format: Some(Format::Evt2),
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
