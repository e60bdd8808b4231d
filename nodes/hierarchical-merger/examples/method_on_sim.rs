//! Runs the method's stages in one process on simulator scenes and prints foreground IoU and
//! egomotion direction error, for quick parameter studies (the graph and `evseg bench` give the
//! official figures).
//!
//! `cargo run --release -p evseg-hierarchical-merger --example method_on_sim -- [preset ...]`
//! env: SEED (1), SECONDS (2), FLOW (est | ideal; "ideal" puts n0 along the true flow, which
//! makes the SVM degenerate), SET ("name=value,...": background-merger, hierarchical-merger and
//! planar parameters, several variants separated by ';'), VERBOSE (per-slice cluster reports:
//! `[B][*]events:planar/warp/relres/angle`, B = merged into the background, * = most of its
//! events on a true object), DIRS (per-slice direction error of the merger and of the final,
//! and the angle the true and the estimated direction turned since the previous slice), DIRVEC
//! (per slice: span, estimated and true direction, the slice's IMU rate, and the final background's
//! median derotated and rotational normal-flow lengths and sample count, for filter studies), SEGS
//! (per slice: each true object's clustered events in clusters it is the majority of (pure) or
//! not (mixed), and each final segment's events per true object id),
//! FLOW_MIN_CONF (the plane-fit estimator's min_confidence; default 0 as in graph.yaml),
//! NF_MAX_SD_DEG (default 16 as in graph.yaml; "inf" = no test), NF_LOOKAHEAD_MS / NF_RADIUS /
//! NF_DT_MAX_MS / NF_OUTLIER_MS / NF_CHECK_RADIUS / NF_CHECK_DEG / NF_CHECK_SPEED /
//! NF_SKIP_CONF / NF_SKIP_SD_DEG (its other settings), PREV_FINAL (the planar segmenter's
//! feedback is the final labels instead of the background merger's coarse groups that
//! graph.yaml wires; the default was the final labels
//! before 2026-11-27, which scored low-contrast higher than the graph does), CONS
//! ("cell,min_neighbours,max_deviation[,ridge]" of the normal-flow consensus, default as
//! graph.yaml: the node's with `max_deviation` 0.15; "0" = off), DUMP=k (PNG panels of slice
//! k: truth, planar, coarse, final, in /tmp/dump-<scene>.png). It prints the share of
//! normal-flow lengths more than 30 % off the truth. Flow oracles: FLOW=truemag (true length
//! along the estimated direction), with DROPTAIL=x (drop the estimates more than x off instead)
//! or DROPTAIL=-x (only those take the true length).
//! DEBUG_FIT: per slice, how many of the object's and of the background's events lie inside the
//! planar segmenter's previous-foreground mask (whether the mask keeps the object out of the fit).
//! XLA=0: the plane fit's look-ahead stops at the slice's end (the node's
//! `lookahead_across_slices: false`).
//! WIDE=0: the final egomotion takes the same flow as the segmentation, not the flow node's
//! wide flow that graph.yaml wires to it; WIDE_RADIUS / WIDE_CHECK_RADIUS / WIDE_MIN_SPEED (px/s) / WIDE_REFITS
//! set the wide fit (`evseg_normal_flow::WideFitParams`); WIDE_ALL=1 feeds the wide flow to
//! every stage (a study: the segmentation loses).
//! TQ_MS: event times floored to multiples of this many ms (frame-stamped simulators).
//! SLICE_MS: the slice length (default 30 ms, as graph.yaml). SIM_SET: the simulator's sensor,
//! IMU and texture settings (see `sim_override`).
//! OVERSEG_K / OVERSEG_LAMBDA: the over-segmentation's cluster count and flow weight.
//! FP_DIST: per scene, the final labels' false positives by their distance to the nearest true
//! object event and false negatives by their distance to the nearest predicted foreground event
//! (chessboard distance in cells of FP_CELL pixels, default 4), and quartiles of event time,
//! planar and coarse residuals (absolute and relative to the normal-flow length) for true
//! positives, false positives in an object's cell and the other false positives.
//! SPLIT_STATS: per slice, the planar 2-means split's figures (object share, planar and final
//! foreground share, centres and their ratio, between-class variance share, Ashman's D).
//! Scenes with windows without a moving object also print the share of those windows' events
//! labelled moving (final and planar), the evaluator's false-alarm figure.
//! FILL_STATS: per scene, final and planar labels' true/false positives and misses split into
//! events with a coarse group and events without (labelled by the hierarchical merger's fill),
//! and the events without a group the fill called background by whether any grouped event lay
//! in their 3x3 cells. FILL_PLANAR (diagnostic; replaces the final labels of events without a
//! group): 1 = those with no grouped event in their 3x3 cells take the planar label, 2 = all of
//! them do, 3 = as 1, and the others stay foreground only where the planar label agrees.
//! STAGE_TIMES: per scene, the seconds spent in the over-segmentation, the planar segmenter,
//! the background merger and the hierarchical merger (wall time of each call, one thread).
//! ORACLE_FIT: the plane fitted to the true background's events only (instead of leaving out
//! the previous slice's foreground).
//! Diagnostics that replace the final labels: ORACLE_GROUPED (every event with a coarse group
//! takes its truth, 1 = moving, and the others the hierarchical merger's fill from them: the
//! fill's ceiling), ORACLE_CLUSTERS (each cluster labelled by its
//! ground-truth majority: the over-segmentation's ceiling), ORACLE_T=ratio (a cluster is
//! background when the true camera translation explains it with a depth of its own).

use anyhow::{Context, bail};
use evseg_background_merger::{BackgroundMerger, BackgroundParams, SliceInput};
use evseg_geometry::Camera;
use evseg_geometry::rigid::{self, dot};
use evseg_hierarchical_merger::{HierParams, HierarchicalMerger};
use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams, WideFitParams};
use evseg_oversegmenter::{OversegParams, Oversegmenter};
use evseg_planar_segmenter::{PlanarParams, PlanarSegmenter};
use evseg_schemas::{NormalFlow, Slice, Truth};
use evseg_slicer::{Slicer, SlicerParams};
use evseg_source::EventSource;
use evseg_source::synthetic::SyntheticSource;

/// Per group key (`None` = the event belongs to no group), the events per true object id of
/// `object` (0 = background), for the SEGS diagnostic.
fn events_per_object<K: Ord>(
    keys: impl Iterator<Item = Option<K>>,
    object: &[u16],
) -> std::collections::BTreeMap<K, std::collections::BTreeMap<u16, usize>> {
    let mut out: std::collections::BTreeMap<K, std::collections::BTreeMap<u16, usize>> = Default::default();
    for (k, &o) in keys.zip(object) {
        if let Some(k) = k {
            *out.entry(k).or_default().entry(o).or_default() += 1;
        }
    }
    out
}

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> anyhow::Result<T> {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .map_err(|_| anyhow::anyhow!("{name}={v:?} does not parse")),
        Err(_) => Ok(default),
    }
}

/// The `name=value` pairs of a comma-separated list read from the variable `var` (empty
/// entries skipped, names trimmed, values numbers).
fn settings<'a>(set: &'a str, var: &str) -> anyhow::Result<Vec<(&'a str, f64)>> {
    set.split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|kv| {
            let (k, v) = kv
                .split_once('=')
                .with_context(|| format!("{var} entries are name=value, got {kv:?}"))?;
            let f: f64 = v.trim().parse().with_context(|| format!("{var}: {kv}"))?;
            Ok((k.trim(), f))
        })
        .collect()
}

fn apply(
    set: &str,
    bg: &mut BackgroundParams,
    hier: &mut HierParams,
    planar: &mut PlanarParams,
) -> anyhow::Result<()> {
    for (k, f) in settings(set, "SET")? {
        match k {
            "warp_weight" => bg.warp_weight = f,
            "warp_weight_moving" => bg.warp_weight_moving = f,
            "moving_relres" => bg.moving_relres = f,
            "candidate_threshold" => bg.candidate_threshold = f,
            "consistency_ratio" => bg.consistency_ratio = f,
            "consistency_floor" => bg.consistency_floor = f,
            "max_flow_angle" => bg.max_flow_angle_deg = f,
            "flow_min_spread" => bg.flow_direction_min_spread = f,
            "flow_weighting" => bg.flow_direction_magnitude_weighting = f != 0.0,
            "refine_rounds" => bg.refine_rounds = f as usize,
            "hypotheses" => bg.hypotheses = f != 0.0,
            "ego_density" => {
                bg.egomotion.density_cell_px = f as u16;
                hier.egomotion.density_cell_px = f as u16;
            }
            "refine_iterations" => {
                bg.egomotion.refine_iterations = f as usize;
                hier.egomotion.refine_iterations = f as usize;
            }
            "ego_min_conf" => {
                bg.egomotion.min_confidence = f as f32;
                hier.egomotion.min_confidence = f as f32;
            }
            "magnitude_weighting" => {
                bg.egomotion.magnitude_weighting = f != 0.0;
                hier.egomotion.magnitude_weighting = f != 0.0;
            }
            "huber_k" => {
                bg.egomotion.huber_k = f;
                hier.egomotion.huber_k = f;
            }
            "depth_memory" => hier.egomotion.depth_memory = f,
            "depth_memory_ramp" => hier.egomotion.depth_memory_ramp_slices = f as u32,
            "depth_memory_restart_ratio" => hier.egomotion.depth_memory_restart_ratio = f,
            // The final egomotion's settings alone (the hierarchical merger's `egomotion`).
            "final_huber_k" => hier.egomotion.huber_k = f,
            "final_min_conf" => hier.egomotion.min_confidence = f as f32,
            "final_clear_px" => hier.egomotion.clear_px = f as u16,
            "final_min_cell_samples" => hier.egomotion.min_cell_samples = f as usize,
            "final_max_samples" => hier.egomotion.max_samples = f as usize,
            "final_refine_iterations" => hier.egomotion.refine_iterations = f as usize,
            "grid_cols" => {
                bg.egomotion.grid_cols = f as usize;
                hier.egomotion.grid_cols = f as usize;
            }
            "prior_floor" => bg.prior_floor = f,
            "hypothesis_max_samples" => bg.hypothesis_max_samples = f as usize,
            "hypothesis_refine_iterations" => bg.hypothesis_refine_iterations = f as usize,
            "alpha_max" => bg.alpha_max = f,
            "merge_threshold" => hier.merge_threshold = f,
            "fill_cell_px" => hier.fill_cell_px = f as u16,
            "fill_reach" => hier.fill_reach = f as u16,
            "direction_prior_samples" => hier.direction_prior_samples = f,
            "background_penalty" => hier.background_penalty = f,
            "lambda_r" => hier.lambda_r = f,
            "lambda" => hier.lambda = f,
            "min_segment_events" => hier.min_segment_events = f as usize,
            "min_segment_fraction" => hier.min_segment_fraction = f,
            "touch_px" => hier.touch_px = f as f32,
            "sigma_px" => planar.sigma_px = f,
            "planar_min_conf" => planar.min_confidence = f as f32,
            "split_power" => planar.split_power = f,
            "min_center_gap" => planar.min_center_gap = f,
            "density_cell_px" => planar.density_cell_px = f as u16,
            "previous_weight" => planar.previous.weight = f,
            "fit_memory" => planar.fit_memory = f,
            "start_centre_weight" => planar.start_centre_weight = f,
            "robust_needs_previous" => planar.robust_needs_previous = f > 0.0,
            "tukey_fit" => planar.fit.robust = evseg_planar_segmenter::Robust::Tukey { c: f },
            "huber_fit" => {
                planar.fit.robust = if f > 0.0 {
                    evseg_planar_segmenter::Robust::Huber { k: f }
                } else {
                    evseg_planar_segmenter::Robust::LeastSquares
                }
            }
            "previous_dilate_px" => planar.previous.dilate_px = f as u16,
            "previous_cell_px" => planar.previous.cell_px = f as u16,
            "previous_min_free_share" => planar.previous.min_free_share = f,
            "planar_silent_share" => bg.planar_silent_share = f,
            "silent_warp_needs_confirmation" => bg.silent_warp_needs_confirmation = f != 0.0,
            "unconfirmed_silent_slices" => bg.unconfirmed_silent_slices = f as u32,
            "confirmed_silent_slices" => bg.confirmed_silent_slices = f as u32,
            other => bail!("unknown parameter {other}"),
        }
    }
    Ok(())
}

/// Counts false positives by their distance (4 px cells, chessboard) to the nearest true object
/// event, and false negatives by their distance to the nearest predicted foreground event.
fn fp_hist(
    e: &evseg_schemas::Events,
    w: u16,
    h: u16,
    label: &[u32],
    truth: &[u16],
    out: &mut [usize; 10],
) -> Vec<u32> {
    let cs: usize = std::env::var("FP_CELL")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(4);
    let (cols, rows) = (usize::from(w).div_ceil(cs), usize::from(h).div_ceil(cs));
    let dist = |mark: &dyn Fn(usize) -> bool| {
        let mut d = vec![u32::MAX; cols * rows];
        let mut q = std::collections::VecDeque::new();
        for i in 0..e.len() {
            if mark(i) {
                let c = usize::from(e.y[i]) / cs * cols + usize::from(e.x[i]) / cs;
                if d[c] != 0 {
                    d[c] = 0;
                    q.push_back(c);
                }
            }
        }
        while let Some(c) = q.pop_front() {
            let (cx, cy) = ((c % cols) as i64, (c / cols) as i64);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    let (nx, ny) = (cx + dx, cy + dy);
                    if nx >= 0 && ny >= 0 && (nx as usize) < cols && (ny as usize) < rows {
                        let n = ny as usize * cols + nx as usize;
                        if d[n] == u32::MAX {
                            d[n] = d[c] + 1;
                            q.push_back(n);
                        }
                    }
                }
            }
        }
        d
    };
    let bucket = |d: u32| match d {
        0 => 0,
        1 => 1,
        2..=3 => 2,
        4..=6 => 3,
        _ => 4,
    };
    let dt = dist(&|i| truth[i] != 0);
    let dp = dist(&|i| label[i] != 0);
    for i in 0..e.len() {
        let c = usize::from(e.y[i]) / cs * cols + usize::from(e.x[i]) / cs;
        if label[i] != 0 && truth[i] == 0 {
            out[bucket(dt[c])] += 1;
        }
        if label[i] == 0 && truth[i] != 0 {
            out[5 + bucket(dp[c])] += 1;
        }
    }
    (0..e.len())
        .map(|i| dt[usize::from(e.y[i]) / cs * cols + usize::from(e.x[i]) / cs])
        .collect()
}

fn c_of(c: &evseg_schemas::Clusters, i: usize) -> Option<usize> {
    (c.id[i] != u16::MAX).then(|| usize::from(c.id[i]))
}

fn color(k: u32) -> [u8; 3] {
    if k == 0 {
        return [110, 110, 110];
    }
    let h = k.wrapping_mul(2654435761);
    [(h >> 24) as u8 | 64, (h >> 16) as u8 | 64, (h >> 8) as u8 | 64]
}

/// Four panels: truth (object red), planar foreground (red), coarse groups (0 grey), final labels.
fn dump(
    path: &str,
    s: &Slice,
    truth: &Truth,
    planar_bg: &[bool],
    group: &[u32],
    label: &[u32],
) -> anyhow::Result<()> {
    let (w, h) = (usize::from(s.camera.width), usize::from(s.camera.height));
    let mut img = vec![0u8; 4 * w * h * 3];
    let ev = &s.events;
    for i in 0..ev.len() {
        let (x, y) = (usize::from(ev.x[i]), usize::from(ev.y[i]));
        let cols = [
            if truth.event_object[i] != 0 {
                [255, 60, 60]
            } else {
                [110, 110, 110]
            },
            if planar_bg[i] {
                [110, 110, 110]
            } else {
                [255, 60, 60]
            },
            if group[i] == u32::MAX {
                [40, 40, 200]
            } else {
                color(group[i])
            },
            color(label[i]),
        ];
        for (p, c) in cols.iter().enumerate() {
            let off = ((y * 4 * w) + p * w + x) * 3;
            img[off..off + 3].copy_from_slice(c);
        }
    }
    let file = std::fs::File::create(path)?;
    let mut enc = png::Encoder::new(std::io::BufWriter::new(file), (4 * w) as u32, h as u32);
    enc.set_color(png::ColorType::Rgb);
    enc.write_header()?.write_image_data(&img)?;
    Ok(())
}

fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
    (rigid::dot(a, b) / (rigid::norm(a) * rigid::norm(b)))
        .clamp(-1.0, 1.0)
        .acos()
        .to_degrees()
}

/// SPLIT_STATS: per slice, the object share, the planar foreground share and separation
/// figures of the 2-means on the square roots of the smoothed residuals.
fn split_stats(r: &evseg_planar_segmenter::PlanarResult, truth: &Truth, label: &[u32], t: f64) {
    let v: Vec<f64> = r
        .smoothed
        .iter()
        .zip(&r.residuals.residual)
        .filter(|(s, res)| s.is_finite() && res.is_finite())
        .map(|(s, _)| f64::from(*s).max(1e-6).sqrt())
        .collect();
    let Some(sp) = r.split else { return };
    let thr = sp.threshold.sqrt();
    let (mut s, mut q, mut n) = ([0.0; 2], [0.0; 2], [0usize; 2]);
    for &x in &v {
        let k = usize::from(x > thr);
        s[k] += x;
        q[k] += x * x;
        n[k] += 1;
    }
    let m = [s[0] / n[0].max(1) as f64, s[1] / n[1].max(1) as f64];
    let var = [
        q[0] / n[0].max(1) as f64 - m[0] * m[0],
        q[1] / n[1].max(1) as f64 - m[1] * m[1],
    ];
    let all = v.len().max(1) as f64;
    let mt = (s[0] + s[1]) / all;
    let vt = (q[0] + q[1]) / all - mt * mt;
    let w1 = n[1] as f64 / all;
    let between = w1 * (1.0 - w1) * (m[1] - m[0]).powi(2);
    let ashman = std::f64::consts::SQRT_2 * (m[1] - m[0]) / (var[0] + var[1]).max(1e-12).sqrt();
    let obj = truth.event_object.iter().filter(|&&o| o != 0).count() as f64
        / truth.event_object.len().max(1) as f64;
    let fin = label.iter().filter(|&&l| l != 0).count() as f64 / label.len().max(1) as f64;
    println!(
        "  split t {t:.2} object {obj:.2} planar fg {w1:.2} final {fin:.2} centres {:.4} {:.4} ratio {:.2} eta {:.3} D {:.2} sd0/m0 {:.2}",
        sp.centers[0],
        sp.centers[1],
        sp.centers[1] / sp.centers[0].max(1e-9),
        between / vt.max(1e-12),
        ashman,
        var[0].max(0.0).sqrt() / m[0].max(1e-9)
    );
}

fn main() -> anyhow::Result<()> {
    let mut names: Vec<String> = std::env::args().skip(1).collect();
    if names.is_empty() {
        names = vec!["one-object".into(), "two-objects".into()];
    }
    let seed: u64 = env_or("SEED", 1)?;
    let seconds: f64 = env_or("SECONDS", 2.0)?;
    let ideal = env_or("FLOW", String::from("est"))? == "ideal";
    let truemag = env_or("FLOW", String::from("est"))? == "truemag";
    // The consensus as graph.yaml's flow node sets it (its `consensus_max_deviation`).
    let graph_consensus = evseg_normal_flow::ConsensusParams {
        max_deviation: 0.15,
        ..Default::default()
    };
    let cons: Option<evseg_normal_flow::ConsensusParams> = match std::env::var("CONS") {
        Err(_) => Some(graph_consensus),
        Ok(v) => {
            let d = graph_consensus;
            let f: Vec<f64> = v.split(',').filter_map(|x| x.parse().ok()).collect();
            let p = evseg_normal_flow::ConsensusParams {
                cell_px: f.first().map_or(d.cell_px, |&c| c as u16),
                min_neighbours: f.get(1).map_or(d.min_neighbours, |&c| c as usize),
                max_deviation: f.get(2).copied().unwrap_or(d.max_deviation),
                ridge: f.get(3).copied().unwrap_or(d.ridge),
                ..d
            };
            (p.cell_px > 0).then_some(p)
        }
    };
    let mut cstat = (0usize, 0usize);
    let droptail: Option<f64> = std::env::var("DROPTAIL").ok().and_then(|v| v.parse().ok());
    let sets: Vec<String> = env_or("SET", String::new())?
        .split(';')
        .map(str::to_string)
        .collect();
    let sim_set: String = env_or("SIM_SET", String::new())?;
    let window_s = env_or("SLICE_MS", 30.0)? * 1e-3;
    for name in &names {
        let mut config = evseg_sim::preset(name, seed)?;
        config.duration_s = seconds;
        sim_override(&sim_set, &mut config)?;
        let mut src = SyntheticSource::from_config(config)?;
        let camera = src.camera();
        let cam = Camera::new(&camera);
        let mut slicer = Slicer::new(SlicerParams {
            window_s,
            ..SlicerParams::default()
        })?;
        let mut slices: Vec<(Slice, Truth, (f64, f64))> = Vec::new();
        let tq: f64 = env_or("TQ_MS", 0.0f64)? * 1e-3;
        let mut t = 0.0;
        loop {
            t += 0.01;
            let Some(mut b) = src.next_batch(t)? else { break };
            // TQ_MS: event times floored to multiples of this (a simulator that stamps events
            // at frame times).
            if tq > 0.0 {
                for t in &mut b.events.t {
                    *t = (*t / tq).floor() * tq;
                }
            }
            let packet = evseg_schemas::EventPacket {
                camera: camera.clone(),
                events: b.events,
                imu: b.imu,
            };
            for s in slicer.push(packet, b.truth, t)? {
                slices.push((s.slice, s.truth.unwrap_or_default(), (s.t_start, s.t_end)));
            }
        }
        let flow_conf: f64 = env_or("FLOW_MIN_CONF", 0.0)?;
        let wide_default = WideFitParams::default();
        let wide_params = (env_or("WIDE", 1u8)? != 0)
            .then(|| -> anyhow::Result<WideFitParams> {
                Ok(WideFitParams {
                    radius: env_or("WIDE_RADIUS", wide_default.radius)?,
                    check_radius: env_or("WIDE_CHECK_RADIUS", wide_default.check_radius)?,
                    min_speed_px_s: env_or("WIDE_MIN_SPEED", wide_default.min_speed_px_s)?,
                    max_refits: env_or("WIDE_REFITS", wide_default.max_refits)?,
                })
            })
            .transpose()?;
        let est = PlaneFitEstimator::new(
            &camera,
            PlaneFitParams {
                min_confidence: flow_conf,
                lookahead_s: env_or("NF_LOOKAHEAD_MS", PlaneFitParams::default().lookahead_s * 1e3)? * 1e-3,
                radius: env_or("NF_RADIUS", PlaneFitParams::default().radius)?,
                dt_max_s: env_or("NF_DT_MAX_MS", PlaneFitParams::default().dt_max_s * 1e3)? * 1e-3,
                outlier_s: env_or("NF_OUTLIER_MS", PlaneFitParams::default().outlier_s * 1e3)? * 1e-3,
                max_direction_sd_rad: env_or("NF_MAX_SD_DEG", 16.0f64)?.to_radians(),
                check_radius: env_or("NF_CHECK_RADIUS", PlaneFitParams::default().check_radius)?,
                check_max_angle_rad: env_or(
                    "NF_CHECK_DEG",
                    PlaneFitParams::default().check_max_angle_rad.to_degrees(),
                )?
                .to_radians(),
                check_max_speed_diff: env_or(
                    "NF_CHECK_SPEED",
                    PlaneFitParams::default().check_max_speed_diff,
                )?,
                check_skip_confidence: env_or(
                    "NF_SKIP_CONF",
                    PlaneFitParams::default().check_skip_confidence,
                )?,
                check_skip_direction_sd_rad: env_or(
                    "NF_SKIP_SD_DEG",
                    PlaneFitParams::default().check_skip_direction_sd_rad.to_degrees(),
                )?
                .to_radians(),
                ..PlaneFitParams::default()
            },
        )?;
        let mut est = match wide_params {
            Some(w) => est.with_wide_fit(w)?,
            None => est,
        };
        // The simulator's optical flow of event `i`, normalized units/s.
        let true_flow = |s: &Slice, truth: &Truth, i: usize| {
            cam.pixel_flow_to_normalized(
                f64::from(s.events.x[i]),
                f64::from(s.events.y[i]),
                f64::from(truth.flow_x[i]),
                f64::from(truth.flow_y[i]),
            )
        };
        // The look-ahead reaches into the next slice as the node's default does
        // (`lookahead_across_slices`); XLA=0 fits each slice on its own.
        let across = env_or("XLA", u8::from(est.params().lookahead_across_slices))? != 0;
        // Each slice's flow and, with the wide fit on, its wide flow (the flow oracles have none).
        let flows: Vec<(NormalFlow, Option<NormalFlow>)> = slices
            .iter()
            .enumerate()
            .map(|(k, (s, truth, _))| {
                let fit_slice =
                    |est: &mut PlaneFitEstimator| -> Result<_, evseg_normal_flow::EstimatorError> {
                        let next = slices.get(k + 1).filter(|_| across).map(|(n, _, _)| &n.events);
                        let mut f = NormalFlow::default();
                        let mut wide = est.wide_fit().map(|_| NormalFlow::default());
                        est.process_wide_into(&s.events, next, &mut f, wide.as_mut())?;
                        Ok((f, wide))
                    };
                if ideal {
                    let mut f = NormalFlow::default();
                    for i in 0..s.events.len() {
                        let v = true_flow(s, truth, i);
                        f.nx.push(v[0] as f32);
                        f.ny.push(v[1] as f32);
                        f.confidence.push(1.0);
                    }
                    Ok((f, None))
                } else if truemag {
                    let (mut f, _) = fit_slice(&mut est)?;
                    for i in 0..s.events.len() {
                        let (nx, ny) = (f64::from(f.nx[i]), f64::from(f.ny[i]));
                        let len = (nx * nx + ny * ny).sqrt();
                        if !(f.confidence[i] > 0.0 && len > 0.0) {
                            continue;
                        }
                        let v = true_flow(s, truth, i);
                        let (ux, uy) = (nx / len, ny / len);
                        let m = v[0] * ux + v[1] * uy;
                        let e = (len / m - 1.0).abs();
                        let off = |x: f64| e.is_nan() || e > x;
                        match droptail {
                            Some(x) if x < 0.0 => {
                                // Only the lengths more than -x off take the true value.
                                if off(-x) {
                                    f.nx[i] = (m * ux) as f32;
                                    f.ny[i] = (m * uy) as f32;
                                }
                            }
                            Some(x) => {
                                // The lengths more than x off are dropped.
                                if off(x) {
                                    f.confidence[i] = 0.0;
                                    f.nx[i] = 0.0;
                                    f.ny[i] = 0.0;
                                }
                            }
                            None => {
                                f.nx[i] = (m * ux) as f32;
                                f.ny[i] = (m * uy) as f32;
                            }
                        }
                    }
                    Ok((f, None))
                } else if let Some(cp) = cons {
                    let (mut f, mut wide) = fit_slice(&mut est)?;
                    let (w, h) = (s.camera.width, s.camera.height);
                    let st = evseg_normal_flow::consensus(&s.events, &mut f, w, h, &cp);
                    cstat.0 += st.valid;
                    cstat.1 += st.replaced;
                    if let Some(wide) = wide.as_mut() {
                        evseg_normal_flow::consensus(&s.events, wide, w, h, &cp);
                    }
                    Ok((f, wide))
                } else {
                    fit_slice(&mut est)
                }
            })
            .collect::<Result<_, _>>()?;
        if cons.is_some() {
            println!("consensus: replaced {} of {} valid", cstat.1, cstat.0);
        }
        let st = est.stats();
        if est.wide_fit().is_some() {
            println!(
                "wide fit: {} of {} valid estimates ({} events) refitted, {} valid; scale check rejected {}",
                st.wide_fits, st.valid, st.events, st.wide_valid, st.disagreed
            );
        }
        // WIDE_ALL: the wide flow for every stage, not only the final egomotion.
        let (flows, wide_flows): (Vec<NormalFlow>, Vec<Option<NormalFlow>>) = flows
            .into_iter()
            .map(|(f, wide)| match wide {
                Some(w) if std::env::var_os("WIDE_ALL").is_some() => (w, None),
                other => (f, other),
            })
            .unzip();
        if std::env::var_os("CELLS").is_some() {
            print_cell_extent(&slices, &flows, camera.width, camera.height);
        }
        {
            // Tail census of the normal-flow lengths against the truth: share of valid estimates
            // with |len / (u . n0) - 1| > 0.3, background and objects, and of those the share
            // with the wrong sign.
            let mut c = [[0usize; 2]; 2];
            let mut wrong_sign = 0usize;
            let mut body: Vec<f64> = Vec::new();
            for ((s, truth, _), f) in slices.iter().zip(&flows) {
                for i in 0..s.events.len() {
                    let (nx, ny) = (f64::from(f.nx[i]), f64::from(f.ny[i]));
                    let len = (nx * nx + ny * ny).sqrt();
                    if f.confidence[i] <= 0.0 || len <= 0.0 {
                        continue;
                    }
                    let v = true_flow(s, truth, i);
                    let m = (v[0] * nx + v[1] * ny) / len;
                    let tail = (len / m - 1.0).abs().is_nan() || (len / m - 1.0).abs() > 0.3;
                    c[usize::from(truth.event_object[i] != 0)][usize::from(tail)] += 1;
                    if !tail && truth.event_object[i] == 0 {
                        body.push(len / m - 1.0);
                    }
                    wrong_sign += usize::from(tail && m < 0.0);
                }
            }
            let tails = c[0][1] + c[1][1];
            body.sort_by(f64::total_cmp);
            let q = |f: f64| {
                body.get((f * body.len() as f64) as usize)
                    .copied()
                    .unwrap_or(f64::NAN)
            };
            println!(
                "background body (within 30 %): relative length error quartiles {:+.4} / {:+.4} / {:+.4}",
                q(0.25),
                q(0.5),
                q(0.75)
            );
            println!(
                "length tail (> 30 % off): background {:.3} of {}, objects {:.3} of {}; wrong sign {:.3} of the tail",
                c[0][1] as f64 / (c[0][0] + c[0][1]).max(1) as f64,
                c[0][0] + c[0][1],
                c[1][1] as f64 / (c[1][0] + c[1][1]).max(1) as f64,
                c[1][0] + c[1][1],
                wrong_sign as f64 / tails.max(1) as f64
            );
        }
        {
            let (mut ov, mut on, mut bv, mut bn) = (0usize, 0usize, 0usize, 0usize);
            for ((_, truth, _), f) in slices.iter().zip(&flows) {
                for (o, c) in truth.event_object.iter().zip(&f.confidence) {
                    if *o != 0 {
                        on += 1;
                        ov += usize::from(*c > 0.0);
                    } else {
                        bn += 1;
                        bv += usize::from(*c > 0.0);
                    }
                }
            }
            println!(
                "flow coverage: objects {:.3} of {on}, background {:.3} of {bn}",
                ov as f64 / on.max(1) as f64,
                bv as f64 / bn.max(1) as f64
            );
        }
        let mut overseg = Oversegmenter::new(OversegParams {
            k: env_or("OVERSEG_K", OversegParams::default().k)?,
            lambda: env_or("OVERSEG_LAMBDA", OversegParams::default().lambda)?,
            ..OversegParams::default()
        })?;
        let overseg_start = std::time::Instant::now();
        let clusters: Vec<_> = slices
            .iter()
            .zip(&flows)
            .map(|((s, _, _), f)| overseg.segment(&s.camera, &s.events, f))
            .collect::<Result<_, _>>()?;
        let overseg_s = overseg_start.elapsed().as_secs_f64();
        for set in &sets {
            let (mut bgp, mut hp, mut pp) = (
                BackgroundParams::default(),
                HierParams::default(),
                PlanarParams::default(),
            );
            apply(set, &mut bgp, &mut hp, &mut pp)?;
            let mut planar = PlanarSegmenter::new(pp)?;
            let mut bg = BackgroundMerger::new(bgp)?;
            let mut hier = HierarchicalMerger::new(hp)?;
            let mut prev: Option<Vec<u32>> = None;
            // The previous slice's (true, estimated) translation directions, for DIRS.
            let mut prev_dirs: Option<([f64; 3], [f64; 3])> = None;
            // The planar segmenter's feedback: the background merger's coarse groups (group != 0
            // = foreground), as graph.yaml wires it, or (PREV_FINAL) the final labels.
            let mut prev_planar: Option<Vec<u32>> = None;
            let (mut ious, mut dirs, mut planar_ious) = (Vec::new(), Vec::new(), Vec::new());
            let mut fp_dist = [0usize; 10];
            let mut feat: [Vec<[f64; 5]>; 3] = Default::default();
            let mut coarse_ious = Vec::new();
            let (mut inter_all, mut union_all) = (0usize, 0usize);
            let (mut predicted_all, mut truth_all) = (0usize, 0usize);
            // FILL_STATS: [grouped, ungrouped] x [final, planar] x (tp, fp, fn).
            let mut fill_stats = [[[0usize; 3]; 2]; 2];
            // FILL_STATS: ungrouped events labelled background: [object, background] x [no labelled neighbour, labelled neighbours].
            let mut fill_why = [[0usize; 2]; 2];
            // STAGE_TIMES: seconds in the planar segmenter, background merger, hierarchical merger.
            let mut stage_s = [0.0f64; 3];
            let (mut planar_pred_all, mut planar_inter_all) = (0usize, 0usize);
            // Slices without a moving object: share of events labelled moving (final, planar).
            let mut static_fa: Vec<(f64, f64)> = Vec::new();
            for (dump_k, (((s, truth, span), f), c)) in slices.iter().zip(&flows).zip(&clusters).enumerate() {
                let clusters_k = c.clone();
                let rate =
                    evseg_geometry::RotationRate::of_slice(s, *span, evseg_geometry::rotation::SLOPE_DEFAULT);
                // ORACLE_FIT: the plane fitted to the true background's events only.
                let oracle_fit: Option<Vec<f64>> = std::env::var("ORACLE_FIT").is_ok().then(|| {
                    truth
                        .event_object
                        .iter()
                        .map(|&o| f64::from(u8::from(o == 0)))
                        .collect()
                });
                let clock = std::time::Instant::now();
                let r = match oracle_fit {
                    Some(w) => planar.segment_weighted(&s.camera, &s.events, f, rate, Some(&w))?,
                    None => {
                        planar.segment_with_previous(&s.camera, &s.events, f, rate, prev_planar.as_deref())?
                    }
                };
                stage_s[0] += clock.elapsed().as_secs_f64();
                let debug_mask = match (std::env::var("DEBUG_FIT").is_ok(), prev_planar.as_deref()) {
                    (true, Some(pl)) if dump_k > 0 => {
                        let ps = &slices[dump_k - 1].0;
                        let pp = planar.params().previous;
                        evseg_planar_segmenter::PreviousForeground::new(
                            s.camera.width,
                            s.camera.height,
                            &ps.events.x,
                            &ps.events.y,
                            pl,
                            &pp,
                        )
                    }
                    _ => None,
                };
                if let Some(mask) = debug_mask {
                    let (mut oi, mut on, mut bi, mut bn) = (0usize, 0usize, 0usize, 0usize);
                    for i in 0..s.events.len() {
                        let inside = mask.contains(s.events.x[i], s.events.y[i]);
                        if truth.event_object[i] != 0 {
                            on += 1;
                            oi += usize::from(inside);
                        } else {
                            bn += 1;
                            bi += usize::from(inside);
                        }
                    }
                    eprintln!(
                        "DEBUG slice {dump_k}: applied {} fitted {} object in mask {oi}/{on} bg in mask {bi}/{bn}",
                        r.previous_applied, r.fitted_events
                    );
                }
                let clock = std::time::Instant::now();
                let m = bg.merge(&SliceInput {
                    camera: &s.camera,
                    events: &s.events,
                    span: *span,
                    rate,
                    flow: f,
                    clusters: c,
                    residuals: &r.residuals,
                    previous_labels: prev.as_deref(),
                })?;
                stage_s[1] += clock.elapsed().as_secs_f64();
                let clock = std::time::Instant::now();
                let h = hier.merge_with_egomotion_flow(
                    &s.camera,
                    &s.events,
                    f,
                    wide_flows[dump_k].as_ref(),
                    rate,
                    &m.coarse,
                )?;
                stage_s[2] += clock.elapsed().as_secs_f64();
                let mut oracle_label;
                let mut label = &h.segmentation.label;
                if std::env::var("SEGS").is_ok() {
                    // Per segment (label != 0) and per over-segmentation cluster: events per
                    // true object id (0 = background).
                    let per = events_per_object(
                        h.segmentation.label.iter().copied().map(Some),
                        &truth.event_object,
                    );
                    let by_cluster = events_per_object(
                        c.id.iter().map(|&id| (id != u16::MAX).then_some(id)),
                        &truth.event_object,
                    );
                    // Per true object: its clustered events in clusters whose majority is that
                    // object (pure) or another object or the background (mixed).
                    let mut purity: std::collections::BTreeMap<u16, (usize, usize)> = Default::default();
                    for m in by_cluster.values() {
                        let major = m.iter().max_by_key(|e| *e.1).map(|e| *e.0);
                        for (&o, &n) in m {
                            let e = purity.entry(o).or_default();
                            if Some(o) == major {
                                e.0 += n;
                            } else {
                                e.1 += n;
                            }
                        }
                    }
                    let mut line = format!("  segs t {:.2} clusters (pure, mixed) {purity:?} |", span.0);
                    for (l, m) in &per {
                        line.push_str(&format!(" {l}:{m:?}"));
                    }
                    println!("{line}");
                    // Pairs of final segments with the same majority object: their motion
                    // similarity and whether their boxes touch.
                    let maj: std::collections::BTreeMap<u32, u16> = per
                        .iter()
                        .filter_map(|(l, m)| m.iter().max_by_key(|e| *e.1).map(|e| (*l, *e.0)))
                        .collect();
                    let segs = &h.segmentation.segments;
                    for a in segs.iter().filter(|s| s.label != 0) {
                        for b in segs.iter().filter(|s| s.label > a.label) {
                            let (Some(&ma), Some(&mb)) = (maj.get(&a.label), maj.get(&b.label)) else {
                                continue;
                            };
                            if ma == 0 || mb == 0 {
                                continue;
                            }
                            let sim = evseg_hierarchical_merger::similarity(
                                a.translation,
                                b.translation,
                                0.0,
                                0.0,
                                0.0,
                            );
                            let touch = evseg_hierarchical_merger::boxes_touch(a.bbox, b.bbox, 2.0);
                            println!(
                                "  pair t {:.2} {}{} objs {ma}/{mb} ev {}/{} sim {sim:.3} touch {touch} ta {:.2?} tb {:.2?}",
                                span.0, a.label, b.label, a.events, b.events, a.translation, b.translation
                            );
                        }
                    }
                }
                // FILL_PLANAR=1: ungrouped events without a grouped event in the 3x3 cells of 4 px
                // take the planar label; =2: every ungrouped event does; =3: as 1, and the other
                // ungrouped events are foreground only where the fill and the planar label agree.
                let fill_planar: u32 = env_or("FILL_PLANAR", 0)?;
                let mut planar_filled;
                let grouped_near = (fill_planar > 0 || std::env::var("FILL_STATS").is_ok())
                    .then(|| grouped_neighbours(&s.events, &m.coarse.group, s.camera.width, s.camera.height));
                if let (true, Some(near)) = (fill_planar > 0, &grouped_near) {
                    let fg_id = h
                        .segmentation
                        .segments
                        .iter()
                        .map(|sg| sg.label)
                        .find(|&i| i != 0)
                        .unwrap_or(1);
                    planar_filled = label.clone();
                    for i in 0..s.events.len() {
                        if m.coarse.group[i] != u32::MAX {
                            continue;
                        }
                        let pf = !r.residuals.background[i];
                        if !near[i] || fill_planar == 2 {
                            planar_filled[i] = if pf {
                                if label[i] != 0 { label[i] } else { fg_id }
                            } else {
                                0
                            };
                        } else if fill_planar == 3 && !pf {
                            planar_filled[i] = 0;
                        }
                    }
                    label = &planar_filled;
                }
                if std::env::var("ORACLE_GROUPED").is_ok() {
                    // Events with a group take their truth (1 = moving); the others the fill.
                    let mut l: Vec<u32> = (0..s.events.len())
                        .map(|i| {
                            if m.coarse.group[i] == u32::MAX {
                                evseg_hierarchical_merger::fill::UNLABELLED
                            } else {
                                u32::from(truth.event_object[i] != 0)
                            }
                        })
                        .collect();
                    evseg_hierarchical_merger::fill::fill_unlabelled(
                        &s.events,
                        s.camera.width,
                        s.camera.height,
                        hier.params().fill_cell_px,
                        hier.params().fill_reach,
                        &mut l,
                    );
                    oracle_label = l;
                    label = &oracle_label;
                }
                if std::env::var("ORACLE_CLUSTERS").is_ok() {
                    let k = usize::from(c.count);
                    let mut votes = vec![(0usize, 0usize); k];
                    for (i, &id) in c.id.iter().enumerate() {
                        if id != u16::MAX {
                            votes[usize::from(id)].0 += usize::from(truth.event_object[i] != 0);
                            votes[usize::from(id)].1 += 1;
                        }
                    }
                    oracle_label =
                        c.id.iter()
                            .map(|&id| {
                                if id == u16::MAX {
                                    evseg_hierarchical_merger::fill::UNLABELLED
                                } else {
                                    let (o, a) = votes[usize::from(id)];
                                    u32::from(2 * o > a)
                                }
                            })
                            .collect::<Vec<u32>>();
                    evseg_hierarchical_merger::fill::fill_unlabelled(
                        &s.events,
                        s.camera.width,
                        s.camera.height,
                        4,
                        1,
                        &mut oracle_label,
                    );
                    label = &oracle_label;
                }
                if let (Ok(ratio), Some(v)) = (
                    std::env::var("ORACLE_T").map(|r| r.parse::<f64>().unwrap_or(0.5)),
                    truth.camera.first().and_then(|c| c.linear_velocity),
                ) {
                    // Diagnostic: a cluster is background when the true camera translation
                    // explains it with a positive depth of its own.
                    let mut table = evseg_geometry::TableCache::default();
                    let samples =
                        evseg_geometry::flow_samples(table.get(&s.camera), &s.events, f, rate.as_ref(), 0.0)?;
                    let k = usize::from(c.count);
                    let mut per: Vec<Vec<&evseg_geometry::FlowSample>> = vec![Vec::new(); k];
                    for sm in &samples {
                        if c.id[sm.index] != u16::MAX {
                            per[usize::from(c.id[sm.index])].push(sm);
                        }
                    }
                    let bgc: Vec<bool> = per
                        .iter()
                        .map(|m| {
                            let (mut num, mut den) = (0.0, 0.0);
                            for sm in m {
                                let q = dot(sm.x_row(), v);
                                num += sm.n_derot * q;
                                den += q * q;
                            }
                            let rho = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
                            let (mut r, mut nn) = (0.0, 0.0);
                            for sm in m {
                                r += (sm.n_derot - rho * dot(sm.x_row(), v)).abs();
                                nn += sm.n_derot.abs();
                            }
                            m.is_empty() || r <= ratio * nn
                        })
                        .collect();
                    oracle_label =
                        c.id.iter()
                            .map(|&id| {
                                if id == u16::MAX {
                                    evseg_hierarchical_merger::fill::UNLABELLED
                                } else {
                                    u32::from(!bgc[usize::from(id)])
                                }
                            })
                            .collect::<Vec<u32>>();
                    evseg_hierarchical_merger::fill::fill_unlabelled(
                        &s.events,
                        s.camera.width,
                        s.camera.height,
                        4,
                        1,
                        &mut oracle_label,
                    );
                    label = &oracle_label;
                }
                if let Ok(d) = std::env::var("DUMP")
                    && d.parse::<usize>().ok() == Some(dump_k)
                {
                    dump(
                        &format!("/tmp/dump-{name}.png"),
                        s,
                        truth,
                        &r.residuals.background,
                        &m.coarse.group,
                        label,
                    )?;
                    for st in &h.steps {
                        println!("  merge {st:?}");
                    }
                    for (c, rep) in m.clusters.iter().enumerate() {
                        let obj = s
                            .events
                            .x
                            .iter()
                            .enumerate()
                            .filter(|(i, _)| c_of(&clusters_k, *i) == Some(c) && truth.event_object[*i] != 0)
                            .count();
                        println!("  cluster {c}: {rep:?} object events {obj}");
                    }
                }
                if std::env::var("VERBOSE").is_ok() {
                    let fg = label.iter().filter(|&&l| l != 0).count();
                    let gt = truth.event_object.iter().filter(|&&o| o != 0).count();
                    let mut obj = vec![0usize; m.clusters.len()];
                    for (i, &o) in truth.event_object.iter().enumerate() {
                        if o != 0
                            && let Some(c) = c_of(&clusters_k, i)
                            && c < obj.len()
                        {
                            obj[c] += 1;
                        }
                    }
                    let cl: Vec<String> = m
                        .clusters
                        .iter()
                        .zip(&obj)
                        .map(|(c, &o)| {
                            format!(
                                "{}{}{}:{:.2}/{}/{:.2}/{:.0}",
                                if c.background { "B" } else { "" },
                                if o * 2 > c.events { "*" } else { "" },
                                c.events,
                                c.planar_background,
                                c.warp_score.map_or("-".into(), |w| format!("{w:.2}")),
                                c.relative_residual,
                                c.flow_angle_deg
                            )
                        })
                        .collect();
                    println!(
                        "  t {:.2} events {} fg {} truth {} segs {} merges {} small {} warped {} | {}",
                        span.0,
                        label.len(),
                        fg,
                        gt,
                        h.segmentation.segments.len(),
                        h.merges,
                        h.dropped_small,
                        m.warped,
                        cl.join(" ")
                    );
                }
                if std::env::var("SPLIT_STATS").is_ok() {
                    split_stats(&r, truth, label, span.0);
                }
                if !truth.event_object.iter().any(|&o| o != 0) && !label.is_empty() {
                    let nl = label.len() as f64;
                    static_fa.push((
                        label.iter().filter(|&&l| l != 0).count() as f64 / nl,
                        r.residuals.background.iter().filter(|&&b| !b).count() as f64 / nl,
                    ));
                }
                if truth.event_object.iter().any(|&o| o != 0) {
                    // Diagnostic: the coarse stage alone (group != 0 is foreground).
                    let mut coarse_label: Vec<u32> = m
                        .coarse
                        .group
                        .iter()
                        .map(|&g| {
                            if g == u32::MAX {
                                evseg_hierarchical_merger::fill::UNLABELLED
                            } else {
                                u32::from(g != 0)
                            }
                        })
                        .collect();
                    evseg_hierarchical_merger::fill::fill_unlabelled(
                        &s.events,
                        s.camera.width,
                        s.camera.height,
                        4,
                        1,
                        &mut coarse_label,
                    );
                    let (mut ci, mut cu) = (0usize, 0usize);
                    for (k, l) in coarse_label.iter().enumerate() {
                        let (p, g) = (*l != 0, truth.event_object[k] != 0);
                        ci += usize::from(p && g);
                        cu += usize::from(p || g);
                    }
                    coarse_ious.push(ci as f64 / cu.max(1) as f64);
                    let (mut i, mut u, mut pi, mut pu) = (0, 0, 0, 0);
                    for (k, l) in label.iter().enumerate() {
                        let (p, g) = (*l != 0, truth.event_object[k] != 0);
                        i += usize::from(p && g);
                        u += usize::from(p || g);
                        predicted_all += usize::from(p);
                        truth_all += usize::from(g);
                        let pp = !r.residuals.background[k];
                        let kind = usize::from(m.coarse.group[k] == u32::MAX);
                        if let (1, false, Some(near)) = (kind, p, &grouped_near) {
                            fill_why[usize::from(!g)][usize::from(near[k])] += 1;
                        }
                        for (which, q) in [p, pp].into_iter().enumerate() {
                            let cell = &mut fill_stats[kind][which];
                            cell[0] += usize::from(q && g);
                            cell[1] += usize::from(q && !g);
                            cell[2] += usize::from(!q && g);
                        }
                        pi += usize::from(pp && g);
                        planar_pred_all += usize::from(pp);
                        planar_inter_all += usize::from(pp && g);
                        pu += usize::from(pp || g);
                    }
                    if std::env::var("FP_DIST").is_ok() {
                        let cells = fp_hist(
                            &s.events,
                            s.camera.width,
                            s.camera.height,
                            label,
                            &truth.event_object,
                            &mut fp_dist,
                        );
                        let t0 = span.0;
                        let dur = (span.1 - span.0).max(1e-9);
                        for i in 0..label.len() {
                            if label[i] == 0 {
                                continue;
                            }
                            let kind = if truth.event_object[i] != 0 {
                                0
                            } else if cells[i] == 0 {
                                1
                            } else {
                                2
                            };
                            let tt = (s.events.t[i] - t0) / dur;
                            let pr = r.residuals.residual[i].abs() as f64;
                            let cr = m.coarse.residual[i].abs() as f64;
                            let nl = (f.nx[i] as f64).hypot(f.ny[i] as f64);
                            feat[kind].push([tt, pr, cr, pr / nl.max(1e-9), cr / nl.max(1e-9)]);
                        }
                    }
                    ious.push(i as f64 / u.max(1) as f64);
                    if std::env::var("SLICE_IOU").is_ok() {
                        let g = truth.event_object.iter().filter(|&&o| o != 0).count();
                        let p = label.iter().filter(|&&l| l != 0).count();
                        println!(
                            "  slice t {:.2} iou {:.2} planar {:.2} coarse {:.2} object share {:.2} prec {:.2} rec {:.2}",
                            span.0,
                            i as f64 / u.max(1) as f64,
                            pi as f64 / pu.max(1) as f64,
                            ci as f64 / cu.max(1) as f64,
                            g as f64 / label.len().max(1) as f64,
                            i as f64 / p.max(1) as f64,
                            i as f64 / g.max(1) as f64
                        );
                    }
                    planar_ious.push(pi as f64 / pu.max(1) as f64);
                    inter_all += i;
                    union_all += u;
                }
                let vel: Vec<[f64; 3]> = truth.camera.iter().filter_map(|c| c.linear_velocity).collect();
                if !vel.is_empty() && h.segmentation.egomotion.valid {
                    let mut v = [0.0; 3];
                    for x in &vel {
                        for k in 0..3 {
                            v[k] += x[k];
                        }
                    }
                    if (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt() / vel.len() as f64 > 0.05 {
                        dirs.push(angle_deg(h.segmentation.egomotion.direction, v));
                        let est = h.segmentation.egomotion.direction;
                        if std::env::var("DIRS").is_ok() {
                            let (turn_true, turn_est) = prev_dirs.map_or((f64::NAN, f64::NAN), |(pv, pe)| {
                                (angle_deg(pv, v), angle_deg(pe, est))
                            });
                            println!(
                                "  dir t {:.2} merger {:.1} final {:.1} deg turn true {:.1} est {:.1}",
                                span.0,
                                angle_deg(m.coarse.egomotion.direction, v),
                                angle_deg(est, v),
                                turn_true,
                                turn_est
                            );
                        }
                        if std::env::var("DIRVEC").is_ok() {
                            let w = rate.map_or([f64::NAN; 3], |r| r.mean);
                            // The final background's median derotated and rotational normal-flow
                            // lengths (normalized units/s) and its sample count: how much of its
                            // flow the translation explains.
                            let mut table = evseg_geometry::TableCache::default();
                            let samples = evseg_geometry::flow_samples(
                                table.get(&s.camera),
                                &s.events,
                                f,
                                rate.as_ref(),
                                0.0,
                            )?;
                            let bg: Vec<&evseg_geometry::FlowSample> =
                                samples.iter().filter(|sm| label[sm.index] == 0).collect();
                            let median = |mut v: Vec<f64>| {
                                if v.is_empty() {
                                    return f64::NAN;
                                }
                                let mid = v.len() / 2;
                                *v.select_nth_unstable_by(mid, f64::total_cmp).1
                            };
                            let derot = median(bg.iter().map(|sm| sm.n_derot.abs()).collect());
                            let rot = median(bg.iter().map(|sm| (sm.n - sm.n_derot).abs()).collect());
                            println!(
                                "  dirvec {:.4} {:.4} est {:.6} {:.6} {:.6} true {:.6} {:.6} {:.6} w {:.6} {:.6} {:.6} bg {:.6} {:.6} {}",
                                span.0,
                                span.1,
                                est[0],
                                est[1],
                                est[2],
                                v[0],
                                v[1],
                                v[2],
                                w[0],
                                w[1],
                                w[2],
                                derot,
                                rot,
                                bg.len()
                            );
                        }
                        prev_dirs = Some((v, est));
                    }
                }
                prev = Some(label.clone());
                prev_planar = Some(if std::env::var("PREV_FINAL").is_err() {
                    m.coarse
                        .group
                        .iter()
                        .map(|&g| u32::from(g != 0 && g != evseg_schemas::CoarseSegmentation::UNASSIGNED))
                        .collect()
                } else {
                    label.clone()
                });
            }
            dirs.sort_by(f64::total_cmp);
            let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
            if std::env::var("FP_DIST").is_ok() {
                for (kind, v) in ["TP", "FP0", "FPfar"].iter().zip(feat.iter_mut()) {
                    let mut q = Vec::new();
                    for j in 0..5 {
                        let mut c: Vec<f64> = v.iter().map(|a| a[j]).filter(|x| x.is_finite()).collect();
                        c.sort_by(f64::total_cmp);
                        let at = |f: f64| {
                            c.get(((c.len() as f64 * f) as usize).min(c.len().saturating_sub(1)))
                                .copied()
                                .unwrap_or(f64::NAN)
                        };
                        q.push(format!("{:.3}/{:.3}/{:.3}", at(0.25), at(0.5), at(0.75)));
                    }
                    println!(
                        "  {kind:5} n {:7} time {} planar|r| {} coarse|r| {} planar rel {} coarse rel {}",
                        v.len(),
                        q[0],
                        q[1],
                        q[2],
                        q[3],
                        q[4]
                    );
                }
                println!(
                    "{name:14} FP by distance to object (4 px cells 0,1,2-3,4-6,>6): {:?}  FN by distance to predicted: {:?}",
                    &fp_dist[..5],
                    &fp_dist[5..]
                );
            }
            if !static_fa.is_empty() {
                let n = static_fa.len() as f64;
                println!(
                    "{name:14} seed {seed} [{set}] static slices {} labelled moving {:.3} (planar {:.3})",
                    static_fa.len(),
                    static_fa.iter().map(|f| f.0).sum::<f64>() / n,
                    static_fa.iter().map(|f| f.1).sum::<f64>() / n
                );
            }
            println!(
                "{name:14} seed {seed} flow {} [{set}] slices {:3} IoU mean {:.3} pooled {:.3} prec {:.2} rec {:.2} (planar {:.3} prec {:.2} rec {:.2}, coarse {:.3}) dir median {:.1} deg (n {})",
                if ideal {
                    "ideal"
                } else if truemag {
                    "truemag"
                } else {
                    "est"
                },
                ious.len(),
                mean(&ious),
                inter_all as f64 / union_all.max(1) as f64,
                inter_all as f64 / predicted_all.max(1) as f64,
                inter_all as f64 / truth_all.max(1) as f64,
                mean(&planar_ious),
                planar_inter_all as f64 / planar_pred_all.max(1) as f64,
                planar_inter_all as f64 / truth_all.max(1) as f64,
                mean(&coarse_ious),
                dirs.get(dirs.len() / 2).copied().unwrap_or(f64::NAN),
                dirs.len()
            );
            if std::env::var("STAGE_TIMES").is_ok() {
                let events: usize = slices.iter().map(|(s, _, _)| s.events.len()).sum();
                println!(
                    "  stage seconds ({events} events): over-segmentation {overseg_s:.3}, planar {:.3}, background merger {:.3}, hierarchical merger {:.3}",
                    stage_s[0], stage_s[1], stage_s[2]
                );
            }
            if std::env::var("FILL_STATS").is_ok() {
                for (kind, name) in ["grouped", "ungrouped"].iter().enumerate() {
                    for (which, w) in ["final", "planar"].iter().enumerate() {
                        let [tp, fp, fneg] = fill_stats[kind][which];
                        println!("  {name:9} {w:6} tp {tp:8} fp {fp:8} fn {fneg:8}");
                    }
                }
                println!(
                    "  ungrouped labelled background: object events without labelled neighbours {} with {}; background events without {} with {}",
                    fill_why[0][0], fill_why[0][1], fill_why[1][0], fill_why[1][1]
                );
            }
        }
    }
    Ok(())
}

/// Applies SIM_SET ("name=value,..."): the simulator's named settings (`evseg_sim::SETTINGS`:
/// sensor thresholds, mismatch, noise, hot pixels, the IMU's noise and bias, texture contrast,
/// camera motion), for studies of how the method holds up on sensors and scenes unlike the
/// presets'.
fn sim_override(set: &str, cfg: &mut evseg_sim::SceneConfig) -> anyhow::Result<()> {
    for (k, f) in settings(set, "SIM_SET")? {
        evseg_sim::apply_setting(cfg, k, f).with_context(|| format!("SIM_SET {k}={f}"))?;
    }
    Ok(())
}

/// CELLS diagnostic: per slice, the 32 px cells in which the true background and the true
/// objects each hold at least 4 events (all events, and events with flow); prints the medians
/// over the slices that have object events and the share of those slices in which the
/// background occupies more cells than the objects.
fn print_cell_extent(slices: &[(Slice, Truth, (f64, f64))], flows: &[NormalFlow], width: u16, height: u16) {
    const CELL: usize = 32;
    const MIN_EVENTS: u32 = 4;
    let cols = usize::from(width).div_ceil(CELL);
    let rows = usize::from(height).div_ceil(CELL);
    // [all, with flow] x [background, objects] occupied-cell counts per slice.
    let mut counts: Vec<[[usize; 2]; 2]> = Vec::new();
    for ((s, truth, _), f) in slices.iter().zip(flows) {
        if !truth.event_object.iter().any(|&o| o != 0) {
            continue;
        }
        let mut grid = vec![[[0u32; 2]; 2]; cols * rows];
        for i in 0..s.events.len() {
            let c = usize::from(s.events.y[i]) / CELL * cols + usize::from(s.events.x[i]) / CELL;
            let side = usize::from(truth.event_object[i] != 0);
            grid[c][0][side] += 1;
            if f.confidence[i] > 0.0 {
                grid[c][1][side] += 1;
            }
        }
        let mut k = [[0usize; 2]; 2];
        for g in &grid {
            for kind in 0..2 {
                for side in 0..2 {
                    k[kind][side] += usize::from(g[kind][side] >= MIN_EVENTS);
                }
            }
        }
        counts.push(k);
    }
    let median = |kind: usize, side: usize| {
        let mut v: Vec<usize> = counts.iter().map(|k| k[kind][side]).collect();
        v.sort_unstable();
        v.get(v.len() / 2).copied().unwrap_or(0)
    };
    let bg_more = |kind: usize| {
        counts.iter().filter(|k| k[kind][0] > k[kind][1]).count() as f64 / counts.len().max(1) as f64
    };
    println!(
        "cells of {CELL} px with >= {MIN_EVENTS} events ({} cells, {} slices): all events background {} objects {} (background more in {:.2}); with flow background {} objects {} ({:.2})",
        cols * rows,
        counts.len(),
        median(0, 0),
        median(0, 1),
        bg_more(0),
        median(1, 0),
        median(1, 1),
        bg_more(1)
    );
}

/// Per event without a group: some grouped event (`group != u32::MAX`) lies in the 3x3 cells
/// of 4 px around it (the hierarchical merger's fill at reach 1 finds a label); true for the
/// grouped events. The fill itself answers: with every grouped event labelled 1, an event
/// without a group gets 1 exactly when one lies in its 3x3 cells.
fn grouped_neighbours(ev: &evseg_schemas::Events, group: &[u32], width: u16, height: u16) -> Vec<bool> {
    use evseg_hierarchical_merger::fill::{UNLABELLED, fill_unlabelled};
    let mut label: Vec<u32> = group
        .iter()
        .map(|&g| if g == u32::MAX { UNLABELLED } else { 1 })
        .collect();
    fill_unlabelled(ev, width, height, 4, 1, &mut label);
    label.iter().map(|&l| l == 1).collect()
}
