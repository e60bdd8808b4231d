//! The learned normal-flow estimator (VecKM_flow style, METHOD_NOTES §2): a random-Fourier-feature
//! encoding of each event's spatio-temporal neighbourhood and a small bias-free MLP.
//!
//! # Encoding
//!
//! A slice `[t0, t1)` is processed as a whole (not causally): `tau = 2 (t - t0) / (t1 - t0)` in
//! `[0, 2)`, quantised to 1/2048 (4096 bins). The neighbours of event `i` are the events of the
//! slice (itself included) whose pixel is within the square window of half-width `r` pixels
//! (Chebyshev distance `<= r`) around its pixel, any polarity, any time of the slice. With the
//! frequency vectors `At, Ax, Ay` (`D` entries each, from the weights file) the feature is the
//! complex vector
//!
//! `F_i = sqrt(D) / N_i * sum_j exp(i ((tau_j - tau_i) At + (x_j - x_i) / r Ax + (y_j - y_i) / r Ay))`
//!
//! (`N_i` neighbours), given to the MLP as `[Re F_i, Im F_i]`. Because the phase is a difference,
//! the sum factors as `conj(z_i) * sum_j z_j` with `z_j = exp(i (tau_j At + x_j / r Ax + y_j / r Ay))`:
//! the `z` are products of tabulated per-column, per-row and per-time-bin factors, summed per
//! pixel, prefix-summed along each row, and the window sum of a pixel is `2 r + 1` differences of
//! row prefix sums. The cost per event is therefore independent of the number of neighbours.
//!
//! # Output
//!
//! The MLP's output is the normal flow in units of `r` pixels per unit of `tau` (`r` pixels per
//! half slice): `flow_px = out * 2 r / (t1 - t0)` pixels per second (x right, y down), converted to
//! normalized camera units per second with the camera Jacobian at the event's pixel
//! ([`jacobian_table`], undistortion included), as the plane fit does.
//!
//! # Ensemble and confidence
//!
//! With `ensemble = K > 1` the coordinates are also rotated by `k 360 / K` degrees (`k < K`; done
//! by rotating the spatial frequency vectors), each prediction rotated back, and the estimate is the
//! circular mean direction with the mean length. The confidence is the mean resultant length `R`
//! of the `K` unit directions (`1 - R` is the circular spread; 1 = all agree); with `K = 1` it is 1.
//! Events with fewer than `min_neighbours` neighbours, a zero or non-finite output, or a confidence
//! at or below `min_confidence` are invalid (flow 0, confidence 0).

use std::f64::consts::PI;

use evseg_schemas::{CameraInfo, Events, NormalFlow};

use crate::estimator::{EstimatorError, PixelEstimate, check_columns, jacobian_table};
use crate::mlp;
use crate::weights::LearnedWeights;

/// Time bins of `tau` over a slice (`tau` in `[0, 2)` is quantised to `1 / (TAU_BINS / 2)`).
pub const TAU_BINS: usize = 4096;
const TAU_FINE: usize = 64;
/// Rows of the MLP batches.
const BATCH: usize = 64;

/// Receives batches of encoded events: `(positions in the pixel order, event indices, features)`.
type Sink<'a> = dyn FnMut(&[u32], &[u32], &[f32]) + 'a;

/// Settings of [`LearnedEstimator`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnedParams {
    /// Window half-width, pixels; 0 = the radius the weights were trained with (recommended).
    pub radius: usize,
    /// Rotated copies in the ensemble, `1..=16`. Default 1 (no ensemble, fastest).
    pub ensemble: usize,
    /// Fewest neighbours (the event included) for an estimate. Default 5.
    pub min_neighbours: usize,
    /// Estimates with a confidence at or below this are invalid, `[0, 1)`. Default 0.7 (the notes
    /// drop a circular spread above 0.3); with `ensemble = 1` every confidence is 1.
    pub min_confidence: f32,
    /// Worker threads per slice, `>= 1`. Default 2.
    pub threads: usize,
}

impl Default for LearnedParams {
    fn default() -> Self {
        Self {
            radius: 0,
            ensemble: 1,
            min_neighbours: 5,
            min_confidence: 0.7,
            threads: 2,
        }
    }
}

/// Errors of the learned estimator.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LearnedError {
    /// Bad settings.
    #[error("learned normal flow: {0}")]
    Params(String),
    /// Inconsistent weights.
    #[error("learned normal flow: inconsistent weights: {0}")]
    Weights(String),
    /// Bad events or camera.
    #[error(transparent)]
    Estimator(#[from] EstimatorError),
}

/// Per-rotation tables: `exp(i ax' x / r)` per column and `exp(i ay' y / r)` per row, each entry
/// `[re_0..re_{D-1}, im_0..im_{D-1}]`.
#[derive(Debug, Clone)]
struct RotTables {
    cos: f32,
    sin: f32,
    tx: Vec<f32>,
    ty: Vec<f32>,
}

/// The events of a slice grouped by pixel.
#[derive(Debug, Clone, Default)]
struct Groups {
    /// Pixel keys `y * width + x`, sorted (the compact pixel order).
    keys: Vec<u32>,
    /// Per sensor row `y`, the first compact pixel of the row (`height + 1` entries).
    row_start: Vec<u32>,
    /// Column of each compact pixel.
    px: Vec<u16>,
    /// Events of compact pixel `k`: `ev_idx[ev_off[k]..ev_off[k + 1]]`.
    ev_off: Vec<u32>,
    /// Event indices grouped by pixel.
    ev_idx: Vec<u32>,
    /// Time bin of each event (by event index).
    qbin: Vec<u16>,
    /// Inclusive prefix sum of the per-pixel event counts along each row.
    cnt_prefix: Vec<u32>,
}

/// Learned per-event normal flow (see the module docs). Stateless between slices apart from
/// buffers.
#[derive(Debug, Clone)]
pub struct LearnedEstimator {
    weights: LearnedWeights,
    params: LearnedParams,
    camera: CameraInfo,
    width: usize,
    height: usize,
    radius: usize,
    d: usize,
    rot: Vec<RotTables>,
    /// `exp(i at c TAU_FINE / (TAU_BINS / 2))` per coarse bin `c`.
    tc: Vec<f32>,
    /// `exp(i at f / (TAU_BINS / 2))` per fine bin `f`.
    tf: Vec<f32>,
    jacobian: Vec<[f32; 4]>,
    slot: Vec<u32>,
    groups: Groups,
    acc: Vec<f32>,
}

fn exp_table(freqs: &[f32], n: usize, step: f64) -> Vec<f32> {
    let d = freqs.len();
    let mut t = vec![0.0f32; n * 2 * d];
    for k in 0..n {
        for (j, &f) in freqs.iter().enumerate() {
            let ph = f64::from(f) * k as f64 * step;
            t[k * 2 * d + j] = ph.cos() as f32;
            t[k * 2 * d + d + j] = ph.sin() as f32;
        }
    }
    t
}

/// `a * b` for complex vectors `[re.., im..]` of length `d`, into `out`.
#[inline(always)]
fn cmul(a: &[f32], b: &[f32], out: &mut [f32], d: usize) {
    let (ar, ai) = a.split_at(d);
    let (br, bi) = b.split_at(d);
    let (or, oi) = out.split_at_mut(d);
    for j in 0..d {
        or[j] = ar[j] * br[j] - ai[j] * bi[j];
        oi[j] = ar[j] * bi[j] + ai[j] * br[j];
    }
}

impl LearnedEstimator {
    /// An estimator for `camera` with `weights`.
    pub fn new(
        camera: &CameraInfo,
        weights: LearnedWeights,
        params: LearnedParams,
    ) -> Result<Self, LearnedError> {
        weights.validate().map_err(LearnedError::Weights)?;
        if params.ensemble == 0 || params.ensemble > 16 {
            return Err(LearnedError::Params(format!(
                "ensemble {} outside 1..=16",
                params.ensemble
            )));
        }
        if params.threads == 0 || params.threads > 64 {
            return Err(LearnedError::Params(format!(
                "threads {} outside 1..=64",
                params.threads
            )));
        }
        if !(0.0..1.0).contains(&params.min_confidence) {
            return Err(LearnedError::Params(format!(
                "min_confidence {} outside [0, 1)",
                params.min_confidence
            )));
        }
        if params.radius > 64 {
            return Err(LearnedError::Params(format!(
                "radius {} px above 64",
                params.radius
            )));
        }
        let (width, height) = (camera.width as usize, camera.height as usize);
        if width == 0 || height == 0 {
            return Err(EstimatorError::EmptySensor {
                width: camera.width,
                height: camera.height,
            }
            .into());
        }
        let radius = if params.radius == 0 {
            (weights.radius_px.round() as usize).max(1)
        } else {
            params.radius
        };
        let d = weights.d();
        let k = params.ensemble;
        let rot = (0..k)
            .map(|i| {
                let th = 2.0 * PI * i as f64 / k as f64;
                let (s, c) = th.sin_cos();
                let ax: Vec<f32> = (0..d)
                    .map(|j| (f64::from(weights.ax[j]) * c + f64::from(weights.ay[j]) * s) as f32)
                    .collect();
                let ay: Vec<f32> = (0..d)
                    .map(|j| (-f64::from(weights.ax[j]) * s + f64::from(weights.ay[j]) * c) as f32)
                    .collect();
                RotTables {
                    cos: c as f32,
                    sin: s as f32,
                    tx: exp_table(&ax, width, 1.0 / radius as f64),
                    ty: exp_table(&ay, height, 1.0 / radius as f64),
                }
            })
            .collect();
        let half = (TAU_BINS / 2) as f64;
        let tc = exp_table(&weights.at, TAU_BINS / TAU_FINE, TAU_FINE as f64 / half);
        let tf = exp_table(&weights.at, TAU_FINE, 1.0 / half);
        Ok(Self {
            jacobian: jacobian_table(camera),
            camera: camera.clone(),
            width,
            height,
            radius,
            d,
            rot,
            tc,
            tf,
            weights,
            params,
            slot: vec![u32::MAX; width * height],
            groups: Groups::default(),
            acc: Vec::new(),
        })
    }

    /// The camera the estimator was built for.
    pub fn camera(&self) -> &CameraInfo {
        &self.camera
    }

    /// The settings in use.
    pub fn params(&self) -> &LearnedParams {
        &self.params
    }

    /// The weights in use.
    pub fn weights(&self) -> &LearnedWeights {
        &self.weights
    }

    /// The window half-width in use, pixels.
    pub fn radius(&self) -> usize {
        self.radius
    }

    /// Groups the events of the slice `[t0, t1)` (seconds) by pixel; events outside the sensor or
    /// with a non-finite time are left out. Returns the slice duration used, seconds.
    fn group(&mut self, events: &Events, t0: f64, t1: f64) -> f64 {
        let n = events.len();
        let w = self.width;
        let g = &mut self.groups;
        g.keys.clear();
        g.qbin.clear();
        g.qbin.resize(n, 0);
        let mut span = t1 - t0;
        let mut start = t0;
        if !(span.is_finite() && span > 0.0 && start.is_finite()) {
            let (lo, hi) = events
                .t
                .iter()
                .filter(|t| t.is_finite())
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &t| {
                    (a.min(t), b.max(t))
                });
            start = if lo.is_finite() { lo } else { 0.0 };
            span = if hi > lo { (hi - lo) * (1.0 + 1e-9) } else { 1e-3 };
        }
        let scale = TAU_BINS as f64 / span;
        let mut counts: Vec<u32> = Vec::new();
        for i in 0..n {
            let (x, y, t) = (events.x[i] as usize, events.y[i] as usize, events.t[i]);
            if x >= w || y >= self.height || !t.is_finite() {
                continue;
            }
            g.qbin[i] = ((t - start) * scale).floor().clamp(0.0, (TAU_BINS - 1) as f64) as u16;
            let key = y * w + x;
            let s = &mut self.slot[key];
            if *s == u32::MAX {
                *s = g.keys.len() as u32;
                g.keys.push(key as u32);
                counts.push(0);
            }
            counts[*s as usize] += 1;
        }
        // Compact order = sorted keys; remap the slots.
        let mut order: Vec<u32> = (0..g.keys.len() as u32).collect();
        order.sort_unstable_by_key(|&k| g.keys[k as usize]);
        let u = order.len();
        let mut sorted_keys = Vec::with_capacity(u);
        g.ev_off.clear();
        g.ev_off.reserve(u + 1);
        g.ev_off.push(0);
        for &o in &order {
            let key = g.keys[o as usize];
            self.slot[key as usize] = sorted_keys.len() as u32;
            sorted_keys.push(key);
            let last = *g.ev_off.last().unwrap_or(&0);
            g.ev_off.push(last + counts[o as usize]);
        }
        g.keys = sorted_keys;
        let total = *g.ev_off.last().unwrap_or(&0) as usize;
        g.ev_idx.clear();
        g.ev_idx.resize(total, 0);
        let mut fill: Vec<u32> = g.ev_off[..u].to_vec();
        for i in 0..n {
            let (x, y, t) = (events.x[i] as usize, events.y[i] as usize, events.t[i]);
            if x >= w || y >= self.height || !t.is_finite() {
                continue;
            }
            let k = self.slot[y * w + x] as usize;
            g.ev_idx[fill[k] as usize] = i as u32;
            fill[k] += 1;
        }
        // Rows, columns, count prefix sums; reset the slots.
        g.row_start.clear();
        g.row_start.resize(self.height + 1, 0);
        g.px.clear();
        g.cnt_prefix.clear();
        let mut row = 0usize;
        for (k, &key) in g.keys.iter().enumerate() {
            let (y, x) = (key as usize / w, key as usize % w);
            while row < y {
                row += 1;
                g.row_start[row] = k as u32;
            }
            g.px.push(x as u16);
            let c = g.ev_off[k + 1] - g.ev_off[k];
            let prev = if k > 0 && (g.keys[k - 1] as usize / w) == y {
                g.cnt_prefix[k - 1]
            } else {
                0
            };
            g.cnt_prefix.push(prev + c);
            self.slot[key as usize] = u32::MAX;
        }
        while row < self.height {
            row += 1;
            g.row_start[row] = u as u32;
        }
        span
    }

    /// Fills `self.acc` with the row prefix sums of `sum_j z_j` per pixel for rotation `r`.
    fn accumulate(&mut self, r: usize) {
        let d = self.d;
        let g = &self.groups;
        let u = g.keys.len();
        self.acc.clear();
        self.acc.resize(u * 2 * d, 0.0);
        let rt = &self.rot[r];
        let mut s = vec![0.0f32; 2 * d];
        let mut tt = vec![0.0f32; 2 * d];
        let mut sxy = vec![0.0f32; 2 * d];
        for k in 0..u {
            s.fill(0.0);
            for &e in &g.ev_idx[g.ev_off[k] as usize..g.ev_off[k + 1] as usize] {
                let q = g.qbin[e as usize] as usize;
                let (c, f) = (q / TAU_FINE, q % TAU_FINE);
                cmul(
                    &self.tc[c * 2 * d..(c + 1) * 2 * d],
                    &self.tf[f * 2 * d..(f + 1) * 2 * d],
                    &mut tt,
                    d,
                );
                for (a, b) in s.iter_mut().zip(&tt) {
                    *a += b;
                }
            }
            let key = g.keys[k] as usize;
            let (y, x) = (key / self.width, key % self.width);
            cmul(
                &rt.tx[x * 2 * d..(x + 1) * 2 * d],
                &rt.ty[y * 2 * d..(y + 1) * 2 * d],
                &mut sxy,
                d,
            );
            let (head, tail) = self.acc.split_at_mut(k * 2 * d);
            let dst = &mut tail[..2 * d];
            cmul(&sxy, &s, dst, d);
            if k > 0 && g.keys[k - 1] as usize / self.width == y {
                let prev = &head[(k - 1) * 2 * d..];
                for (a, b) in dst.iter_mut().zip(prev) {
                    *a += b;
                }
            }
        }
    }

    /// Calls `sink(positions, event_indices, features)` with batches of at most 64 encoded
    /// events of the compact pixels `k0..k1`, for rotation `r`, skipping events with fewer than
    /// `min_neighbours` neighbours; `positions` index `ev_idx`.
    fn encode_range(&self, r: usize, k0: usize, k1: usize, sink: &mut Sink<'_>) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("fma") {
                // SAFETY: the CPU supports the features the function is compiled for.
                unsafe { self.encode_range_avx512(r, k0, k1, sink) };
                return;
            }
            if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma") {
                // SAFETY: the CPU supports the features the function is compiled for.
                unsafe { self.encode_range_avx2(r, k0, k1, sink) };
                return;
            }
        }
        self.encode_range_generic(r, k0, k1, sink);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx2,fma")]
    fn encode_range_avx512(&self, r: usize, k0: usize, k1: usize, sink: &mut Sink<'_>) {
        self.encode_range_generic(r, k0, k1, sink);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2,fma")]
    fn encode_range_avx2(&self, r: usize, k0: usize, k1: usize, sink: &mut Sink<'_>) {
        self.encode_range_generic(r, k0, k1, sink);
    }

    #[inline(always)]
    fn encode_range_generic(&self, r: usize, k0: usize, k1: usize, sink: &mut Sink<'_>) {
        let d = self.d;
        let g = &self.groups;
        let rt = &self.rot[r];
        let rad = self.radius;
        let sqrt_d = (d as f32).sqrt();
        let mut wsum = vec![0.0f32; 2 * d];
        let mut sxy = vec![0.0f32; 2 * d];
        let mut z = vec![0.0f32; 2 * d];
        let mut tt = vec![0.0f32; 2 * d];
        let mut feats = vec![0.0f32; BATCH * 2 * d];
        let mut pos: Vec<u32> = Vec::with_capacity(BATCH);
        let min_n = self.params.min_neighbours.max(1) as u32;
        let mut cur_y = usize::MAX;
        let mut lo_c = vec![0usize; 2 * rad + 1];
        let mut hi_c = vec![0usize; 2 * rad + 1];
        for k in k0..k1 {
            let key = g.keys[k] as usize;
            let (y, x) = (key / self.width, key % self.width);
            let (xl, xh) = (x.saturating_sub(rad) as u16, (x + rad).min(self.width - 1) as u16);
            // Per window row, cursors [lo, hi) into the row's pixels with x in [xl, xh]; the
            // pixels come in (y, x) order, so within a centre row both only move forward.
            if y != cur_y {
                cur_y = y;
                for (j, (lo, hi)) in lo_c.iter_mut().zip(hi_c.iter_mut()).enumerate() {
                    let yy = (y + j).checked_sub(rad).filter(|&v| v < self.height);
                    let start = yy.map_or(0, |v| g.row_start[v] as usize);
                    *lo = start;
                    *hi = start;
                }
            }
            wsum.fill(0.0);
            let mut n = 0u32;
            for (j, (lo, hi)) in lo_c.iter_mut().zip(hi_c.iter_mut()).enumerate() {
                let Some(yy) = (y + j).checked_sub(rad).filter(|&v| v < self.height) else {
                    continue;
                };
                let (rs, re) = (g.row_start[yy] as usize, g.row_start[yy + 1] as usize);
                while *lo < re && g.px[*lo] < xl {
                    *lo += 1;
                }
                if *hi < *lo {
                    *hi = *lo;
                }
                while *hi < re && g.px[*hi] <= xh {
                    *hi += 1;
                }
                if *hi <= *lo {
                    continue;
                }
                let top = *hi - 1;
                n += g.cnt_prefix[top];
                for (a, b) in wsum.iter_mut().zip(&self.acc[top * 2 * d..(top + 1) * 2 * d]) {
                    *a += b;
                }
                if *lo > rs {
                    let bot = *lo - 1;
                    n -= g.cnt_prefix[bot];
                    for (a, b) in wsum.iter_mut().zip(&self.acc[bot * 2 * d..(bot + 1) * 2 * d]) {
                        *a -= b;
                    }
                }
            }
            if n < min_n {
                continue;
            }
            let scale = sqrt_d / n as f32;
            cmul(
                &rt.tx[x * 2 * d..(x + 1) * 2 * d],
                &rt.ty[y * 2 * d..(y + 1) * 2 * d],
                &mut sxy,
                d,
            );
            for p in g.ev_off[k]..g.ev_off[k + 1] {
                let e = g.ev_idx[p as usize] as usize;
                let q = g.qbin[e] as usize;
                let (c, f) = (q / TAU_FINE, q % TAU_FINE);
                cmul(
                    &self.tc[c * 2 * d..(c + 1) * 2 * d],
                    &self.tf[f * 2 * d..(f + 1) * 2 * d],
                    &mut tt,
                    d,
                );
                cmul(&sxy, &tt, &mut z, d);
                // feature = conj(z) * wsum * scale
                let row = pos.len();
                let (fr, fi) = feats[row * 2 * d..(row + 1) * 2 * d].split_at_mut(d);
                for j in 0..d {
                    let (zr, zi) = (z[j], -z[j + d]);
                    let (wr, wi) = (wsum[j], wsum[j + d]);
                    fr[j] = (zr * wr - zi * wi) * scale;
                    fi[j] = (zr * wi + zi * wr) * scale;
                }
                pos.push(p);
                if pos.len() == BATCH {
                    let idx: Vec<u32> = pos.iter().map(|&p| g.ev_idx[p as usize]).collect();
                    sink(&pos, &idx, &feats[..BATCH * 2 * d]);
                    pos.clear();
                }
            }
        }
        if !pos.is_empty() {
            let idx: Vec<u32> = pos.iter().map(|&p| g.ev_idx[p as usize]).collect();
            sink(&pos, &idx, &feats[..pos.len() * 2 * d]);
        }
    }

    /// The encoded features of the events of the slice `[t0, t1)` for which
    /// `select(event_index)` holds and that have enough neighbours, with the coordinates rotated
    /// by `rotation * 360 / ensemble` degrees (`rotation < ensemble`; the network then sees the
    /// flow `R u`): returns their indices and a row-major `indices.len() x 2 D` feature matrix.
    /// Used for training.
    pub fn features(
        &mut self,
        events: &Events,
        t0: f64,
        t1: f64,
        rotation: usize,
        select: &dyn Fn(usize) -> bool,
    ) -> Result<(Vec<u32>, Vec<f32>), LearnedError> {
        check_columns(events)?;
        if rotation >= self.rot.len() {
            return Err(LearnedError::Params(format!(
                "rotation {rotation} of an ensemble of {}",
                self.rot.len()
            )));
        }
        let r = rotation;
        self.group(events, t0, t1);
        self.accumulate(r);
        let d2 = 2 * self.d;
        let (mut idx_out, mut feat_out) = (Vec::new(), Vec::new());
        let u = self.groups.keys.len();
        self.encode_range(r, 0, u, &mut |_pos, idx, feats| {
            for (r, &e) in idx.iter().enumerate() {
                if select(e as usize) {
                    idx_out.push(e);
                    feat_out.extend_from_slice(&feats[r * d2..(r + 1) * d2]);
                }
            }
        });
        Ok((idx_out, feat_out))
    }

    /// The rotation angle of ensemble member `r`, as `(cos, sin)`.
    pub fn rotation(&self, r: usize) -> Option<(f32, f32)> {
        self.rot.get(r).map(|t| (t.cos, t.sin))
    }

    /// Estimates the events of the slice `[t0, t1)` in pixels per second, in the pixel order
    /// of the groups (`ev_idx`); returns the slice duration used, the flows and confidences.
    fn estimate_sorted(&mut self, events: &Events, t0: f64, t1: f64) -> (f64, Vec<[f32; 2]>, Vec<f32>) {
        let span = self.group(events, t0, t1);
        let total = self.groups.ev_idx.len();
        let k_rot = self.rot.len();
        // Per position in ev_idx: sum of unit vectors, sum of lengths; NaN = invalid.
        let mut su = vec![[0.0f32; 2]; total];
        let mut sm = vec![0.0f32; total];
        let mut ok = vec![true; total];
        let mut seen = vec![false; total];
        let mut out = vec![[f32::NAN; 2]; total];
        for r in 0..k_rot {
            self.accumulate(r);
            out.fill([f32::NAN; 2]);
            let this = &*self;
            let u = this.groups.keys.len();
            let threads = this.params.threads.min(u.max(1));
            // Balanced split of the pixels by event count.
            let mut bounds = vec![0usize];
            for t in 1..threads {
                let target = (total * t / threads) as u32;
                bounds.push(this.groups.ev_off.partition_point(|&o| o < target).min(u));
            }
            bounds.push(u);
            std::thread::scope(|scope| {
                let mut rest: &mut [[f32; 2]] = &mut out;
                let mut offset = 0usize;
                for t in 0..threads {
                    let (k0, k1) = (bounds[t], bounds[t + 1].max(bounds[t]));
                    let p1 = this.groups.ev_off[k1] as usize;
                    let (mine, tail) = std::mem::take(&mut rest).split_at_mut(p1 - offset);
                    rest = tail;
                    let base = offset;
                    offset = p1;
                    let mut work = move || {
                        let w = &this.weights;
                        let mut scratch = mlp::Scratch::default();
                        let mut y = vec![0.0f32; BATCH * 2];
                        this.encode_range(r, k0, k1, &mut |pos, _idx, feats| {
                            let rows = pos.len();
                            mlp::forward(&w.sizes, &w.layers, feats, rows, &mut y, &mut scratch);
                            for (i, &p) in pos.iter().enumerate() {
                                mine[p as usize - base] = [y[2 * i], y[2 * i + 1]];
                            }
                        });
                    };
                    if t + 1 == threads {
                        work();
                    } else {
                        scope.spawn(work);
                    }
                }
            });
            let (c, s) = (self.rot[r].cos, self.rot[r].sin);
            for p in 0..total {
                let [a, b] = out[p];
                // Back from the rotated frame: R(theta)^T.
                let v = [c * a + s * b, -s * a + c * b];
                let m = v[0].hypot(v[1]);
                if !(m > 0.0 && m.is_finite()) {
                    ok[p] = false;
                    continue;
                }
                seen[p] = true;
                su[p][0] += v[0] / m;
                su[p][1] += v[1] / m;
                sm[p] += m;
            }
        }
        let scale = (2.0 * self.radius as f64 / span) as f32;
        let kf = k_rot as f32;
        let mut flow = vec![[0.0f32; 2]; total];
        let mut conf = vec![0.0f32; total];
        for p in 0..total {
            if !(ok[p] && seen[p]) {
                continue;
            }
            let r_len = su[p][0].hypot(su[p][1]);
            let c = if k_rot == 1 { 1.0 } else { (r_len / kf).min(1.0) };
            if r_len <= 0.0 || r_len.is_nan() || c <= self.params.min_confidence {
                continue;
            }
            let m = sm[p] / kf * scale;
            flow[p] = [su[p][0] / r_len * m, su[p][1] / r_len * m];
            conf[p] = c;
        }
        (span, flow, conf)
    }

    /// Estimates the normal flow of the events of the slice `[t0, t1)` (seconds) in pixels per
    /// second, aligned with the events (invalid: flow 0, confidence 0).
    pub fn process_pixels(
        &mut self,
        events: &Events,
        t0: f64,
        t1: f64,
    ) -> Result<Vec<PixelEstimate>, LearnedError> {
        check_columns(events)?;
        let (_, flow, conf) = self.estimate_sorted(events, t0, t1);
        let mut res = vec![PixelEstimate::INVALID; events.len()];
        for (p, &e) in self.groups.ev_idx.iter().enumerate() {
            if conf[p] > 0.0 {
                res[e as usize] = PixelEstimate {
                    flow_px: [f64::from(flow[p][0]), f64::from(flow[p][1])],
                    confidence: f64::from(conf[p]),
                };
            }
        }
        Ok(res)
    }

    /// Estimates the normal flow of the events of the slice `[t0, t1)` (seconds) in normalized
    /// camera units per second, aligned with the events (invalid: flow 0, confidence 0). When
    /// `t1 <= t0` or either is not finite, the events' own time span is used as the slice.
    pub fn process(&mut self, events: &Events, t0: f64, t1: f64) -> Result<NormalFlow, LearnedError> {
        let mut out = NormalFlow::default();
        self.process_into(events, t0, t1, &mut out)?;
        Ok(out)
    }

    /// As [`process`](Self::process), writing into `out` (cleared first).
    pub fn process_into(
        &mut self,
        events: &Events,
        t0: f64,
        t1: f64,
        out: &mut NormalFlow,
    ) -> Result<(), LearnedError> {
        check_columns(events)?;
        let n = events.len();
        let (_, flow, conf) = self.estimate_sorted(events, t0, t1);
        out.reset_invalid(n);
        for (p, &e) in self.groups.ev_idx.iter().enumerate() {
            if conf[p] > 0.0 {
                let e = e as usize;
                let idx = events.y[e] as usize * self.width + events.x[e] as usize;
                let [j00, j01, j10, j11] = self.jacobian[idx];
                let [fu, fv] = flow[p];
                out.nx[e] = j00 * fu + j01 * fv;
                out.ny[e] = j10 * fu + j11 * fv;
                out.confidence[e] = conf[p];
            }
        }
        Ok(())
    }
}

/// Draws `D` frequency vectors `(At, Ax, Ay)`: per axis the `D` standard normal quantiles at
/// `(k + 1/2) / D`, scaled by `alpha_t` (time) or `alpha_xy` (space) and shuffled with a
/// SplitMix64 stream seeded by `seed` ("alpha-scaled normal quantiles", METHOD_NOTES §2).
pub fn draw_frequencies(d: usize, alpha_xy: f32, alpha_t: f32, seed: u64) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let mut rng = SplitMix64(seed ^ 0x5eed_f00d_cafe_0001);
    let q: Vec<f64> = (0..d)
        .map(|k| normal_quantile((k as f64 + 0.5) / d as f64))
        .collect();
    let mut axis = |alpha: f32| {
        let mut v: Vec<f32> = q.iter().map(|&x| (x * f64::from(alpha)) as f32).collect();
        for i in (1..v.len()).rev() {
            let j = (rng.next_u64() % (i as u64 + 1)) as usize;
            v.swap(i, j);
        }
        v
    };
    let at = axis(alpha_t);
    let ax = axis(alpha_xy);
    let ay = axis(alpha_xy);
    (at, ax, ay)
}

/// SplitMix64 pseudo-random generator (deterministic across platforms).
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Standard normal (Box-Muller).
    pub fn normal(&mut self) -> f64 {
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
    }
}

/// Inverse of the standard normal CDF (Acklam's rational approximation, relative error < 1.2e-9),
/// for `p` in `(0, 1)`.
pub fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] = [
        7.784_695_709_041_462e-3,
        3.224_671_290_700_398e-1,
        2.445_134_137_142_996,
        3.754_408_661_907_416,
    ];
    let plow = 0.02425;
    if p < plow {
        let q = (-2.0 * p.ln()).sqrt();
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    } else if p <= 1.0 - plow {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    } else {
        -normal_quantile(1.0 - p)
    }
}
