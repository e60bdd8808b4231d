//! Over-segmentation of a 100k-event slice with the paper's settings (k = 30, lambda = 0.5).

use criterion::{Criterion, criterion_group, criterion_main};
use evseg_oversegmenter::rng::SplitMix64;
use evseg_oversegmenter::{OversegParams, Oversegmenter};
use evseg_schemas::{CameraInfo, Events, NormalFlow};

fn bench(c: &mut Criterion) {
    let camera = CameraInfo::pinhole(640, 480, 500.0, "bench");
    let mut rng = SplitMix64::new(1);
    let n = 100_000;
    let mut ev = Events::with_capacity(n);
    let mut fl = NormalFlow::default();
    for i in 0..n {
        let (u, v) = (rng.below(640) as u16, rng.below(480) as u16);
        ev.push(i as f64 * 3e-7, u, v, 1);
        // Flow varying smoothly over the image plus a fast square object.
        let obj = (200..300).contains(&u) && (150..250).contains(&v);
        let (fx, fy) = if obj {
            (1.5, -0.5)
        } else {
            (f64::from(u) / 640.0 - 0.5, 0.2)
        };
        let a = rng.next_f64() * std::f64::consts::TAU;
        let len = fx * a.cos() + fy * a.sin();
        fl.nx.push((len * a.cos()) as f32);
        fl.ny.push((len * a.sin()) as f32);
        fl.confidence.push(1.0);
    }
    let mut seg = Oversegmenter::new(OversegParams::default()).expect("default params are valid");
    c.bench_function("oversegment_100k_events_k30", |b| {
        b.iter(|| seg.segment(&camera, &ev, &fl).expect("well-formed input"))
    });
}

criterion_group!(benches, bench);
criterion_main!(benches);
