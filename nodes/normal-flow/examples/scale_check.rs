//! Measures the plane fit's length error with and without the scale check
//! ([`PlaneFitParams::check_radius`]) on simulator presets, the way the method uses the flow:
//! the error of the normal-flow length along the estimated direction, `| |p| - u . n0 |`,
//! divided by the true flow's speed `|u|` (so an edge nearly parallel to the motion, whose true
//! normal flow is near 0, counts by how far its estimate is off in absolute terms).
//!
//! Background events at pixels that a moving object partly covers at the event's time (one of
//! the renderer's 2 x 2 anti-aliasing sub-samples on the object) are left out: the simulator's
//! truth names the surface at the pixel centre, so those events carry the background's flow
//! while the object's edge caused them (their estimates follow the object).
//!
//! `cargo run --release -p evseg-normal-flow --example scale_check -- [--seconds S] [--seed N]
//! [--check-radius R] [--check-deg D] [--check-speed X] [--skip-confidence C] [--skip-sd-deg D]
//! [presets...]`
//! (defaults 1 s, seed 11, the estimator's check settings; presets one-object fast-rotation
//! high-contrast camera-only). Each preset prints one row without the check and one with it.

use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams};
use evseg_sim::camera::Rays;
use evseg_sim::render::FrameGeom;
use evseg_sim::scene::Scene;
use evseg_sim::{Simulator, preset};

fn value<T: std::str::FromStr>(args: &mut impl Iterator<Item = String>, flag: &str) -> Result<T, String> {
    let v = args.next().ok_or(format!("{flag} needs a value"))?;
    v.parse().map_err(|_| format!("{flag}: cannot parse '{v}'"))
}

/// Sub-sample offsets of the renderer's edge anti-aliasing, pixels.
const SUBSAMPLES: [(f32, f32); 4] = [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)];

/// Length errors over `|u|` of one class of events, and counts.
#[derive(Default)]
struct Class {
    errors: Vec<f64>,
    reversed: usize,
    events: usize,
}

impl Class {
    fn row(&mut self, name: &str) -> String {
        self.errors.sort_by(f64::total_cmp);
        let n = self.errors.len();
        let q = |f: f64| {
            self.errors
                .get((f * n as f64) as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        let over = self.errors.iter().filter(|&&e| e > 0.2).count();
        format!(
            "{name} coverage {:.3}, |e|/|u| median {:.3} q75 {:.3} q90 {:.3}, > 0.2: {:.3}, reversed {:.3}",
            n as f64 / self.events.max(1) as f64,
            q(0.5),
            q(0.75),
            q(0.9),
            over as f64 / n.max(1) as f64,
            self.reversed as f64 / n.max(1) as f64
        )
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut checked = PlaneFitParams {
        min_confidence: 0.0,
        max_direction_sd_rad: 16f64.to_radians(),
        ..PlaneFitParams::default()
    };
    if checked.check_radius == 0 {
        checked.check_radius = checked.radius + 1;
    }
    let (mut seconds, mut seed) = (1.0f64, 11u64);
    let mut presets = Vec::new();
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--seconds" => seconds = value(&mut args, &a)?,
            "--seed" => seed = value(&mut args, &a)?,
            "--check-radius" => checked.check_radius = value(&mut args, &a)?,
            "--check-deg" => checked.check_max_angle_rad = value::<f64>(&mut args, &a)?.to_radians(),
            "--check-speed" => checked.check_max_speed_diff = value(&mut args, &a)?,
            "--skip-confidence" => checked.check_skip_confidence = value(&mut args, &a)?,
            "--skip-sd-deg" => {
                checked.check_skip_direction_sd_rad = value::<f64>(&mut args, &a)?.to_radians()
            }
            _ => presets.push(a),
        }
    }
    if presets.is_empty() {
        presets = ["one-object", "fast-rotation", "high-contrast", "camera-only"]
            .map(String::from)
            .to_vec();
    }
    let unchecked = PlaneFitParams {
        check_radius: 0,
        ..checked
    };
    println!(
        "seed {seed}, {seconds} s; check radius {}, {:.1} deg, {:.2}",
        checked.check_radius,
        checked.check_max_angle_rad.to_degrees(),
        checked.check_max_speed_diff
    );
    for name in &presets {
        for (label, params) in [("no check", unchecked), ("check", checked)] {
            let cfg = preset(name, seed)?;
            let scene = Scene::of_config(&cfg);
            let rays = Rays::new(&cfg.camera);
            let mut sim = Simulator::new(cfg.clone())?;
            let mut est = PlaneFitEstimator::new(&sim.camera_info(), params)?;
            let (mut bg, mut obj, mut edge) = (Class::default(), Class::default(), 0usize);
            let mut t = 0.0;
            while t < seconds - 1e-9 {
                t = (t + 0.03).min(seconds);
                let chunk = sim.next_chunk(t);
                let (ev, truth) = (&chunk.events, &chunk.truth);
                if truth.flow_x.len() != ev.len() || truth.event_object.len() != ev.len() {
                    continue;
                }
                let flow = est.process_pixels(ev)?;
                // Scene geometry at 0.5 ms resolution, built when a background event needs it.
                let mut geom: Option<(i64, FrameGeom)> = None;
                for (i, estimate) in flow.iter().enumerate() {
                    let on_object = truth.event_object[i] != 0;
                    let class = if on_object { &mut obj } else { &mut bg };
                    class.events += 1;
                    if estimate.confidence <= 0.0 {
                        continue;
                    }
                    if !on_object {
                        let bin = (ev.t[i] / 5e-4) as i64;
                        if geom.as_ref().is_none_or(|g| g.0 != bin) {
                            geom = Some((
                                bin,
                                FrameGeom::new(&scene, &cfg.camera, (bin as f64 + 0.5) * 5e-4),
                            ));
                        }
                        let Some((_, g)) = geom.as_ref() else { continue };
                        let (u, v) = (i32::from(ev.x[i]), i32::from(ev.y[i]));
                        let near = g
                            .object_bboxes()
                            .any(|(_, b)| u >= b[0] - 1 && u <= b[2] + 1 && v >= b[1] - 1 && v <= b[3] + 1);
                        if near {
                            let k = v as usize * rays.width + u as usize;
                            let (x, y, du, dv) = (rays.x[k], rays.y[k], rays.d_du[k], rays.d_dv[k]);
                            let partly = SUBSAMPLES.iter().any(|(ou, ov)| {
                                g.locate(
                                    x + ou * du[0] + ov * dv[0],
                                    y + ou * du[1] + ov * dv[1],
                                    u,
                                    v,
                                    None,
                                )
                                .id != 0
                            });
                            if partly {
                                edge += 1;
                                class.events -= 1;
                                continue;
                            }
                        }
                    }
                    let [px, py] = estimate.flow_px;
                    let s = px.hypot(py);
                    let (ux, uy) = (f64::from(truth.flow_x[i]), f64::from(truth.flow_y[i]));
                    let speed = ux.hypot(uy);
                    if speed < 1.0 || s <= 0.0 {
                        continue;
                    }
                    let along = (ux * px + uy * py) / s;
                    class.errors.push((s - along).abs() / speed);
                    class.reversed += usize::from(along < 0.0);
                }
            }
            println!(
                "{name:14} {label:8}: {} | {} | object-edge events left out {edge}",
                bg.row("background"),
                obj.row("objects")
            );
        }
    }
    Ok(())
}
