//! Runs a preset and prints event rates, work counters and wall time.
//!
//! `cargo run --release -p evseg-sim --example sim_stats -- one-object 1.0 [seed]`

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map(String::as_str).unwrap_or("one-object");
    let secs: f64 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(1.0);
    let seed: u64 = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let cfg = evseg_sim::preset(name, seed)?;
    let t0 = Instant::now();
    let mut sim = evseg_sim::Simulator::new(cfg)?;
    let setup = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let (mut n, mut on, mut obj) = (0usize, 0usize, 0usize);
    let mut t = 0.0;
    while t < secs.min(sim.duration()) - 1e-9 {
        t = (t + 0.05).min(secs);
        let c = sim.next_chunk(t);
        n += c.events.len();
        on += c.events.p.iter().filter(|&&p| p == 1).count();
        obj += c.truth.event_object.iter().filter(|&&i| i != 0).count();
    }
    let wall = t1.elapsed().as_secs_f64();
    let s = sim.stats();
    let px = 640.0 * 480.0;
    println!("preset {name} seed {seed}: {t:.2} s simulated in {wall:.2} s wall (setup {setup:.2} s)");
    println!(
        "  events {n} ({:.2} M/s sensor time), on share {:.2}, object share {:.3}",
        n as f64 / t / 1e6,
        on as f64 / n.max(1) as f64,
        obj as f64 / n.max(1) as f64
    );
    println!(
        "  sim-seconds per wall-second {:.3}, events per wall-second {:.2} M",
        t / wall,
        n as f64 / wall / 1e6
    );
    println!(
        "  steps {} ({:.0}/s), keyframes {}, rays per step {:.3} of the image, interpolated samples per step {:.3} of the image, supersampled per step {:.0}, noise {}, skip violations {}",
        s.steps,
        s.steps as f64 / t,
        s.keyframes,
        s.pixel_renders as f64 / s.steps as f64 / px,
        s.interpolated_samples as f64 / s.steps as f64 / px,
        s.supersampled as f64 / s.steps as f64,
        s.noise_events,
        s.skip_violations
    );
    Ok(())
}
