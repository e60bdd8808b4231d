//! Truncated and corrupted copies of the real recordings: every complete event before the fault
//! is delivered, then an error names the file and the byte offset; nothing panics.

mod common;

use std::path::{Path, PathBuf};

use common::{Decoded, decode_file, decode_file_lenient, real_data_dir};
use evseg_formats::DecodeError;

/// Length of the `%` header of a Prophesee file.
fn prophesee_header_len(data: &[u8]) -> usize {
    let mut i = 0;
    while data.get(i) == Some(&b'%') {
        i += data[i..].iter().position(|&b| b == b'\n').unwrap() + 1;
    }
    i
}

/// Events in the whole EVT 3.0 words of `data[..cut]`, counted without the decoder (clean
/// stream: every row is in range), and the offset of a partial word if any.
fn evt3_expected(data: &[u8], cut: usize) -> (usize, Option<u64>) {
    let start = prophesee_header_len(data);
    let mut n = 0;
    let mut time_base = false;
    for w in data[start..cut].chunks_exact(2) {
        let w = u16::from_le_bytes([w[0], w[1]]);
        match (w >> 12, time_base) {
            (0x8, _) => time_base = true,
            (0x2, true) => n += 1,
            (0x4, true) => n += (w & 0xFFF).count_ones() as usize,
            (0x5, true) => n += (w & 0xFF).count_ones() as usize,
            _ => {}
        }
    }
    let partial = (cut - start) % 2;
    (n, (partial != 0).then_some((cut - partial) as u64))
}

/// Same for EVT 2.0 (32-bit words, CD events of type 0 and 1).
fn evt2_expected(data: &[u8], cut: usize) -> (usize, Option<u64>) {
    let start = prophesee_header_len(data);
    let mut n = 0;
    let mut time_base = false;
    for w in data[start..cut].chunks_exact(4) {
        let w = u32::from_le_bytes([w[0], w[1], w[2], w[3]]);
        match (w >> 28, time_base) {
            (0x8, _) => time_base = true,
            (0x0 | 0x1, true) => n += 1,
            _ => {}
        }
    }
    let partial = (cut - start) % 4;
    (n, (partial != 0).then_some((cut - partial) as u64))
}

/// Same for an Event Stream DVS file: complete 5-byte events after the 20-byte header.
fn es_expected(data: &[u8], cut: usize) -> (usize, Option<u64>) {
    let (mut i, mut n) = (20, 0);
    while i < cut {
        if data[i] >= 0xFE {
            i += 1;
        } else if i + 5 <= cut {
            n += 1;
            i += 5;
        } else {
            return (n, Some(i as u64));
        }
    }
    (n, None)
}

/// AEDAT 4 packets: (offset, total length) of each packet before the data table.
fn aedat_packets(data: &[u8]) -> Vec<(usize, usize)> {
    let header_len = u32::from_le_bytes(data[14..18].try_into().unwrap()) as usize;
    let mut at = 18 + header_len;
    let mut packets = Vec::new();
    while at + 8 <= data.len() {
        let size = i32::from_le_bytes(data[at + 4..at + 8].try_into().unwrap()) as usize;
        packets.push((at, 8 + size));
        at += 8 + size;
        if at >= 6_122_043 {
            break; // the data table of davis346.aedat4 (position from its IOHeader)
        }
    }
    packets
}

fn write_copy(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn check_error(decoded: &Decoded, path: &Path, offset: Option<u64>) {
    match (&decoded.error, offset) {
        (None, None) => {}
        (Some(error @ DecodeError::Truncated { .. }), Some(offset)) => {
            assert_eq!(error.path(), path);
            assert_eq!(error.offset(), Some(offset), "{error}");
            let text = error.to_string();
            assert!(
                text.contains(&path.display().to_string()) && text.contains(&offset.to_string()),
                "{text}"
            );
        }
        (error, offset) => panic!(
            "{}: expected a truncation at {offset:?}, got {error:?}",
            path.display()
        ),
    }
}

#[test]
fn truncated_word_formats_deliver_every_complete_event() {
    let Some(dir) = real_data_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    type Expect = fn(&[u8], usize) -> (usize, Option<u64>);
    let cases: [(&str, Expect); 3] = [
        ("evt3.raw", evt3_expected),
        ("evt2.raw", evt2_expected),
        ("dvs.es", es_expected),
    ];
    for (name, expected) in cases {
        let data = std::fs::read(dir.join(name)).unwrap();
        let reference = decode_file(&dir.join(name), 100_000).unwrap();
        assert_eq!(
            expected(&data, data.len()),
            (reference.events.len(), None),
            "{name}: independent counter"
        );
        let header = if name.ends_with(".raw") {
            prophesee_header_len(&data)
        } else {
            20
        };
        let len = data.len();
        let mut cuts = vec![
            header + 1,
            header + 2,
            header + 3,
            header + 4097,
            len / 3 + 1,
            len / 2,
            len / 2 + 1,
        ];
        cuts.extend([
            len / 2 + 2,
            len / 2 + 3,
            2 * len / 3 + 3,
            len - 1,
            len - 2,
            len - 3,
        ]);
        for cut in cuts {
            let path = write_copy(tmp.path(), name, &data[..cut]);
            let decoded = decode_file_lenient(&path, 65_536);
            let (count, partial) = expected(&data, cut);
            assert_eq!(decoded.events.len(), count, "{name} cut at {cut}");
            assert_eq!(
                decoded.events[..],
                reference.events[..count],
                "{name} cut at {cut}"
            );
            check_error(&decoded, &path, partial);
        }
    }
}

#[test]
fn truncated_aedat4_delivers_every_complete_packet() {
    let Some(dir) = real_data_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let data = std::fs::read(dir.join("davis346.aedat4")).unwrap();
    let reference = decode_file(&dir.join("davis346.aedat4"), 100_000).unwrap();
    let packets = aedat_packets(&data);
    for k in [0, 1, 2, 3, 10, packets.len() / 2, packets.len() - 1] {
        let (offset, size) = packets[k];
        for cut in [
            offset,
            offset + 5,
            offset + 8,
            offset + size / 2,
            offset + size - 1,
        ] {
            let path = write_copy(tmp.path(), "cut.aedat4", &data[..cut]);
            let decoded = decode_file_lenient(&path, 1000);
            // Events of the packets before k, all of them: the same as a cut at the packet start.
            let boundary = write_copy(tmp.path(), "boundary.aedat4", &data[..offset]);
            let complete = decode_file_lenient(&boundary, 1000);
            assert_eq!(decoded.events, complete.events, "cut at {cut} in packet {k}");
            assert_eq!(decoded.imu, complete.imu, "cut at {cut} in packet {k}");
            assert_eq!(decoded.events[..], reference.events[..decoded.events.len()]);
            check_error(&decoded, &path, Some(offset as u64));
        }
    }
    // Cut at the data table: every packet is there, the table (an index) is not needed.
    let (last, size) = packets[packets.len() - 1];
    let path = write_copy(tmp.path(), "tail.aedat4", &data[..last + size]);
    let decoded = decode_file_lenient(&path, 1000);
    assert_eq!(decoded.events, reference.events);
    check_error(&decoded, &path, None);
    // One byte short of it: the last packet is incomplete.
    let path = write_copy(tmp.path(), "tail.aedat4", &data[..last + size - 1]);
    let decoded = decode_file_lenient(&path, 1000);
    check_error(&decoded, &path, Some(last as u64));
    assert_eq!(decoded.events[..], reference.events[..decoded.events.len()]);
    // A cut inside the header fails at open, naming the file.
    for cut in [5, 16, 100] {
        let path = write_copy(tmp.path(), "head.aedat4", &data[..cut]);
        let error = evseg_formats::open(&path, &Default::default())
            .err()
            .expect("a cut header fails");
        assert_eq!(error.path(), path);
    }
}

/// A tiny deterministic generator (xorshift64*), so failures can be replayed.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
}

#[test]
fn corrupted_files_never_panic_and_keep_the_events_before_the_damage() {
    let Some(dir) = real_data_dir() else { return };
    let tmp = tempfile::tempdir().unwrap();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    for name in ["evt3.raw", "evt2.raw", "dvs.es", "davis346.aedat4"] {
        let data = std::fs::read(dir.join(name)).unwrap();
        let reference = decode_file(&dir.join(name), 100_000).unwrap();
        for trial in 0..12 {
            let mut bytes = data.clone();
            // Damage a run of 1 to 16 bytes somewhere after the first 200 bytes.
            let at = 200 + (rng.next() as usize) % (data.len() - 216);
            let run = 1 + (rng.next() as usize) % 16;
            for b in &mut bytes[at..at + run] {
                *b = rng.next() as u8;
            }
            let path = write_copy(tmp.path(), name, &bytes);
            let decoded = match decode_file(&path, 50_000) {
                Ok(decoded) => decoded,
                Err(error) => {
                    // Damage in a header: the error names the file.
                    assert_eq!(error.path(), path, "{name} trial {trial}");
                    continue;
                }
            };
            if let Some(error) = &decoded.error {
                assert_eq!(error.path(), path);
                if let Some(offset) = error.offset() {
                    assert!(offset <= bytes.len() as u64, "{error}");
                }
            }
            // Every event wholly before the damage is delivered unchanged.
            let before = match name {
                "evt3.raw" => evt3_expected(&data, at).0,
                "evt2.raw" => evt2_expected(&data, at).0,
                "dvs.es" => es_expected(&data, at).0,
                _ => {
                    let boundary = aedat_packets(&data)
                        .into_iter()
                        .take_while(|&(o, s)| o + s <= at)
                        .count();
                    let packets = aedat_packets(&data);
                    let end = if boundary == 0 {
                        0
                    } else {
                        packets[boundary - 1].0 + packets[boundary - 1].1
                    };
                    let cut = write_copy(tmp.path(), "before.aedat4", &data[..end]);
                    decode_file(&cut, 50_000).map(|d| d.events.len()).unwrap_or(0)
                }
            };
            assert!(decoded.events.len() >= before.min(reference.events.len()) || decoded.error.is_some());
            let n = before.min(decoded.events.len());
            assert_eq!(
                decoded.events[..n],
                reference.events[..n],
                "{name} trial {trial}, damage at {at}"
            );
        }
    }
}

#[test]
fn random_bytes_behind_each_magic_never_panic() {
    let tmp = tempfile::tempdir().unwrap();
    let mut rng = Rng(12345);
    let heads: [(&str, &[u8]); 6] = [
        ("a.raw", b"% evt 3.0\n% geometry 1280x720\n"),
        ("b.raw", b"% evt 2.0\n"),
        ("c.es", b"Event Stream\x02\x00\x00\x01\x40\x01\xf0\x00"),
        ("d.es", b"Event Stream\x02\x00\x00\x02\x40\x01\xf0\x00"),
        ("e.aedat4", b"#!AER-DAT4.0\r\n"),
        ("f.txt", b"0.1 1 2 1\n"),
    ];
    for (name, head) in heads {
        for trial in 0..40 {
            let mut bytes = head.to_vec();
            let n = (rng.next() % 3000) as usize;
            bytes.extend((0..n).map(|_| rng.next() as u8));
            let path = write_copy(tmp.path(), name, &bytes);
            for policy in [evseg_formats::OutOfRange::Error, evseg_formats::OutOfRange::Drop] {
                let options = evseg_formats::OpenOptions {
                    out_of_range: policy,
                    ..Default::default()
                };
                match evseg_formats::open(&path, &options) {
                    Ok(mut decoder) => {
                        let decoded = common::decode_all(decoder.as_mut(), 1 + trial * 7);
                        let (w, h) = decoder.geometry();
                        assert!(decoded.events.iter().all(|e| e.1 < w && e.2 < h && e.3 <= 1));
                        if let Some(error) = decoded.error {
                            assert_eq!(error.path(), path);
                        }
                    }
                    Err(error) => assert_eq!(error.path(), path),
                }
            }
        }
    }
}
