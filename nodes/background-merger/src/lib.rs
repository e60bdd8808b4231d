//! Coarse segment merging through temporal consistency (paper section 3.4).
//!
//! Per slice, with the over-segmentation clusters, the planar segmenter's background flags and
//! (through a feedback input) the previous slice's final labels:
//! 1. **Background prior per cluster.** The fraction of the cluster's events the planar
//!    segmenter called background, averaged (weight [`BackgroundParams::warp_weight`]) with its
//!    *warp score*: the previous slice's events are warped to now with the previous background's
//!    planar motion ([`warp`]); the score is the fraction of the cluster's events that land on
//!    warped previous background rather than warped previous foreground. The first slice, or a
//!    cluster that lands on too few warped events, uses the planar vote alone ("Initialization");
//!    a slice whose planar vote separated (almost) nothing uses the warp score alone
//!    ([`BackgroundParams::planar_silent_share`]) where it lands on confirmed previous foreground
//!    or within a short grace ([`BackgroundParams::silent_warp_needs_confirmation`],
//!    [`BackgroundParams::unconfirmed_silent_slices`]); a cluster that lands on previous foreground
//!    which clearly moved gets the larger weight [`BackgroundParams::warp_weight_moving`] where
//!    the warp says more foreground than the planar vote.
//!    Clusters with a prior of at least [`BackgroundParams::candidate_threshold`] are background
//!    candidates.
//! 2. **Egomotion.** The linear SVM on the candidates' derotated normal flow gives the camera's
//!    translation direction `t` (METHOD_NOTES section 3), refined with one inverse depth per
//!    image cell (`evseg_geometry::egomotion`; `refine_iterations = 0` gives the SVM alone).
//! 3. **Residuals under the refined background motion.** Each cluster gets its own inverse depth
//!    `rho >= 0` (least squares of `n_derot = rho (X . t)`, clamped at 0 by cheirality), and each
//!    event the residual `r_new = n_derot - rho (X . t)`. The paper writes
//!    `r_new = n - n(x, t_new, w)` without saying which depth; a per-cluster depth makes the
//!    residual small for the background at *any* depth (a room is not one plane) and large for a
//!    cluster whose flow no positive depth explains.
//! 4. **Merging.** Candidates consistent with `t` form group 0, the coarse background; every
//!    other cluster stays a group of its own for the hierarchical merger. Consistent: mean
//!    `|r_new|` below [`BackgroundParams::consistency_floor`]; or else the cluster's 2-D flow
//!    fitted to its normal flows points within [`BackgroundParams::max_flow_angle_deg`] of the
//!    translational flow `A(x) t` (`evseg_geometry::direction`: no depth absorbs a wrong
//!    direction); or, where that flow is undetermined, mean `|r_new|` at most
//!    [`BackgroundParams::consistency_ratio`] of the mean `|n_derot|`.
//! 5. **Persistent background map** ([`map`]): an EMA over image cells of the background
//!    fraction, with a weight growing with the similarity of the current background to the map.
//!    Each group's mean map value (before this slice's update) is published for the hierarchical
//!    merger's background penalty.

#![warn(missing_docs)]

pub mod map;
pub mod params;
pub mod warp;

use evseg_geometry::cache::prefetch_referent_ahead;
use evseg_geometry::rigid::dot;
use evseg_geometry::{
    EgomotionParams, FlowSample, RotationRate, TableCache, estimate_background_translation,
    estimate_translation, flow_direction, flow_samples,
};
use evseg_schemas::align::AlignError;
use evseg_schemas::{CameraInfo, Clusters, CoarseSegmentation, Egomotion, Events, NormalFlow, Residuals};

pub use evseg_geometry::CellGrid;
pub use map::{BackgroundMap, MapUpdate};
pub use params::{BackgroundParams, ParamError};
pub use warp::{PreviousSlice, WarpedPrevious, warp_previous};

/// Malformed input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MergeError {
    /// Per-event flow or events do not fit the slice.
    #[error(transparent)]
    Align(#[from] AlignError),
    /// A per-event input has the wrong length.
    #[error("{what} has {got} entries for {events} events")]
    Length {
        /// Which input.
        what: &'static str,
        /// Its length.
        got: usize,
        /// Events in the slice.
        events: usize,
    },
    /// A cluster id is not below the cluster count.
    #[error("event {index} has cluster id {id} but the over-segmentation has {count} clusters")]
    ClusterId {
        /// Event index.
        index: usize,
        /// The id.
        id: u16,
        /// Number of clusters.
        count: u16,
    },
    /// The rotation rate is not finite.
    #[error("rotation rate {0:?} (rad/s, rad/s^2) is not finite")]
    Omega(RotationRate),
}

/// One slice's inputs.
#[derive(Debug, Clone, Copy)]
pub struct SliceInput<'a> {
    /// Camera of the slice.
    pub camera: &'a CameraInfo,
    /// The events.
    pub events: &'a Events,
    /// The slice's window `[t_start, t_end)`, seconds.
    pub span: (f64, f64),
    /// IMU rotation rate over the slice (camera frame); `None` without IMU.
    pub rate: Option<RotationRate>,
    /// Per-event normal flow.
    pub flow: &'a NormalFlow,
    /// Over-segmentation.
    pub clusters: &'a Clusters,
    /// Planar segmenter's residuals and background flags.
    pub residuals: &'a Residuals,
    /// The previous slice's final labels (0 = background), aligned with the previous slice's
    /// events; `None` for the first slice or when unavailable.
    pub previous_labels: Option<&'a [u32]>,
}

/// Per-cluster figures of one slice (for logs and tests).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ClusterReport {
    /// Events of the cluster.
    pub events: usize,
    /// Fraction the planar segmenter called background.
    pub planar_background: f64,
    /// Warp score, if enough events landed on warped previous events.
    pub warp_score: Option<f64>,
    /// Background prior in [0, 1] (step 1).
    pub prior: f64,
    /// Background candidate (step 1).
    pub candidate: bool,
    /// Mean `|r_new|` / mean `|n_derot|` (NaN without samples or without a translation).
    pub relative_residual: f64,
    /// Angle between the cluster's fitted 2-D derotated flow and the translational flow
    /// direction, degrees (NaN when the direction test did not run: no translation, residual
    /// below the floor, or a flow the samples do not determine).
    pub flow_angle_deg: f64,
    /// Merged into the coarse background.
    pub background: bool,
}

/// Everything computed for one slice.
#[derive(Debug, Clone, PartialEq)]
pub struct MergeResult {
    /// The message for the hierarchical merger.
    pub coarse: CoarseSegmentation,
    /// Per over-segmentation cluster.
    pub clusters: Vec<ClusterReport>,
    /// True when the previous slice's labels were warped in.
    pub warped: bool,
    /// Map update of this slice.
    pub map: MapUpdate,
}

/// The background merger with its state across slices.
#[derive(Debug, Clone)]
pub struct BackgroundMerger {
    params: BackgroundParams,
    table: TableCache,
    previous: Option<PreviousSlice>,
    map: Option<BackgroundMap>,
}

impl BackgroundMerger {
    /// A merger with checked `params`.
    pub fn new(params: BackgroundParams) -> Result<Self, ParamError> {
        params.validate()?;
        Ok(Self {
            params,
            table: TableCache::default(),
            previous: None,
            map: None,
        })
    }

    /// The settings.
    pub fn params(&self) -> &BackgroundParams {
        &self.params
    }

    /// The persistent background map, once a slice was processed.
    pub fn map(&self) -> Option<&BackgroundMap> {
        self.map.as_ref()
    }

    /// Processes one slice.
    pub fn merge(&mut self, input: &SliceInput<'_>) -> Result<MergeResult, MergeError> {
        let p = self.params;
        let events = input.events;
        let n = events.len();
        check_lengths(input)?;
        if let Some(r) = input.rate
            && !r.is_finite()
        {
            return Err(MergeError::Omega(r));
        }
        let rate = input.rate.filter(|_| p.derotate);
        let samples = flow_samples(
            self.table.get(input.camera),
            events,
            input.flow,
            rate.as_ref(),
            p.min_confidence,
        )?;
        let k = usize::from(input.clusters.count);
        let t_mid = 0.5 * (input.span.0 + input.span.1);
        // The warp moves the slice's events by its mean rate.
        let omega = rate.map(|r| r.mean);

        // 1. Background prior per cluster.
        let warped = match (&self.previous, input.previous_labels) {
            (Some(prev), Some(labels)) if prev.camera == *input.camera => {
                let table = self.table.get(&prev.camera);
                let w = warp_previous(prev, labels, table, t_mid, p.warp_cell_px);
                if w.is_none() {
                    tracing::warn!(
                        labels = labels.len(),
                        events = prev.x.len(),
                        "previous labels do not fit the previous slice; not warped"
                    );
                }
                w
            }
            _ => None,
        };
        let mut reports = vec![ClusterReport::default(); k];
        let mut planar_bg = vec![0usize; k];
        let mut hits = vec![(0.0f64, 0.0f64); k];
        // The part of `hits.1` (foreground) on cells with warped events whose cluster clearly
        // moved ([`PreviousSlice::moving`]).
        let mut moving_hits = vec![0.0f64; k];
        // The same for [`PreviousSlice::confirmed`].
        let mut confirmed_hits = vec![0.0f64; k];
        for i in 0..n {
            let Some(c) = cluster_of(input.clusters, i) else {
                continue;
            };
            reports[c].events += 1;
            planar_bg[c] += usize::from(input.residuals.background[i]);
            if let Some(w) = &warped
                && let Some(cell) = w.background.cell(events.x[i], events.y[i])
            {
                let (b, f) = (w.background.values[cell] > 0.0, w.foreground.values[cell] > 0.0);
                let moving = f64::from(u8::from(w.moving_foreground.values[cell] > 0.0));
                let confirmed = f64::from(u8::from(w.confirmed_foreground.values[cell] > 0.0));
                // An event on both kinds of warped cells votes half for each.
                match (b, f) {
                    (true, false) => hits[c].0 += 1.0,
                    (false, true) => {
                        hits[c].1 += 1.0;
                        moving_hits[c] += moving;
                        confirmed_hits[c] += confirmed;
                    }
                    (true, true) => {
                        hits[c].0 += 0.5;
                        hits[c].1 += 0.5;
                        moving_hits[c] += 0.5 * moving;
                        confirmed_hits[c] += 0.5 * confirmed;
                    }
                    (false, false) => {}
                }
            }
        }
        let planar_silent = planar_is_silent(&reports, &planar_bg, p.planar_silent_share);
        // Consecutive slices with a silent planar vote, this one included.
        let silent_run = match (&warped, &self.previous) {
            (Some(_), Some(prev)) if planar_silent => prev.silent_run.saturating_add(1),
            _ => u32::from(planar_silent),
        };
        // Unconfirmed foreground is still carried by the warp alone within the grace.
        let grace = silent_run <= p.unconfirmed_silent_slices;
        // Confirmed foreground too, up to a longer limit (0 = none).
        let confirmed_in_time = p.confirmed_silent_slices == 0 || silent_run <= p.confirmed_silent_slices;
        // Per cluster: confirmed foreground ([`PreviousSlice::confirmed`]).
        let mut confirmed = vec![!p.silent_warp_needs_confirmation; k];
        for (c, r) in reports.iter_mut().enumerate() {
            if r.events == 0 {
                continue;
            }
            r.planar_background = planar_bg[c] as f64 / r.events as f64;
            let (b, f) = hits[c];
            if b + f >= p.warp_min_hits as f64 {
                r.warp_score = Some(b / (b + f));
            }
            let mostly = |part: f64| hits[c].1 > 0.0 && part >= 0.5 * hits[c].1;
            // Mostly on previous foreground that clearly moved.
            let moved = mostly(moving_hits[c]);
            if p.silent_warp_needs_confirmation {
                // Two independent votes for moving in this slice, or mostly on confirmed
                // previous foreground.
                let both_moving = !planar_silent
                    && r.planar_background < p.candidate_threshold
                    && r.warp_score.is_some_and(|s| s < p.candidate_threshold);
                confirmed[c] = both_moving || mostly(confirmed_hits[c]);
            }
            r.prior = match r.warp_score {
                Some(s) if planar_silent && ((confirmed[c] && confirmed_in_time) || grace) => s,
                Some(s) => {
                    // ...and the warp says more foreground than the planar vote: the warp gets
                    // the larger weight.
                    let w = if moved && s < r.planar_background {
                        p.warp_weight_moving
                    } else {
                        p.warp_weight
                    };
                    (1.0 - w) * r.planar_background + w * s
                }
                None => r.planar_background,
            };
            r.candidate = r.prior >= p.candidate_threshold;
        }

        // 2-3. Egomotion from the candidates, residuals under it with a depth per cluster, and
        // again from the candidates that it explains (the paper's "refined background motion").
        let mut per_cluster: Vec<Vec<&FlowSample>> = vec![Vec::new(); k];
        for s in &samples {
            if let Some(c) = cluster_of(input.clusters, s.index) {
                per_cluster[c].push(s);
            }
        }
        let previous_direction = self.previous.as_ref().and_then(|prev| prev.direction);
        let mut residual = vec![f32::NAN; n];
        let mut direction = previous_direction;
        let priors: Vec<f64> = reports.iter().map(|r| r.prior).collect();
        let mut in_svm: Vec<bool> = reports.iter().map(|r| r.candidate).collect();
        if p.hypotheses {
            let chosen = select_hypothesis(&per_cluster, &priors, previous_direction, input, &p);
            if let Some((t, consistent)) = chosen {
                direction = Some(t);
                in_svm = consistent
                    .iter()
                    .zip(&reports)
                    .map(|(&c, r)| c && r.candidate)
                    .collect();
            }
        }
        for round in 0..p.refine_rounds.max(1) {
            let chosen: Vec<&FlowSample> = per_cluster
                .iter()
                .enumerate()
                .filter(|(c, _)| in_svm[*c])
                .flat_map(|(_, m)| m.iter().copied())
                .collect();
            let estimate = estimate_background_translation(
                &chosen,
                events,
                (input.camera.width, input.camera.height),
                &p.egomotion,
                |i| cluster_of(input.clusters, i).is_some_and(|c| !in_svm[c]),
            );
            direction = estimate.or(previous_direction);
            for (c, members) in per_cluster.iter().enumerate() {
                let consistent = explain(members, direction, &p, &mut residual, &mut reports[c]);
                reports[c].background = reports[c].candidate && consistent;
            }
            let next: Vec<bool> = reports.iter().map(|r| r.background).collect();
            if next == in_svm || round + 1 == p.refine_rounds.max(1) {
                break;
            }
            in_svm = next;
        }

        // 4. Groups: 0 = merged background, c + 1 = cluster c on its own.
        let mut group = vec![CoarseSegmentation::UNASSIGNED; n];
        for (i, g) in group.iter_mut().enumerate() {
            if let Some(c) = cluster_of(input.clusters, i) {
                *g = if reports[c].background { 0 } else { c as u32 + 1 };
            }
        }

        // 5. Persistent map: mean value per group before the update, then the update.
        let cam = input.camera;
        let map = match &mut self.map {
            Some(m) if m.grid.fits(cam.width, cam.height, p.map_cell_px) => m,
            slot => slot.insert(BackgroundMap::new(cam.width, cam.height, p.map_cell_px)),
        };
        let mut overlap = vec![(0.0f64, 0usize); k + 1];
        let mut cells = vec![(0u32, 0u32); map.grid.values.len()];
        for (i, &g) in group.iter().enumerate() {
            if g == CoarseSegmentation::UNASSIGNED {
                continue;
            }
            if let Some(v) = map.value(events.x[i], events.y[i]) {
                overlap[g as usize].0 += f64::from(v);
                overlap[g as usize].1 += 1;
            }
            if let Some(c) = map.grid.cell(events.x[i], events.y[i]) {
                cells[c].0 += u32::from(g == 0);
                cells[c].1 += 1;
            }
        }
        let current: Vec<Option<f32>> = cells
            .iter()
            .map(|&(bg, all)| (all > 0).then(|| bg as f32 / all as f32))
            .collect();
        let first = map.updates == 0;
        let update = map.update(&current, p.map_threshold, p.alpha_min, p.alpha_max);
        let map_overlap: Vec<f32> = overlap
            .iter()
            .enumerate()
            .map(|(g, &(sum, count))| {
                if count > 0 {
                    (sum / count as f64) as f32
                } else if first {
                    // No map before the first slice: the group's own background vote.
                    if g == 0 { 1.0 } else { 0.0 }
                } else {
                    f32::NAN
                }
            })
            .collect();

        let warped_in = warped.is_some();
        // Per event, from its cluster: clearly not explained by this slice's translation
        // (`moving`), and confirmed foreground (`confirmed`).
        let (moving, confirmed): (Vec<bool>, Vec<bool>) = (0..n)
            .map(|i| {
                cluster_of(input.clusters, i).map_or((false, false), |c| {
                    (reports[c].relative_residual >= p.moving_relres, confirmed[c])
                })
            })
            .unzip();
        self.previous = Some(PreviousSlice {
            camera: input.camera.clone(),
            x: events.x.clone(),
            y: events.y.clone(),
            samples,
            omega,
            t_mid,
            direction,
            moving,
            confirmed,
            silent_run,
        });
        Ok(MergeResult {
            coarse: CoarseSegmentation {
                group,
                residual,
                map_overlap,
                egomotion: Egomotion {
                    direction: direction.unwrap_or([0.0; 3]),
                    omega: input.rate.map_or([0.0; 3], |r| r.mean),
                    valid: direction.is_some(),
                },
            },
            clusters: reports,
            warped: warped_in,
            map: update,
        })
    }
}

/// True when `share` > 0 and the planar vote called at most `share` of the clustered events foreground
/// (`reports[c].events` events of cluster `c`, `planar_bg[c]` of them planar background); see
/// [`BackgroundParams::planar_silent_share`].
fn planar_is_silent(reports: &[ClusterReport], planar_bg: &[usize], share: f64) -> bool {
    let all: usize = reports.iter().map(|r| r.events).sum();
    let background: usize = planar_bg.iter().sum();
    share > 0.0 && all.saturating_sub(background) as f64 <= share * all as f64
}

/// Sums `(|r|, |n_derot|)` over `members` (one cluster) under translation `t` (`None`: no
/// translation, `r = n_derot`) with the cluster's own inverse depth; `each` sees every sample
/// with its residual `r`.
fn cluster_fit(
    members: &[&FlowSample],
    t: Option<[f64; 3]>,
    mut each: impl FnMut(&FlowSample, f64),
) -> (f64, f64) {
    let rho = t.map(|t| inverse_depth(members, t));
    let (mut sum_r, mut sum_n) = (0.0, 0.0);
    for (k, s) in members.iter().enumerate() {
        prefetch_referent_ahead(members, k);
        let predicted = match (t, rho) {
            (Some(t), Some(rho)) => rho * dot(s.x_row(), t),
            _ => 0.0,
        };
        let r = s.n_derot - predicted;
        each(s, r);
        sum_r += r.abs();
        sum_n += s.n_derot.abs();
    }
    (sum_r, sum_n)
}

/// True when a cluster `members` with residual sums `(sum_r, sum_n)` under translation `t` is
/// explained: its mean residual is below the floor; or else, when the direction test applies
/// ([`BackgroundParams::max_flow_angle_deg`] > 0 and the cluster's 2-D flow is determined), its
/// fitted flow is within that angle of the translation's flow direction; or else its residual
/// is at most [`BackgroundParams::consistency_ratio`] of its derotated flow. Also returns the
/// direction test's angle (degrees) when that test decided.
fn is_consistent(
    members: &[&FlowSample],
    t: [f64; 3],
    sum_r: f64,
    sum_n: f64,
    p: &BackgroundParams,
) -> (bool, Option<f64>) {
    let m = members.len();
    if m == 0 {
        return (false, None);
    }
    if sum_r / m as f64 <= p.consistency_floor {
        return (true, None);
    }
    if p.max_flow_angle_deg > 0.0
        && let Some(d) = flow_direction(
            members,
            t,
            p.flow_direction_min_spread,
            p.flow_direction_magnitude_weighting,
        )
    {
        return (d.angle_deg <= p.max_flow_angle_deg, Some(d.angle_deg));
    }
    (sum_r <= p.consistency_ratio * sum_n, None)
}

/// Step 2a: background translation hypotheses and the one that explains the most image area.
///
/// Hypotheses: the estimate from the background candidates, the previous slice's direction, and
/// estimates from the samples of each image half and quadrant (an object rarely covers all of
/// them, so at least one is mostly background). Each is scored by the image area (occupied
/// cells of [`BackgroundParams::map_cell_px`]) of the clusters it explains, each weighted by
/// `prior_floor + prior`: the background is the motion that explains most of the scene, with
/// the planar and warp votes as tie-breakers. Returns the winner and the clusters it explains.
fn select_hypothesis(
    per_cluster: &[Vec<&FlowSample>],
    priors: &[f64],
    previous: Option<[f64; 3]>,
    input: &SliceInput<'_>,
    p: &BackgroundParams,
) -> Option<([f64; 3], Vec<bool>)> {
    let (ev, cam) = (input.events, input.camera);
    let (w, h) = (u32::from(cam.width.max(1)), u32::from(cam.height.max(1)));
    let rough = EgomotionParams {
        refine_iterations: p.egomotion.refine_iterations.min(p.hypothesis_refine_iterations),
        ..p.egomotion
    };
    // Every sample once, in cluster order, with its pixel: the nine hypotheses below each pick
    // from these, and reading the pixels from one array is much faster than through each
    // sample's event index (scattered over the slice).
    let flat: Vec<&FlowSample> = per_cluster.iter().flatten().copied().collect();
    let pixels: Vec<(u16, u16)> = flat.iter().map(|s| (ev.x[s.index], ev.y[s.index])).collect();
    let estimate = |keep: &dyn Fn(usize) -> bool| {
        let chosen: Vec<&FlowSample> = flat
            .iter()
            .enumerate()
            .filter(|&(k, _)| keep(k))
            .map(|(_, &s)| s)
            .collect();
        // A regular subsample: the hypotheses only need to be roughly right (the winner is
        // re-estimated from all its samples afterwards).
        let stride = chosen.len().div_ceil(p.hypothesis_max_samples.max(1)).max(1);
        let sub: Vec<&FlowSample> = chosen.iter().step_by(stride).copied().collect();
        estimate_translation(&sub, &ev.x, &ev.y, cam.width, cam.height, &rough)
    };
    let mut hypotheses: Vec<[f64; 3]> = previous.into_iter().collect();
    let candidate_set: Vec<bool> = priors.iter().map(|&q| q >= p.candidate_threshold).collect();
    let candidate: Vec<bool> = flat
        .iter()
        .map(|s| cluster_of(input.clusters, s.index).is_some_and(|c| candidate_set[c]))
        .collect();
    if let Some(t) = estimate(&|k: usize| candidate[k]) {
        hypotheses.push(t);
    }
    // Halves and quadrants: (column range, row range) in units of half the sensor.
    let parts: [(u32, u32, u32, u32); 8] = [
        (0, 1, 0, 2),
        (1, 2, 0, 2),
        (0, 2, 0, 1),
        (0, 2, 1, 2),
        (0, 1, 0, 1),
        (1, 2, 0, 1),
        (0, 1, 1, 2),
        (1, 2, 1, 2),
    ];
    for (x0, x1, y0, y1) in parts {
        let inside = |k: usize| {
            let (u, v) = (2 * u32::from(pixels[k].0), 2 * u32::from(pixels[k].1));
            u >= x0 * w && u < x1 * w && v >= y0 * h && v < y1 * h
        };
        if let Some(t) = estimate(&inside) {
            hypotheses.push(t);
        }
    }
    // Area of each cluster: distinct occupied cells, counted by marking each cell with the
    // last cluster that occupied it (a cluster's samples are one run of `pixels`).
    let grid = CellGrid::new(cam.width, cam.height, p.map_cell_px);
    let mut marked = vec![usize::MAX; grid.values.len()];
    let mut start = 0;
    let area: Vec<f64> = per_cluster
        .iter()
        .enumerate()
        .map(|(c, m)| {
            let mut cells = 0usize;
            for &(x, y) in &pixels[start..start + m.len()] {
                if let Some(cell) = grid.cell(x, y)
                    && marked[cell] != c
                {
                    marked[cell] = c;
                    cells += 1;
                }
            }
            start += m.len();
            cells as f64
        })
        .collect();
    let mut best: Option<(f64, [f64; 3], Vec<bool>)> = None;
    for t in hypotheses {
        let consistent: Vec<bool> = per_cluster
            .iter()
            .map(|m| {
                let (r, nsum) = cluster_fit(m, Some(t), |_, _| {});
                is_consistent(m, t, r, nsum, p).0
            })
            .collect();
        let score: f64 = consistent
            .iter()
            .zip(&area)
            .zip(priors)
            .filter(|((c, _), _)| **c)
            .map(|((_, a), q)| a * (p.prior_floor + q))
            .sum();
        if best.as_ref().is_none_or(|(b, _, _)| score > *b) {
            best = Some((score, t, consistent));
        }
    }
    best.map(|(_, t, c)| (t, c))
}

/// Residuals of `members` (one cluster) under translation `direction` with the cluster's own
/// inverse depth, written into `residual`; fills the report's relative residual and returns
/// whether the cluster is consistent with the translation.
fn explain(
    members: &[&FlowSample],
    direction: Option<[f64; 3]>,
    p: &BackgroundParams,
    residual: &mut [f32],
    report: &mut ClusterReport,
) -> bool {
    if members.is_empty() {
        report.relative_residual = f64::NAN;
        return false;
    }
    let (sum_r, sum_n) = cluster_fit(members, direction, |s, r| residual[s.index] = r as f32);
    report.relative_residual = if direction.is_some() && sum_n > 0.0 {
        sum_r / sum_n
    } else {
        f64::NAN
    };
    let Some(t) = direction else {
        report.flow_angle_deg = f64::NAN;
        return true;
    };
    let (consistent, angle) = is_consistent(members, t, sum_r, sum_n, p);
    report.flow_angle_deg = angle.unwrap_or(f64::NAN);
    consistent
}

/// Least-squares inverse depth of `members` under translation `t`, clamped at 0 (cheirality).
fn inverse_depth(members: &[&FlowSample], t: [f64; 3]) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (k, s) in members.iter().enumerate() {
        prefetch_referent_ahead(members, k);
        let q = dot(s.x_row(), t);
        num += s.n_derot * q;
        den += q * q;
    }
    if den > 0.0 { (num / den).max(0.0) } else { 0.0 }
}

fn cluster_of(clusters: &Clusters, i: usize) -> Option<usize> {
    let id = clusters.id[i];
    (id != u16::MAX).then_some(usize::from(id))
}

fn check_lengths(input: &SliceInput<'_>) -> Result<(), MergeError> {
    let n = input.events.len();
    let len = |what, got| {
        if got == n {
            Ok(())
        } else {
            Err(MergeError::Length { what, got, events: n })
        }
    };
    len("clusters.id", input.clusters.id.len())?;
    len("residuals.background", input.residuals.background.len())?;
    for (index, &id) in input.clusters.id.iter().enumerate() {
        if id != u16::MAX && id >= input.clusters.count {
            return Err(MergeError::ClusterId {
                index,
                id,
                count: input.clusters.count,
            });
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests;
