//! Refinement of a translation direction with one inverse depth per region: alternating least
//! squares on `n_derot_i = rho_r(i) (X_i . t)`, `rho >= 0`, `|t| = 1`.
//!
//! The SVM of [`crate::svm`] only uses the *sign* of the derotated flow; on a narrow field of
//! view many directions separate the samples and its max-margin answer can be tens of degrees
//! from the truth (measured on the simulator's camera-only scene: 15-30 degrees with the true
//! flow magnitude). Regions of roughly constant depth (the over-segmentation's clusters) make
//! the magnitude usable: with `t` fixed each region's `rho` is a 1-parameter least squares
//! (clamped at 0 by cheirality); with every `rho` fixed `t` is a 3-parameter least squares.

use nalgebra::{Matrix3, Vector3};

use crate::samples::FlowSample;

/// The alternation stops once the unit direction moves by less than this between two rounds
/// (radians, about 6e-5 degrees: far below the direction's accuracy of a degree or more). It
/// was 1e-9, which the Huber-weighted alternation, converging linearly, almost never reached,
/// so it ran all of its rounds; see `docs/speed-history.md`.
pub const CONVERGED: f64 = 1e-6;

/// Refines `t0` (any length, camera frame) over `regions` (each a set of samples, with a prior
/// weight each, assumed at one depth) for `iterations` rounds; returns the unit direction, or `None` when the system is
/// degenerate (no region with signal). Regions with fewer than `min_region` samples are left out.
pub fn refine_direction(
    regions: &[Vec<(&FlowSample, f64)>],
    t0: [f64; 3],
    iterations: usize,
    min_region: usize,
) -> Option<[f64; 3]> {
    refine_direction_robust(regions, t0, iterations, min_region, None)
}

/// [`refine_direction`] with Huber weights `min(1, k s / |e|)` on the residuals `e` when
/// `huber_k` is given (`s` = 1.4826 x the median absolute residual of the previous round): a few
/// events with a wrong normal flow (about 4 % on the simulator, mostly at object boundaries)
/// otherwise pull the direction.
pub fn refine_direction_robust(
    regions: &[Vec<(&FlowSample, f64)>],
    t0: [f64; 3],
    iterations: usize,
    min_region: usize,
    huber_k: Option<f64>,
) -> Option<[f64; 3]> {
    refine_direction_with_memory(regions, t0, iterations, min_region, huber_k, None)
}

/// Inverse depths of the regions (cells) of the previous slices, carried to the next slice's
/// refinement as a prior ([`refine_direction_with_memory`]). The depths of the static scene
/// change slowly, while each slice's own per-region depth is free to absorb errors of the normal
/// flow's length that then tilt the direction.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DepthMemory {
    /// Inverse depth per region, in the units of the last slice's unit translation (1/s:
    /// speed over depth); NaN where no slice has fitted the region yet.
    pub rho: Vec<f64>,
    /// Slices whose estimate has updated the memory since it started (see
    /// [`crate::EgomotionParams::depth_memory_ramp_slices`]).
    pub slices: u32,
}

/// [`refine_direction_robust`] with a prior on each region's inverse depth from `memory`
/// (`Some((memory, weight))`): the previous depths, times one scale fitted per slice (the
/// speed changes), pull each region's depth with `weight` times the mean information of the
/// regions. `memory` is then updated with this slice's depths (regions not fitted keep theirs,
/// rescaled). `weight` 0 or `None`: as [`refine_direction_robust`].
pub fn refine_direction_with_memory(
    regions: &[Vec<(&FlowSample, f64)>],
    t0: [f64; 3],
    iterations: usize,
    min_region: usize,
    huber_k: Option<f64>,
    mut memory: Option<(&mut DepthMemory, f64)>,
) -> Option<[f64; 3]> {
    if let Some((mem, _)) = memory.as_mut()
        && mem.rho.len() != regions.len()
    {
        mem.rho = vec![f64::NAN; regions.len()];
        mem.slices = 0;
    }
    let prior_weight = memory.as_ref().map_or(0.0, |(_, w)| *w);
    let prior: Vec<f64> = memory
        .as_ref()
        .map_or_else(|| vec![f64::NAN; regions.len()], |(m, _)| m.rho.clone());
    let mut fitted = vec![f64::NAN; regions.len()];
    let mut scale_fit = 1.0;
    let mut t = Vector3::from(t0);
    let norm = t.norm();
    if !(norm.is_finite() && norm > 0.0) {
        return None;
    }
    t /= norm;
    if huber_k.is_none() && memory.is_none() {
        return refine_by_moments(regions, t, iterations, min_region);
    }
    let (ids, rows): (Vec<usize>, Vec<RegionRows>) = regions
        .iter()
        .enumerate()
        .filter(|(_, r)| r.len() >= min_region.max(1))
        .map(|(k, r)| (k, RegionRows::new(r)))
        .unzip();
    if rows.is_empty() {
        return None;
    }
    let mut scale: Option<f64> = None;
    let mut abs_res: Vec<f64> = Vec::new();
    for _ in 0..iterations {
        let mut m = Matrix3::zeros();
        let mut b = Vector3::zeros();
        abs_res.clear();
        let cut = match (huber_k, scale) {
            (Some(k), Some(s)) => k * s,
            _ => f64::INFINITY,
        };
        // Each region's own inverse depth and information under `t`, then (with a memory) the
        // slice's scale of the previous depths and the blend.
        let own: Vec<(f64, f64)> = rows.iter().map(|region| region.own_depth(&t)).collect();
        let blended: Vec<f64> = if prior_weight > 0.0 {
            let (mut num, mut den, mut info) = (0.0, 0.0, 0.0);
            for (&(rho, d), &k) in own.iter().zip(&ids) {
                info += d;
                // A remembered depth of 0 (a cell without signal) is no prior.
                if prior[k] > 0.0 {
                    num += d * rho * prior[k];
                    den += d * prior[k] * prior[k];
                }
            }
            // The slice's scale of the previous depths (the speed changes): least squares of
            // the regions' own depths on them, weighted by the regions' information.
            scale_fit = if den > 0.0 { num / den } else { 1.0 };
            let lam = prior_weight * info / own.len() as f64;
            own.iter()
                .zip(&ids)
                .map(|(&(rho, d), &k)| {
                    if prior[k] > 0.0 && d + lam > 0.0 {
                        ((d * rho + lam * scale_fit * prior[k]) / (d + lam)).max(0.0)
                    } else {
                        rho
                    }
                })
                .collect()
        } else {
            own.iter().map(|&(rho, _)| rho).collect()
        };
        for ((region, &rho), &k) in rows.iter().zip(&blended).zip(&ids) {
            fitted[k] = rho;
            if rho == 0.0 {
                continue;
            }
            // The t half-step's sums: the region's moments, less the Huber discount of the
            // samples beyond the cut (a minority), so a round costs one dot product per sample.
            let (mut xx, mut nx) = (region.xx, region.nx);
            for (x, n, prior) in &region.rows {
                let e = (n - rho * x.dot(&t)).abs();
                abs_res.push(e);
                if e > cut {
                    let less = prior * (1.0 - cut / e);
                    xx -= less * x * x.transpose();
                    nx -= less * n * x;
                }
            }
            m += rho * rho * xx;
            b += rho * nx;
        }
        if huber_k.is_some() {
            scale = robust_scale(&mut abs_res).or(scale);
        }
        match direction_step(&m, &b, &mut t) {
            Some(change) if change >= CONVERGED => {}
            _ => break,
        }
    }
    if let Some((mem, _)) = memory {
        for (k, r) in mem.rho.iter_mut().enumerate() {
            *r = if fitted[k].is_finite() && fitted[k] > 0.0 {
                fitted[k]
            } else if scale_fit.is_finite() && scale_fit > 0.0 {
                *r * scale_fit
            } else {
                *r
            };
        }
    }
    Some(t.into())
}

/// The robust scale of absolute residuals: 1.4826 x their median (the standard deviation of
/// Gaussian residuals), at least the smallest positive number; `None` when there are none.
/// Reorders `abs_res`.
fn robust_scale(abs_res: &mut [f64]) -> Option<f64> {
    if abs_res.is_empty() {
        return None;
    }
    let mid = abs_res.len() / 2;
    let (_, med, _) = abs_res.select_nth_unstable_by(mid, f64::total_cmp);
    Some((1.4826 * *med).max(f64::MIN_POSITIVE))
}

/// How well a unit direction explains one slice's regions on their own: see [`profile_cost`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProfileCost {
    /// The Huber cost of the residuals under the direction (normalized flow squared, 1/s^2,
    /// times the samples' weights).
    pub cost: f64,
    /// The robust scale used, 1/s.
    pub scale: f64,
}

/// How well the unit direction `t` explains one slice's `regions` on their own (no memory):
/// each region with at least `min_region` samples at its own best inverse depth under `t`
/// (clamped at 0), the Huber loss of its samples' residuals `n_derot - rho X . t` (normalized
/// flow, 1/s) weighted by the samples' weights, summed. The Huber constant is `huber_k` robust
/// scales; `scale` is that scale (1/s), or `None` to take it from these residuals (1.4826 x
/// their median absolute value). Lower is better; only differences between directions scored
/// on the same regions and scale (pass the first one's `scale` to the second) mean anything.
pub fn profile_cost(
    regions: &[Vec<(&FlowSample, f64)>],
    t: [f64; 3],
    min_region: usize,
    huber_k: f64,
    scale: Option<f64>,
) -> ProfileCost {
    let t = Vector3::from(t);
    // (residual, weight) per sample.
    let mut residuals: Vec<(f64, f64)> = Vec::new();
    for region in regions.iter().filter(|r| r.len() >= min_region.max(1)) {
        let rows = RegionRows::new(region);
        let (rho, _) = rows.own_depth(&t);
        residuals.extend(rows.rows.iter().map(|(x, n, w)| (n - rho * x.dot(&t), *w)));
    }
    let scale = scale.unwrap_or_else(|| {
        let mut abs: Vec<f64> = residuals.iter().map(|(e, _)| e.abs()).collect();
        robust_scale(&mut abs).unwrap_or(f64::MIN_POSITIVE)
    });
    let c = huber_k * scale;
    let cost = residuals
        .iter()
        .map(|&(e, w)| {
            let e = e.abs();
            w * if e <= c { 0.5 * e * e } else { c * (e - 0.5 * c) }
        })
        .sum();
    ProfileCost { cost, scale }
}

/// One region's samples for the Huber refinement: `(X, n_derot, prior weight)` rows and their
/// prior-weighted moments `sum w X X^T`, `sum w n X`.
struct RegionRows {
    rows: Vec<(Vector3<f64>, f64, f64)>,
    xx: Matrix3<f64>,
    nx: Vector3<f64>,
}

impl RegionRows {
    fn new(region: &[(&FlowSample, f64)]) -> Self {
        let rows: Vec<(Vector3<f64>, f64, f64)> = region
            .iter()
            .map(|(s, w)| (Vector3::from(s.x_row()), s.n_derot, *w))
            .collect();
        let (xx, nx) = moments(rows.iter().map(|&(x, n, w)| (x, n, w)));
        Self { rows, xx, nx }
    }

    /// The region's own inverse depth under unit direction `t` (least squares of its samples,
    /// clamped at 0) and its information `t^T (sum w X X^T) t` (at least 0).
    fn own_depth(&self, t: &Vector3<f64>) -> (f64, f64) {
        let den = t.dot(&(self.xx * t));
        let rho = if den > 0.0 {
            (t.dot(&self.nx) / den).max(0.0)
        } else {
            0.0
        };
        (rho, den.max(0.0))
    }
}

/// `sum w X X^T` and `sum w n X` over `(X, n, w)`.
fn moments(rows: impl Iterator<Item = (Vector3<f64>, f64, f64)>) -> (Matrix3<f64>, Vector3<f64>) {
    let mut xx = Matrix3::zeros();
    let mut nx = Vector3::zeros();
    for (x, n, w) in rows {
        xx += w * x * x.transpose();
        nx += w * n * x;
    }
    (xx, nx)
}

/// The unweighted-by-residual refinement through each region's moments `sum w X X^T` and
/// `sum w n X`: with fixed weights both half-steps only need these, so an iteration costs
/// O(regions) instead of O(samples) (same result as the per-sample loop up to rounding).
fn refine_by_moments(
    regions: &[Vec<(&FlowSample, f64)>],
    mut t: Vector3<f64>,
    iterations: usize,
    min_region: usize,
) -> Option<[f64; 3]> {
    let moments: Vec<(Matrix3<f64>, Vector3<f64>)> = regions
        .iter()
        .filter(|r| r.len() >= min_region.max(1))
        .map(|r| moments(r.iter().map(|(s, w)| (Vector3::from(s.x_row()), s.n_derot, *w))))
        .collect();
    if moments.is_empty() {
        return None;
    }
    for _ in 0..iterations {
        let mut m = Matrix3::zeros();
        let mut b = Vector3::zeros();
        for (xx, nx) in &moments {
            let den = t.dot(&(xx * t));
            let rho = if den > 0.0 {
                (t.dot(nx) / den).max(0.0)
            } else {
                0.0
            };
            if rho == 0.0 {
                continue;
            }
            m += rho * rho * xx;
            b += rho * nx;
        }
        match direction_step(&m, &b, &mut t) {
            Some(change) if change >= CONVERGED => {}
            _ => break,
        }
    }
    Some(t.into())
}

/// The translation half-step shared by both refinements: solves `m t' = b` (the depth-weighted
/// normal equations), normalizes `t'` and stores it in `t`. Returns how far the unit direction
/// moved, or `None` (leaving `t`) when the system is singular or the solution degenerate.
fn direction_step(m: &Matrix3<f64>, b: &Vector3<f64>, t: &mut Vector3<f64>) -> Option<f64> {
    let next = m.cholesky().map(|c| c.solve(b))?;
    let nn = next.norm();
    if !(nn.is_finite() && nn > 0.0) {
        return None;
    }
    let next = next / nn;
    let change = (next - *t).norm();
    *t = next;
    Some(change)
}

/// Groups `samples` into the cells of a `cols` x `rows` grid over the `width` x `height` pixel
/// sensor by their events' pixels (`x`, `y`: the slice's event columns), with `rows` chosen so
/// the cells are about square: the regions of roughly constant depth for
/// [`refine_direction`].
pub fn grid_regions<'a>(
    samples: impl IntoIterator<Item = (&'a FlowSample, f64)>,
    x: &[u16],
    y: &[u16],
    width: u16,
    height: u16,
    cols: usize,
) -> Vec<Vec<(&'a FlowSample, f64)>> {
    let cols = cols.max(1);
    let (w, h) = (usize::from(width.max(1)), usize::from(height.max(1)));
    let rows = ((cols * h) as f64 / w as f64).round().max(1.0) as usize;
    let mut out: Vec<Vec<(&FlowSample, f64)>> = vec![Vec::new(); cols * rows];
    for (s, weight) in samples {
        let (Some(&u), Some(&v)) = (x.get(s.index), y.get(s.index)) else {
            continue;
        };
        let (c, r) = (
            (usize::from(u) * cols / w).min(cols - 1),
            (usize::from(v) * rows / h).min(rows - 1),
        );
        out[r * cols + c].push((s, weight));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::translational_flow;

    /// Samples of the translational flow of `t_true` in regions at `(cx, cy, inv_z)` (normalized
    /// image units, 1 / m), at the offsets `points` around each centre, with normal directions
    /// turning by the golden angle from sample to sample; the normal flow of the samples for
    /// which `wrong(k)` holds (k counts from 1 over all regions) is flipped and doubled.
    fn region_samples(
        t_true: [f64; 3],
        regions: impl Iterator<Item = (f64, f64, f64)>,
        points: &[(f64, f64)],
        wrong: impl Fn(usize) -> bool,
    ) -> Vec<Vec<FlowSample>> {
        let mut k = 0usize;
        regions
            .map(|(cx, cy, inv_z)| {
                points
                    .iter()
                    .map(|&(dx, dy)| {
                        k += 1;
                        let (x, y) = (cx + dx, cy + dy);
                        let u = translational_flow(x, y, t_true, inv_z);
                        let ang = k as f64 * 2.399963;
                        let n0 = [ang.cos(), ang.sin()];
                        let mut n = u[0] * n0[0] + u[1] * n0[1];
                        if wrong(k) {
                            n *= -2.0;
                        }
                        FlowSample {
                            index: k,
                            x,
                            y,
                            n0,
                            n,
                            n_derot: n,
                            confidence: 1.0,
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// [`region_samples`] of twelve regions on a 4 x 3 grid, each at its own depth (inverse
    /// depth 0.2 to 1.85), of 60 samples on an 8-wide grid 0.01 apart.
    fn twelve_regions(t_true: [f64; 3], wrong: impl Fn(usize) -> bool) -> Vec<Vec<FlowSample>> {
        let centres = (0..12u32).map(|r| {
            (
                f64::from(r % 4) * 0.3 - 0.45,
                f64::from(r / 4) * 0.3 - 0.3,
                0.2 + 0.15 * f64::from(r),
            )
        });
        let points: Vec<(f64, f64)> = (0..60u32)
            .map(|j| (f64::from(j % 8) * 0.01, f64::from(j / 8) * 0.01))
            .collect();
        region_samples(t_true, centres, &points, wrong)
    }

    #[test]
    fn regions_at_different_depths_give_the_direction_from_a_poor_start() {
        let t_true = [0.3, -0.2, 0.9];
        let samples = twelve_regions(t_true, |_| false);
        let regions: Vec<Vec<(&FlowSample, f64)>> = samples
            .iter()
            .map(|m| m.iter().map(|s| (s, 1.0)).collect())
            .collect();
        let t = refine_direction(&regions, [0.6, 0.3, 0.5], 50, 10).unwrap();
        let tn = Vector3::from(t_true).normalize();
        assert!((Vector3::from(t) - tn).norm() < 1e-3, "{t:?} vs {tn:?}");
        assert!(refine_direction(&regions, [0.0; 3], 5, 10).is_none());
        // The moments path (no Huber) and the per-sample path (Huber that never triggers) agree.
        let a = refine_direction(&regions, [0.6, 0.3, 0.5], 3, 10).unwrap();
        let b = refine_direction_robust(&regions, [0.6, 0.3, 0.5], 3, 10, Some(1e12)).unwrap();
        assert!(
            (Vector3::from(a) - Vector3::from(b)).norm() < 1e-9,
            "{a:?} vs {b:?}"
        );
    }

    #[test]
    fn the_profile_cost_is_least_at_the_true_direction() {
        let t_true = [0.3, -0.2, 0.9];
        // Every tenth sample flipped, so the robust scale is not 0.
        let samples = twelve_regions(t_true, |k| k % 10 == 0);
        let regions: Vec<Vec<(&FlowSample, f64)>> = samples
            .iter()
            .map(|m| m.iter().map(|s| (s, 1.0)).collect())
            .collect();
        let tn: [f64; 3] = Vector3::from(t_true).normalize().into();
        let at_truth = profile_cost(&regions, tn, 10, 1.5, None);
        assert!(at_truth.scale > 0.0 && at_truth.cost > 0.0, "{at_truth:?}");
        let mut last = at_truth.cost;
        // Turning away from the truth costs more, and more the further it turns.
        for deg in [2.0f64, 5.0, 10.0, 20.0] {
            let r = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), deg.to_radians());
            let t: [f64; 3] = (r * Vector3::from(tn)).into();
            let c = profile_cost(&regions, t, 10, 1.5, Some(at_truth.scale));
            assert!(c.cost > last, "{deg} deg: {} after {last}", c.cost);
            assert_eq!(c.scale, at_truth.scale);
            last = c.cost;
        }
        // Regions below the size limit count for nothing.
        assert_eq!(profile_cost(&regions, tn, 61, 1.5, Some(1.0)).cost, 0.0);
    }

    #[test]
    fn the_previous_slices_depths_steady_the_direction_of_noisy_slices() {
        // Twelve regions of eight samples each, their lengths with 20 % of independent noise
        // in every slice, over 40 slices of the same motion (the speed varying): each slice's
        // own depths trade off against the direction, the remembered ones do not.
        let t_true = [0.3, -0.2, 0.9];
        let tn = Vector3::from(t_true).normalize();
        let points: Vec<(f64, f64)> = (0..8u32)
            .map(|j| (f64::from(j % 4) * 0.02, f64::from(j / 4) * 0.02))
            .collect();
        let mut state = 12345u64;
        let mut noise = move || {
            // SplitMix64 to [-1, 1).
            state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^= z >> 31;
            (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        let mut memory = DepthMemory::default();
        let (mut alone_sum, mut held_sum) = (0.0, 0.0);
        for slice in 0..40 {
            let speed = 1.0 + 0.3 * (f64::from(slice) * 0.4).sin();
            let t = [speed * t_true[0], speed * t_true[1], speed * t_true[2]];
            let centres = (0..12u32).map(|r| {
                (
                    f64::from(r % 4) * 0.3 - 0.45,
                    f64::from(r / 4) * 0.3 - 0.3,
                    0.2 + 0.15 * f64::from(r),
                )
            });
            let mut samples = region_samples(t, centres, &points, |_| false);
            for s in samples.iter_mut().flatten() {
                let f = 1.0 + 0.2 * noise();
                s.n *= f;
                s.n_derot *= f;
            }
            let regions: Vec<Vec<(&FlowSample, f64)>> = samples
                .iter()
                .map(|m| m.iter().map(|s| (s, 1.0)).collect())
                .collect();
            let alone = refine_direction_robust(&regions, [0.6, 0.3, 0.5], 50, 4, Some(1.5)).unwrap();
            let held = refine_direction_with_memory(
                &regions,
                [0.6, 0.3, 0.5],
                50,
                4,
                Some(1.5),
                Some((&mut memory, 1.0)),
            )
            .unwrap();
            if slice >= 10 {
                alone_sum += (Vector3::from(alone) - tn).norm();
                held_sum += (Vector3::from(held) - tn).norm();
            }
        }
        assert_eq!(memory.rho.len(), 12);
        assert!(
            memory.rho.iter().all(|r| r.is_finite() && *r > 0.0),
            "{:?}",
            memory.rho
        );
        assert!(
            held_sum < 0.85 * alone_sum,
            "with memory {held_sum}, without {alone_sum}"
        );
        // Weight 0: the refinement without memory.
        let mut off = DepthMemory::default();
        let samples = region_samples(t_true, std::iter::once((0.1, 0.1, 0.5)), &points, |_| false);
        let regions: Vec<Vec<(&FlowSample, f64)>> = samples
            .iter()
            .map(|m| m.iter().map(|s| (s, 1.0)).collect())
            .collect();
        let a = refine_direction_robust(&regions, [0.6, 0.3, 0.5], 20, 4, Some(1.5));
        let b =
            refine_direction_with_memory(&regions, [0.6, 0.3, 0.5], 20, 4, Some(1.5), Some((&mut off, 0.0)));
        assert_eq!(a, b);
    }

    /// The Huber refinement sample by sample, as written before the moments form: the reference
    /// the faster form must reproduce.
    fn huber_reference(
        regions: &[Vec<(&FlowSample, f64)>],
        t0: [f64; 3],
        iterations: usize,
        k: f64,
    ) -> [f64; 3] {
        let mut t = Vector3::from(t0).normalize();
        let mut scale: Option<f64> = None;
        for _ in 0..iterations {
            let (mut m, mut b, mut abs_res) = (Matrix3::zeros(), Vector3::zeros(), Vec::new());
            for region in regions {
                let (mut num, mut den) = (0.0, 0.0);
                for (s, w) in region {
                    let q = Vector3::from(s.x_row()).dot(&t);
                    num += w * s.n_derot * q;
                    den += w * q * q;
                }
                let rho = if den > 0.0 { (num / den).max(0.0) } else { 0.0 };
                if rho == 0.0 {
                    continue;
                }
                for (s, prior) in region {
                    let x = Vector3::from(s.x_row());
                    let e = s.n_derot - rho * x.dot(&t);
                    abs_res.push(e.abs());
                    let w = match scale {
                        Some(sc) if e.abs() > k * sc => prior * k * sc / e.abs(),
                        _ => *prior,
                    };
                    m += w * rho * rho * x * x.transpose();
                    b += w * rho * s.n_derot * x;
                }
            }
            abs_res.sort_by(f64::total_cmp);
            scale = Some(1.4826 * abs_res[abs_res.len() / 2]);
            if direction_step(&m, &b, &mut t).is_none_or(|c| c < CONVERGED) {
                break;
            }
        }
        t.into()
    }

    #[test]
    fn the_huber_refinement_on_moments_matches_the_per_sample_form() {
        let t_true = [-0.4, 0.1, 0.8];
        let centres = (0..9u32).map(|r| {
            (
                f64::from(r % 3) * 0.3 - 0.3,
                f64::from(r / 3) * 0.3 - 0.3,
                0.3 + 0.1 * f64::from(r),
            )
        });
        let points: Vec<(f64, f64)> = (0..40u32)
            .map(|j| (f64::from(j % 7) * 0.013, f64::from(j / 7) * 0.011))
            .collect();
        // Every seventh estimate is wrong (sign flipped and doubled), so Huber bites.
        let samples = region_samples(t_true, centres, &points, |k| k.is_multiple_of(7));
        let regions: Vec<Vec<(&FlowSample, f64)>> = samples
            .iter()
            .enumerate()
            .map(|(r, m)| m.iter().map(|s| (s, 0.5 + 0.1 * r as f64)).collect())
            .collect();
        for iterations in [1, 2, 5, 30] {
            let fast =
                refine_direction_robust(&regions, [0.5, 0.5, 0.5], iterations, 1, Some(1.345)).unwrap();
            let slow = huber_reference(&regions, [0.5, 0.5, 0.5], iterations, 1.345);
            assert!(
                (Vector3::from(fast) - Vector3::from(slow)).norm() < 1e-9,
                "{iterations} rounds: {fast:?} vs {slow:?}"
            );
        }
    }
}
