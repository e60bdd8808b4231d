//! The plane-fit estimator with `graphs/evimo2.yaml`'s settings over the slices of a simulated
//! sequence, for instruction counts (`perf stat -e instructions:u`) and a digest of the output
//! (so that a speed change can be shown to leave every estimate bit-identical).
//!
//! `cargo run --release -p evseg-normal-flow --example flow_speed -- [scene] [seed] [seconds]`
//! (default `two-objects 7 3`, as `evseg bench pipeline`); `XLA=0` fits each slice on its own
//! instead of letting the look-ahead reach into the next slice as the node does;
//! `NF_CHECK_RADIUS` (0 = no scale check), `NF_SKIP_CONF` and `NF_SKIP_SD_DEG` change the scale
//! check's window and the fits it skips (`PlaneFitParams::check_radius`,
//! `check_skip_confidence`, `check_skip_direction_sd_rad`). The simulated events are cached in
//! `/tmp/flow_speed-<scene>-<seed>-<seconds>.bin` so that a second run counts the estimator only.
//! Prints the events, the estimator's time (s) and an FNV-1a digest of `nx`, `ny`, `confidence`.

use std::io::{Read, Write};
use std::time::Instant;

use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams};
use evseg_schemas::{Events, NormalFlow};
use evseg_sim::{Simulator, preset};

const SLICE_S: f64 = 0.03;

/// The value of environment variable `name`, or `default` when it is unset or not a `T`.
fn env_or<T: std::str::FromStr>(name: &str, default: T) -> T {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let scene = args.first().map_or("two-objects", String::as_str).to_string();
    let seed: u64 = args.get(1).map_or(Ok(7), |s| s.parse())?;
    let seconds: f64 = args.get(2).map_or(Ok(3.0), |s| s.parse())?;
    let cache = format!("/tmp/flow_speed-{scene}-{seed}-{seconds}.bin");
    let cfg = preset(&scene, seed)?;
    let mut sim = Simulator::new(cfg)?;
    let camera = sim.camera_info();
    let slices = load_or_simulate(&cache, &mut sim, seconds)?;
    let params = PlaneFitParams {
        min_confidence: 0.0,
        max_direction_sd_rad: 16f64.to_radians(),
        check_radius: env_or("NF_CHECK_RADIUS", PlaneFitParams::default().check_radius),
        check_skip_confidence: env_or("NF_SKIP_CONF", PlaneFitParams::default().check_skip_confidence),
        check_skip_direction_sd_rad: env_or(
            "NF_SKIP_SD_DEG",
            PlaneFitParams::default().check_skip_direction_sd_rad.to_degrees(),
        )
        .to_radians(),
        ..PlaneFitParams::default()
    };
    let mut est = PlaneFitEstimator::new(&camera, params)?;
    // XLA=0: each slice fitted on its own (the node's `lookahead_across_slices: false`).
    let across = params.lookahead_across_slices && std::env::var("XLA").map_or(true, |v| v != "0");
    let mut out = NormalFlow::default();
    let mut digest = 0xcbf2_9ce4_8422_2325u64;
    let mut n = 0usize;
    let start = Instant::now();
    for (k, events) in slices.iter().enumerate() {
        // As the node: the look-ahead reaches into the next slice (`lookahead_across_slices`).
        let next = slices.get(k + 1).filter(|_| across);
        est.process_with_next_into(events, next, &mut out)?;
        n += events.len();
        for v in out.nx.iter().chain(&out.ny).chain(&out.confidence) {
            for b in v.to_bits().to_le_bytes() {
                digest = (digest ^ u64::from(b)).wrapping_mul(0x100_0000_01b3);
            }
        }
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{n} events, {secs:.3} s, {:.2} M events/s, digest {digest:016x}",
        n as f64 / secs / 1e6
    );
    Ok(())
}

fn load_or_simulate(cache: &str, sim: &mut Simulator, seconds: f64) -> anyhow::Result<Vec<Events>> {
    let chunks = (seconds / SLICE_S).round() as usize;
    if let Ok(mut f) = std::fs::File::open(cache) {
        let mut bytes = Vec::new();
        f.read_to_end(&mut bytes)?;
        let mut at = 0usize;
        let mut take = |k: usize| -> anyhow::Result<&[u8]> {
            let s = bytes
                .get(at..at + k)
                .ok_or_else(|| anyhow::anyhow!("short cache"))?;
            at += k;
            Ok(s)
        };
        let mut slices = Vec::with_capacity(chunks);
        for _ in 0..chunks {
            let len = u64::from_le_bytes(take(8)?.try_into()?) as usize;
            let mut ev = Events::default();
            for _ in 0..len {
                ev.t.push(f64::from_le_bytes(take(8)?.try_into()?));
                ev.x.push(u16::from_le_bytes(take(2)?.try_into()?));
                ev.y.push(u16::from_le_bytes(take(2)?.try_into()?));
                ev.p.push(take(1)?[0]);
            }
            slices.push(ev);
        }
        return Ok(slices);
    }
    let slices: Vec<Events> = (1..=chunks)
        .map(|k| sim.next_chunk(k as f64 * SLICE_S).events)
        .collect();
    let mut f = std::fs::File::create(cache)?;
    for ev in &slices {
        f.write_all(&(ev.len() as u64).to_le_bytes())?;
        for i in 0..ev.len() {
            f.write_all(&ev.t[i].to_le_bytes())?;
            f.write_all(&ev.x[i].to_le_bytes())?;
            f.write_all(&ev.y[i].to_le_bytes())?;
            f.write_all(&[ev.p[i]])?;
        }
    }
    Ok(slices)
}
