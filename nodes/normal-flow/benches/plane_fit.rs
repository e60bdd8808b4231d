//! Plane-fit normal flow throughput on a simulator slice.
//!
//! `cargo bench -p evseg-normal-flow --bench plane_fit`. The slice (preset "two-objects",
//! 640x480, the first 0.1 s) is simulated once, outside the timing loop. Each iteration runs a
//! fresh estimator (empty surfaces, as at the start of a run) over every event of the slice;
//! criterion reports events per second (the target is >= 3 M events/s on one core), for the
//! default window with its scale check, without the check, and for the 3 x 3 window; and for the
//! default window with the wide fit's second flow (`WideFitParams::default()`, the wide flow
//! graph.yaml wires to the final egomotion). The estimator's construction (per-pixel Jacobian
//! table) is excluded.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BatchSize, Criterion, Throughput, criterion_group, criterion_main};
use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams, WideFitParams};
use evseg_schemas::NormalFlow;
use evseg_sim::{Simulator, preset};

const SLICE_S: f64 = 0.1;

fn bench(c: &mut Criterion) {
    let cfg = preset("two-objects", 1).expect("preset exists");
    let mut sim = Simulator::new(cfg).expect("valid preset");
    let camera = sim.camera_info();
    let events = sim.next_chunk(SLICE_S).events;
    println!("two-objects: {} events in {SLICE_S} s", events.len());
    let mut group = c.benchmark_group("plane_fit_two_objects_0.1s");
    group
        .sample_size(20)
        .measurement_time(Duration::from_secs(8))
        .warm_up_time(Duration::from_secs(1))
        .throughput(Throughput::Elements(events.len() as u64));
    // The default (5 x 5 with the 7 x 7 scale check), without the check, 3 x 3, and the default
    // with the wide flow.
    let variants = [
        ("radius2", 2, 3, false),
        ("radius2_nocheck", 2, 0, false),
        ("radius1", 1, 3, false),
        ("radius2_wide", 2, 3, true),
    ];
    for (name, radius, check_radius, wide) in variants {
        let params = PlaneFitParams {
            radius,
            check_radius,
            ..PlaneFitParams::default()
        };
        let fresh = PlaneFitEstimator::new(&camera, params).expect("valid parameters");
        let fresh = match wide {
            true => fresh
                .with_wide_fit(WideFitParams::default())
                .expect("valid parameters"),
            false => fresh,
        };
        group.bench_function(name, |b| {
            b.iter_batched(
                || {
                    (
                        fresh.clone(),
                        NormalFlow::default(),
                        wide.then(NormalFlow::default),
                    )
                },
                |(mut est, mut out, mut wide_out)| {
                    est.process_wide_into(&events, None, &mut out, wide_out.as_mut())
                        .expect("consistent columns");
                    black_box(out.confidence.len())
                },
                BatchSize::LargeInput,
            )
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
