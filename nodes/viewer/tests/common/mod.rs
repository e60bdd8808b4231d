//! A synthetic run for the viewer tests: slices of events on a 64 x 48 sensor with two moving
//! squares, their track labels, normal flow, truth and metrics, as encoded frames.

#![allow(dead_code)]

use evseg_schemas::{
    CameraInfo, CameraMotion, Egomotion, Events, Message, Metric, Metrics, NormalFlow, Slice, Track, Tracks,
    Truth, encode,
};

/// Sensor width and height, pixels.
pub const W: u16 = 64;
/// Sensor height, pixels.
pub const H: u16 = 48;
/// Slice window, seconds.
pub const WINDOW: f64 = 0.03;

/// Object id of pixel `(x, y)` at slice `k`: two 10 x 10 squares moving right and down.
pub fn object_at(x: u16, y: u16, k: u64) -> u16 {
    let k = k as u16;
    if (5 + k..15 + k).contains(&x) && (5..15).contains(&y) {
        1
    } else if (40..50).contains(&x) && (10 + k..20 + k).contains(&y) {
        2
    } else {
        0
    }
}

/// SplitMix64: a deterministic, well-mixed hash of `i`.
fn mix(i: u64) -> u64 {
    let mut z = i.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Slice `k` with `n` events at pseudo-random pixels (deterministic, time-ordered), like a
/// real slice as far as compression goes.
pub fn slice(k: u64, n: usize) -> Slice {
    let mut events = Events::with_capacity(n);
    let t0 = k as f64 * WINDOW;
    for i in 0..n {
        let j = mix(k << 32 | i as u64) as usize;
        events.push(
            t0 + WINDOW * i as f64 / n as f64,
            (j % W as usize) as u16,
            ((j / W as usize) % H as usize) as u16,
            (i % 2) as u8,
        );
    }
    Slice {
        camera: CameraInfo::pinhole(W, H, 50.0, "test"),
        events,
        imu: vec![],
        omega: Some([0.0, 0.1, 0.0]),
    }
}

/// Per-event truth ids of a slice.
pub fn ids(s: &Slice, k: u64) -> Vec<u16> {
    (0..s.events.len())
        .map(|i| object_at(s.events.x[i], s.events.y[i], k))
        .collect()
}

/// Tracks of slice `k`: labels = truth ids + 10 (background stays 0), one box per object.
pub fn tracks(s: &Slice, k: u64) -> Tracks {
    let label = ids(s, k)
        .into_iter()
        .map(|o| if o == 0 { 0 } else { u32::from(o) + 10 })
        .collect();
    let kf = k as f32;
    let track = |id: u32, bbox: [f32; 4]| Track {
        id,
        centroid: [
            f64::from(bbox[0] + bbox[2]) / 2.0,
            f64::from(bbox[1] + bbox[3]) / 2.0,
        ],
        velocity: [33.0, 0.0],
        bbox,
        translation: [0.1, 0.0, 0.0],
        age: k as u32,
        events: 100,
    };
    Tracks {
        label,
        tracks: vec![
            track(11, [5.0 + kf, 5.0, 14.0 + kf, 14.0]),
            track(12, [40.0, 10.0 + kf, 49.0, 19.0 + kf]),
        ],
        egomotion: Egomotion {
            direction: [0.6, 0.0, 0.8],
            omega: [0.0, 0.1, 0.0],
            valid: true,
        },
    }
}

/// Normal flow of a slice: objects move, the background has no estimate.
pub fn flow(s: &Slice, k: u64) -> NormalFlow {
    let ids = ids(s, k);
    let n = ids.len();
    let mut f = NormalFlow {
        nx: vec![0.0; n],
        ny: vec![0.0; n],
        confidence: vec![0.0; n],
    };
    for (i, o) in ids.iter().enumerate() {
        match o {
            1 => (f.nx[i], f.confidence[i]) = (0.7, 1.0),
            2 => (f.ny[i], f.confidence[i]) = (0.7, 1.0),
            _ => {}
        }
    }
    f
}

/// Truth of a slice: per-event ids and one camera motion sample.
pub fn truth(s: &Slice, k: u64) -> Truth {
    Truth {
        event_object: ids(s, k),
        camera: vec![CameraMotion {
            t: k as f64 * WINDOW,
            position: [0.0; 3],
            orientation: [0.0, 0.0, 0.0, 1.0],
            linear_velocity: Some([0.0, 0.0, 2.0]),
            angular_velocity: Some([0.0, 0.1, 0.0]),
        }],
        ..Truth::default()
    }
}

/// Metrics of a slice.
pub fn metrics(k: u64) -> Metrics {
    Metrics {
        values: vec![
            Metric {
                name: "iou".into(),
                value: 0.5 + 0.01 * k as f64,
            },
            Metric {
                name: "direction_error_deg".into(),
                value: if k == 0 { f64::NAN } else { 10.0 },
            },
        ],
    }
}

/// The frame of message `body` for slice `k`.
pub fn frame<T: Message>(k: u64, body: &T) -> Vec<u8> {
    encode(k, k as f64 * WINDOW, (k + 1) as f64 * WINDOW, body).expect("encode")
}

/// `(producer, frame)` of every message of `slices` slices of `n` events, slices first in each
/// slice's group unless `labels_first`.
pub fn run(slices: u64, n: usize, labels_first: bool) -> Vec<(&'static str, Vec<u8>)> {
    let mut out = Vec::new();
    for k in 0..slices {
        let s = slice(k, n);
        let per_event = vec![
            ("tracker", frame(k, &tracks(&s, k))),
            ("flow", frame(k, &flow(&s, k))),
            ("slicer", frame(k, &truth(&s, k))),
            ("evaluator", frame(k, &metrics(k))),
        ];
        if labels_first {
            out.extend(per_event);
            out.push(("slicer", frame(k, &s)));
        } else {
            out.push(("slicer", frame(k, &s)));
            out.extend(per_event);
        }
    }
    out
}

/// Entity paths (without the leading `/`) and their row counts (summed over chunks) in an .rrd
/// file, as the official `rerun rrd print` lists them; panics when Rerun cannot read the file.
pub fn rrd_entities(cli: &std::path::Path, rrd: &std::path::Path) -> std::collections::BTreeMap<String, u64> {
    let o = std::process::Command::new(cli)
        .args(["rrd", "print"])
        .arg(rrd)
        .output()
        .expect("run rerun rrd print");
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "rerun rrd print {} failed:\n{text}\n{}",
        rrd.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let mut out = std::collections::BTreeMap::new();
    for line in text.lines() {
        // Chunk lines: `Chunk(...) with N rows (...) - /entity/path - columns: [...]`.
        let mut parts = line.split(" - ");
        let (Some(head), Some(path)) = (parts.next(), parts.next()) else {
            continue;
        };
        let rows = head
            .split(" with ")
            .nth(1)
            .and_then(|r| r.split(' ').next())
            .and_then(|n| n.parse::<u64>().ok());
        if let (Some(rows), Some(path)) = (rows, path.trim().strip_prefix('/')) {
            *out.entry(path.to_string()).or_insert(0) += rows;
        }
    }
    out
}
