//! Measures the planar segmenter on simulator sequences with ideal normal flow.
//!
//! The normal flow is the simulator's true optical flow (pixels/s, converted to normalized
//! units/s through the camera), so `n0` is the flow direction and the normal flow is the full
//! flow: an upper bound on what estimated normal flow can give. The rotation rate is the mean of
//! the slice's simulated (noisy) IMU samples rotated into the camera frame. Foreground =
//! `background == false`, truth = `event_object != 0`; IoU per slice over slices whose truth has
//! object events (the paper's protocol), and pooled over all those slices.
//!
//! `cargo run -p evseg-planar-segmenter --example planar_on_sim -- [preset ...]`
//! (default presets one-object two-objects; env SEED (1), SLICE_MS (30), SECONDS (3)).

use anyhow::Context;
use evseg_geometry::Camera;
use evseg_planar_segmenter::{FitParams, PlanarParams, PlanarSegmenter, Robust};
use evseg_schemas::{CameraInfo, NormalFlow};
use evseg_sim::{SimChunk, Simulator, presets::preset};

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> anyhow::Result<T> {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .map_err(|_| anyhow::anyhow!("{name}={v:?} does not parse")),
        Err(_) => Ok(default),
    }
}

fn omega(cam: &CameraInfo, chunk: &SimChunk) -> Option<[f64; 3]> {
    if chunk.imu.is_empty() {
        return None;
    }
    let mut m = [0.0; 3];
    for s in &chunk.imu {
        for (mi, g) in m.iter_mut().zip(s.gyro) {
            *mi += g / chunk.imu.len() as f64;
        }
    }
    let r = cam.imu_to_camera;
    Some([
        r[0] * m[0] + r[1] * m[1] + r[2] * m[2],
        r[3] * m[0] + r[4] * m[1] + r[5] * m[2],
        r[6] * m[0] + r[7] * m[1] + r[8] * m[2],
    ])
}

#[derive(Default)]
struct Score {
    slices: usize,
    iou_sum: f64,
    inter: usize,
    union: usize,
    predicted: usize,
    truth: usize,
    events: usize,
}

fn main() -> anyhow::Result<()> {
    let mut names: Vec<String> = std::env::args().skip(1).collect();
    if names.is_empty() {
        names = vec!["one-object".into(), "two-objects".into()];
    }
    let seed: u64 = env_or("SEED", 1)?;
    let slice_s = env_or("SLICE_MS", 30.0)? * 1e-3;
    let seconds: f64 = env_or("SECONDS", 3.0)?;
    let variants = [
        ("least_squares", Robust::LeastSquares),
        ("huber", Robust::Huber { k: 1.345 }),
        ("tukey", Robust::Tukey { c: 4.685 }),
    ];
    for name in &names {
        let mut sim = Simulator::new(preset(name, seed)?).with_context(|| format!("preset {name}"))?;
        let info = sim.camera_info();
        let cam = Camera::new(&info);
        let mut segs: Vec<PlanarSegmenter> = variants
            .iter()
            .map(|(_, r)| {
                PlanarSegmenter::new(PlanarParams {
                    fit: FitParams {
                        robust: *r,
                        ..Default::default()
                    },
                    ..Default::default()
                })
            })
            .collect::<Result<_, _>>()?;
        let mut scores: Vec<Score> = variants.iter().map(|_| Score::default()).collect();
        let mut k = 1;
        while !sim.is_finished() && sim.time() < seconds {
            let chunk = sim.next_chunk(k as f64 * slice_s);
            k += 1;
            let ev = &chunk.events;
            let truth = &chunk.truth;
            anyhow::ensure!(truth.flow_x.len() == ev.len(), "simulator truth without flow");
            let mut flow = NormalFlow::default();
            for i in 0..ev.len() {
                let f = cam.pixel_flow_to_normalized(
                    f64::from(ev.x[i]),
                    f64::from(ev.y[i]),
                    f64::from(truth.flow_x[i]),
                    f64::from(truth.flow_y[i]),
                );
                flow.nx.push(f[0] as f32);
                flow.ny.push(f[1] as f32);
                flow.confidence.push(1.0);
            }
            let objects = truth.event_object.iter().filter(|&&o| o != 0).count();
            if objects == 0 {
                continue;
            }
            let w = omega(&info, &chunk);
            for (seg, score) in segs.iter_mut().zip(scores.iter_mut()) {
                let r = seg.segment(&info, ev, &flow, w.map(Into::into))?;
                let (mut inter, mut union) = (0, 0);
                for (bg, obj) in r.residuals.background.iter().zip(&truth.event_object) {
                    let (p, t) = (!bg, *obj != 0);
                    inter += usize::from(p && t);
                    union += usize::from(p || t);
                    score.predicted += usize::from(p);
                    score.truth += usize::from(t);
                }
                score.slices += 1;
                score.iou_sum += inter as f64 / union.max(1) as f64;
                score.inter += inter;
                score.union += union;
                score.events += ev.len();
            }
        }
        for ((v, _), s) in variants.iter().zip(&scores) {
            println!(
                "{name:12} seed {seed} {v:14} slices with objects {:4}  mean IoU {:.3}  pooled IoU {:.3}  \
                 precision {:.3}  recall {:.3}  events/slice {:.0}",
                s.slices,
                s.iou_sum / s.slices.max(1) as f64,
                s.inter as f64 / s.union.max(1) as f64,
                s.inter as f64 / s.predicted.max(1) as f64,
                s.inter as f64 / s.truth.max(1) as f64,
                s.events as f64 / s.slices.max(1) as f64
            );
        }
    }
    Ok(())
}
