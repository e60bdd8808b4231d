//! Hierarchical segment merging through refinement (paper section 3.5).
//!
//! Input: the background merger's groups (0 = coarse background, others = single clusters).
//! 1. Per group: the translation with depth 1 by Tikhonov-regularized least squares on the
//!    derotated normal flow ([`evseg_geometry::TranslationFit`], `lambda` 1e-6), the mean
//!    absolute residual under the refined background motion, the bounding box and the mean
//!    value on the persistent background map.
//! 2. Repeatedly merge the most similar pair of *touching* segments (bounding boxes within
//!    [`HierParams::touch_px`]) while the similarity
//!    `-|ti - tj|^2 / (|ti|^2 + |tj|^2) - lambda_r (ri - rj)^2 - penalty` is at least
//!    [`HierParams::merge_threshold`]; `penalty` = [`HierParams::background_penalty`] when
//!    exactly one of the two lies on the background map. A merged segment's translation is
//!    re-solved from the union of the equations.
//! 3. The segment holding group 0 is the background (label 0); without one, the segment with
//!    the highest map value if it lies on the map, else the largest. Object segments smaller
//!    than [`HierParams::min_segment_fraction`] of the slice (or
//!    [`HierParams::min_segment_events`]) become background. The others get labels 1, 2, ... by
//!    decreasing size.
//! 4. Events without flow (no group) take the most common label among labelled events in the
//!    3x3 cells around them ([`fill`]); where those are empty, in the nearest ring of cells
//!    out to [`HierParams::fill_reach`] that holds any; background where none does.
//! 5. The final egomotion: the linear SVM on the final background's derotated normal flow, for
//!    the next slice (section 3.5, last paragraph), refined with one inverse depth per image cell
//!    (`evseg_geometry::egomotion`).

#![warn(missing_docs)]

pub mod fill;
pub mod params;

use evseg_geometry::{
    DepthMemory, FlowSample, RotationRate, TableCache, TranslationFit,
    estimate_background_translation_with_memory, flow_samples, rigid,
};
use evseg_schemas::align::AlignError;
use evseg_schemas::{CameraInfo, CoarseSegmentation, Egomotion, Events, NormalFlow, Segment, Segmentation};

pub use params::{HierParams, ParamError};

/// Malformed input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum HierError {
    /// Flow or events do not fit the slice.
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
    /// A group number has no `map_overlap` entry.
    #[error("event {index} is in group {group} but map_overlap has {groups} entries")]
    Group {
        /// Event index.
        index: usize,
        /// The group.
        group: u32,
        /// Entries of `map_overlap`.
        groups: usize,
    },
    /// The rotation rate is not finite.
    #[error("rotation rate {0:?} (rad/s, rad/s^2) is not finite")]
    Omega(RotationRate),
}

/// One segment while merging.
#[derive(Debug, Clone)]
struct Node {
    fit: TranslationFit,
    t: Option<[f64; 3]>,
    residual_sum: f64,
    residual_count: usize,
    map_sum: f64,
    map_count: usize,
    bbox: [f32; 4],
    xy_sum: [f64; 2],
    events: usize,
    has_background_group: bool,
    groups: Vec<u32>,
}

impl Node {
    fn new() -> Self {
        Self {
            fit: TranslationFit::default(),
            t: None,
            residual_sum: 0.0,
            residual_count: 0,
            map_sum: 0.0,
            map_count: 0,
            bbox: [f32::MAX, f32::MAX, f32::MIN, f32::MIN],
            xy_sum: [0.0; 2],
            events: 0,
            has_background_group: false,
            groups: Vec::new(),
        }
    }

    fn mean_residual(&self) -> f64 {
        if self.residual_count == 0 {
            0.0
        } else {
            self.residual_sum / self.residual_count as f64
        }
    }

    fn map_value(&self) -> Option<f64> {
        (self.map_count > 0).then(|| self.map_sum / self.map_count as f64)
    }

    fn absorb(&mut self, other: &Node, lambda: f64) {
        self.fit.merge(&other.fit);
        self.t = self.fit.solve(lambda);
        self.residual_sum += other.residual_sum;
        self.residual_count += other.residual_count;
        self.map_sum += other.map_sum;
        self.map_count += other.map_count;
        self.bbox = [
            self.bbox[0].min(other.bbox[0]),
            self.bbox[1].min(other.bbox[1]),
            self.bbox[2].max(other.bbox[2]),
            self.bbox[3].max(other.bbox[3]),
        ];
        self.xy_sum = [self.xy_sum[0] + other.xy_sum[0], self.xy_sum[1] + other.xy_sum[1]];
        self.events += other.events;
        self.has_background_group |= other.has_background_group;
        self.groups.extend_from_slice(&other.groups);
    }
}

/// The paper's similarity of two segments (without the background penalty): motion term plus
/// residual term (translations with depth 1, residuals in normalized units/s).
pub fn similarity(ti: [f64; 3], tj: [f64; 3], ri: f64, rj: f64, lambda_r: f64) -> f64 {
    let d: f64 = (0..3).map(|k| (ti[k] - tj[k]).powi(2)).sum();
    let s: f64 = (0..3).map(|k| ti[k] * ti[k] + tj[k] * tj[k]).sum();
    let motion = if s > 0.0 { -d / s } else { 0.0 };
    motion - lambda_r * (ri - rj).powi(2)
}

/// True when the boxes `[x_min, y_min, x_max, y_max]` are within `margin` pixels of each other.
pub fn boxes_touch(a: [f32; 4], b: [f32; 4], margin: f32) -> bool {
    a[0] <= b[2] + margin && b[0] <= a[2] + margin && a[1] <= b[3] + margin && b[1] <= a[3] + margin
}

/// Everything computed for one slice.
#[derive(Debug, Clone, PartialEq)]
pub struct HierResult {
    /// The message for the tracker.
    pub segmentation: Segmentation,
    /// Segments before merging (groups with events).
    pub initial_segments: usize,
    /// Merges made.
    pub merges: usize,
    /// Each merge in order (for logs and studies).
    pub steps: Vec<MergeStep>,
    /// Object segments turned background for being too small.
    pub dropped_small: usize,
}

/// One merge of the agglomeration.
#[derive(Debug, Clone, PartialEq)]
pub struct MergeStep {
    /// Events of the two segments.
    pub events: [usize; 2],
    /// Their translations (depth 1, normalized units/s).
    pub translations: [[f64; 3]; 2],
    /// Their mean map values.
    pub map: [f64; 2],
    /// True when one held the coarse background.
    pub background: bool,
    /// The similarity that made them merge.
    pub similarity: f64,
}

/// The hierarchical merger. Its state across slices: the undistortion table, the final
/// egomotion's depth memory and the last published direction.
#[derive(Debug, Clone)]
pub struct HierarchicalMerger {
    params: HierParams,
    table: TableCache,
    /// The final egomotion's cell depths of the previous slices (`egomotion.depth_memory`).
    depth_memory: DepthMemory,
    /// The last published direction of translation (unit, camera frame of its slice) and its
    /// slice's time (midpoint of its events, seconds), for `direction_prior_samples`.
    last_direction: Option<(f64, [f64; 3])>,
}

impl HierarchicalMerger {
    /// A merger with checked `params`.
    pub fn new(params: HierParams) -> Result<Self, ParamError> {
        params.validate()?;
        Ok(Self {
            params,
            table: TableCache::default(),
            depth_memory: DepthMemory::default(),
            last_direction: None,
        })
    }

    /// The settings.
    pub fn params(&self) -> &HierParams {
        &self.params
    }

    /// Merges one slice: `events` seen by `camera`, their `flow`, the slice's rotation `rate`
    /// (camera frame) and the background merger's `coarse` groups.
    pub fn merge(
        &mut self,
        camera: &CameraInfo,
        events: &Events,
        flow: &NormalFlow,
        rate: Option<RotationRate>,
        coarse: &CoarseSegmentation,
    ) -> Result<HierResult, HierError> {
        self.merge_with_egomotion_flow(camera, events, flow, None, rate, coarse)
    }

    /// As [`merge`](Self::merge), with the final egomotion (step 5) fitted on
    /// `egomotion_flow` (aligned with `events`, normalized units/s) instead of `flow` when
    /// given: the normal-flow node's wide flow, whose fast lengths come from a larger window
    /// (`evseg_normal_flow::WideFitParams`). The segmentation always uses `flow`.
    pub fn merge_with_egomotion_flow(
        &mut self,
        camera: &CameraInfo,
        events: &Events,
        flow: &NormalFlow,
        egomotion_flow: Option<&NormalFlow>,
        rate: Option<RotationRate>,
        coarse: &CoarseSegmentation,
    ) -> Result<HierResult, HierError> {
        let p = self.params;
        let n = events.len();
        if let Some(r) = rate
            && !r.is_finite()
        {
            return Err(HierError::Omega(r));
        }
        for (what, got) in [
            ("coarse.group", coarse.group.len()),
            ("coarse.residual", coarse.residual.len()),
        ] {
            if got != n {
                return Err(HierError::Length { what, got, events: n });
            }
        }
        let groups = coarse.map_overlap.len();
        for (index, &g) in coarse.group.iter().enumerate() {
            if g != CoarseSegmentation::UNASSIGNED && g as usize >= groups {
                return Err(HierError::Group {
                    index,
                    group: g,
                    groups,
                });
            }
        }
        let w = rate.filter(|_| p.derotate);
        let samples = flow_samples(self.table.get(camera), events, flow, w.as_ref(), p.min_confidence)?;

        // 1. Per-group statistics.
        let mut nodes: Vec<Node> = (0..groups).map(|_| Node::new()).collect();
        for (g, node) in nodes.iter_mut().enumerate() {
            node.groups.push(g as u32);
            node.has_background_group = g == 0;
        }
        for i in 0..n {
            let g = coarse.group[i];
            if g == CoarseSegmentation::UNASSIGNED {
                continue;
            }
            let node = &mut nodes[g as usize];
            let (x, y) = (f32::from(events.x[i]), f32::from(events.y[i]));
            node.bbox = [
                node.bbox[0].min(x),
                node.bbox[1].min(y),
                node.bbox[2].max(x),
                node.bbox[3].max(y),
            ];
            node.xy_sum[0] += f64::from(x);
            node.xy_sum[1] += f64::from(y);
            node.events += 1;
            let r = coarse.residual[i];
            if r.is_finite() {
                node.residual_sum += f64::from(r.abs());
                node.residual_count += 1;
            }
        }
        for s in &samples {
            let g = coarse.group[s.index];
            if g != CoarseSegmentation::UNASSIGNED {
                nodes[g as usize].fit.add(s);
            }
        }
        for (g, node) in nodes.iter_mut().enumerate() {
            node.t = node.fit.solve(p.lambda);
            let m = coarse.map_overlap[g];
            if m.is_finite() && node.events > 0 {
                node.map_sum = f64::from(m) * node.events as f64;
                node.map_count = node.events;
            }
        }
        let mut active: Vec<Node> = nodes.into_iter().filter(|nd| nd.events > 0).collect();
        let initial_segments = active.len();

        // 2. Agglomerative merging of touching segments.
        let on_map = |nd: &Node| nd.map_value().is_some_and(|v| v >= f64::from(p.map_threshold));
        let mut merges = 0;
        let mut steps = Vec::new();
        loop {
            let mut best: Option<(f64, usize, usize)> = None;
            for i in 0..active.len() {
                for j in i + 1..active.len() {
                    let (a, b) = (&active[i], &active[j]);
                    if !boxes_touch(a.bbox, b.bbox, p.touch_px) {
                        continue;
                    }
                    let (Some(ta), Some(tb)) = (a.t, b.t) else {
                        continue;
                    };
                    let mut s = similarity(ta, tb, a.mean_residual(), b.mean_residual(), p.lambda_r);
                    if on_map(a) != on_map(b) {
                        s -= p.background_penalty;
                    }
                    if s >= p.merge_threshold && best.is_none_or(|(bs, _, _)| s > bs) {
                        best = Some((s, i, j));
                    }
                }
            }
            let Some((sim, i, j)) = best else { break };
            let (a, b) = (&active[i], &active[j]);
            steps.push(MergeStep {
                events: [a.events, b.events],
                translations: [a.t.unwrap_or_default(), b.t.unwrap_or_default()],
                map: [
                    a.map_value().unwrap_or(f64::NAN),
                    b.map_value().unwrap_or(f64::NAN),
                ],
                background: a.has_background_group || b.has_background_group,
                similarity: sim,
            });
            let other = active.swap_remove(j);
            active[i].absorb(&other, p.lambda);
            merges += 1;
        }

        // 3. Background and object labels.
        let background = active
            .iter()
            .position(|nd| nd.has_background_group)
            .or_else(|| {
                let best = (0..active.len()).max_by(|&a, &b| {
                    let va = active[a].map_value().unwrap_or(0.0);
                    let vb = active[b].map_value().unwrap_or(0.0);
                    va.total_cmp(&vb)
                })?;
                on_map(&active[best]).then_some(best)
            })
            .or_else(|| (0..active.len()).max_by_key(|&a| active[a].events));
        let min_events = (p.min_segment_fraction * n as f64)
            .ceil()
            .max(p.min_segment_events as f64) as usize;
        let mut order: Vec<usize> = (0..active.len()).filter(|&a| Some(a) != background).collect();
        order.sort_by_key(|&a| std::cmp::Reverse(active[a].events));
        let mut group_label = vec![0u32; groups];
        let mut segments = Vec::new();
        let mut dropped_small = 0;
        let mut next = 1u32;
        for &a in &order {
            let nd = &active[a];
            if nd.events < min_events {
                dropped_small += 1;
                continue;
            }
            for &g in &nd.groups {
                group_label[g as usize] = next;
            }
            segments.push((next, a));
            next += 1;
        }
        let mut label: Vec<u32> = coarse
            .group
            .iter()
            .map(|&g| {
                if g == CoarseSegmentation::UNASSIGNED {
                    fill::UNLABELLED
                } else {
                    group_label[g as usize]
                }
            })
            .collect();

        // 4. Events without a group.
        fill::fill_unlabelled(
            events,
            camera.width,
            camera.height,
            p.fill_cell_px,
            p.fill_reach,
            &mut label,
        );

        // Segment descriptions, measured on the final labels.
        let mut stats = vec![([f32::MAX, f32::MAX, f32::MIN, f32::MIN], [0.0f64; 2], 0u32); next as usize];
        for i in 0..n {
            let st = &mut stats[label[i] as usize];
            let (x, y) = (f32::from(events.x[i]), f32::from(events.y[i]));
            st.0 = [st.0[0].min(x), st.0[1].min(y), st.0[2].max(x), st.0[3].max(y)];
            st.1[0] += f64::from(x);
            st.1[1] += f64::from(y);
            st.2 += 1;
        }
        let describe = |l: u32, t: Option<[f64; 3]>| {
            let (bbox, sum, count) = stats[l as usize];
            let c = f64::from(count.max(1));
            Segment {
                label: l,
                translation: t.unwrap_or([0.0; 3]),
                centroid: [sum[0] / c, sum[1] / c],
                bbox: if count > 0 { bbox } else { [0.0; 4] },
                events: count,
            }
        };
        let mut out_segments = vec![describe(0, background.and_then(|b| active[b].t))];
        for &(l, a) in &segments {
            out_segments.push(describe(l, active[a].t));
        }

        // 5. Final egomotion on the final background.
        let egomotion_samples = match egomotion_flow {
            Some(f) => Some(flow_samples(
                self.table.get(camera),
                events,
                f,
                w.as_ref(),
                p.min_confidence,
            )?),
            None => None,
        };
        let samples = egomotion_samples.as_ref().unwrap_or(&samples);
        let bg_samples: Vec<&FlowSample> = samples.iter().filter(|s| label[s.index] == 0).collect();
        let estimate = estimate_background_translation_with_memory(
            &bg_samples,
            events,
            (camera.width, camera.height),
            &p.egomotion,
            |i| label[i] != 0,
            Some(&mut self.depth_memory),
        );
        let estimate =
            estimate.map(|direction| self.with_direction_prior(direction, events, rate, bg_samples.len()));
        let egomotion = match estimate {
            Some(direction) => Egomotion {
                direction,
                omega: rate.map_or([0.0; 3], |r| r.mean),
                valid: true,
            },
            None => coarse.egomotion,
        };
        Ok(HierResult {
            segmentation: Segmentation {
                label,
                segments: out_segments,
                egomotion,
            },
            initial_segments,
            merges,
            steps,
            dropped_small,
        })
    }

    /// The slice's unit `direction` blended with the last published one, turned into this
    /// slice's camera frame by the rotation `rate` over the time between the two slices, with
    /// weights `n` and `direction_prior_samples` (`n` the slice's background samples with
    /// flow); remembered for the next slice. The slice alone when the parameter is 0, when there
    /// is no earlier direction within [`PRIOR_MAX_GAP_S`], or when the two cancel.
    fn with_direction_prior(
        &mut self,
        direction: [f64; 3],
        events: &Events,
        rate: Option<RotationRate>,
        n: usize,
    ) -> [f64; 3] {
        let c = self.params.direction_prior_samples;
        let t = match (events.t.first(), events.t.last()) {
            (Some(a), Some(b)) => 0.5 * (a + b),
            _ => return direction,
        };
        let prior = self.last_direction.and_then(|(t_last, last)| {
            let dt = t - t_last;
            (c > 0.0 && dt > 0.0 && dt <= PRIOR_MAX_GAP_S).then(|| {
                // A direction fixed in the world turns by -w dt in the camera's frame.
                let w = rate.map_or([0.0; 3], |r| r.at(t_last + 0.5 * dt));
                let angle = rigid::norm(w) * dt;
                if angle > 0.0 {
                    let turn = rigid::quat_to_mat(rigid::quat_from_axis_angle(rigid::normalize(w), -angle));
                    rigid::mul_mv(&turn, last)
                } else {
                    last
                }
            })
        });
        let out = match prior {
            Some(prior) => {
                let k = n as f64 / (n as f64 + c);
                let blend = rigid::add(rigid::scale(direction, k), rigid::scale(prior, 1.0 - k));
                if rigid::norm(blend) > 1e-9 {
                    rigid::normalize(blend)
                } else {
                    direction
                }
            }
            None => direction,
        };
        self.last_direction = Some((t, out));
        out
    }
}

/// Longest time between two slices (seconds) over which the last direction is a prior for the
/// next (`direction_prior_samples`): beyond it the heading may have turned anywhere.
pub const PRIOR_MAX_GAP_S: f64 = 0.2;

#[cfg(test)]
mod tests;
