//! Writes the seed corpora of the fuzz targets (`nodes/formats/fuzz`): prefixes of the real
//! recordings, the AEDAT 4 recording re-encoded uncompressed and with zstd, and hand-made files
//! like those of `tests/synthetic.rs` and `tests/text_and_camera.rs`.
//!
//! ```text
//! cargo run -p evseg-formats --example fuzz_seeds -- nodes/formats/fuzz/corpus ../shared/data/real
//! ```
//!
//! One sub-directory per fuzz target. The real-data directory is optional; without it only the
//! hand-made seeds are written.

use std::io::Read;
use std::path::{Path, PathBuf};

/// Prefix lengths taken from each real recording, bytes: small enough for the fuzzer to mutate
/// quickly, large enough to hold the header and a few complete records (the AEDAT 4 header alone
/// is 3,126 bytes).
const PREFIXES: [usize; 2] = [4096, 16384];

type Failure = Box<dyn std::error::Error>;

fn write(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), Failure> {
    std::fs::create_dir_all(dir)?;
    std::fs::write(dir.join(name), bytes)?;
    Ok(())
}

fn u32_at(b: &[u8], p: usize) -> Result<usize, Failure> {
    let bytes: [u8; 4] = b.get(p..p + 4).ok_or("short")?.try_into()?;
    Ok(u32::from_le_bytes(bytes) as usize)
}

/// Position of IOHeader field `index` inside the AEDAT 4 header flatbuffer.
fn header_field(header: &[u8], index: usize) -> Result<usize, Failure> {
    let root = u32_at(header, 0)?;
    let back = u32_at(header, root)? as u32 as i32;
    let vtable = (root as i64 - back as i64) as usize;
    let at = vtable + 4 + 2 * index;
    let offset = u16::from_le_bytes(header.get(at..at + 2).ok_or("short vtable")?.try_into()?);
    if offset == 0 {
        return Err(format!("IOHeader field {index} absent").into());
    }
    Ok(root + offset as usize)
}

/// The header and the first `packets` packets of an LZ4 AEDAT 4 file, skipping packets above
/// 8 KiB (APS frames), re-encoded with compression `code` (0 none, 1 LZ4 as is, 3 zstd) and no
/// data table.
fn aedat4_reencoded(data: &[u8], code: i32, packets: usize) -> Result<Vec<u8>, Failure> {
    let header_len = u32_at(data, 14)?;
    let mut header = data.get(18..18 + header_len).ok_or("short header")?.to_vec();
    let compression = header_field(&header, 0)?;
    header[compression..compression + 4].copy_from_slice(&code.to_le_bytes());
    let position = header_field(&header, 1)?;
    header[position..position + 8].copy_from_slice(&(-1i64).to_le_bytes());
    let mut out = data[..18].to_vec();
    out.extend_from_slice(&header);
    let mut at = 18 + header_len;
    let mut kept = 0;
    while kept < packets && at + 8 <= data.len() {
        let size = u32_at(data, at + 4)?;
        let body = data.get(at + 8..at + 8 + size).ok_or("short packet")?;
        if size <= 8192 {
            let mut plain = Vec::new();
            lz4_flex::frame::FrameDecoder::new(body).read_to_end(&mut plain)?;
            let payload = match code {
                0 => plain,
                1 => body.to_vec(),
                _ => {
                    ruzstd::encoding::compress_to_vec(&plain[..], ruzstd::encoding::CompressionLevel::Fastest)
                }
            };
            out.extend_from_slice(&data[at..at + 4]);
            out.extend_from_slice(&(payload.len() as i32).to_le_bytes());
            out.extend_from_slice(&payload);
            kept += 1;
        }
        at += 8 + size;
    }
    Ok(out)
}

fn real_seeds(out: &Path, real: &Path) -> Result<(), Failure> {
    for (file, target) in [("evt3.raw", "evt3"), ("evt2.raw", "evt2"), ("dvs.es", "es")] {
        let data = std::fs::read(real.join(file))?;
        for n in PREFIXES {
            write(
                &out.join(target),
                &format!("real-{file}-{n}"),
                &data[..n.min(data.len())],
            )?;
        }
    }
    let data = std::fs::read(real.join("davis346.aedat4"))?;
    let aedat4 = out.join("aedat4");
    for n in [3126, 6537, 16384] {
        write(&aedat4, &format!("real-davis346-{n}"), &data[..n.min(data.len())])?;
    }
    for (code, name) in [(0, "none"), (1, "lz4"), (3, "zstd")] {
        write(
            &aedat4,
            &format!("reencoded-{name}"),
            &aedat4_reencoded(&data, code, 4)?,
        )?;
    }
    let any = out.join("decode_any");
    for (selector, file, n) in [
        (0u8, "evt3.raw", 4096),
        (1, "evt2.raw", 4096),
        (2, "dvs.es", 4096),
    ] {
        let bytes = std::fs::read(real.join(file))?;
        let header_end = if selector < 2 {
            prophesee_header_len(&bytes)
        } else {
            0
        };
        let mut seed = vec![selector];
        seed.extend_from_slice(&bytes[header_end..n.min(bytes.len())]);
        write(&any, &format!("real-{file}"), &seed)?;
    }
    let mut seed = vec![3u8];
    seed.extend_from_slice(&aedat4_reencoded(&data, 1, 3)?);
    write(&any, "real-davis346", &seed)?;
    Ok(())
}

/// Length of the `%` header of a Prophesee file.
fn prophesee_header_len(bytes: &[u8]) -> usize {
    let mut at = 0;
    while bytes.get(at) == Some(&b'%') {
        match bytes[at..].iter().position(|&b| b == b'\n') {
            Some(n) => at += n + 1,
            None => return bytes.len(),
        }
    }
    at
}

const fn w3(kind: u16, payload: u16) -> u16 {
    kind << 12 | payload
}

const fn cd2(on: u32, t_low: u32, x: u32, y: u32) -> u32 {
    on << 28 | t_low << 22 | x << 11 | y
}

fn synthetic_seeds(out: &Path) -> Result<(), Failure> {
    let evt3_words = [
        w3(0x0, 1),
        w3(0x8, 5),
        w3(0x6, 7),
        w3(0x0, 3),
        w3(0x2, 1 << 11 | 4),
        w3(0x3, 10),
        w3(0x4, 0b1111_0000_0101),
        w3(0x5, 0xFF),
        w3(0xA, 0x101),
        w3(0x8, 4095),
        w3(0x6, 1),
        w3(0x2, 5),
        w3(0x8, 0),
        w3(0x2, 6),
        w3(0x1, 2),
        w3(0x2, 7),
        w3(0x0, 2),
        w3(0xE, 0x123),
        w3(0xF, 0x456),
        w3(0x7, 0x1),
        w3(0x6, 9),
        w3(0x2, 1 << 11 | 15),
    ];
    let mut evt3 = b"% evt 3.0\n% format EVT3;height=8;width=16\n".to_vec();
    evt3.extend(evt3_words.iter().flat_map(|w| w.to_le_bytes()));
    write(&out.join("evt3"), "synthetic", &evt3)?;
    let mut evt3_bare = b"% evt 3.0\n".to_vec();
    evt3_bare.extend(evt3_words.iter().flat_map(|w| w.to_le_bytes()));
    write(&out.join("evt3"), "synthetic-no-geometry", &evt3_bare)?;

    let evt2_words = [
        cd2(1, 1, 1, 1),
        0x8 << 28 | 0x0FFF_FFFF,
        cd2(1, 63, 639, 479),
        0xA << 28,
        0x8 << 28,
        cd2(0, 5, 0, 0),
    ];
    for (name, header) in [
        ("synthetic", &b"% evt 2.0\n"[..]),
        ("synthetic-geometry", b"% evt 2.0\n% geometry 320x240\n"),
        ("synthetic-format", b"% format EVT2;width=640;height=480\n"),
    ] {
        let mut bytes = header.to_vec();
        bytes.extend(evt2_words.iter().flat_map(|w| w.to_le_bytes()));
        write(&out.join("evt2"), name, &bytes)?;
    }

    let es = |kind: u8, body: &[u8]| {
        let mut bytes = b"Event Stream".to_vec();
        bytes.extend_from_slice(&[2, 0, 0, kind]);
        bytes.extend_from_slice(&4u16.to_le_bytes());
        bytes.extend_from_slice(&3u16.to_le_bytes());
        bytes.extend_from_slice(body);
        bytes
    };
    let atis = [
        5 << 2 | 1 << 1,
        1,
        0,
        0,
        0,
        2 << 2 | 1,
        2,
        0,
        1,
        0,
        0xFD,
        0xFC,
        0,
        3,
        0,
        2,
        0,
    ];
    write(&out.join("es"), "synthetic-atis", &es(2, &atis))?;
    write(
        &out.join("es"),
        "synthetic-dvs",
        &es(1, &[0xFF, 0xFE, 3 << 1 | 1, 3, 0, 2, 0, 0, 1, 0, 0, 0]),
    )?;

    let events = "# t x y p\n0.0001 10 20 1\n0.0002 11 20 0\n0.0002 12 21 -1\n0.5,3,4,1\n";
    let calib = "200 201 120 90 -0.1 0.01 0.001 0.002 0.0001\n";
    let imu = "t ax ay az gx gy gz\n0.0000 0.1 -9.8 0.2 0.01 0.02 0.03\n0.0003 0.1 -9.8 0.2 0.01 0.02 0.03\n";
    let text = out.join("text");
    write(&text, "events-only", events.as_bytes())?;
    write(&text, "with-calib", format!("{events}\0{calib}").as_bytes())?;
    write(
        &text,
        "with-calib-imu",
        format!("{events}\0{calib}\0{imu}").as_bytes(),
    )?;
    write(
        &text,
        "pinhole-calib",
        format!("{events}\0200 200 120 90\n").as_bytes(),
    )?;
    let mut any = vec![4u8];
    any.extend_from_slice(events.as_bytes());
    write(&out.join("decode_any"), "text", &any)?;

    let camera = out.join("camera_file");
    write(
        &camera,
        "rad_tan",
        br#"{"sensor": "davis346", "width": 346, "height": 260, "fx": 320.5, "fy": 320.1,
"cx": 172.3, "cy": 130.9,
"distortion": {"model": "rad_tan", "k1": -0.35, "k2": 0.15, "p1": 0.0, "p2": 0.0, "k3": 0.0},
"imu_to_camera": [1, 0, 0, 0, 1, 0, 0, 0, 1], "imu_time_offset_s": 0.0}"#,
    )?;
    write(
        &camera,
        "equidistant",
        br#"{"fx": 300, "fy": 300, "cx": 173, "cy": 130,
"distortion": {"model": "equidistant", "k1": 0.1, "k2": 0.01, "k3": 0.0, "k4": 0.0},
"imu_to_camera": [1, 0, 0, 0, -1, 0, 0, 0, -1]}"#,
    )?;
    write(
        &camera,
        "none",
        br#"{"fx": 300, "fy": 300, "cx": 173, "cy": 130, "distortion": {"model": "none"}}"#,
    )?;
    Ok(())
}

fn main() -> Result<(), Failure> {
    let mut args = std::env::args_os().skip(1);
    let out = PathBuf::from(args.next().ok_or("usage: fuzz_seeds OUT_DIR [REAL_DATA_DIR]")?);
    synthetic_seeds(&out)?;
    if let Some(real) = args.next() {
        real_seeds(&out, Path::new(&real))?;
    }
    println!("seeds written under {}", out.display());
    Ok(())
}
