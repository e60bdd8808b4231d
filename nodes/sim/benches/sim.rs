//! Simulator throughput at full resolution (640x480).
//!
//! `cargo bench -p evseg-sim --bench sim` (every preset; `-- one-object` for one). Each
//! iteration simulates `SIM_SECONDS` of a preset from a fresh simulator (texture baking
//! excluded); criterion's time per iteration divided into `SIM_SECONDS` gives sim-seconds per
//! wall-second, and the events per sim-second are printed once per preset. The requirement is
//! real time: at most `SIM_SECONDS` of wall time per iteration.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use evseg_sim::{Simulator, preset};

const SIM_SECONDS: f64 = 0.1;

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("simulate_0.1s_640x480");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10))
        .warm_up_time(Duration::from_secs(1));
    for &name in evseg_sim::PRESET_NAMES {
        let cfg = preset(name, 1).expect("preset exists");
        let fresh = Simulator::new(cfg).expect("valid preset");
        let mut probe = fresh.clone();
        let events = probe.next_chunk(SIM_SECONDS).events.len();
        println!(
            "{name}: {events} events in {SIM_SECONDS} s of sensor time ({:.2} M events/s)",
            events as f64 / SIM_SECONDS / 1e6
        );
        group.throughput(Throughput::Elements(events as u64));
        group.bench_function(name, |b| {
            b.iter_batched(
                || fresh.clone(),
                |mut sim| black_box(sim.next_chunk(SIM_SECONDS).events.len()),
                criterion::BatchSize::LargeInput,
            )
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
