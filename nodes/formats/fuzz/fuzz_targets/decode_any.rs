//! Feeds arbitrary bytes to every decoder (first byte picks the format) and decodes them whole:
//! any panic is a bug. Coordinates returned must lie inside the sensor.
#![no_main]

use evseg_formats::{Format, OpenOptions, OutOfRange};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&selector, rest)) = data.split_first() else { return };
    let (name, format, prefix): (&str, Format, &[u8]) = match selector % 6 {
        0 => ("f.raw", Format::Evt3, b"% evt 3.0\n% geometry 64x48\n"),
        1 => ("f.raw", Format::Evt2, b"% evt 2.0\n"),
        2 => ("f.es", Format::EventStream, b""),
        3 => ("f.aedat4", Format::Aedat4, b""),
        4 => ("f.txt", Format::Text, b""),
        _ => ("f.bin", Format::Evt3, b""),
    };
    let dir = std::env::temp_dir().join(format!("evseg-fuzz-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join(name);
    let mut bytes = prefix.to_vec();
    bytes.extend_from_slice(rest);
    if std::fs::write(&path, &bytes).is_err() {
        return;
    }
    let policy = if selector & 0x80 != 0 { OutOfRange::Drop } else { OutOfRange::Error };
    let options = OpenOptions {
        format: (selector & 0x40 != 0).then_some(format),
        geometry: Some((64, 48)),
        out_of_range: policy,
        read_block_bytes: 64 + (selector as usize & 0x3F),
        max_packet_bytes: 1 << 20,
        ..Default::default()
    };
    if let Ok(mut decoder) = evseg_formats::open(&path, &options) {
        let (w, h) = decoder.geometry();
        while let Ok(Some(chunk)) = decoder.next_chunk(1 + selector as usize) {
            assert!(chunk.events.is_consistent());
            assert!(chunk.events.x.iter().all(|&x| x < w));
            assert!(chunk.events.y.iter().all(|&y| y < h));
        }
    }
});
