//! Cost of one `Tracker::update` on a slice of 100 000 events with 10 moving segments (steady
//! state: every segment continues a track).
//!
//! ```text
//! cargo bench -p evseg-tracker --bench update
//! ```

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use evseg_schemas::{Egomotion, Segment, Segmentation};
use evseg_tracker::{Tracker, TrackerParams};

const EVENTS: usize = 100_000;
const SEGMENTS: u32 = 10;
const DT: f64 = 0.03;

/// Slice `k`: segment `j` centred at (40 + 60 j + 100 t, 100 + 20 j) px, events round-robin over
/// background and the segments (a quarter background).
fn slice(k: usize) -> Segmentation {
    let t = k as f64 * DT;
    let label = (0..EVENTS)
        .map(|i| {
            let r = (i % (SEGMENTS as usize + 4)) as u32;
            if r < 4 { 0 } else { r - 3 }
        })
        .collect();
    let segments = (1..=SEGMENTS)
        .map(|j| {
            let (x, y) = (
                40.0 + 60.0 * f64::from(j) + 100.0 * t,
                100.0 + 20.0 * f64::from(j),
            );
            Segment {
                label: j,
                translation: [0.0; 3],
                centroid: [x, y],
                bbox: [
                    (x - 15.0) as f32,
                    (y - 8.0) as f32,
                    (x + 15.0) as f32,
                    (y + 8.0) as f32,
                ],
                events: 0,
            }
        })
        .collect();
    Segmentation {
        label,
        segments,
        egomotion: Egomotion::default(),
    }
}

fn bench(c: &mut Criterion) {
    let slices: Vec<Segmentation> = (0..64).map(slice).collect();
    let mut tracker = match Tracker::new(TrackerParams::default()) {
        Ok(t) => t,
        Err(e) => panic!("default parameters refused: {e}"),
    };
    let mut k = 0usize;
    c.bench_function("update_100k_events_10_segments", |b| {
        b.iter(|| {
            let seg = &slices[k % slices.len()];
            // Time keeps increasing while the scene repeats every 64 slices: the jump back makes
            // the tracks restart once per cycle, which is part of what is measured.
            let span = (k as f64 * DT, (k + 1) as f64 * DT);
            k += 1;
            black_box(
                tracker
                    .update(span, EVENTS, black_box(seg))
                    .map(|t| t.label.len()),
            )
        })
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
