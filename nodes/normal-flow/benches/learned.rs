//! Learned normal flow throughput on simulator slices.
//!
//! `cargo bench -p evseg-normal-flow --bench learned`. Preset "two-objects" (640x480, seed 1),
//! the first 0.12 s cut into four 30 ms slices, simulated once outside the timing loop. Each
//! iteration runs the estimator (weights from nodes/normal-flow/weights/learned.bin) over the
//! four slices; criterion reports events per second (the target is >= 1 M events/s with 2
//! threads). The estimator's construction (tables, weights loading) is excluded.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use evseg_normal_flow::{LearnedEstimator, LearnedParams, LearnedWeights};
use evseg_schemas::NormalFlow;
use evseg_sim::{Simulator, preset};

const SLICE_S: f64 = 0.03;
const SLICES: usize = 4;

fn bench(c: &mut Criterion) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/weights/learned.bin");
    let weights = LearnedWeights::load(path).expect("committed weights file");
    let cfg = preset("two-objects", 1).expect("preset exists");
    let mut sim = Simulator::new(cfg).expect("valid preset");
    let camera = sim.camera_info();
    let slices: Vec<_> = (0..SLICES)
        .map(|k| {
            let (t0, t1) = (k as f64 * SLICE_S, (k + 1) as f64 * SLICE_S);
            (t0, t1, sim.next_chunk(t1).events)
        })
        .collect();
    let total: usize = slices.iter().map(|s| s.2.len()).sum();
    println!("two-objects: {total} events in {SLICES} slices of {SLICE_S} s");
    let mut group = c.benchmark_group("learned_two_objects_4x30ms");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10))
        .warm_up_time(Duration::from_secs(2))
        .throughput(Throughput::Elements(total as u64));
    for (name, threads, ensemble) in [
        ("threads2", 2, 1),
        ("threads1", 1, 1),
        ("threads2_ensemble4", 2, 4),
    ] {
        let params = LearnedParams {
            threads,
            ensemble,
            ..LearnedParams::default()
        };
        let mut est = LearnedEstimator::new(&camera, weights.clone(), params).expect("valid parameters");
        let mut out = NormalFlow::default();
        group.bench_function(name, |b| {
            b.iter(|| {
                for (t0, t1, ev) in &slices {
                    est.process_into(ev, *t0, *t1, &mut out)
                        .expect("consistent columns");
                }
                black_box(out.confidence.len())
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
