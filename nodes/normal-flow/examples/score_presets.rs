//! Runs the plane-fit estimator and the learned estimator on the same slices of simulator presets,
//! scores both against the true flow and prints them side by side.
//!
//! `cargo run --release -p evseg-normal-flow --example score_presets -- [options] [presets...]`
//! Options: `--seconds S` (default 0.5), `--slice-ms M` (default 30), `--seed N` scene seed
//! (default 1), `--radius R`, `--dt-min-ms X`, `--dt-max-ms X`, `--min-confidence C` (plane
//! fit's, default 0.5), `--learned FILE` (default nodes/normal-flow/weights/learned.bin; `none`
//! for the plane fit only), `--ensemble K` (learned, default 1), `--learned-min-confidence C`
//! (learned, default 0.7), `--lookahead-across-slices B` (plane fit, `true` by default as in
//! the node: each slice's look-ahead reaches into the next slice; `false` fits each slice on its
//! own), `--json` (one JSON line per preset and estimator).
//! Default presets: one-object, two-objects, fast-rotation.

use evseg_normal_flow::{
    LearnedEstimator, LearnedParams, LearnedWeights, PlaneFitEstimator, PlaneFitParams, ScoreParams, Scorer,
};
use evseg_sim::{Simulator, preset};

fn value<T: std::str::FromStr>(args: &mut impl Iterator<Item = String>, flag: &str) -> Result<T, String> {
    let v = args.next().ok_or(format!("{flag} needs a value"))?;
    v.parse().map_err(|_| format!("{flag}: cannot parse '{v}'"))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut params = PlaneFitParams::default();
    let score_params = ScoreParams::default();
    let (mut seconds, mut slice_s, mut json, mut seed) = (0.5, 0.03, false, 1u64);
    let mut learned_path = String::from("nodes/normal-flow/weights/learned.bin");
    let mut lparams = LearnedParams::default();
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
            "--max-direction-sd-deg" => {
                params.max_direction_sd_rad = value::<f64>(&mut args, &a)?.to_radians()
            }
            "--lookahead-ms" => params.lookahead_s = value::<f64>(&mut args, &a)? * 1e-3,
            "--outlier-ms" => params.outlier_s = value::<f64>(&mut args, &a)? * 1e-3,
            "--lookahead-across-slices" => params.lookahead_across_slices = value(&mut args, &a)?,
            "--json" => json = true,
            "--seed" => seed = value(&mut args, &a)?,
            "--learned" => learned_path = value(&mut args, &a)?,
            "--ensemble" => lparams.ensemble = value(&mut args, &a)?,
            "--learned-min-confidence" => lparams.min_confidence = value(&mut args, &a)?,
            _ => presets.push(a),
        }
    }
    if presets.is_empty() {
        presets = ["one-object", "two-objects", "fast-rotation"]
            .map(String::from)
            .to_vec();
    }
    let weights = if learned_path == "none" {
        None
    } else {
        Some(LearnedWeights::load(&learned_path)?)
    };
    println!(
        "plane fit {params:?}; learned {learned_path} {lparams:?}; scene seed {seed}, {seconds} s per preset, slices of {} ms",
        slice_s * 1e3
    );
    for name in &presets {
        let mut sim = Simulator::new(preset(name, seed)?)?;
        let camera = sim.camera_info();
        let mut est = PlaneFitEstimator::new(&camera, params)?;
        let mut learned = match &weights {
            Some(w) => Some(LearnedEstimator::new(&camera, w.clone(), lparams)?),
            None => None,
        };
        let mut scorer = Scorer::new(&camera, score_params);
        let mut scorer_l = Scorer::new(&camera, score_params);
        let mut t = 0.0;
        let (mut time_p, mut time_l) = (0.0, 0.0);
        // The plane fit's slice waiting for the next one (as the node holds it).
        let mut held: Option<evseg_sim::SimChunk> = None;
        let mut flow = evseg_schemas::NormalFlow::default();
        while t < seconds - 1e-9 {
            let t0 = t;
            t = (t + slice_s).min(seconds);
            let chunk = sim.next_chunk(t);
            let clock = std::time::Instant::now();
            if params.lookahead_across_slices {
                if let Some(h) = held.take() {
                    est.process_with_next_into(&h.events, Some(&chunk.events), &mut flow)?;
                    scorer.add_slice(&h.events, &flow, &h.truth)?;
                }
            } else {
                est.process_into(&chunk.events, &mut flow)?;
                scorer.add_slice(&chunk.events, &flow, &chunk.truth)?;
            }
            time_p += clock.elapsed().as_secs_f64();
            if let Some(l) = learned.as_mut() {
                let clock = std::time::Instant::now();
                let flow = l.process(&chunk.events, t0, t)?;
                time_l += clock.elapsed().as_secs_f64();
                scorer_l.add_slice(&chunk.events, &flow, &chunk.truth)?;
            }
            if params.lookahead_across_slices {
                held = Some(chunk);
            }
        }
        if let Some(h) = held.take() {
            let clock = std::time::Instant::now();
            est.process_with_next_into(&h.events, None, &mut flow)?;
            time_p += clock.elapsed().as_secs_f64();
            scorer.add_slice(&h.events, &flow, &h.truth)?;
        }
        let mut rows = vec![("plane-fit", scorer.summary(), time_p)];
        if learned.is_some() {
            rows.push(("learned", scorer_l.summary(), time_l));
        }
        for (estimator, s, secs) in rows {
            if json {
                println!(
                    "{}",
                    serde_json::json!({ "preset": name, "seed": seed, "estimator": estimator, "seconds": secs, "score": s })
                );
                continue;
            }
            println!(
                "{name} {estimator}: {} events, {:.2} M events/s",
                s.all.events,
                s.all.events as f64 / secs.max(1e-9) / 1e6
            );
            for (region, r) in [
                ("all", &s.all),
                ("boundary", &s.boundary),
                ("interior", &s.interior),
            ] {
                println!("  {region:9} {}", r.summary_line());
            }
        }
    }
    Ok(())
}
