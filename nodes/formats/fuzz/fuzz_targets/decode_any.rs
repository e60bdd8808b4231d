//! Format detection and every decoder behind it: the first byte picks a magic or header to put
//! in front of the rest (or none), and `open` detects the format from the bytes and the file
//! name. Checks the invariants of `common::drain_checked`.
#![no_main]

mod common;

use evseg_formats::{OpenOptions, OutOfRange};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else {
        return;
    };
    let (name, prefix): (&str, &[u8]) = match selector % 6 {
        0 => ("f.raw", b"% evt 3.0\n% geometry 64x48\n"),
        1 => ("f.raw", b"% evt 2.0\n"),
        2 => ("f.es", b""),
        3 => ("f.aedat4", b""),
        4 => ("f.txt", b""),
        _ => ("f.bin", b""),
    };
    let mut bytes = prefix.to_vec();
    bytes.extend_from_slice(rest);
    let Some(path) = common::write_input(name, &bytes) else {
        return;
    };
    let options = OpenOptions {
        geometry: Some((64, 48)),
        out_of_range: if selector & 0x80 != 0 {
            OutOfRange::Drop
        } else {
            OutOfRange::Error
        },
        read_block_bytes: 64 + (selector as usize & 0x3F),
        max_packet_bytes: 1 << 20,
        text_sidecars: false,
        ..Default::default()
    };
    common::decode_checked(&path, &options, 1 + selector as usize);
});
