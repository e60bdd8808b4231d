//! AEDAT 4 decoder on arbitrary bytes (seeds: prefixes of a real DV recording, re-encoded
//! uncompressed and zstd). Checks the invariants of `common::drain_checked` and that the result
//! does not depend on the read block or chunk size.
#![no_main]

mod common;

use evseg_formats::{Format, OpenOptions, OutOfRange};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let knob = common::knob(data);
    let Some(path) = common::write_input("f.aedat4", data) else {
        return;
    };
    let options = OpenOptions {
        format: Some(Format::Aedat4),
        out_of_range: if knob & 1 == 0 {
            OutOfRange::Error
        } else {
            OutOfRange::Drop
        },
        // Small enough that a corrupt size field is rejected quickly, larger than real packets.
        max_packet_bytes: 1 << 20,
        ..Default::default()
    };
    common::decode_twice(&path, &options, knob);
});
