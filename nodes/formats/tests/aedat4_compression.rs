//! The real AEDAT 4 recording re-encoded without compression and with zstd (DV's other
//! compression settings) decodes to the same events and IMU samples.

mod common;

use std::io::Read;

use common::{decode_file, real_data_dir};

/// Position of IOHeader field `index` inside the header flatbuffer.
fn header_field(header: &[u8], index: usize) -> usize {
    let u32_at = |p: usize| u32::from_le_bytes(header[p..p + 4].try_into().unwrap()) as usize;
    let root = u32_at(0);
    let vtable =
        (root as i64 - i32::from_le_bytes(header[root..root + 4].try_into().unwrap()) as i64) as usize;
    let offset = u16::from_le_bytes(
        header[vtable + 4 + 2 * index..vtable + 6 + 2 * index]
            .try_into()
            .unwrap(),
    );
    assert!(offset != 0, "field {index} present");
    root + offset as usize
}

/// Re-encodes `data` (LZ4 packets) with compression `code` (0 none, 3 zstd); `data_table` says
/// whether to keep a data-table position (the file then ends exactly there) or write -1.
fn reencode(data: &[u8], code: i32, data_table: bool) -> Vec<u8> {
    let header_len = u32::from_le_bytes(data[14..18].try_into().unwrap()) as usize;
    let mut header = data[18..18 + header_len].to_vec();
    let compression = header_field(&header, 0);
    assert_eq!(
        i32::from_le_bytes(header[compression..compression + 4].try_into().unwrap()),
        1,
        "LZ4"
    );
    header[compression..compression + 4].copy_from_slice(&code.to_le_bytes());
    let position = header_field(&header, 1);
    let end = i64::from_le_bytes(header[position..position + 8].try_into().unwrap()) as usize;
    let mut packets = Vec::new();
    let mut at = 18 + header_len;
    while at < end {
        let size = i32::from_le_bytes(data[at + 4..at + 8].try_into().unwrap()) as usize;
        let mut plain = Vec::new();
        lz4_flex::frame::FrameDecoder::new(&data[at + 8..at + 8 + size])
            .read_to_end(&mut plain)
            .unwrap();
        let payload = match code {
            0 => plain,
            _ => ruzstd::encoding::compress_to_vec(&plain[..], ruzstd::encoding::CompressionLevel::Fastest),
        };
        packets.extend_from_slice(&data[at..at + 4]);
        packets.extend_from_slice(&(payload.len() as i32).to_le_bytes());
        packets.extend_from_slice(&payload);
        at += 8 + size;
    }
    let new_end = if data_table {
        (18 + header_len + packets.len()) as i64
    } else {
        -1
    };
    header[position..position + 8].copy_from_slice(&new_end.to_le_bytes());
    let mut out = data[..18].to_vec();
    out.extend_from_slice(&header);
    out.extend_from_slice(&packets);
    out
}

#[test]
fn uncompressed_and_zstd_recordings_decode_the_same() {
    let Some(dir) = real_data_dir() else { return };
    let original = dir.join("davis346.aedat4");
    let data = std::fs::read(&original).unwrap();
    let reference = decode_file(&original, 50_000).unwrap();
    assert_eq!(reference.events.len(), 78_830);
    let tmp = tempfile::tempdir().unwrap();
    for (code, data_table) in [(0, true), (0, false), (3, true), (3, false)] {
        let path = tmp.path().join(format!("c{code}_{data_table}.aedat4"));
        std::fs::write(&path, reencode(&data, code, data_table)).unwrap();
        let decoded = decode_file(&path, 50_000).unwrap();
        assert!(decoded.error.is_none(), "{:?}", decoded.error);
        assert_eq!(decoded.events, reference.events, "compression {code}");
        assert_eq!(decoded.imu, reference.imu, "compression {code}");
    }
    // A zstd file with damaged compressed bytes: a corrupt-data error naming file and packet.
    let mut bytes = reencode(&data, 3, true);
    let header_len = u32::from_le_bytes(bytes[14..18].try_into().unwrap()) as usize;
    let first = 18 + header_len;
    for b in &mut bytes[first + 8..first + 20] {
        *b = 0xA5;
    }
    let path = tmp.path().join("bad.aedat4");
    std::fs::write(&path, &bytes).unwrap();
    let error = evseg_formats::open(&path, &Default::default())
        .err()
        .expect("first packet is an event packet");
    assert_eq!(error.offset(), Some(first as u64), "{error}");
    assert!(error.to_string().contains("zstd"), "{error}");
}
