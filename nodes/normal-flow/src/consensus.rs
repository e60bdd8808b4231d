//! Neighbourhood consensus of normal flow: repairs the heavy tail of per-event estimates.
//!
//! A local plane fit's normal-flow *length* is grossly off for a minority of events (a
//! neighbourhood holding pixels of an earlier edge, a direction a few degrees off while the flow
//! along the edge is large, a window mixing two motions): on the simulator 11-15 % of the
//! background's estimates were more than 30 % off, a third of them with the wrong sign. Those
//! decide most of the segmentation's and the egomotion's error: in the hierarchical merger's
//! `examples/method_on_sim.rs`, replacing only those lengths by the true ones (keeping the
//! estimated directions; `FLOW=truemag DROPTAIL=-0.3`) raised the IoU about as much as
//! replacing all lengths (one-object 0.42 -> 0.61, two-objects 0.47 -> 0.65, median direction
//! error 13-25 -> 4-6 deg), while dropping them lost most of that gain.
//!
//! The events around an event (the 3 x 3 block of `cell_px` grid cells around its own cell,
//! same slice) that move with one 2-D image flow `u` have normal flows `n_j = n0_j . u`; `u` is
//! fitted to them by least squares (weighted by the estimator's confidence; ridge-regularized,
//! since the edges of a small block are often parallel and `u` is then known only across them,
//! which is all `n0_i . u` needs). An event whose own length differs from the prediction
//! `n0_i . u` by more than `max_deviation` of it takes the prediction, keeping its direction (a
//! negative prediction turns the vector round: the sign was wrong). Events that are outliers
//! against the first prediction are left out of the second, which decides. Cost: six sums per
//! cell, the 3 x 3 block sums once per cell, one block lookup per event.

use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, NodeConfig};
use evseg_schemas::{Events, NormalFlow, Slice};

/// Settings of [`consensus`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConsensusParams {
    /// Side of the grid cells, pixels; an event's neighbourhood is the 3 x 3 block of cells
    /// around its own (a window of `3 cell_px` pixels). 0 = off. Default 6 (18 px): the
    /// hierarchical merger's `examples/method_on_sim.rs` (3 s, bench seeds, flow `dt_max` 100
    /// ms, all estimates) was flat over 5-8 px cells and 4-10 px exact windows (IoU one-object
    /// / two-objects / high-contrast / enter-leave 0.505 / 0.584 / 0.444 / 0.566 at 5 px, 0.499 /
    /// 0.586 / 0.469 / 0.580 at 6, 0.510 / 0.618 / 0.455 / 0.579 at 8, against 0.463 / 0.580 /
    /// 0.388 / 0.557 off); the smaller end of the flat part, since a larger neighbourhood mixes
    /// more of a small object's flow with the background's. `evseg bench` at 8: IoU mask 42.90
    /// % against 42.53 % at 6 (noise).
    pub cell_px: u16,
    /// Fewest valid neighbours for a prediction (default 8: a 2-D flow from fewer is itself
    /// noisy; a 30 ms slice has tens of events in an 18 px block along an edge).
    pub min_neighbours: usize,
    /// Relative deviation `|n_i - n0_i . u| / |n0_i . u|` above which the event takes the
    /// prediction. Default 0.3: the median relative length error of the plane fit is 3-7 %
    /// (crate README), so 0.3 touches only the gross errors; 0.2 scored lower on every scene
    /// tried (`method_on_sim`, same set as `cell_px`: 0.496 / 0.569 / 0.449 / 0.562).
    pub max_deviation: f64,
    /// ...and by more than this absolute amount, normalized units/s: near-zero predictions
    /// (edges almost parallel to the flow) make the relative test meaningless. Default 0.002
    /// (1 px/s at a 500 px focal length, far below any estimator's accuracy).
    pub min_deviation: f64,
    /// Ridge weight relative to the summed neighbour weight (default 1e-3: only keeps the 2x2
    /// solve defined when every normal in the block is parallel; it shrinks the fitted flow by
    /// about this fraction).
    pub ridge: f64,
}

impl Default for ConsensusParams {
    fn default() -> Self {
        Self {
            cell_px: 6,
            min_neighbours: 8,
            max_deviation: 0.3,
            min_deviation: 0.002,
            ridge: 1e-3,
        }
    }
}

impl ConsensusParams {
    /// Checks the ranges: `max_deviation`, `min_deviation` and `ridge` finite and >= 0.
    pub fn validate(&self) -> Result<(), evseg_schemas::params::ParamError> {
        use evseg_schemas::params::finite_non_negative as nonneg;
        nonneg("consensus_max_deviation", self.max_deviation)?;
        nonneg("consensus_ridge", self.ridge)?;
        nonneg("consensus_min_deviation", self.min_deviation)?;
        Ok(())
    }
}

/// Declares the consensus parameters (`consensus_*`) on a normal-flow node's description `d`,
/// with the defaults of `defaults`; one block for every estimator node.
pub fn describe_consensus(d: Describe, defaults: &ConsensusParams) -> Describe {
    d.param(
        "consensus_cell_px",
        u64::from(defaults.cell_px),
        "neighbourhood consensus: grid cell, pixels (neighbourhood = 3x3 cells); 0 = off",
    )
    .param(
        "consensus_min_neighbours",
        defaults.min_neighbours as u64,
        "neighbourhood consensus: fewest valid neighbours for a prediction",
    )
    .param(
        "consensus_max_deviation",
        defaults.max_deviation,
        "neighbourhood consensus: relative deviation from the neighbours' prediction above which an estimate's length is replaced",
    )
    .param(
        "consensus_min_deviation",
        defaults.min_deviation,
        "neighbourhood consensus: ...and by more than this, normalized units/s",
    )
    .param(
        "consensus_ridge",
        defaults.ridge,
        "neighbourhood consensus: ridge of the local 2-D flow fit, relative to the summed weight",
    )
}

/// Reads the parameters declared by [`describe_consensus`] from the node's config (the launcher
/// fills in the defaults) and checks their ranges ([`ConsensusParams::validate`]).
pub fn consensus_from_config(cfg: &NodeConfig) -> Result<ConsensusParams, BoxError> {
    let p = ConsensusParams {
        cell_px: cfg.param("consensus_cell_px")?,
        min_neighbours: cfg.param("consensus_min_neighbours")?,
        max_deviation: cfg.param("consensus_max_deviation")?,
        min_deviation: cfg.param("consensus_min_deviation")?,
        ridge: cfg.param("consensus_ridge")?,
    };
    p.validate()?;
    Ok(p)
}

/// What [`consensus`] did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ConsensusStats {
    /// Valid events seen.
    pub valid: usize,
    /// Events whose length was replaced.
    pub replaced: usize,
}

/// Weighted normal-equation sums of one cell: `sum w n0 n0^T` (xx, xy, yy), `sum w n0 n`
/// (x, y), `sum w`, count.
#[derive(Debug, Clone, Copy, Default)]
struct Sums {
    xx: f64,
    xy: f64,
    yy: f64,
    bx: f64,
    by: f64,
    w: f64,
    count: usize,
}

impl Sums {
    fn add(&mut self, n0: [f64; 2], len: f64, w: f64, sign: f64) {
        let [ux, uy] = n0;
        self.xx += sign * w * ux * ux;
        self.xy += sign * w * ux * uy;
        self.yy += sign * w * uy * uy;
        self.bx += sign * w * ux * len;
        self.by += sign * w * uy * len;
        self.w += sign * w;
        if sign > 0.0 {
            self.count += 1;
        } else {
            self.count = self.count.saturating_sub(1);
        }
    }

    fn merge(&mut self, o: &Sums) {
        self.xx += o.xx;
        self.xy += o.xy;
        self.yy += o.yy;
        self.bx += o.bx;
        self.by += o.by;
        self.w += o.w;
        self.count += o.count;
    }
}

/// [`consensus`] on a slice's events and sensor: what the estimator nodes run on each slice.
pub fn consensus_on_slice(slice: &Slice, flow: &mut NormalFlow, params: &ConsensusParams) -> ConsensusStats {
    consensus(
        &slice.events,
        flow,
        slice.camera.width,
        slice.camera.height,
        params,
    )
}

/// Replaces outlying normal-flow lengths of `flow` (aligned with `events`, a `width` x `height`
/// sensor) by their neighbourhood's prediction; see the module docs.
pub fn consensus(
    events: &Events,
    flow: &mut NormalFlow,
    width: u16,
    height: u16,
    params: &ConsensusParams,
) -> ConsensusStats {
    let n = events.len();
    let mut stats = ConsensusStats::default();
    if params.cell_px == 0 || flow.nx.len() != n || flow.ny.len() != n || flow.confidence.len() != n {
        return stats;
    }
    let cell = usize::from(params.cell_px);
    let (cw, ch) = (
        usize::from(width).div_ceil(cell),
        usize::from(height).div_ceil(cell),
    );
    let cell_of = |i: usize| -> Option<(usize, usize)> {
        let (x, y) = (usize::from(events.x[i]) / cell, usize::from(events.y[i]) / cell);
        (x < cw && y < ch).then_some((x, y))
    };
    let mut len = vec![0.0f64; n];
    let mut n0 = vec![[0.0f64; 2]; n];
    let mut weight = vec![0.0f64; n];
    let mut grid = vec![Sums::default(); cw * ch];
    for i in 0..n {
        let (nx, ny) = (f64::from(flow.nx[i]), f64::from(flow.ny[i]));
        let l = (nx * nx + ny * ny).sqrt();
        let w = f64::from(flow.confidence[i]);
        if w > 0.0
            && l > 0.0
            && l.is_finite()
            && let Some((x, y)) = cell_of(i)
        {
            len[i] = l;
            n0[i] = [nx / l, ny / l];
            weight[i] = w;
            grid[y * cw + x].add(n0[i], l, w, 1.0);
            stats.valid += 1;
        }
    }
    // Sums over the 3 x 3 block of cells around each cell.
    let blocks = |grid: &[Sums]| -> Vec<Sums> {
        let mut rows = vec![Sums::default(); cw * ch];
        for y in 0..ch {
            for x in 0..cw {
                let r = &mut rows[y * cw + x];
                for gx in x.saturating_sub(1)..=(x + 1).min(cw - 1) {
                    r.merge(&grid[y * cw + gx]);
                }
            }
        }
        let mut out = vec![Sums::default(); cw * ch];
        for y in 0..ch {
            for x in 0..cw {
                let o = &mut out[y * cw + x];
                for gy in y.saturating_sub(1)..=(y + 1).min(ch - 1) {
                    o.merge(&rows[gy * cw + x]);
                }
            }
        }
        out
    };
    // Prediction `n0_i . u` from the block around event `i`, without `i` itself when
    // `own_in_block`.
    let predict = |block: &[Sums], i: usize, own_in_block: bool| -> Option<f64> {
        let (x, y) = cell_of(i)?;
        let mut s = block[y * cw + x];
        if own_in_block {
            s.add(n0[i], len[i], weight[i], -1.0);
        }
        if s.count < params.min_neighbours || s.w.is_nan() || s.w <= 0.0 {
            return None;
        }
        let mu = params.ridge * s.w;
        let (sxx, syy) = (s.xx + mu, s.yy + mu);
        let det = sxx * syy - s.xy * s.xy;
        if det.is_nan() || det <= 0.0 {
            return None;
        }
        let u = [(syy * s.bx - s.xy * s.by) / det, (sxx * s.by - s.xy * s.bx) / det];
        let m = u[0] * n0[i][0] + u[1] * n0[i][1];
        m.is_finite().then_some(m)
    };
    let deviates =
        |l: f64, m: f64| (l - m).abs() > (params.max_deviation * m.abs()).max(params.min_deviation);
    // First pass: outliers against all neighbours. Second: against the inliers only.
    let all = blocks(&grid);
    let outlier: Vec<bool> = (0..n)
        .map(|i| len[i] > 0.0 && predict(&all, i, true).is_some_and(|m| deviates(len[i], m)))
        .collect();
    let mut inliers = grid;
    for i in 0..n {
        if outlier[i]
            && let Some((x, y)) = cell_of(i)
        {
            inliers[y * cw + x].add(n0[i], len[i], weight[i], -1.0);
        }
    }
    let inlier_blocks = blocks(&inliers);
    for i in 0..n {
        if !outlier[i] {
            continue;
        }
        let Some(m) = predict(&inlier_blocks, i, false) else {
            continue;
        };
        if !deviates(len[i], m) {
            continue;
        }
        // `m < 0` is a flow against the estimated normal direction (a wrong sign): `m n0`
        // is then the normal flow pointing the other way.
        if m != 0.0 {
            flow.nx[i] = (m * n0[i][0]) as f32;
            flow.ny[i] = (m * n0[i][1]) as f32;
        } else {
            flow.nx[i] = 0.0;
            flow.ny[i] = 0.0;
            flow.confidence[i] = 0.0;
        }
        stats.replaced += 1;
    }
    stats
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 60 x 60 patch of events (every other pixel) translating with `u` (normalized units/s),
    /// normals at varied angles (or all at `fixed_angle`), lengths `n0 . u`.
    fn field(u: [f64; 2], fixed_angle: Option<f64>) -> (Events, NormalFlow) {
        let (mut ev, mut f) = (Events::default(), NormalFlow::default());
        for k in 0..900u32 {
            let (x, y) = (20 + 2 * (k % 30) as u16, 20 + 2 * (k / 30) as u16);
            let a = fixed_angle.unwrap_or(f64::from(k) * 0.77);
            let n0 = [a.cos(), a.sin()];
            let m = n0[0] * u[0] + n0[1] * u[1];
            ev.t.push(f64::from(k) * 1e-5);
            ev.x.push(x);
            ev.y.push(y);
            ev.p.push(1);
            f.nx.push((m * n0[0]) as f32);
            f.ny.push((m * n0[1]) as f32);
            f.confidence.push(1.0);
        }
        (ev, f)
    }

    fn length_along_truth(f: &NormalFlow, i: usize, u: [f64; 2]) -> (f64, f64) {
        let (nx, ny) = (f64::from(f.nx[i]), f64::from(f.ny[i]));
        let l = nx.hypot(ny);
        (l, (nx * u[0] + ny * u[1]) / l)
    }

    #[test]
    fn gross_lengths_and_wrong_signs_are_repaired_and_the_rest_kept() {
        let u = [0.2, -0.1];
        let (ev, mut f) = field(u, None);
        let clean = f.clone();
        let mut bad = Vec::new();
        for i in (0..900).step_by(17) {
            // Three times too long, or pointing against the motion.
            let s = if i % 2 == 0 { 3.0 } else { -1.0 };
            f.nx[i] *= s;
            f.ny[i] *= s;
            bad.push(i);
        }
        let stats = consensus(&ev, &mut f, 640, 480, &ConsensusParams::default());
        assert_eq!(stats.valid, 900);
        assert_eq!(stats.replaced, bad.len(), "{stats:?}");
        for i in 0..900 {
            let (l, m) = length_along_truth(&f, i, u);
            // The ridge shrinks the fitted flow by about its weight (1e-3 of |u| = 0.22).
            assert!((l - m.abs()).abs() < 5e-4, "event {i}: length {l}, truth {m}");
            if !bad.contains(&i) {
                assert_eq!((f.nx[i], f.ny[i]), (clean.nx[i], clean.ny[i]));
            }
        }
    }

    #[test]
    fn parallel_edges_still_get_their_normal_length() {
        // Every normal along x: the flow along y is unobserved, n0 . u is not.
        let u = [0.3, 0.5];
        let (ev, mut f) = field(u, Some(0.0));
        f.nx[450] *= 2.5;
        let stats = consensus(&ev, &mut f, 640, 480, &ConsensusParams::default());
        assert_eq!(stats.replaced, 1);
        assert!((f64::from(f.nx[450]) - 0.3).abs() < 1e-3, "{}", f.nx[450]);
    }

    #[test]
    fn off_sparse_or_misaligned_input_changes_nothing() {
        let (ev, mut f) = field([0.2, 0.1], None);
        f.nx[100] *= 3.0;
        let before = f.clone();
        let off = ConsensusParams {
            cell_px: 0,
            ..ConsensusParams::default()
        };
        assert_eq!(consensus(&ev, &mut f, 640, 480, &off), ConsensusStats::default());
        let lonely = ConsensusParams {
            min_neighbours: 10_000,
            ..ConsensusParams::default()
        };
        assert_eq!(consensus(&ev, &mut f, 640, 480, &lonely).replaced, 0);
        let mut short = f.clone();
        short.confidence.pop();
        assert_eq!(
            consensus(&ev, &mut short, 640, 480, &ConsensusParams::default()).valid,
            0
        );
        // Events outside a (wrongly) small sensor are skipped, not a panic.
        assert_eq!(
            consensus(&ev, &mut f, 10, 10, &ConsensusParams::default()).valid,
            0
        );
        assert_eq!(f, before);
    }

    #[test]
    fn invalid_estimates_are_neither_used_nor_changed() {
        let (ev, mut f) = field([0.2, 0.1], None);
        for i in 0..900 {
            if i % 3 != 0 {
                f.confidence[i] = 0.0;
                f.nx[i] = 0.0;
                f.ny[i] = 0.0;
            }
        }
        let before = f.clone();
        let stats = consensus(&ev, &mut f, 640, 480, &ConsensusParams::default());
        assert_eq!(stats.valid, 300);
        assert_eq!(stats.replaced, 0);
        assert_eq!(f, before);
    }

    #[test]
    fn node_parameters_read_back_and_bad_ones_are_refused_with_their_name() {
        let description =
            describe_consensus(Describe::new("evseg-test", "test"), &ConsensusParams::default()).build();
        let defaults: serde_json::Map<_, _> = description
            .params
            .iter()
            .map(|p| (p.name.clone(), p.default.clone()))
            .collect();
        let read = |changes: serde_json::Value| {
            let mut params = defaults.clone();
            if let serde_json::Value::Object(o) = changes {
                params.extend(o);
            }
            consensus_from_config(&NodeConfig::with_params("flow", params))
        };
        assert_eq!(read(serde_json::json!({})).unwrap(), ConsensusParams::default());
        assert_eq!(
            read(serde_json::json!({"consensus_cell_px": 0})).unwrap().cell_px,
            0
        );
        for (name, bad) in [
            ("consensus_max_deviation", serde_json::json!(-0.5)),
            ("consensus_ridge", serde_json::json!("big")),
            ("consensus_cell_px", serde_json::json!(-1)),
            ("consensus_min_deviation", serde_json::json!(-1.0)),
        ] {
            let err = read(serde_json::json!({ name: bad })).unwrap_err().to_string();
            assert!(err.contains(name), "{name}: {err}");
        }
    }

    #[test]
    fn ranges_are_checked() {
        assert!(ConsensusParams::default().validate().is_ok());
        for bad in [-0.1, f64::NAN] {
            let p = ConsensusParams {
                max_deviation: bad,
                ..ConsensusParams::default()
            };
            assert!(p.validate().is_err());
            let p = ConsensusParams {
                ridge: bad,
                ..ConsensusParams::default()
            };
            assert!(p.validate().is_err());
        }
    }
}
