//! Runs the plane-fit estimator and the scorer on simulator presets and prints the scores.
//!
//! `cargo run --release -p evseg-normal-flow --example score_presets -- [options] [presets...]`
//! Options: `--seconds S` (default 0.5), `--slice-ms M` (default 30), `--radius R`,
//! `--dt-min-ms X`, `--dt-max-ms X`, `--min-confidence C` (estimator's, default 0.5), `--json` (one JSON line per preset).
//! Default presets: one-object, two-objects, fast-rotation (seed 1).

use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams, ScoreParams, Scorer};
use evseg_sim::{Simulator, preset};

fn value<T: std::str::FromStr>(args: &mut impl Iterator<Item = String>, flag: &str) -> Result<T, String> {
    let v = args.next().ok_or(format!("{flag} needs a value"))?;
    v.parse().map_err(|_| format!("{flag}: cannot parse '{v}'"))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut params = PlaneFitParams::default();
    let score_params = ScoreParams::default();
    let (mut seconds, mut slice_s, mut json) = (0.5, 0.03, false);
    let mut presets = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seconds" => seconds = value(&mut args, &a)?,
            "--slice-ms" => slice_s = value::<f64>(&mut args, &a)? * 1e-3,
            "--radius" => params.radius = value(&mut args, &a)?,
            "--dt-min-ms" => params.dt_min_s = value::<f64>(&mut args, &a)? * 1e-3,
            "--dt-max-ms" => params.dt_max_s = value::<f64>(&mut args, &a)? * 1e-3,
            "--min-confidence" => params.min_confidence = value(&mut args, &a)?,
            "--json" => json = true,
            _ => presets.push(a),
        }
    }
    if presets.is_empty() {
        presets = ["one-object", "two-objects", "fast-rotation"]
            .map(String::from)
            .to_vec();
    }
    println!(
        "{params:?}, {seconds} s per preset, slices of {} ms",
        slice_s * 1e3
    );
    for name in &presets {
        let mut sim = Simulator::new(preset(name, 1)?)?;
        let camera = sim.camera_info();
        let mut est = PlaneFitEstimator::new(&camera, params)?;
        let mut scorer = Scorer::new(&camera, score_params);
        let mut t = 0.0;
        while t < seconds - 1e-9 {
            t = (t + slice_s).min(seconds);
            let chunk = sim.next_chunk(t);
            let flow = est.process(&chunk.events)?;
            scorer.add_slice(&chunk.events, &flow, &chunk.truth)?;
        }
        let s = scorer.summary();
        if json {
            println!("{}", serde_json::json!({ "preset": name, "score": s }));
            continue;
        }
        println!("{name}: {} events", s.all.events);
        for (region, r) in [
            ("all", &s.all),
            ("boundary", &s.boundary),
            ("interior", &s.interior),
        ] {
            println!("  {region:9} {}", r.summary_line());
        }
    }
    Ok(())
}
