//! Diagnoses the length (speed) error of the plane-fit normal flow on simulator presets: the
//! relative error `e = |p| / (u . n0) - 1` (pixel units, `n0 = p / |p|`, `u` the true flow) of
//! background events with a valid estimate, binned by the true normal speed, confidence, inliers,
//! points, polarity, the plane's offset at the event's own pixel, the time since the previous
//! same-polarity event at the pixel, and the direction of `n0` to the pixel grid.
//!
//! `cargo run --release -p evseg-normal-flow --example length_error -- [options] [presets...]`
//! Options: `--seconds S` (default 1), `--seed N` (1), `--radius R`, `--outlier-ms X`,
//! `--min-confidence C`, `--dt-max-ms X`, `--lookahead-ms X`.

use std::collections::BTreeMap;

use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams};
use evseg_sim::{Simulator, preset};

fn value<T: std::str::FromStr>(args: &mut impl Iterator<Item = String>, flag: &str) -> Result<T, String> {
    let v = args.next().ok_or(format!("{flag} needs a value"))?;
    v.parse().map_err(|_| format!("{flag}: cannot parse '{v}'"))
}

#[derive(Default)]
struct Bins {
    /// bin label -> relative errors
    bins: BTreeMap<(usize, String), Vec<f64>>,
}

impl Bins {
    fn add(&mut self, order: usize, label: String, e: f64) {
        self.bins.entry((order, label)).or_default().push(e);
    }
    fn print(&mut self, title: &str) {
        let total: f64 = self.bins.values().flatten().map(|x| x.abs()).sum();
        println!("  {title}: bin | n | median e | median |e| | p90 |e| | share of sum |e|");
        for ((_, label), v) in &mut self.bins {
            let mut a: Vec<f64> = v.iter().map(|x| x.abs()).collect();
            v.sort_by(f64::total_cmp);
            a.sort_by(f64::total_cmp);
            let n = v.len();
            println!(
                "    {label:>14} | {n:7} | {:+.3} | {:.3} | {:.3} | {:.3}",
                v[n / 2],
                a[n / 2],
                a[n * 9 / 10],
                a.iter().sum::<f64>() / total
            );
        }
    }
}

fn bin_of(x: f64, edges: &[f64]) -> (usize, String) {
    let k = edges.iter().take_while(|&&e| x >= e).count();
    let lo = if k == 0 { f64::NEG_INFINITY } else { edges[k - 1] };
    let hi = edges.get(k).copied().unwrap_or(f64::INFINITY);
    (k, format!("[{lo}, {hi})"))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut params = PlaneFitParams::default();
    let (mut seconds, mut seed) = (1.0f64, 1u64);
    let mut presets = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seconds" => seconds = value(&mut args, &a)?,
            "--seed" => seed = value(&mut args, &a)?,
            "--radius" => params.radius = value(&mut args, &a)?,
            "--dt-max-ms" => params.dt_max_s = value::<f64>(&mut args, &a)? * 1e-3,
            "--min-confidence" => params.min_confidence = value(&mut args, &a)?,
            "--max-direction-sd-deg" => {
                params.max_direction_sd_rad = value::<f64>(&mut args, &a)?.to_radians()
            }
            "--lookahead-ms" => params.lookahead_s = value::<f64>(&mut args, &a)? * 1e-3,
            "--outlier-ms" => params.outlier_s = value::<f64>(&mut args, &a)? * 1e-3,
            _ => presets.push(a),
        }
    }
    if presets.is_empty() {
        presets = ["one-object", "two-objects", "camera-only"]
            .map(String::from)
            .to_vec();
    }
    println!("{params:?}; seed {seed}, {seconds} s");
    for name in &presets {
        let mut sim = Simulator::new(preset(name, seed)?)?;
        let camera = sim.camera_info();
        let (w, h) = (usize::from(camera.width), usize::from(camera.height));
        let mut est = PlaneFitEstimator::new(&camera, params)?;
        let mut prev = [vec![f64::NEG_INFINITY; w * h], vec![f64::NEG_INFINITY; w * h]];
        let (mut speed, mut conf, mut inl, mut pts, mut pol): (Bins, Bins, Bins, Bins, Bins) =
            Default::default();
        let (mut offs, mut gap, mut grid, mut outl): (Bins, Bins, Bins, Bins) = Default::default();
        let mut since_start = Bins::default();
        // Absolute length errors |p| - u . n0 (px/s), by the angle between n0 and u and by the
        // fit's direction standard deviation.
        let (mut abs_angle, mut abs_dsd, mut rel_dsd): (Bins, Bins, Bins) = Default::default();
        let mut all = Vec::new();
        let mut per_pixel: Vec<(f64, f64, u32)> = vec![(0.0, 0.0, 0); w * h];
        let mut t = 0.0f64;
        while t < seconds - 1e-9 {
            t = (t + 0.03).min(seconds);
            let chunk = sim.next_chunk(t);
            let (ev, truth) = (&chunk.events, &chunk.truth);
            if truth.flow_x.len() != ev.len() || truth.event_object.len() != ev.len() {
                continue;
            }
            let fits = est.process_with_fits(ev)?;
            for (i, &(e, fit)) in fits.iter().enumerate() {
                let (x, y, p) = (
                    usize::from(ev.x[i]),
                    usize::from(ev.y[i]),
                    usize::from(ev.p[i] != 0),
                );
                let idx = y * w + x;
                let last = std::mem::replace(&mut prev[p][idx], ev.t[i]);
                if e.confidence <= 0.0 || truth.event_object[i] != 0 {
                    continue;
                }
                let Some(fit) = fit else { continue };
                let [px, py] = e.flow_px;
                let s_est = px.hypot(py);
                let n0 = [px / s_est, py / s_est];
                let u = [f64::from(truth.flow_x[i]), f64::from(truth.flow_y[i])];
                let s_true = u[0] * n0[0] + u[1] * n0[1];
                if s_true <= 0.0 {
                    continue;
                }
                let rel = s_est / s_true - 1.0;
                let abs_err = s_est - s_true;
                let un = u[0].hypot(u[1]);
                let k = bin_of(
                    (s_true / un).clamp(-1.0, 1.0).acos().to_degrees(),
                    &[30.0, 50.0, 65.0, 75.0, 85.0],
                );
                abs_angle.add(k.0, k.1, abs_err);
                let k = bin_of(fit.direction_sd_rad.to_degrees(), &[1.0, 2.0, 4.0, 8.0, 16.0]);
                abs_dsd.add(k.0, k.1.clone(), abs_err);
                rel_dsd.add(k.0, k.1, rel);
                all.push(rel);
                let pp = &mut per_pixel[idx];
                pp.0 += rel;
                pp.1 += rel * rel;
                pp.2 += 1;
                let sp = bin_of(s_true, &[25.0, 50.0, 100.0, 200.0, 400.0, 800.0]);
                speed.add(sp.0, sp.1, rel);
                let c = bin_of(e.confidence, &[0.6, 0.7, 0.8, 0.9, 0.95]);
                conf.add(c.0, c.1, rel);
                let k = bin_of(fit.inliers as f64, &[6.0, 9.0, 12.0, 15.0, 18.0, 21.0]);
                inl.add(k.0, k.1, rel);
                let k = bin_of(fit.points as f64, &[6.0, 9.0, 12.0, 15.0, 18.0, 21.0]);
                pts.add(k.0, k.1, rel);
                let k = bin_of((fit.points - fit.inliers) as f64, &[1.0, 2.0, 3.0, 5.0, 8.0]);
                outl.add(k.0, k.1, rel);
                pol.add(p, if p == 1 { "ON".into() } else { "OFF".into() }, rel);
                // Plane time at the own pixel, in pixels of travel (positive: the plane says the
                // edge reached the pixel after the event).
                let k = bin_of(fit.c * s_true, &[-1.0, -0.5, -0.2, -0.05, 0.05, 0.2, 0.5, 1.0]);
                offs.add(k.0, k.1, rel);
                // Time since the previous same-polarity event at the pixel, in pixels of travel.
                let k = bin_of((ev.t[i] - last) * s_true, &[0.1, 0.3, 1.0, 3.0, 10.0]);
                gap.add(k.0, k.1, rel);
                let ang = n0[1].atan2(n0[0]).to_degrees().rem_euclid(90.0);
                let ang = ang.min(90.0 - ang);
                let k = bin_of(ang, &[5.0, 15.0, 25.0, 35.0]);
                grid.add(k.0, k.1, rel);
                let k = bin_of(ev.t[i] * 1e3, &[10.0, 20.0, 30.0, 60.0, 100.0, 200.0, 500.0]);
                since_start.add(k.0, k.1, rel);
            }
        }
        all.sort_by(f64::total_cmp);
        let n = all.len();
        let mean = all.iter().sum::<f64>() / n.max(1) as f64;
        let var = all.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / n.max(1) as f64;
        // Share of the variance explained by a per-pixel mean (pixels with >= 5 events).
        let (mut between, mut within, mut m) = (0.0, 0.0, 0usize);
        for &(s, ss, c) in &per_pixel {
            if c >= 5 {
                let c = f64::from(c);
                let mu = s / c;
                between += c * (mu - mean).powi(2);
                within += ss - c * mu * mu;
                m += c as usize;
            }
        }
        println!(
            "{name}: {n} bg events, e median {:+.3}, mean {:+.3}, sd {:.3}; pixels with >=5 events: {m} events, per-pixel mean explains {:.2} of the variance (within sd {:.3})",
            all[n / 2],
            mean,
            var.sqrt(),
            between / (between + within),
            (within / m.max(1) as f64).sqrt()
        );
        speed.print("true normal speed px/s");
        conf.print("confidence");
        inl.print("inliers");
        pts.print("points");
        outl.print("rejected points");
        pol.print("polarity");
        offs.print("plane offset at own pixel, px of travel");
        gap.print("since previous same-pol event at pixel, px of travel");
        grid.print("n0 angle to pixel axes, deg");
        since_start.print("event time since the stream's start, ms");
        abs_angle.print("ABSOLUTE error px/s by angle(n0, u) deg");
        abs_dsd.print("ABSOLUTE error px/s by direction sd deg");
        rel_dsd.print("relative error by direction sd deg");
    }
    Ok(())
}
