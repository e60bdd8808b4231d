//! The camera's translation direction from the background's derotated normal flow: the linear
//! SVM (METHOD_NOTES section 3) as the start, refined with one inverse depth per image cell
//! ([`crate::refine`]). One function, used by both mergers.

use crate::density::density_weights;
use crate::refine::{DepthMemory, grid_regions, profile_cost, refine_direction_with_memory};
use crate::rigid;
use crate::samples::{FlowSample, median_length};
use crate::svm::{SvmParams, translation_direction};

/// Settings of [`estimate_translation`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EgomotionParams {
    /// The SVM.
    pub svm: SvmParams,
    /// Only samples whose flow confidence is above this take part (default 0.5). The stages
    /// before may keep every flow estimate for the segmentation's coverage, but the egomotion
    /// is better on the confident ones: on `evseg bench` (evseg-bench-v1) the median direction
    /// error was 61.6 deg with flow gated at 0.5 everywhere and 71.2 deg with every estimate.
    pub min_confidence: f32,
    /// Fewest samples for an estimate (default 30: the 3-parameter problem is well posed with a
    /// few tens of spread-out samples).
    pub min_samples: usize,
    /// Rounds of depth refinement after the SVM (default 50; 0 = the SVM alone, as in the
    /// paper). On the simulator's camera-only scene with estimated normal flow the SVM alone is
    /// 23-47 degrees off; 10-50 rounds bring most slices to 1-9 degrees.
    pub refine_iterations: usize,
    /// Columns of the grid of constant-depth cells (default 8: cells of 80 px on a 640 px
    /// sensor, small enough for one depth, large enough for tens of samples). Measured on
    /// `evseg bench` (evseg-bench-v3, at 0559795; median direction error / mean RMSE x y z
    /// m/s): 5 columns 8.7 deg / 0.047 0.050 0.096, 8 columns 8.4 / 0.050 0.051 0.099, 12
    /// columns 9.2 / 0.054 0.054 0.106. A depth that varies linearly across each cell (exact
    /// for planes such as a floor; tried in both mergers, not kept) was worse: 10.3 deg with
    /// free slopes, 8.8 with a ridge on them. Every background sample instead of at most
    /// `max_samples` gave 8.3 deg. So the direction is limited neither by the depth model nor by
    /// the sample count, but by errors shared by many samples (the normal flow's length).
    pub grid_cols: usize,
    /// Cells with fewer samples are left out of the refinement (default 20).
    pub min_cell_samples: usize,
    /// Side of the cells over which the samples are density-normalized, pixels: each sample is
    /// weighted by 1 / (samples in its cell) in the SVM and the refinement, so every patch counts
    /// alike however densely it fires (default 0 = equal weights, as in the reference). It
    /// limits the pull of a densely textured object wrongly kept in the background, but costs
    /// accuracy otherwise: median direction error on the simulator's camera-only scene 13 deg
    /// without, 25 deg with 8 px cells.
    pub density_cell_px: u16,
    /// Huber constant of the depth refinement, in units of the robust residual scale (1.4826 x
    /// the median absolute residual): residuals beyond `huber_k` scales are down-weighted
    /// ([`crate::refine::refine_direction_robust`]); 0 = plain least squares. Default 1.5 (the
    /// usual Huber constant, not tuned): on the simulator's true background with estimated normal
    /// flow (hierarchical merger's `examples/oracle_ladder.rs`, rung R6, seed 1, 2 s) the median
    /// direction error was 40.7 / 37.4 / 15.0 deg with least squares and 29.8 / 32.2 / 12.9 deg
    /// with Huber 1.5 (one-object / two-objects / camera-only); the least-squares refinement was
    /// worse than the SVM alone (32.9 / 35.1 / 22.8) on the scenes with objects.
    pub huber_k: f64,
    /// Weight each sample by `1 / (n^2 + n_med^2)` (`n` its normal-flow length, `n_med` the
    /// median over the samples) in the SVM and the refinement: an estimator's magnitude error
    /// grows with the flow's length, which is mostly rotational flow, so a long flow carries
    /// less information on the translation per unit of its length (default true). Measured on
    /// the simulator's true background with estimated normal flow (`examples/oracle_ladder.rs` of
    /// the hierarchical merger, rung R6, seed 1, 2 s, Huber 1.5): median direction error
    /// 29.8 / 32.2 / 12.9 deg without, 23.0 / 18.2 / 10.8 deg with (one-object / two-objects /
    /// camera-only). The `n_med` term keeps short, noisy flows from taking over.
    pub magnitude_weighting: bool,
    /// Leave out background samples within about this many pixels of an event that is not
    /// background (0 = keep all; see [`clear_of_foreground`]). A segmentation's border is where
    /// it errs most: object events wrongly kept in the background sit next to the object, and
    /// their flow pulls the direction towards the object's motion (the hierarchical merger's
    /// `examples/oracle_ladder.rs`, rung R6 with `R6_BOUNDARY_PX`, located the egomotion error
    /// of the object scenes there). Default 24 px, from 0 / 8 / 16 / 24 / 32 on `evseg bench`
    /// (evseg-bench-v1, causal flow, both mergers): IoU mask 25.25 / 27.50 / 29.07 / 29.93 /
    /// 29.90 %, median direction error 45.5 / 39.3 / 36.6 / 35.5 / 40.6 deg; the camera-only
    /// scene pays (13.0 -> 18.5 deg) where false foreground clusters take background with them.
    /// It scales with how far segment borders stray, i.e. with the flow's neighbourhood and the
    /// residual smoothing, not with the scene.
    pub clear_px: u16,
    /// Most samples of an estimate; more are thinned by a regular stride in the order given (0 =
    /// all). Default 8000: the 3-parameter direction is set by far fewer (the
    /// background merger's hypotheses use 600), and the SVM and the depth refinement cost
    /// grows with the count; with the repaired normal flow a 30 ms slice of a 640 x 480 scene
    /// keeps up to ~20000 background samples, which put both mergers on the pipeline's
    /// critical path (`evseg bench pipeline`).
    pub max_samples: usize,
    /// Weight of the previous slices' inverse depths of the refinement's grid cells as a prior
    /// on this slice's, relative to the cells' mean information (0 = off: every slice fits its
    /// cells' depths afresh; see [`crate::refine::refine_direction_with_memory`]). Used where
    /// the caller keeps a [`DepthMemory`] (the hierarchical merger's final estimate). Not in
    /// the paper. The depths of the static scene change little from one slice to the next,
    /// while a slice's own cell depth absorbs errors of the normal flow's length shared by the
    /// cell's samples and tilts the direction: with the simulator's true cell depths the
    /// direction error falls from 6.9 to 4.7 deg (`oracle_ladder` R6 / R7, true background,
    /// five presets x seeds 1-3, 1 s).
    pub depth_memory: f64,
    /// With [`EgomotionParams::depth_memory`]: slices over which the memory's weight grows
    /// from 0 to its full value after the memory starts (0 = at once). Default 10 (0.3 s of
    /// 30 ms slices; not in the paper): the first slices' estimates are still settling, and at
    /// full weight at once their wrong depths held the direction off for a long time
    /// (`graph.yaml`'s 1 s two-objects 7: median 11.5 deg without the memory, 19.1 with it at
    /// once, 16.3 with the ramp). `method_on_sim` (mean of fourteen median direction errors) 0
    /// -> 10 slices: bench seeds 5.58 -> 5.48 deg, seeds 301-307 and 401-407 6.89 -> 6.38.
    pub depth_memory_ramp_slices: u32,
    /// With [`EgomotionParams::depth_memory`], while the memory is still settling (fewer than
    /// [`EgomotionParams::depth_memory_ramp_slices`] slices since it started): the memory is
    /// restarted from this slice's own depths when the direction it leads to explains the
    /// slice's samples worse, by more than this fraction of the robust cost, than the direction
    /// the slice gives alone ([`crate::refine::profile_cost`], each grid cell at its own best
    /// depth; 0 = never). Not in the paper. The first slices of a stream have the worst normal
    /// flow (a simulator's or a camera's first events fire together: every pixel's reference
    /// level starts at its own intensity; the background's median length error is +5 to +12 %
    /// in the first 30-150 ms and about 0 after), and depths remembered from a wrong first
    /// direction held the estimate there while the camera's heading turned: two-objects 102's
    /// final direction drifted from 39 to 78 deg off over its first ten slices while the
    /// background merger's estimate (no memory) came to within 4-9 deg; the cost excess was
    /// 1.12-1.41 in those slices and 1.00-1.05 in settled ones. Default 0.2, from 0.1 / 0.2 on
    /// `method_on_sim` (the mean of fourteen per-sequence median direction errors, deg, off ->
    /// 0.2): bench seeds 5.48 -> 5.50, unseen seeds 301-307 / 401-407 6.38 -> 6.14, 501-507 /
    /// 601-607 5.91 -> 5.78; the mean over the first ten slices 14.3 -> 11.9, 22.0 -> 17.8 and
    /// 11.4 -> 11.1 deg. `evseg bench`: median direction error 5.41 -> 5.43 deg, RMSE Vy / Vz
    /// 0.0362 / 0.0510 -> 0.0355 / 0.0501 m/s. It costs one more refinement in the ramp's
    /// slices only.
    pub depth_memory_restart_ratio: f64,
}

/// Default of [`EgomotionParams::huber_k`] (the usual Huber constant), also the constant of the
/// memory's check ([`EgomotionParams::depth_memory_restart_ratio`]) when the refinement runs
/// without Huber weights.
const DEFAULT_HUBER_K: f64 = 1.5;

/// Directions closer than this (radians) are the same solution of the depth refinement: ten
/// times its convergence step ([`crate::refine::CONVERGED`]).
const SAME_DIRECTION_RAD: f64 = 10.0 * crate::refine::CONVERGED;

impl Default for EgomotionParams {
    fn default() -> Self {
        Self {
            svm: SvmParams::default(),
            min_confidence: 0.5,
            min_samples: 30,
            refine_iterations: 50,
            grid_cols: 8,
            min_cell_samples: 20,
            density_cell_px: 0,
            huber_k: DEFAULT_HUBER_K,
            magnitude_weighting: true,
            clear_px: 24,
            max_samples: 8000,
            depth_memory: 0.0,
            depth_memory_ramp_slices: 10,
            depth_memory_restart_ratio: 0.2,
        }
    }
}

/// The `samples` (background) whose pixel lies at least about `clear_px` pixels from every
/// event `i` with `foreground(i)` (events at pixels `x`, `y` of a sensor of `size` = (width,
/// height) pixels):
/// foreground events mark cells of `clear_px` pixels, the marks are dilated by one cell, and
/// samples in marked cells are left out, so a sample is kept only when it is at least
/// `clear_px` (and at most `2 clear_px`) pixels away from every foreground event in x or y.
/// When fewer than `min_keep` samples would remain, all are kept (a slice where the objects
/// cover most of the view still needs an estimate). `clear_px` 0 keeps all.
pub fn clear_of_foreground<'a>(
    samples: &[&'a FlowSample],
    x: &[u16],
    y: &[u16],
    size: (u16, u16),
    clear_px: u16,
    min_keep: usize,
    foreground: impl Fn(usize) -> bool,
) -> Vec<&'a FlowSample> {
    if clear_px == 0 || samples.is_empty() {
        return samples.to_vec();
    }
    let cell = usize::from(clear_px);
    let cols = usize::from(size.0).div_ceil(cell).max(1);
    let rows = usize::from(size.1).div_ceil(cell).max(1);
    let mut marked = vec![false; cols * rows];
    let mut any = false;
    for (i, (&xi, &yi)) in x.iter().zip(y).enumerate() {
        if foreground(i) {
            let (c, r) = (usize::from(xi) / cell, usize::from(yi) / cell);
            if c < cols && r < rows {
                marked[r * cols + c] = true;
                any = true;
            }
        }
    }
    if !any {
        return samples.to_vec();
    }
    let near = |c: usize, r: usize| {
        (r.saturating_sub(1)..=(r + 1).min(rows - 1))
            .any(|rr| (c.saturating_sub(1)..=(c + 1).min(cols - 1)).any(|cc| marked[rr * cols + cc]))
    };
    let kept: Vec<&FlowSample> = samples
        .iter()
        .copied()
        .filter(|s| {
            let (Some(&xi), Some(&yi)) = (x.get(s.index), y.get(s.index)) else {
                return false;
            };
            let (c, r) = (usize::from(xi) / cell, usize::from(yi) / cell);
            c >= cols || r >= rows || !near(c, r)
        })
        .collect();
    if kept.len() < min_keep {
        samples.to_vec()
    } else {
        kept
    }
}

/// The translation direction of the background `samples` of a slice with `events` seen by a
/// sensor of `size` = (width, height) pixels, leaving out the samples next to an event with
/// `foreground(i)` first: [`clear_of_foreground`] with `p.clear_px` and `p.min_samples`, then
/// [`estimate_translation`]. What both mergers do with their background.
pub fn estimate_background_translation(
    samples: &[&FlowSample],
    events: &evseg_schemas::Events,
    size: (u16, u16),
    p: &EgomotionParams,
    foreground: impl Fn(usize) -> bool,
) -> Option<[f64; 3]> {
    estimate_background_translation_with_memory(samples, events, size, p, foreground, None)
}

/// [`estimate_background_translation`] with the grid cells' depths of the previous slices in
/// `memory` as a prior of weight [`EgomotionParams::depth_memory`] (0: not used), updated with
/// this slice's.
pub fn estimate_background_translation_with_memory(
    samples: &[&FlowSample],
    events: &evseg_schemas::Events,
    size: (u16, u16),
    p: &EgomotionParams,
    foreground: impl Fn(usize) -> bool,
    memory: Option<&mut DepthMemory>,
) -> Option<[f64; 3]> {
    let kept = clear_of_foreground(
        samples,
        &events.x,
        &events.y,
        size,
        p.clear_px,
        p.min_samples,
        foreground,
    );
    let memory = memory
        .filter(|_| p.depth_memory > 0.0)
        .map(|m| (m, p.depth_memory));
    estimate_translation_with_memory(&kept, &events.x, &events.y, size.0, size.1, p, memory)
}

/// The unit translation direction (camera frame) of the background `samples`, whose events lie
/// at pixels `x`, `y` (the slice's event columns) of a `width` x `height` sensor. `None` with too
/// few samples or no translation signal.
pub fn estimate_translation(
    samples: &[&FlowSample],
    x: &[u16],
    y: &[u16],
    width: u16,
    height: u16,
    p: &EgomotionParams,
) -> Option<[f64; 3]> {
    estimate_translation_with_memory(samples, x, y, width, height, p, None)
}

/// [`estimate_translation`] whose depth refinement takes the previous slices' depths of its
/// grid cells as a prior (`Some((memory, weight))`, see
/// [`crate::refine::refine_direction_with_memory`]) and leaves this slice's in `memory`.
pub fn estimate_translation_with_memory(
    samples: &[&FlowSample],
    x: &[u16],
    y: &[u16],
    width: u16,
    height: u16,
    p: &EgomotionParams,
    memory: Option<(&mut DepthMemory, f64)>,
) -> Option<[f64; 3]> {
    let confident: Vec<&FlowSample>;
    let samples = if samples.iter().all(|s| s.confidence > p.min_confidence) {
        samples
    } else {
        confident = samples
            .iter()
            .copied()
            .filter(|s| s.confidence > p.min_confidence)
            .collect();
        &confident[..]
    };
    if samples.len() < p.min_samples.max(3) {
        return None;
    }
    let thinned: Vec<&FlowSample>;
    let samples = if p.max_samples > 0 && samples.len() > p.max_samples {
        thinned = samples
            .iter()
            .step_by(samples.len().div_ceil(p.max_samples))
            .copied()
            .collect();
        &thinned[..]
    } else {
        samples
    };
    let weights: Vec<f64> = if p.density_cell_px > 0 {
        density_weights(
            samples.iter().map(|s| {
                (
                    x.get(s.index).copied().unwrap_or(0),
                    y.get(s.index).copied().unwrap_or(0),
                )
            }),
            width,
            height,
            p.density_cell_px,
        )
    } else {
        vec![1.0; samples.len()]
    };
    let weights = if p.magnitude_weighting {
        let med = median_length(samples.iter().copied()).unwrap_or(0.0);
        let med2 = (med * med).max(f64::MIN_POSITIVE);
        weights
            .iter()
            .zip(samples)
            .map(|(w, s)| w / (s.n * s.n + med2))
            .collect()
    } else {
        weights
    };
    let weighted = samples.iter().copied().zip(weights.iter().copied());
    let svm = translation_direction(weighted.clone(), &p.svm)?;
    if p.refine_iterations == 0 {
        return Some(svm.direction);
    }
    let regions = grid_regions(weighted, x, y, width, height, p.grid_cols);
    let huber = (p.huber_k > 0.0).then_some(p.huber_k);
    let refine = |memory: Option<(&mut DepthMemory, f64)>| {
        refine_direction_with_memory(
            &regions,
            svm.direction,
            p.refine_iterations,
            p.min_cell_samples,
            huber,
            memory,
        )
    };
    let (memory, weight) = match memory {
        Some((m, w)) if w > 0.0 => (m, w),
        other => return Some(refine(other).unwrap_or(svm.direction)),
    };
    // The remembered depths weigh in fully only after `depth_memory_ramp_slices` slices: the
    // first slices of a sequence, whose estimates are still settling, would otherwise hold
    // their wrong depths for a long time.
    let ramp = match p.depth_memory_ramp_slices {
        0 => 1.0,
        n => (f64::from(memory.slices) / f64::from(n)).min(1.0),
    };
    // While the memory settles, the slice's own estimate (no memory) is the check: a memory
    // that pulls the direction to where the slice's samples fit clearly worse is replaced by
    // the fresh one that estimate filled with this slice's depths.
    let settling = memory.slices < p.depth_memory_ramp_slices && p.depth_memory_restart_ratio > 0.0;
    let mut fresh = DepthMemory::default();
    let alone = if settling {
        refine(Some((&mut fresh, 0.0)))
    } else {
        None
    };
    let mut t = refine(Some((&mut *memory, weight * ramp)));
    if let (Some(alone), Some(held)) = (alone, t) {
        let k = if p.huber_k > 0.0 {
            p.huber_k
        } else {
            DEFAULT_HUBER_K
        };
        let own = profile_cost(&regions, alone, p.min_cell_samples, k, None);
        let with_memory = profile_cost(&regions, held, p.min_cell_samples, k, Some(own.scale));
        // Directions within the refinement's resolution are one solution, however their costs
        // round (a slice its own direction explains exactly has a cost near 0).
        let apart = rigid::angle_between(alone, held) > SAME_DIRECTION_RAD;
        if apart && with_memory.cost > (1.0 + p.depth_memory_restart_ratio) * own.cost {
            *memory = fresh;
            t = Some(alone);
        }
    }
    memory.slices = memory.slices.saturating_add(1);
    Some(t.unwrap_or(svm.direction))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::translational_flow;

    #[test]
    fn samples_next_to_foreground_are_left_out_unless_too_few_remain() {
        // Events along a row: x = 0, 10, ..., 190; the one at x = 100 is foreground.
        let xs: Vec<u16> = (0..20).map(|k| k * 10).collect();
        let ys = vec![5u16; 20];
        let all: Vec<FlowSample> = (0..20)
            .filter(|&k| k != 10)
            .map(|index| FlowSample {
                index,
                x: 0.0,
                y: 0.0,
                n0: [1.0, 0.0],
                n: 1.0,
                n_derot: 1.0,
                confidence: 1.0,
            })
            .collect();
        let refs: Vec<&FlowSample> = all.iter().collect();
        let fg = |i: usize| i == 10;
        // 8 px cells: the foreground's cell is 12 (x 96..103), dilated to 11..=13 (x 88..111):
        // the samples at x = 90 and 110 go.
        let kept = clear_of_foreground(&refs, &xs, &ys, (200, 10), 8, 1, fg);
        let gone: Vec<usize> = refs
            .iter()
            .map(|s| s.index)
            .filter(|i| !kept.iter().any(|k| k.index == *i))
            .collect();
        assert_eq!(gone, vec![9, 11]);
        assert_eq!(
            clear_of_foreground(&refs, &xs, &ys, (200, 10), 0, 1, fg).len(),
            19
        );
        // Too few would remain: all are kept.
        assert_eq!(
            clear_of_foreground(&refs, &xs, &ys, (200, 10), 8, 18, fg).len(),
            19
        );
    }

    /// Samples of a camera translating along `t` past a scene whose depth varies by image cell,
    /// on a 640 x 480 sensor with focal length 320 px; every sample gets `confidence`.
    fn scene(t: [f64; 3], confidence: f32, start: usize, n: usize) -> (Vec<FlowSample>, Vec<u16>, Vec<u16>) {
        let (mut samples, mut xs, mut ys) = (Vec::new(), Vec::new(), Vec::new());
        for k in start..start + n {
            let (u, v) = ((k * 37) % 640, (k * 53 / 7) % 480);
            let (x, y) = ((u as f64 - 320.0) / 320.0, (v as f64 - 240.0) / 320.0);
            let inv_z = 0.5 + 0.4 * (((u / 80) + (v / 80)) % 3) as f64;
            let f = translational_flow(x, y, t, inv_z);
            let ang = k as f64 * 2.399963;
            let mut n0 = [ang.cos(), ang.sin()];
            let mut nf = f[0] * n0[0] + f[1] * n0[1];
            if nf < 0.0 {
                n0 = [-n0[0], -n0[1]];
                nf = -nf;
            }
            if nf < 1e-6 {
                continue;
            }
            samples.push(FlowSample {
                index: xs.len(),
                x,
                y,
                n0,
                n: nf,
                n_derot: nf,
                confidence,
            });
            xs.push(u as u16);
            ys.push(v as u16);
        }
        (samples, xs, ys)
    }

    fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
        let dot: f64 = (0..3).map(|i| a[i] * b[i]).sum();
        let na = a.iter().map(|v| v * v).sum::<f64>().sqrt();
        let nb = b.iter().map(|v| v * v).sum::<f64>().sqrt();
        (dot / (na * nb)).clamp(-1.0, 1.0).acos().to_degrees()
    }

    #[test]
    fn low_confidence_flow_is_left_out_of_the_egomotion() {
        let t_true = [0.6, 0.0, 0.8];
        let (mut samples, mut xs, mut ys) = scene(t_true, 0.9, 0, 1500);
        // As many unconfident samples that follow another motion.
        let (wrong, wx, wy) = scene([-0.2, 0.9, 0.1], 0.1, 1500, 1500);
        for mut s in wrong {
            s.index += xs.len();
            samples.push(s);
        }
        xs.extend(wx);
        ys.extend(wy);
        let refs: Vec<&FlowSample> = samples.iter().collect();
        let gated = EgomotionParams::default();
        let t = estimate_translation(&refs, &xs, &ys, 640, 480, &gated).unwrap();
        assert!(angle_deg(t, t_true) < 3.0, "gated: {t:?}");
        let all = EgomotionParams {
            min_confidence: 0.0,
            ..EgomotionParams::default()
        };
        let t_all = estimate_translation(&refs, &xs, &ys, 640, 480, &all).unwrap();
        assert!(
            angle_deg(t_all, t_true) > 10.0,
            "ungated should be pulled away: {t_all:?}"
        );
        // Too few confident samples (the last few of the first scene, 1500 unconfident ones):
        // no estimate.
        let few_refs: Vec<&FlowSample> = samples.iter().skip(1480).collect();
        assert!(few_refs.len() > 1000);
        let strict = EgomotionParams {
            min_samples: 100,
            ..EgomotionParams::default()
        };
        assert!(estimate_translation(&few_refs, &xs, &ys, 640, 480, &strict).is_none());
    }

    #[test]
    fn the_depth_memory_starts_at_no_weight_and_counts_its_slices() {
        let t_true = [0.6, 0.0, 0.8];
        let (samples, xs, ys) = scene(t_true, 0.9, 0, 1500);
        let refs: Vec<&FlowSample> = samples.iter().collect();
        let p = EgomotionParams {
            depth_memory: 1.0,
            depth_memory_ramp_slices: 3,
            ..EgomotionParams::default()
        };
        let plain = estimate_translation(&refs, &xs, &ys, 640, 480, &p).unwrap();
        let mut memory = DepthMemory::default();
        // The first slice weighs the (empty) memory 0: the plain estimate, and the memory
        // takes its depths.
        let first = estimate_translation_with_memory(&refs, &xs, &ys, 640, 480, &p, Some((&mut memory, 1.0)))
            .unwrap();
        assert_eq!(first, plain);
        assert_eq!(memory.slices, 1);
        assert!(
            memory.rho.iter().any(|r| r.is_finite() && *r > 0.0),
            "{:?}",
            memory.rho
        );
        // The same slice again, with the memory weighing in more each time: the remembered
        // depths are this scene's, so the estimate stays.
        for k in 2..=5 {
            let t = estimate_translation_with_memory(&refs, &xs, &ys, 640, 480, &p, Some((&mut memory, 1.0)))
                .unwrap();
            assert!(angle_deg(t, plain) < 0.01, "slice {k}: {t:?} vs {plain:?}");
            assert_eq!(memory.slices, k);
        }
        assert!(angle_deg(plain, t_true) < 3.0, "{plain:?}");
    }

    #[test]
    fn a_settling_memory_that_contradicts_the_slice_is_restarted() {
        let t_true = [0.6, 0.0, 0.8];
        let (samples, xs, ys) = scene(t_true, 0.9, 0, 3000);
        let refs: Vec<&FlowSample> = samples.iter().collect();
        let p = EgomotionParams {
            depth_memory: 1000.0,
            depth_memory_ramp_slices: 3,
            ..EgomotionParams::default()
        };
        let plain = estimate_translation(&refs, &xs, &ys, 640, 480, &p).unwrap();
        // Depths of another scene (the cells' inverse depths swapped end for end), held
        // firmly.
        let mut learnt = DepthMemory::default();
        estimate_translation_with_memory(&refs, &xs, &ys, 640, 480, &p, Some((&mut learnt, 1000.0)));
        let wrong = DepthMemory {
            rho: learnt.rho.iter().rev().copied().collect(),
            slices: 2,
        };
        let run = |ratio: f64| {
            let q = EgomotionParams {
                depth_memory_restart_ratio: ratio,
                ..p
            };
            let mut memory = wrong.clone();
            let t =
                estimate_translation_with_memory(&refs, &xs, &ys, 640, 480, &q, Some((&mut memory, 1000.0)))
                    .unwrap();
            (t, memory)
        };
        // Without the check the wrong depths pull the direction off (a little: this scene's
        // cells see every normal direction, which pins the direction down).
        let (held, memory) = run(0.0);
        assert!(angle_deg(held, plain) > 0.1, "{held:?} vs {plain:?}");
        assert_eq!(memory.slices, 3);
        // With it the memory starts again from this slice: the slice's own estimate.
        let (t, memory) = run(0.2);
        assert!(angle_deg(t, plain) < 0.01, "{t:?} vs {plain:?}");
        assert_eq!(memory.slices, 1);
        // A settled memory is not checked.
        let settled = EgomotionParams {
            depth_memory_restart_ratio: 0.2,
            ..p
        };
        let mut memory = DepthMemory {
            slices: 3,
            ..wrong.clone()
        };
        let t = estimate_translation_with_memory(
            &refs,
            &xs,
            &ys,
            640,
            480,
            &settled,
            Some((&mut memory, 1000.0)),
        )
        .unwrap();
        assert!(angle_deg(t, plain) > 0.1, "{t:?}");
        assert_eq!(memory.slices, 4);
    }

    #[test]
    fn many_samples_are_thinned_by_a_regular_stride() {
        // Every fourth sample follows the camera's translation, the others another motion.
        let t_true = [0.6, 0.0, 0.8];
        let (good, xs, ys) = scene(t_true, 0.9, 0, 2000);
        let (bad, _, _) = scene([-0.2, 0.9, 0.1], 0.9, 0, 2000);
        let mut samples = Vec::new();
        for (g, b) in good.iter().zip(&bad).take(1500) {
            samples.push(*g);
            for _ in 0..3 {
                samples.push(FlowSample { index: g.index, ..*b });
            }
        }
        let refs: Vec<&FlowSample> = samples.iter().collect();
        let all = EgomotionParams {
            max_samples: 0,
            ..EgomotionParams::default()
        };
        let t_all = estimate_translation(&refs, &xs, &ys, 640, 480, &all).unwrap();
        assert!(angle_deg(t_all, t_true) > 10.0, "all samples: {t_all:?}");
        let thinned = EgomotionParams {
            max_samples: refs.len() / 4,
            ..EgomotionParams::default()
        };
        let t = estimate_translation(&refs, &xs, &ys, 640, 480, &thinned).unwrap();
        assert!(angle_deg(t, t_true) < 3.0, "every fourth sample: {t:?}");
    }
}
