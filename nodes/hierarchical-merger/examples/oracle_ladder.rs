//! Oracle ladder: how far the geometry separates background from moving objects when more and
//! more of the input is replaced by the simulator's ground truth. Each rung should score high if
//! the frames, signs, units and time alignment are right; the rung where the IoU collapses points
//! at the stage (or the convention) that loses the information.
//!
//! `cargo run --release -p evseg-hierarchical-merger --example oracle_ladder -- [preset ...]`
//! env: SEED (1), SECONDS (2), TAU (0.3: relative residual above which an event is foreground on
//! the per-event rungs), RATIO (0.5: a cluster is background when its summed absolute residual is
//! at most RATIO times its summed absolute derotated normal flow, as `method_on_sim`'s ORACLE_T).
//!
//! Per slice, with `w` the mean true camera rate and `t` the mean true camera velocity (both
//! camera frame, from the Truth message), `u` the true optical flow (normalized units/s), `n0` the
//! estimated normal direction and `n` the estimated normal-flow length:
//! - R0: `|omega_slicer - w|` (the IMU path: axes, sign, time alignment);
//! - R1: full true flow, per event: derotated flow `d = u - B(x) w` against `A(x) t`; an event is
//!   foreground when the part of `d` not explained by `rho A(x) t` (rho >= 0 fitted per event)
//!   exceeds TAU |d|. With the slicer's rate as well (R1i: the line fitted to the slice's gyro
//!   samples, `evseg_geometry::RotationRate`, at each event's time);
//! - R2: true normal flow along the estimated `n0`, `n_t = u . n0`; sign and magnitude agreement
//!   of the estimate with it;
//! - R3: per k-means cluster one inverse depth, true twist; cluster background when it is
//!   explained (RATIO): with the full true flow (R3u: n0 = u/|u|), with the true normal flow along
//!   the estimated n0 (R3t), with the estimated normal flow (R3e, the ORACLE_T figure);
//! - R4: per-event inverse depth from the full true flow (an oracle depth), residual of the
//!   (true / estimated) normal flow against it, thresholded at TAU times |d| (R4t / R4e);
//! - R3 sweep: the per-cluster constant-depth test at several ratios, and with a planar inverse
//!   depth per cluster (`rho = a + b x + c y`);
//! - R5: per cluster, the 2-D derotated flow `v` fitted to the normal flows (`r = n0 . v`); the
//!   cluster is foreground when the angle between `v` and its mean `A(x) t` exceeds a threshold
//!   (sweep), with the true and with the estimated normal flow;
//! - R6: the egomotion estimate (`evseg_geometry::estimate_translation`, default settings) on
//!   the true background events only: its direction error with the estimated normal flow and
//!   with the true normal flow along the estimated n0 (R6_TRUE_OMEGA=1: derotated with the
//!   slice's mean true rate instead of the slicer's; R8 too);
//! - R7: the translation fitted with the inverse depth known (from the true flow), linear in
//!   `t`, on the estimated normal flow of the true background: per event and per 80 px cell,
//!   least squares and Huber (how much the refinement's free depth per cell costs);
//! - R8: the egomotion estimate of R6 with the previous slices' cell depths as a prior
//!   (`evseg_geometry::estimate_translation_with_memory`), at the weights of DEPTH_MEM
//!   (comma-separated, default 0.25,1,4).
//!
//! The IoU is per event over the events with a valid estimated flow (coverage printed), mean over
//! the slices with a moving object.

use anyhow::Context;
use evseg_geometry::motion::{a_matrix, b_matrix};
use evseg_geometry::{Camera, TableCache};
use evseg_normal_flow::{PlaneFitEstimator, PlaneFitParams};
use evseg_oversegmenter::{OversegParams, Oversegmenter};
use evseg_schemas::{NormalFlow, Slice, Truth};
use evseg_slicer::{Slicer, SlicerParams};
use evseg_source::EventSource;
use evseg_source::synthetic::SyntheticSource;

fn env_or<T: std::str::FromStr>(name: &str, default: T) -> anyhow::Result<T> {
    match std::env::var(name) {
        Ok(v) => v
            .parse()
            .map_err(|_| anyhow::anyhow!("{name}={v:?} does not parse")),
        Err(_) => Ok(default),
    }
}

fn mul2x3(m: &[[f64; 3]; 2], v: [f64; 3]) -> [f64; 2] {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
    ]
}

/// Angle between an estimated direction `d` and the true translation `t`, degrees.
fn direction_error_deg(d: [f64; 3], t: [f64; 3]) -> f64 {
    let c = (d[0] * t[0] + d[1] * t[1] + d[2] * t[2])
        / (d[0].hypot(d[1]).hypot(d[2]) * t[0].hypot(t[1]).hypot(t[2]));
    c.clamp(-1.0, 1.0).acos().to_degrees()
}

fn dot2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

fn mean3(v: &[[f64; 3]]) -> Option<[f64; 3]> {
    if v.is_empty() {
        return None;
    }
    let mut m = [0.0; 3];
    for x in v {
        for k in 0..3 {
            m[k] += x[k] / v.len() as f64;
        }
    }
    Some(m)
}

/// Accumulates intersection and union per slice.
#[derive(Default)]
struct Iou {
    per_slice: Vec<f64>,
    i: usize,
    u: usize,
    /// Background events called foreground, all background events, object events called
    /// foreground, all object events (over the whole run).
    counts: [usize; 4],
}

impl Iou {
    fn add(&mut self, pred: bool, truth: bool) {
        self.i += usize::from(pred && truth);
        self.u += usize::from(pred || truth);
        let k = if truth { 2 } else { 0 };
        self.counts[k] += usize::from(pred);
        self.counts[k + 1] += 1;
    }
    fn end_slice(&mut self) {
        if self.u > 0 {
            self.per_slice.push(self.i as f64 / self.u as f64);
        }
        self.i = 0;
        self.u = 0;
    }
    fn mean(&self) -> f64 {
        self.per_slice.iter().sum::<f64>() / self.per_slice.len().max(1) as f64
    }
}

impl std::fmt::Display for Iou {
    /// `IoU (background called foreground / objects called foreground)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = self.counts;
        write!(
            f,
            "{:.3} (bg->fg {:.2}, obj->fg {:.2})",
            self.mean(),
            c[0] as f64 / c[1].max(1) as f64,
            c[2] as f64 / c[3].max(1) as f64
        )
    }
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Per-cluster decision: one inverse depth rho >= 0 per cluster fitted to `r = rho q`; the cluster
/// is background when `sum |r - rho q| <= ratio sum |r|`. `items` = (cluster, r, q).
fn cluster_background(k: usize, items: &[(usize, f64, f64)], ratio: f64) -> Vec<bool> {
    let (mut num, mut den) = (vec![0.0; k], vec![0.0; k]);
    for &(c, r, q) in items {
        num[c] += r * q;
        den[c] += q * q;
    }
    let rho: Vec<f64> = (0..k)
        .map(|c| {
            if den[c] > 0.0 {
                (num[c] / den[c]).max(0.0)
            } else {
                0.0
            }
        })
        .collect();
    let (mut res, mut tot) = (vec![0.0; k], vec![0.0; k]);
    for &(c, r, q) in items {
        res[c] += (r - rho[c] * q).abs();
        tot[c] += r.abs();
    }
    (0..k).map(|c| res[c] <= ratio * tot[c]).collect()
}

/// Relative residual per cluster (as [`cluster_background`]; NaN for an empty cluster).
fn cluster_relative(k: usize, items: &[(usize, f64, f64)]) -> Vec<f64> {
    let (mut num, mut den) = (vec![0.0; k], vec![0.0; k]);
    for &(c, r, q) in items {
        num[c] += r * q;
        den[c] += q * q;
    }
    let rho: Vec<f64> = (0..k)
        .map(|c| {
            if den[c] > 0.0 {
                (num[c] / den[c]).max(0.0)
            } else {
                0.0
            }
        })
        .collect();
    let (mut res, mut tot) = (vec![0.0; k], vec![0.0; k]);
    for &(c, r, q) in items {
        res[c] += (r - rho[c] * q).abs();
        tot[c] += r.abs();
    }
    (0..k).map(|c| res[c] / tot[c]).collect()
}

/// Relative residual per cluster with a *planar* inverse depth per cluster:
/// `r = (a + b x + c y) q`, items = (cluster, r, q, x, y).
fn cluster_relative_plane(k: usize, items: &[(usize, f64, f64, f64, f64)]) -> Vec<f64> {
    let mut ne = vec![evseg_geometry::lsq::NormalEquations::<3>::default(); k];
    for &(c, r, q, x, y) in items {
        ne[c].add(&[q, x * q, y * q], r, 1.0);
    }
    let sol: Vec<Option<[f64; 3]>> = ne.iter().map(|e| e.solve(1e-9)).collect();
    let (mut res, mut tot) = (vec![0.0; k], vec![0.0; k]);
    for &(c, r, q, x, y) in items {
        let rho = sol[c].map_or(0.0, |p| (p[0] + p[1] * x + p[2] * y).max(0.0));
        res[c] += (r - rho * q).abs();
        tot[c] += r.abs();
    }
    (0..k).map(|c| res[c] / tot[c]).collect()
}

/// Per cluster: the 2-D derotated flow `v` fitted to `r = n0 . v` and the angle (deg) between
/// `v` and the cluster's mean translational direction `A(x) t`. items = (cluster, r, n0, A t).
fn cluster_flow_angle(k: usize, items: &[(usize, f64, [f64; 2], [f64; 2])]) -> Vec<f64> {
    let weighted: Vec<WeightedItem> = items.iter().map(|&(c, r, n0, tr)| (c, r, n0, tr, 1.0)).collect();
    cluster_flow_angle_weighted(k, &weighted)
}

/// [`cluster_flow_angle`] with a weight per sample (last field).
fn cluster_flow_angle_weighted(k: usize, items: &[WeightedItem]) -> Vec<f64> {
    let mut ne = vec![evseg_geometry::lsq::NormalEquations::<2>::default(); k];
    let mut at = vec![[0.0; 2]; k];
    for &(c, r, n0, tr, wt) in items {
        ne[c].add(&n0, r, wt);
        at[c][0] += tr[0];
        at[c][1] += tr[1];
    }
    (0..k)
        .map(|c| match ne[c].solve(1e-12) {
            Some(v) => {
                let (nv, na) = (dot2(v, v).sqrt(), dot2(at[c], at[c]).sqrt());
                if nv > 0.0 && na > 0.0 {
                    (dot2(v, at[c]) / (nv * na)).clamp(-1.0, 1.0).acos().to_degrees()
                } else {
                    0.0
                }
            }
            None => 0.0,
        })
        .collect()
}

/// Angles (deg) of the R5 sweep.
const ANGLES: [f64; 5] = [10.0, 15.0, 20.0, 30.0, 45.0];

/// (cluster, derotated normal flow r, n0, A t, weight) of the weighted R5 fit.
type WeightedItem = (usize, f64, [f64; 2], [f64; 2], f64);

/// Ratios of the R3 sweep.
const RATIOS: [f64; 5] = [0.1, 0.2, 0.3, 0.5, 0.7];

fn main() -> anyhow::Result<()> {
    let mut names: Vec<String> = std::env::args().skip(1).collect();
    if names.is_empty() {
        names = vec!["one-object".into(), "two-objects".into(), "camera-only".into()];
    }
    let seed: u64 = env_or("SEED", 1)?;
    let seconds: f64 = env_or("SECONDS", 2.0)?;
    let tau: f64 = env_or("TAU", 0.3)?;
    let ratio: f64 = env_or("RATIO", 0.5)?;
    for name in &names {
        let mut src = SyntheticSource::new(name, seed, Some(seconds))?;
        let camera = src.camera();
        let cam = Camera::new(&camera);
        let mut slicer = Slicer::new(SlicerParams::default())?;
        let mut slices: Vec<(Slice, Truth)> = Vec::new();
        let mut t = 0.0;
        loop {
            t += 0.01;
            let Some(b) = src.next_batch(t)? else { break };
            let packet = evseg_schemas::EventPacket {
                camera: camera.clone(),
                events: b.events,
                imu: b.imu,
            };
            for s in slicer.push(packet, b.truth, t)? {
                slices.push((s.slice, s.truth.unwrap_or_default()));
            }
        }
        // Plane-fit settings from env (NF_LOOKAHEAD_MS, NF_RADIUS, NF_OUTLIER_MS, NF_DT_MAX_MS,
        // NF_MIN_CONF, NF_MAX_DIR_SD_DEG), defaults otherwise.
        let d = PlaneFitParams::default();
        let nf = PlaneFitParams {
            lookahead_s: env_or("NF_LOOKAHEAD_MS", d.lookahead_s * 1e3)? * 1e-3,
            radius: env_or("NF_RADIUS", d.radius)?,
            outlier_s: env_or("NF_OUTLIER_MS", d.outlier_s * 1e3)? * 1e-3,
            dt_max_s: env_or("NF_DT_MAX_MS", d.dt_max_s * 1e3)? * 1e-3,
            min_confidence: env_or("NF_MIN_CONF", d.min_confidence)?,
            max_direction_sd_rad: env_or("NF_MAX_DIR_SD_DEG", d.max_direction_sd_rad.to_degrees())?
                .to_radians(),
            ..d
        };
        let mut est = PlaneFitEstimator::new(&camera, nf)?;
        let mut overseg = Oversegmenter::new(OversegParams::default())?;
        let mut table = TableCache::default();
        let table = table.get(&camera).clone();
        // Per-pixel Jacobian pixel flow -> normalized flow (the simulator's flow is in px/s).
        let (w, h) = (usize::from(camera.width), usize::from(camera.height));
        let mut jac = Vec::with_capacity(w * h);
        for v in 0..h {
            for u in 0..w {
                let a = cam.pixel_flow_to_normalized(u as f64, v as f64, 1.0, 0.0);
                let b = cam.pixel_flow_to_normalized(u as f64, v as f64, 0.0, 1.0);
                jac.push([a[0], b[0], a[1], b[1]]);
            }
        }
        let (mut omega_err, mut omega_norm, mut t_norm) = (Vec::new(), Vec::new(), Vec::new());
        let mut r1 = Iou::default();
        let (mut ego_est, mut ego_true) = (Vec::new(), Vec::new());
        let (mut ego_scaled, mut scales) = (Vec::new(), Vec::new());
        let mut variants: [Vec<f64>; 7] = Default::default();
        // R7: the direction with the depth known (per event / per 80 px cell, unweighted / Huber).
        let mut depth_known: [Vec<f64>; 4] = Default::default();
        // R8: the egomotion estimate with the previous slices' cell depths as a prior (weights
        // in DEPTH_MEM, comma-separated; default 0.25,1,4).
        let mut mems: Vec<(f64, evseg_geometry::DepthMemory, Vec<f64>)> = std::env::var("DEPTH_MEM")
            .unwrap_or_else(|_| "0.25,1,4".into())
            .split(',')
            .filter_map(|w| w.parse().ok())
            .map(|w| (w, evseg_geometry::DepthMemory::default(), Vec::new()))
            .collect();
        let mut r1i = Iou::default();
        let (mut r3u, mut r3t, mut r3e) = (Iou::default(), Iou::default(), Iou::default());
        let (mut r4t, mut r4e) = (Iou::default(), Iou::default());
        let mut sweep_t: Vec<Iou> = RATIOS.iter().map(|_| Iou::default()).collect();
        let mut sweep_e: Vec<Iou> = RATIOS.iter().map(|_| Iou::default()).collect();
        let mut sweep_pt: Vec<Iou> = RATIOS.iter().map(|_| Iou::default()).collect();
        let mut sweep_pe: Vec<Iou> = RATIOS.iter().map(|_| Iou::default()).collect();
        let mut sweep_vt: Vec<Iou> = ANGLES.iter().map(|_| Iou::default()).collect();
        let mut sweep_ve: Vec<Iou> = ANGLES.iter().map(|_| Iou::default()).collect();
        let mut sweep_vw: Vec<Iou> = ANGLES.iter().map(|_| Iou::default()).collect();
        let (mut ang_bg, mut ang_obj) = (Vec::new(), Vec::new());
        let (mut sign_ok, mut sign_n, mut mag_err) = (0usize, 0usize, Vec::new());
        let mut bg_rel: Vec<f64> = Vec::new();
        let mut err_fit = (
            evseg_geometry::lsq::NormalEquations::<5>::default(),
            0.0f64,
            Vec::<([f64; 5], f64)>::new(),
        );
        let (mut mag_signed, mut trans_share) = (Vec::new(), Vec::new());
        let (mut rot_share, mut covered, mut total) = (Vec::new(), 0usize, 0usize);
        for (s, truth) in &slices {
            let n_ev = s.events.len();
            if truth.flow_x.len() != n_ev || truth.event_object.len() != n_ev {
                continue;
            }
            let (Some(w_true), Some(t_true)) = (
                mean3(
                    &truth
                        .camera
                        .iter()
                        .filter_map(|c| c.angular_velocity)
                        .collect::<Vec<_>>(),
                ),
                mean3(
                    &truth
                        .camera
                        .iter()
                        .filter_map(|c| c.linear_velocity)
                        .collect::<Vec<_>>(),
                ),
            ) else {
                continue;
            };
            let w_imu = s.omega.unwrap_or([0.0; 3]);
            // The slicer's rate as a line in time (what the stages derotate with).
            let span = (
                s.events.t.first().copied().unwrap_or(0.0),
                s.events.t.last().copied().unwrap_or(0.0),
            );
            let rate =
                evseg_geometry::RotationRate::of_slice(s, span, true).unwrap_or_else(|| [0.0; 3].into());
            omega_err.push(
                ((w_imu[0] - w_true[0]).powi(2)
                    + (w_imu[1] - w_true[1]).powi(2)
                    + (w_imu[2] - w_true[2]).powi(2))
                .sqrt(),
            );
            omega_norm.push((w_true[0].powi(2) + w_true[1].powi(2) + w_true[2].powi(2)).sqrt());
            t_norm.push((t_true[0].powi(2) + t_true[1].powi(2) + t_true[2].powi(2)).sqrt());
            let flow: NormalFlow = est.process(&s.events)?;
            let clusters = overseg.segment(&s.camera, &s.events, &flow)?;
            let k = usize::from(clusters.count);
            let has_object = truth.event_object.iter().any(|&o| o != 0);
            // The true optical flow of event `i`, normalized units/s.
            let true_flow = |i: usize| {
                let j = jac[usize::from(s.events.y[i]) * w + usize::from(s.events.x[i])];
                let (fu, fv) = (f64::from(truth.flow_x[i]), f64::from(truth.flow_y[i]));
                [j[0] * fu + j[1] * fv, j[2] * fu + j[3] * fv]
            };
            // R6: the egomotion estimate on the true background only (slicer omega), with the
            // estimated normal flow and with the true normal flow along the estimated n0.
            {
                // R6_TRUE_OMEGA=1: derotate with the slice's mean true rate instead of the
                // slicer's (how much the gyro path costs the direction).
                let rate6 = if env_or("R6_TRUE_OMEGA", 0u8)? == 1 {
                    evseg_geometry::RotationRate::from(w_true)
                } else {
                    rate
                };
                let samples = evseg_geometry::flow_samples(&table, &s.events, &flow, Some(&rate6), 0.0)?;
                // R6_BOUNDARY_PX=k (default 0 = keep all): leave out background events within k
                // px (Chebyshev) of an object event of the slice.
                let margin: usize = env_or("R6_BOUNDARY_PX", 0usize)?;
                let mut near_obj = vec![false; if margin > 0 { w * h } else { 0 }];
                if margin > 0 {
                    for i in 0..n_ev {
                        if truth.event_object[i] != 0 {
                            let (x, y) = (usize::from(s.events.x[i]), usize::from(s.events.y[i]));
                            for yy in y.saturating_sub(margin)..=(y + margin).min(h - 1) {
                                for xx in x.saturating_sub(margin)..=(x + margin).min(w - 1) {
                                    near_obj[yy * w + xx] = true;
                                }
                            }
                        }
                    }
                }
                let bg: Vec<evseg_geometry::FlowSample> = samples
                    .iter()
                    .filter(|sm| truth.event_object[sm.index] == 0)
                    .filter(|sm| {
                        margin == 0
                            || !near_obj
                                [usize::from(s.events.y[sm.index]) * w + usize::from(s.events.x[sm.index])]
                    })
                    .copied()
                    .collect();
                let bg_true: Vec<evseg_geometry::FlowSample> = bg
                    .iter()
                    .map(|sm| {
                        let uf = true_flow(sm.index);
                        let n_t = dot2(uf, sm.n0);
                        let mut out = *sm;
                        out.n_derot = sm.n_derot + (n_t - sm.n);
                        out.n = n_t;
                        out
                    })
                    .collect();
                // The estimate with its magnitude rescaled by the slice's median ratio to the
                // truth (an oracle scale): does a common scale bias explain the error?
                let mut ratios: Vec<f64> = bg
                    .iter()
                    .zip(&bg_true)
                    .filter(|(_, t)| t.n > 0.0)
                    .map(|(e, t)| e.n / t.n)
                    .collect();
                let k_scale = median(&mut ratios);
                scales.push(k_scale);
                let bg_scaled: Vec<evseg_geometry::FlowSample> = bg
                    .iter()
                    .map(|sm| {
                        let mut out = *sm;
                        out.n = sm.n / k_scale;
                        out.n_derot = sm.n_derot + (out.n - sm.n);
                        out
                    })
                    .collect();
                let p = evseg_geometry::EgomotionParams::default();
                // Variants on the estimated flow (confident samples, as estimate_translation):
                // the SVM alone, the Huber refinement from the SVM, and both refinements
                // started from the true direction.
                {
                    let conf: Vec<(&evseg_geometry::FlowSample, f64)> = bg
                        .iter()
                        .filter(|sm| sm.confidence > p.min_confidence)
                        .map(|sm| (sm, 1.0))
                        .collect();
                    let err = |d: [f64; 3]| direction_error_deg(d, t_true);
                    if let Some(svm) = evseg_geometry::translation_direction(conf.iter().copied(), &p.svm) {
                        let regions = evseg_geometry::grid_regions(
                            conf.iter().copied(),
                            &s.events.x,
                            &s.events.y,
                            camera.width,
                            camera.height,
                            p.grid_cols,
                        );
                        variants[0].push(err(svm.direction));
                        let it = p.refine_iterations;
                        let m = p.min_cell_samples;
                        let rr = evseg_geometry::refine_direction_robust;
                        if let Some(d) = rr(&regions, svm.direction, it, m, Some(1.5)) {
                            variants[1].push(err(d));
                        }
                        if let Some(d) = rr(&regions, t_true, it, m, None) {
                            variants[2].push(err(d));
                        }
                        if let Some(d) = rr(&regions, t_true, it, m, Some(1.5)) {
                            variants[3].push(err(d));
                        }
                        // Heteroscedastic weights: the estimator's error grows with |n|
                        // (mostly rotational flow), so weight 1 / (n^2 + n_med^2).
                        let mut ns: Vec<f64> = conf.iter().map(|(sm, _)| sm.n).collect();
                        let n_med = median(&mut ns);
                        let hw: Vec<(&evseg_geometry::FlowSample, f64)> = conf
                            .iter()
                            .map(|(sm, _)| (*sm, 1.0 / (sm.n * sm.n + n_med * n_med)))
                            .collect();
                        let regions_w = evseg_geometry::grid_regions(
                            hw.iter().copied(),
                            &s.events.x,
                            &s.events.y,
                            camera.width,
                            camera.height,
                            p.grid_cols,
                        );
                        if let Some(d) = rr(&regions_w, svm.direction, it, m, Some(1.5)) {
                            variants[4].push(err(d));
                        }
                        if let Some(svm_w) = evseg_geometry::translation_direction(hw.iter().copied(), &p.svm)
                        {
                            variants[5].push(err(svm_w.direction));
                            if let Some(d) = rr(&regions_w, svm_w.direction, it, m, Some(1.5)) {
                                variants[6].push(err(d));
                            }
                        }
                    }
                }
                // R7: the translation fitted with each sample's inverse depth known from the truth
                // (`rho = d . A t / |A t|^2`, `d` the true derotated flow), linear in `t`:
                // `n_derot ~ rho n0^T A(x) t`; per event, and per 80 px cell (the median rho of
                // the cell's samples, as a depth prior per cell would give), plain least squares
                // and 5 rounds of Huber weights (k 1.5, as the egomotion's refinement).
                {
                    let p = evseg_geometry::EgomotionParams::default();
                    let mut rows: Vec<([f64; 3], f64, f64, usize)> = Vec::new();
                    for sm in bg.iter().filter(|sm| sm.confidence > p.min_confidence) {
                        let uf = true_flow(sm.index);
                        let rot = mul2x3(&b_matrix(sm.x, sm.y), w_true);
                        let d = [uf[0] - rot[0], uf[1] - rot[1]];
                        let a = a_matrix(sm.x, sm.y);
                        let tr = mul2x3(&a, t_true);
                        let tt = dot2(tr, tr);
                        if tt <= 0.0 {
                            continue;
                        }
                        let rho = (dot2(d, tr) / tt).max(0.0);
                        let g = [
                            sm.n0[0] * a[0][0] + sm.n0[1] * a[1][0],
                            sm.n0[0] * a[0][1] + sm.n0[1] * a[1][1],
                            sm.n0[0] * a[0][2] + sm.n0[1] * a[1][2],
                        ];
                        let (u, v) = (s.events.x[sm.index], s.events.y[sm.index]);
                        let cell = usize::from(v) / 80 * 64 + usize::from(u) / 80;
                        rows.push((g, sm.n_derot, rho, cell));
                    }
                    let mut cell_rho: std::collections::HashMap<usize, Vec<f64>> = Default::default();
                    for r in &rows {
                        cell_rho.entry(r.3).or_default().push(r.2);
                    }
                    let cell_med: std::collections::HashMap<usize, f64> = cell_rho
                        .into_iter()
                        .map(|(c, mut v)| (c, median(&mut v)))
                        .collect();
                    let err = |d: [f64; 3]| direction_error_deg(d, t_true);
                    for (mode, per_cell) in [(0usize, false), (2, true)] {
                        let rho_of =
                            |r: &([f64; 3], f64, f64, usize)| if per_cell { cell_med[&r.3] } else { r.2 };
                        let mut wts = vec![1.0; rows.len()];
                        for round in 0..6 {
                            let mut m = nalgebra::Matrix3::<f64>::zeros();
                            let mut b = nalgebra::Vector3::<f64>::zeros();
                            for (r, &wt) in rows.iter().zip(&wts) {
                                let g = nalgebra::Vector3::from(r.0) * rho_of(r);
                                m += wt * g * g.transpose();
                                b += wt * r.1 * g;
                            }
                            let Some(t) = m.try_inverse().map(|mi| mi * b) else {
                                break;
                            };
                            if round == 0 {
                                depth_known[mode].push(err([t[0], t[1], t[2]]));
                            }
                            let res: Vec<f64> = rows
                                .iter()
                                .map(|r| (r.1 - rho_of(r) * nalgebra::Vector3::from(r.0).dot(&t)).abs())
                                .collect();
                            let mut sorted = res.clone();
                            let scale = (1.4826 * median(&mut sorted)).max(f64::MIN_POSITIVE);
                            if round == 5 {
                                depth_known[mode + 1].push(err([t[0], t[1], t[2]]));
                                break;
                            }
                            for (wt, e) in wts.iter_mut().zip(&res) {
                                *wt = if *e > 1.5 * scale { 1.5 * scale / e } else { 1.0 };
                            }
                        }
                    }
                }
                {
                    let refs: Vec<&evseg_geometry::FlowSample> = bg.iter().collect();
                    let p = evseg_geometry::EgomotionParams::default();
                    for (wt, mem, out) in mems.iter_mut() {
                        if let Some(d) = evseg_geometry::estimate_translation_with_memory(
                            &refs,
                            &s.events.x,
                            &s.events.y,
                            camera.width,
                            camera.height,
                            &p,
                            Some((mem, *wt)),
                        ) {
                            out.push(direction_error_deg(d, t_true));
                        }
                    }
                }
                for (set, out) in [
                    (&bg, &mut ego_est),
                    (&bg_true, &mut ego_true),
                    (&bg_scaled, &mut ego_scaled),
                ] {
                    let refs: Vec<&evseg_geometry::FlowSample> = set.iter().collect();
                    if let Some(d) = evseg_geometry::estimate_translation(
                        &refs,
                        &s.events.x,
                        &s.events.y,
                        camera.width,
                        camera.height,
                        &p,
                    ) {
                        out.push(direction_error_deg(d, t_true));
                    }
                }
            }
            // Per event: (index, cluster, q = n0.A t, r_true, r_est, rho_full, |d|, q_u = u0.A t, |d| along u0)
            let mut rows = Vec::new();
            let mut n0s = std::collections::HashMap::new();
            let mut ns = std::collections::HashMap::new();
            for i in 0..n_ev {
                let (u, v) = (s.events.x[i], s.events.y[i]);
                let Some([x, y]) = table.get(u, v) else {
                    continue;
                };
                let (x, y) = (f64::from(x), f64::from(y));
                let uf = true_flow(i);
                let is_obj = truth.event_object[i] != 0;
                let rot = mul2x3(&b_matrix(x, y), w_true);
                let rot_i = mul2x3(&b_matrix(x, y), rate.at(s.events.t[i]));
                let tr = mul2x3(&a_matrix(x, y), t_true);
                let d = [uf[0] - rot[0], uf[1] - rot[1]];
                let di = [uf[0] - rot_i[0], uf[1] - rot_i[1]];
                let fg = |d: [f64; 2]| {
                    let tt = dot2(tr, tr);
                    let rho = if tt > 0.0 {
                        (dot2(d, tr) / tt).max(0.0)
                    } else {
                        0.0
                    };
                    let e = [d[0] - rho * tr[0], d[1] - rho * tr[1]];
                    (dot2(e, e).sqrt() > tau * dot2(d, d).sqrt(), rho)
                };
                let (fg_true, rho) = fg(d);
                let (fg_imu, _) = fg(di);
                if has_object {
                    r1.add(fg_true, is_obj);
                    r1i.add(fg_imu, is_obj);
                }
                let dn = dot2(d, d).sqrt();
                let tn = dot2(tr, tr).sqrt();
                if dn > 0.0 && tn > 0.0 {
                    let ang = (dot2(d, tr) / (dn * tn)).clamp(-1.0, 1.0).acos().to_degrees();
                    if is_obj {
                        ang_obj.push(ang);
                    } else {
                        ang_bg.push(ang);
                    }
                }
                let un = dot2(uf, uf).sqrt();
                if un > 0.0 {
                    rot_share.push(dot2(rot, rot).sqrt() / un);
                }
                total += 1;
                let (nx, ny) = (f64::from(flow.nx[i]), f64::from(flow.ny[i]));
                let n = nx.hypot(ny);
                if !(flow.confidence[i] > 0.0 && n.is_finite() && n > 0.0) {
                    continue;
                }
                covered += 1;
                let n0 = [nx / n, ny / n];
                let n_t = dot2(uf, n0);
                sign_n += 1;
                sign_ok += usize::from(n_t > 0.0);
                mag_err.push((n - n_t).abs() / n_t.abs().max(1e-9));
                mag_signed.push((n - n_t) / n_t.abs().max(1e-9));
                if !is_obj {
                    // R2b: the estimate's error explained by its scale, its direction and the
                    // change of the rotational flow over time (a time offset).
                    let rdot = dot2(n0, mul2x3(&b_matrix(x, y), rate.slope));
                    let c2 = n0[0] * n0[0] - n0[1] * n0[1];
                    let s2 = 2.0 * n0[0] * n0[1];
                    let f = [n_t, n_t * c2, n_t * s2, rdot, 1.0];
                    let e = n - n_t;
                    err_fit.0.add(&f, e, 1.0);
                    err_fit.1 += e * e;
                    err_fit.2.push((f, e));
                    if flow.confidence[i] > 0.5 {
                        bg_rel.push((e / n_t.abs().max(1e-9)).abs());
                    }
                }
                trans_share.push((n_t - dot2(n0, rot)).abs() / n_t.abs().max(1e-9));
                let q = dot2(n0, tr);
                let r_true = n_t - dot2(n0, rot);
                let r_est = n - dot2(n0, rot);
                let cid = clusters.id[i];
                n0s.insert(i, n0);
                ns.insert(i, n);
                rows.push((i, cid, q, r_true, r_est, rho, d, is_obj));
            }
            if !has_object {
                continue;
            }
            for &(_, _, q, r_true, r_est, rho, d, is_obj) in &rows {
                let scale = tau * dot2(d, d).sqrt();
                r4t.add((r_true - rho * q).abs() > scale, is_obj);
                r4e.add((r_est - rho * q).abs() > scale, is_obj);
            }
            let mut items_u = Vec::new();
            let mut items_t = Vec::new();
            let mut items_e = Vec::new();
            let (mut items_pt, mut items_pe) = (Vec::new(), Vec::new());
            let (mut items_vt, mut items_ve) = (Vec::new(), Vec::new());
            let mut items_vw: Vec<WeightedItem> = Vec::new();
            for &(i, cid, q, r_true, r_est, _, d, _) in &rows {
                if cid == u16::MAX {
                    continue;
                }
                let c = usize::from(cid);
                items_t.push((c, r_true, q));
                items_e.push((c, r_est, q));
                // Full flow as normal flow along its own direction: n0 = d/|d| of the true flow.
                let [x, y] = table
                    .get(s.events.x[i], s.events.y[i])
                    .context("event inside the sensor")?;
                items_pt.push((c, r_true, q, f64::from(x), f64::from(y)));
                items_pe.push((c, r_est, q, f64::from(x), f64::from(y)));
                let n0 = n0s[&i];
                let tr = mul2x3(&a_matrix(f64::from(x), f64::from(y)), t_true);
                items_vt.push((c, r_true, n0, tr));
                items_ve.push((c, r_est, n0, tr));
                items_vw.push((c, r_est, n0, tr, ns[&i]));
                let dn = dot2(d, d).sqrt();
                if dn > 0.0 {
                    // d is derotated already: r = |d|, q = (d/|d|) . A t.
                    items_u.push((c, dn, dot2(d, tr) / dn));
                }
            }
            let bu = cluster_background(k, &items_u, ratio);
            let bt = cluster_background(k, &items_t, ratio);
            let be = cluster_background(k, &items_e, ratio);
            let (rel_t, rel_e) = (cluster_relative(k, &items_t), cluster_relative(k, &items_e));
            let (rel_pt, rel_pe) = (
                cluster_relative_plane(k, &items_pt),
                cluster_relative_plane(k, &items_pe),
            );
            for &(_, cid, _, _, _, _, _, is_obj) in &rows {
                if cid == u16::MAX {
                    continue;
                }
                let c = usize::from(cid);
                for (j, &rt) in RATIOS.iter().enumerate() {
                    sweep_t[j].add(rel_t[c].is_nan() || rel_t[c] > rt, is_obj);
                    sweep_e[j].add(rel_e[c].is_nan() || rel_e[c] > rt, is_obj);
                    sweep_pt[j].add(rel_pt[c].is_nan() || rel_pt[c] > rt, is_obj);
                    sweep_pe[j].add(rel_pe[c].is_nan() || rel_pe[c] > rt, is_obj);
                }
            }
            let (ang_t, ang_e) = (cluster_flow_angle(k, &items_vt), cluster_flow_angle(k, &items_ve));
            let mut all_n: Vec<f64> = items_vw.iter().map(|it| it.4).collect();
            let n_med = median(&mut all_n);
            for it in &mut items_vw {
                it.4 = 1.0 / (it.4 * it.4 + n_med * n_med);
            }
            let ang_w = cluster_flow_angle_weighted(k, &items_vw);
            for &(_, cid, _, _, _, _, _, is_obj) in &rows {
                if cid == u16::MAX {
                    continue;
                }
                let c = usize::from(cid);
                for (j, &a) in ANGLES.iter().enumerate() {
                    sweep_vt[j].add(ang_t[c] > a, is_obj);
                    sweep_ve[j].add(ang_e[c] > a, is_obj);
                    sweep_vw[j].add(ang_w[c] > a, is_obj);
                }
            }
            for iou in sweep_vt
                .iter_mut()
                .chain(sweep_ve.iter_mut())
                .chain(sweep_vw.iter_mut())
            {
                iou.end_slice();
            }
            for iou in sweep_t
                .iter_mut()
                .chain(sweep_e.iter_mut())
                .chain(sweep_pt.iter_mut())
                .chain(sweep_pe.iter_mut())
            {
                iou.end_slice();
            }
            for &(_, cid, _, _, _, _, _, is_obj) in &rows {
                if cid == u16::MAX {
                    continue;
                }
                let c = usize::from(cid);
                r3u.add(!bu[c], is_obj);
                r3t.add(!bt[c], is_obj);
                r3e.add(!be[c], is_obj);
            }
            for iou in [
                &mut r1, &mut r1i, &mut r3u, &mut r3t, &mut r3e, &mut r4t, &mut r4e,
            ] {
                iou.end_slice();
            }
        }
        println!(
            "{name:13} seed {seed} slices {} | R0 |omega_imu - w_true| median {:.4} rad/s (|w| {:.3}, |t| {:.3} m/s, |rot flow|/|flow| {:.2})",
            slices.len(),
            median(&mut omega_err),
            median(&mut omega_norm),
            median(&mut t_norm),
            median(&mut rot_share),
        );
        {
            let (eqs, ee, rows) = &err_fit;
            let cnt = rows.len() as f64;
            if let Some(sol) = eqs.solve(0.0) {
                let left: f64 = rows
                    .iter()
                    .map(|(f, e)| {
                        let p: f64 = f.iter().zip(&sol).map(|(a, b)| a * b).sum();
                        (e - p).powi(2)
                    })
                    .sum();
                let explained = ee - left;
                bg_rel.sort_by(f64::total_cmp);
                let q = |p: f64| {
                    bg_rel
                        .get(((bg_rel.len() as f64 - 1.0) * p) as usize)
                        .copied()
                        .unwrap_or(f64::NAN)
                };
                let frac =
                    |k: f64| bg_rel.iter().filter(|&&r| r > k).count() as f64 / bg_rel.len().max(1) as f64;
                println!(
                    "  R2c background, confidence > 0.5: |n - n_t| / |n_t| quantiles 50 % {:.3}, 75 % {:.3}, 90 % {:.3}, 95 % {:.3}, 99 % {:.3}; above 0.3: {:.3}, above 1: {:.3}",
                    q(0.5),
                    q(0.75),
                    q(0.9),
                    q(0.95),
                    q(0.99),
                    frac(0.3),
                    frac(1.0)
                );
                println!(
                    "  R2b background error n - n_t = {:.4} n_t + {:.4} n_t cos2th + {:.4} n_t sin2th + {:.4} s * n0.B(x)dw/dt + {:.4}; rms {:.4}, explained {:.1} %",
                    sol[0],
                    sol[1],
                    sol[2],
                    sol[3],
                    sol[4],
                    (ee / cnt.max(1.0)).sqrt(),
                    100.0 * explained / ee.max(1e-300)
                );
            }
        }
        println!(
            "  R1 full flow angle(d, A t) median: background {:.1} deg, objects {:.1} deg; IoU true w {}, slicer w(t) {}",
            median(&mut ang_bg),
            median(&mut ang_obj),
            r1,
            r1i
        );
        println!(
            "  R2 est vs true normal flow along est n0: coverage {:.3}, sign-correct {:.3}, median rel. magnitude error {:.3}, signed {:.3}; |derotated n_t| / |n_t| median {:.3}",
            covered as f64 / total.max(1) as f64,
            sign_ok as f64 / sign_n.max(1) as f64,
            median(&mut mag_err),
            median(&mut mag_signed),
            median(&mut trans_share)
        );
        println!(
            "  R3 per-cluster depth IoU: full flow {}, true normal flow {}, est normal flow {}",
            r3u, r3t, r3e
        );
        for (j, r) in RATIOS.iter().enumerate() {
            println!(
                "  R3 sweep ratio {r}: true normal flow {}, est {} | planar depth: true {}, est {}",
                sweep_t[j], sweep_e[j], sweep_pt[j], sweep_pe[j]
            );
        }
        for (j, a) in ANGLES.iter().enumerate() {
            println!(
                "  R5 cluster flow angle to A t > {a} deg: true normal flow {}, est {}, est weighted 1/(n^2+n_med^2) {}",
                sweep_vt[j], sweep_ve[j], sweep_vw[j]
            );
        }
        println!(
            "  R6 egomotion on the true background, median direction error: est normal flow {:.1} deg, true normal flow along est n0 {:.1} deg, est rescaled by the slice's median est/true ratio (median {:.3}) {:.1} deg (slices {} / {})",
            median(&mut ego_est.clone()),
            median(&mut ego_true.clone()),
            median(&mut scales),
            median(&mut ego_scaled),
            ego_est.len(),
            ego_true.len()
        );
        for (wt, _, out) in mems.iter_mut() {
            println!(
                "  R8 depth memory weight {wt}: median direction error {:.1} deg",
                median(out)
            );
        }
        println!(
            "  R7 depth known (est normal flow, true background): per event LS {:.1} deg, Huber {:.1}; per 80 px cell LS {:.1}, Huber {:.1}",
            median(&mut depth_known[0]),
            median(&mut depth_known[1]),
            median(&mut depth_known[2]),
            median(&mut depth_known[3])
        );
        println!(
            "  R6 est flow variants: SVM alone {:.1} deg, Huber refine from SVM {:.1}, refine from the true t {:.1}, Huber from the true t {:.1}; weights 1/(n^2+n_med^2): Huber refine from SVM {:.1}, weighted SVM {:.1}, Huber from weighted SVM {:.1}",
            median(&mut variants[0]),
            median(&mut variants[1]),
            median(&mut variants[2]),
            median(&mut variants[3]),
            median(&mut variants[4]),
            median(&mut variants[5]),
            median(&mut variants[6])
        );
        println!(
            "  R4 per-event oracle depth IoU: true normal flow {}, est normal flow {}",
            r4t, r4e
        );
    }
    Ok(())
}
