//! Decode speed of each real recording, whole file per iteration, into one reused chunk of
//! 65,536 events (the hot loops allocate nothing per event).
//!
//! `CARGO_TARGET_DIR=/work/target-formats cargo bench -p evseg-formats --bench decode`
//! Target: EVT 3.0 at 50 M events/s or more on one core.

use std::path::PathBuf;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use evseg_formats::{Chunk, OpenOptions};

fn real_data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("EVSEG_SHARED") {
        Some(shared) => PathBuf::from(shared).join("data/real"),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/real"),
    };
    dir.join("evt3.raw").is_file().then_some(dir)
}

fn decode_whole(path: &std::path::Path, chunk: &mut Chunk) -> u64 {
    let mut decoder = evseg_formats::open(path, &OpenOptions::default()).expect("opens");
    let mut n = 0;
    while decoder.decode_into(chunk, 65_536).expect("decodes") {
        n += chunk.events.len() as u64;
    }
    n
}

fn bench(c: &mut Criterion) {
    let Some(dir) = real_data_dir() else {
        eprintln!("SKIP: shared/data/real not found; nothing to benchmark");
        return;
    };
    let mut group = c.benchmark_group("decode");
    group.sample_size(20);
    for file in ["evt3.raw", "evt2.raw", "dvs.es", "davis346.aedat4"] {
        let path = dir.join(file);
        let mut chunk = Chunk::with_capacity(65_536 + 16);
        let events = decode_whole(&path, &mut chunk);
        group.throughput(Throughput::Elements(events));
        group.bench_function(file, |b| b.iter(|| decode_whole(&path, &mut chunk)));
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
