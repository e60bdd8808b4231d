//! Runs a preset (or every preset) and prints event rates, work counters, wall time and CPU
//! time (the CPU time of the simulating thread is steadier than wall time on a shared machine).
//!
//! `cargo run --release -p evseg-sim --example sim_stats -- one-object 1.0 [seed]`
//! `cargo run --release -p evseg-sim --example sim_stats -- all 1.0 [seed]`

use evseg_sim::throughput::time_simulation;

struct Row {
    name: String,
    events_per_s: f64,
    wall: f64,
    cpu: Option<f64>,
    simulated: f64,
}

fn run(name: &str, secs: f64, seed: u64) -> Result<Row, Box<dyn std::error::Error>> {
    let mut cfg = evseg_sim::preset(name, seed)?;
    // Development overrides of the render schedule (defaults: the preset's).
    if let Some(k) = std::env::var("SIM_STEPS_PER_KEYFRAME")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        cfg.render.steps_per_keyframe = k;
    }
    if let Some(s) = std::env::var("SIM_SPEED_SAFETY")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        cfg.render.speed_safety = s;
    }
    if std::env::var("SIM_NO_SUPERSAMPLING").is_ok() {
        cfg.render.edge_supersampling = false;
    }
    let (mut n, mut on, mut obj) = (0usize, 0usize, 0usize);
    // FNV-1a digest of every event and its truth: equal digests mean identical output.
    let mut digest = 0xcbf2_9ce4_8422_2325u64;
    let mut mix = |bits: u64| {
        digest = (digest ^ bits).wrapping_mul(0x0100_0000_01b3);
    };
    let (sim, timing) = time_simulation(cfg, secs, |c| {
        n += c.events.len();
        on += c.events.p.iter().filter(|&&p| p == 1).count();
        obj += c.truth.event_object.iter().filter(|&&i| i != 0).count();
        for i in 0..c.events.len() {
            mix(c.events.t[i].to_bits());
            mix(((c.events.x[i] as u64) << 32) | ((c.events.y[i] as u64) << 16) | c.events.p[i] as u64);
            mix(c.truth.event_object[i] as u64);
            mix(((c.truth.flow_x[i].to_bits() as u64) << 32) | c.truth.flow_y[i].to_bits() as u64);
        }
    })?;
    let (t, wall, cpu, setup) = (timing.simulated_s, timing.wall_s, timing.cpu_s, timing.setup_s);
    let s = sim.stats();
    println!("  output digest {digest:016x}");
    let px = 640.0 * 480.0;
    println!("preset {name} seed {seed}: {t:.2} s simulated in {wall:.2} s wall (setup {setup:.2} s)");
    println!(
        "  events {n} ({:.2} M/s sensor time), on share {:.2}, object share {:.3}",
        n as f64 / t / 1e6,
        on as f64 / n.max(1) as f64,
        obj as f64 / n.max(1) as f64
    );
    println!(
        "  sim-seconds per wall-second {:.3}, per CPU-second {}, events per wall-second {:.2} M",
        t / wall,
        cpu.map_or("n/a".to_string(), |c| format!("{:.3}", t / c)),
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
    Ok(Row {
        name: name.to_string(),
        events_per_s: n as f64 / t,
        wall,
        cpu,
        simulated: t,
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map(String::as_str).unwrap_or("one-object");
    let secs: f64 = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(1.0);
    let seed: u64 = args.get(3).map(|s| s.parse()).transpose()?.unwrap_or(1);
    let names: Vec<&str> = if name == "all" {
        evseg_sim::PRESET_NAMES.to_vec()
    } else {
        vec![name]
    };
    let mut rows = Vec::new();
    for n in names {
        rows.push(run(n, secs, seed)?);
    }
    if rows.len() > 1 {
        println!();
        println!(
            "{:<16} {:>10} {:>14} {:>14}",
            "preset", "M ev/s", "sim-s/wall-s", "sim-s/CPU-s"
        );
        for r in &rows {
            println!(
                "{:<16} {:>10.2} {:>14.3} {:>14}",
                r.name,
                r.events_per_s / 1e6,
                r.simulated / r.wall,
                r.cpu
                    .map_or("n/a".to_string(), |c| format!("{:.3}", r.simulated / c))
            );
        }
    }
    Ok(())
}
