//! Training of the learned estimator's MLP with the circle loss (METHOD_NOTES §2), hand-written
//! backpropagation and Adam, data-parallel over threads, deterministic from a seed.
//!
//! Targets are the true optical flow `u` of each event in the network's units (`r` pixels per
//! unit of `tau`, i.e. `u_px_s * (t1 - t0) / (2 r)`, see [`crate::learned`]). The loss of a
//! prediction `p` is `-cos angle(p - u/2, u) + (ln(0.1 + |u|/2) - ln(0.1 + |p - u/2|))^2`: it is
//! smallest on the circle with diameter `u`, the set of normal flows consistent with `u` (the
//! network sees only the local edge, so it cannot know the flow along the edge).

use crate::learned::{LearnedEstimator, SplitMix64, draw_frequencies};
use crate::mlp;
use crate::weights::LearnedWeights;
use evseg_schemas::Events;

/// Training settings.
#[derive(Debug, Clone, PartialEq)]
pub struct TrainConfig {
    /// Seed of the frequencies, the initial weights, the sample choice and the shuffles.
    pub seed: u64,
    /// Number of frequency vectors `D` (2 D inputs).
    pub d: usize,
    /// Hidden layer sizes.
    pub hidden: Vec<usize>,
    /// Neighbourhood radius, pixels.
    pub radius_px: usize,
    /// Spatial frequency scale, radians per radius.
    pub alpha_xy: f32,
    /// Temporal frequency scale, radians per unit of `tau`.
    pub alpha_t: f32,
    /// Passes over the training set.
    pub epochs: usize,
    /// Rows per Adam step.
    pub batch: usize,
    /// Adam learning rate at the start (cosine decay to 5% of it at the end).
    pub lr: f32,
    /// Threads for the gradient.
    pub threads: usize,
}

impl Default for TrainConfig {
    fn default() -> Self {
        Self {
            seed: 1,
            d: 64,
            hidden: vec![128, 128],
            radius_px: 8,
            alpha_xy: 3.0,
            alpha_t: 6.0,
            epochs: 6,
            batch: 256,
            lr: 2e-3,
            threads: 2,
        }
    }
}

/// Training rows: features (`rows x dim`) and targets (`rows x 2`, network units).
#[derive(Debug, Clone, Default)]
pub struct Dataset {
    /// Feature width (`2 D`).
    pub dim: usize,
    /// Row-major features.
    pub features: Vec<f32>,
    /// Target flow per row, network units.
    pub targets: Vec<f32>,
}

impl Dataset {
    /// An empty set of `dim`-wide rows.
    pub fn new(dim: usize) -> Self {
        Self {
            dim,
            ..Self::default()
        }
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.targets.len() / 2
    }

    /// True without rows.
    pub fn is_empty(&self) -> bool {
        self.targets.is_empty()
    }

    /// Appends `other`'s rows.
    pub fn append(&mut self, other: &Dataset) {
        self.features.extend_from_slice(&other.features);
        self.targets.extend_from_slice(&other.targets);
    }

    /// Encodes the events of the slice `[t0, t1)` whose true flow (`flow_x`, `flow_y`, pixels
    /// per second, aligned with the events) is finite and at least `min_speed_px_s`, keeping each
    /// with probability `keep` (drawn from `rng`), and appends them. Augmentation: the
    /// coordinates are rotated by ensemble member `rotation` of `est` (the target becomes `R u`),
    /// and with `reverse` time runs backwards in the slice (`t -> t0 + t1 - t`, target `-u`); a
    /// texture then cannot tell the flow, only the geometry of the events can.
    #[allow(clippy::too_many_arguments)]
    pub fn add_slice(
        &mut self,
        est: &mut LearnedEstimator,
        events: &Events,
        flow_x: &[f32],
        flow_y: &[f32],
        t0: f64,
        t1: f64,
        keep: f64,
        min_speed_px_s: f32,
        rotation: usize,
        reverse: bool,
        rng: &mut SplitMix64,
    ) -> Result<(), crate::learned::LearnedError> {
        let n = events.len();
        if flow_x.len() != n || flow_y.len() != n {
            return Ok(());
        }
        let mask: Vec<bool> = (0..n)
            .map(|i| {
                let s = flow_x[i].hypot(flow_y[i]);
                rng.uniform() < keep && s.is_finite() && s >= min_speed_px_s
            })
            .collect();
        let reversed;
        let events = if reverse {
            let mut r = events.clone();
            for t in &mut r.t {
                *t = t0 + t1 - *t;
            }
            reversed = r;
            &reversed
        } else {
            events
        };
        let Some((c, s)) = est.rotation(rotation) else {
            return Err(crate::learned::LearnedError::Params(format!(
                "no rotation {rotation}"
            )));
        };
        let (idx, feats) = est.features(events, t0, t1, rotation, &|i| mask[i])?;
        let sign = if reverse { -1.0 } else { 1.0 };
        let to_net = sign * ((t1 - t0) / (2.0 * est.radius() as f64)) as f32;
        self.features.extend_from_slice(&feats);
        for &e in &idx {
            let (ux, uy) = (flow_x[e as usize], flow_y[e as usize]);
            self.targets.push((c * ux - s * uy) * to_net);
            self.targets.push((s * ux + c * uy) * to_net);
        }
        Ok(())
    }
}

/// The circle loss of prediction `p` for true flow `u` (METHOD_NOTES §2); writes `dL/dp` into
/// `dp`. `u` must be non-zero.
pub fn circle_loss(p: [f32; 2], u: [f32; 2], dp: &mut [f32; 2]) -> f32 {
    let d = [p[0] - 0.5 * u[0], p[1] - 0.5 * u[1]];
    let nd = d[0].hypot(d[1]).max(1e-6);
    let nu = u[0].hypot(u[1]).max(1e-6);
    let cos = (d[0] * u[0] + d[1] * u[1]) / (nd * nu);
    let e = (0.1 + 0.5 * nu).ln() - (0.1 + nd).ln();
    let k2 = -2.0 * e / ((0.1 + nd) * nd);
    for j in 0..2 {
        let dcos = u[j] / (nd * nu) - cos * d[j] / (nd * nd);
        dp[j] = -dcos + k2 * d[j];
    }
    -cos + e * e
}

/// Fresh weights for `cfg`: frequencies from [`draw_frequencies`], He-normal initial layers.
pub fn init_weights(cfg: &TrainConfig) -> LearnedWeights {
    let (at, ax, ay) = draw_frequencies(cfg.d, cfg.alpha_xy, cfg.alpha_t, cfg.seed);
    let mut sizes = vec![2 * cfg.d];
    sizes.extend_from_slice(&cfg.hidden);
    sizes.push(2);
    let mut rng = SplitMix64(cfg.seed ^ 0x1417_0000_0000_0002);
    let nl = sizes.len() - 1;
    let layers = (0..nl)
        .map(|k| {
            let gain = if k + 1 == nl { 1.0 } else { 2.0 };
            let s = (gain / sizes[k] as f64).sqrt();
            (0..sizes[k] * sizes[k + 1])
                .map(|_| (rng.normal() * s) as f32)
                .collect()
        })
        .collect();
    LearnedWeights {
        radius_px: cfg.radius_px as f32,
        alpha_xy: cfg.alpha_xy,
        alpha_t: cfg.alpha_t,
        seed: cfg.seed,
        at,
        ax,
        ay,
        sizes,
        layers,
    }
}

/// Figures of a pass over a data set.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Evaluation {
    /// Mean circle loss.
    pub loss: f64,
    /// Share of rows with `p . u > 0`.
    pub sign_correct: f64,
    /// Median angle at the origin between `p` and the nearest point of the circle, degrees.
    pub circle_angle_deg_median: f64,
}

/// Evaluates `w` on `data`.
pub fn evaluate(w: &LearnedWeights, data: &Dataset) -> Evaluation {
    let n = data.len();
    if n == 0 {
        return Evaluation::default();
    }
    let mut out = vec![0.0f32; 2 * 256];
    let mut s = mlp::Scratch::default();
    let (mut loss, mut sign) = (0.0f64, 0usize);
    let mut angles = Vec::with_capacity(n);
    let mut r0 = 0;
    while r0 < n {
        let rows = (n - r0).min(256);
        mlp::forward(
            &w.sizes,
            &w.layers,
            &data.features[r0 * data.dim..(r0 + rows) * data.dim],
            rows,
            &mut out,
            &mut s,
        );
        for r in 0..rows {
            let p = [out[2 * r], out[2 * r + 1]];
            let u = [data.targets[2 * (r0 + r)], data.targets[2 * (r0 + r) + 1]];
            let mut dp = [0.0; 2];
            loss += f64::from(circle_loss(p, u, &mut dp));
            sign += usize::from(p[0] * u[0] + p[1] * u[1] > 0.0);
            let pf = [f64::from(p[0]), f64::from(p[1])];
            let uf = [f64::from(u[0]), f64::from(u[1])];
            angles.push(
                crate::score::event_errors(pf, uf)
                    .map(|e| e.circle_angle_error_deg)
                    .unwrap_or(90.0),
            );
        }
        r0 += rows;
    }
    angles.sort_by(f64::total_cmp);
    Evaluation {
        loss: loss / n as f64,
        sign_correct: sign as f64 / n as f64,
        circle_angle_deg_median: angles[n / 2],
    }
}

/// Trains `w` on `data` for `cfg.epochs` epochs with Adam (betas 0.9 / 0.999) and a cosine
/// learning-rate decay; `report(epoch, mean training loss)` is called after every epoch.
pub fn train(
    w: &mut LearnedWeights,
    data: &Dataset,
    cfg: &TrainConfig,
    report: &mut dyn FnMut(usize, f64, &LearnedWeights),
) {
    let n = data.len();
    if n == 0 || cfg.batch == 0 {
        return;
    }
    let dim = data.dim;
    let mut rng = SplitMix64(cfg.seed ^ 0x5u64.rotate_left(40));
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut m: Vec<Vec<f32>> = w.layers.iter().map(|l| vec![0.0; l.len()]).collect();
    let mut v = m.clone();
    let steps_per_epoch = n.div_ceil(cfg.batch);
    let total_steps = (steps_per_epoch * cfg.epochs).max(1);
    let mut step = 0usize;
    let threads = cfg.threads.max(1);
    let mut xb = vec![0.0f32; cfg.batch * dim];
    let mut ub = vec![0.0f32; cfg.batch * 2];
    for epoch in 0..cfg.epochs {
        for i in (1..n).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            order.swap(i, j);
        }
        let mut epoch_loss = 0.0f64;
        for b0 in (0..n).step_by(cfg.batch) {
            let rows = (n - b0).min(cfg.batch);
            for (r, &o) in order[b0..b0 + rows].iter().enumerate() {
                let o = o as usize;
                xb[r * dim..(r + 1) * dim].copy_from_slice(&data.features[o * dim..(o + 1) * dim]);
                ub[2 * r] = data.targets[2 * o];
                ub[2 * r + 1] = data.targets[2 * o + 1];
            }
            // Data-parallel gradient: thread t takes rows [t rows / T, (t + 1) rows / T); the
            // partial gradients are summed in thread order (deterministic).
            let wl = &*w;
            let (xb_ref, ub_ref) = (&xb, &ub);
            let parts: Vec<(f64, Vec<Vec<f32>>)> = std::thread::scope(|scope| {
                let handles: Vec<_> = (0..threads)
                    .map(|t| {
                        let (r0, r1) = (rows * t / threads, rows * (t + 1) / threads);
                        scope.spawn(move || {
                            let mut g: Vec<Vec<f32>> = wl.layers.iter().map(|l| vec![0.0; l.len()]).collect();
                            if r1 == r0 {
                                return (0.0, g);
                            }
                            let mut lg = |r: usize, p: [f32; 2], dp: &mut [f32; 2]| {
                                let u = [ub_ref[2 * (r0 + r)], ub_ref[2 * (r0 + r) + 1]];
                                circle_loss(p, u, dp)
                            };
                            let loss = mlp::backprop(
                                &wl.sizes,
                                &wl.layers,
                                &xb_ref[r0 * dim..r1 * dim],
                                r1 - r0,
                                &mut g,
                                &mut lg,
                            );
                            (loss, g)
                        })
                    })
                    .collect();
                handles
                    .into_iter()
                    .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                    .collect()
            });
            let mut grads: Vec<Vec<f32>> = w.layers.iter().map(|l| vec![0.0; l.len()]).collect();
            for (loss, g) in &parts {
                epoch_loss += loss;
                for (a, b) in grads.iter_mut().zip(g) {
                    for (x, y) in a.iter_mut().zip(b) {
                        *x += y;
                    }
                }
            }
            step += 1;
            let progress = step as f64 / total_steps as f64;
            let lr = cfg.lr * (0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * progress).cos())) as f32;
            let (b1, b2, eps) = (0.9f32, 0.999f32, 1e-8f32);
            let c1 = 1.0 - b1.powi(step as i32);
            let c2 = 1.0 - b2.powi(step as i32);
            let inv = 1.0 / rows as f32;
            for k in 0..w.layers.len() {
                for ((wv, g), (mv, vv)) in w.layers[k]
                    .iter_mut()
                    .zip(&grads[k])
                    .zip(m[k].iter_mut().zip(v[k].iter_mut()))
                {
                    let g = g * inv;
                    *mv = b1 * *mv + (1.0 - b1) * g;
                    *vv = b2 * *vv + (1.0 - b2) * g * g;
                    *wv -= lr * (*mv / c1) / ((*vv / c2).sqrt() + eps);
                }
            }
        }
        report(epoch, epoch_loss / n as f64, w);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn circle_loss_is_lowest_on_the_circle_and_gradient_matches() {
        let u = [2.0f32, 1.0];
        let mut dp = [0.0; 2];
        // p = u is the minimum (-1); along any ray from the centre u/2 the loss is lowest on the
        // circle (|p - u/2| = |u|/2), where the log term vanishes.
        assert!((circle_loss(u, u, &mut dp) + 1.0).abs() < 1e-5);
        let half = 0.5 * u[0].hypot(u[1]);
        for deg in [0.0f32, 40.0, 100.0, 170.0, 250.0] {
            let dir = [deg.to_radians().cos(), deg.to_radians().sin()];
            let at = |s: f32| {
                circle_loss(
                    [0.5 * u[0] + s * dir[0], 0.5 * u[1] + s * dir[1]],
                    u,
                    &mut [0.0; 2],
                )
            };
            let on = at(half);
            assert!(on >= -1.0 - 1e-5);
            for s in [0.3 * half, 0.8 * half, 1.2 * half, 3.0 * half] {
                assert!(at(s) > on, "{deg} deg, {s}");
            }
        }
        for p in [[0.3f32, -0.4], [1.5, 2.0], [-1.0, 0.2]] {
            circle_loss(p, u, &mut dp);
            for j in 0..2 {
                let mut q = p;
                q[j] += 1e-3;
                let mut q2 = p;
                q2[j] -= 1e-3;
                let fd = (circle_loss(q, u, &mut [0.0; 2]) - circle_loss(q2, u, &mut [0.0; 2])) / 2e-3;
                assert!((fd - dp[j]).abs() < 1e-2, "{p:?} {j}: {fd} vs {}", dp[j]);
            }
        }
    }
}
