//! Decode speed measured on process CPU time (robust on a shared, loaded machine, where the
//! criterion wall-clock numbers of `benches/decode.rs` are not):
//! `cargo run --release -p evseg-formats --example decode_speed -- FILE [SECONDS]`.
//! Linux only (reads /proc/self/stat; assumes 100 clock ticks per second).

use evseg_formats::{Chunk, OpenOptions};

fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit_once(')').map_or("", |(_, rest)| rest);
    let fields: Vec<&str> = after.split_whitespace().collect();
    let ticks = |i: usize| fields.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (ticks(11) + ticks(12)) / 100.0
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: decode_speed FILE [SECONDS]")?;
    let seconds: f64 = args.next().map_or(Ok(3.0), |s| s.parse())?;
    let mut chunk = Chunk::with_capacity(65_536 + 16);
    let (wall, cpu) = (std::time::Instant::now(), cpu_seconds());
    let (mut events, mut passes) = (0u64, 0u32);
    while cpu_seconds() - cpu < seconds {
        let mut decoder = evseg_formats::open(&path, &OpenOptions::default())?;
        while decoder.decode_into(&mut chunk, 65_536)? {
            events += chunk.events.len() as u64;
        }
        passes += 1;
    }
    let (wall, cpu) = (wall.elapsed().as_secs_f64(), cpu_seconds() - cpu);
    println!(
        "{path}: {passes} passes, {events} events, {:.1} M events/s per CPU second ({:.1} M/s wall)",
        events as f64 / cpu / 1e6,
        events as f64 / wall / 1e6
    );
    Ok(())
}
