//! Lloyd's k-means with k-means++ seeding (Arthur & Vassilvitskii 2007) on fixed-size feature
//! vectors, deterministic for a seed.
//!
//! For speed on large slices, seeding and the Lloyd iterations run on a uniform random subsample
//! of at most [`KMeansParams::max_samples`] points; every point is then assigned to its nearest
//! final centre, and the centres are recomputed as the means of all their points.

use crate::rng::SplitMix64;

/// k-means settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KMeansParams {
    /// Number of clusters wanted (fewer are made when there are fewer distinct points).
    pub k: usize,
    /// Most Lloyd iterations (default 50: the fits on slices of the simulator converge in
    /// 10-30; a cap keeps the worst case bounded).
    pub max_iter: usize,
    /// Seed of the random generator (seeding and subsampling).
    pub seed: u64,
    /// Largest number of points used for seeding and iterations (default 6 000: the centres of
    /// 30 clusters are then each estimated from ~200 points; at 20 000 the over-segmentation was
    /// the graph's slowest stage, 2.8 s of 3.5 M events in `evseg bench pipeline`).
    pub max_samples: usize,
}

impl Default for KMeansParams {
    fn default() -> Self {
        Self {
            k: 30,
            max_iter: 50,
            seed: 0,
            max_samples: 6_000,
        }
    }
}

/// The result of [`kmeans`].
#[derive(Debug, Clone, PartialEq)]
pub struct KMeans<const D: usize> {
    /// Cluster centres (at most `k`; fewer when there are fewer distinct points).
    pub centers: Vec<[f64; D]>,
    /// Index of the nearest centre for every input point.
    pub assignment: Vec<u32>,
    /// Lloyd iterations run.
    pub iterations: usize,
    /// True when the last iteration changed no assignment of the subsample.
    pub converged: bool,
}

fn dist2<const D: usize>(a: &[f64; D], b: &[f64; D]) -> f64 {
    let mut s = 0.0;
    for i in 0..D {
        let d = a[i] - b[i];
        s += d * d;
    }
    s
}

/// Nearest centre and its squared distance.
fn nearest<const D: usize>(p: &[f64; D], centers: &[[f64; D]]) -> (usize, f64) {
    let mut best = (0, f64::INFINITY);
    for (j, c) in centers.iter().enumerate() {
        let d = dist2(p, c);
        if d < best.1 {
            best = (j, d);
        }
    }
    best
}

/// A uniform subsample of `min(n, m)` indices (partial Fisher-Yates), sorted.
fn subsample(n: usize, m: usize, rng: &mut SplitMix64) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..n).collect();
    if m >= n {
        return idx;
    }
    for i in 0..m {
        let j = i + rng.below(n - i);
        idx.swap(i, j);
    }
    idx.truncate(m);
    idx.sort_unstable();
    idx
}

/// k-means++ seeding: each next centre is drawn with probability proportional to its squared
/// distance to the nearest centre so far. Stops early when every point coincides with a centre.
fn seed_centers<const D: usize>(pts: &[[f64; D]], k: usize, rng: &mut SplitMix64) -> Vec<[f64; D]> {
    let mut centers = vec![pts[rng.below(pts.len())]];
    let mut d2: Vec<f64> = pts.iter().map(|p| dist2(p, &centers[0])).collect();
    while centers.len() < k {
        let total: f64 = d2.iter().sum();
        if total <= 0.0 || !total.is_finite() {
            break;
        }
        let mut target = rng.next_f64() * total;
        let mut pick = pts.len() - 1;
        for (i, &d) in d2.iter().enumerate() {
            if target < d {
                pick = i;
                break;
            }
            target -= d;
        }
        if d2[pick] <= 0.0 {
            // Rounding landed on a point already a centre; take the farthest point instead.
            pick = farthest(&d2).0;
        }
        let c = pts[pick];
        centers.push(c);
        for (d, p) in d2.iter_mut().zip(pts) {
            *d = d.min(dist2(p, &c));
        }
    }
    centers
}

/// Means of the points per cluster; clusters without points keep their previous centre and are
/// reported in the returned list.
fn update_centers<const D: usize>(pts: &[[f64; D]], assign: &[u32], centers: &mut [[f64; D]]) -> Vec<usize> {
    let mut sums = vec![[0.0; D]; centers.len()];
    let mut counts = vec![0usize; centers.len()];
    for (p, &a) in pts.iter().zip(assign) {
        let s = &mut sums[a as usize];
        for i in 0..D {
            s[i] += p[i];
        }
        counts[a as usize] += 1;
    }
    let mut empty = vec![];
    for (j, c) in centers.iter_mut().enumerate() {
        if counts[j] == 0 {
            empty.push(j);
            continue;
        }
        let inv = 1.0 / counts[j] as f64;
        for i in 0..D {
            c[i] = sums[j][i] * inv;
        }
    }
    empty
}

/// Index and value of the largest of `d` (the first of equal ones; `(0, -1)` when empty).
fn farthest(d: &[f64]) -> (usize, f64) {
    d.iter()
        .enumerate()
        .fold((0, -1.0), |b, (i, &v)| if v > b.1 { (i, v) } else { b })
}

/// Restarts each cluster of `empty` at the sample point farthest from its centre (`dist`:
/// squared distances of `sample` to their centres); a point taken is then left out of
/// consideration for the next empty cluster. Stops when no point lies off its centre. Returns
/// whether any centre moved.
fn restart_empty<const D: usize>(
    empty: &[usize],
    dist: &mut [f64],
    sample: &[[f64; D]],
    centers: &mut [[f64; D]],
) -> bool {
    let mut moved = false;
    for &j in empty {
        let (far, d) = farthest(dist);
        if d <= 0.0 {
            break;
        }
        centers[j] = sample[far];
        dist[far] = 0.0;
        moved = true;
    }
    moved
}

/// Relative margin on Hamerly's bounds in [`lloyd`]: they are sums of rounded distances, off by
/// about 1e-15 relative per iteration; a point is skipped only when its bound holds by more.
const BOUND_MARGIN: f64 = 1e-9;

/// Nearest centre, its distance and the distance to the second nearest (Euclidean; the first
/// of equally near centres wins, as in [`nearest`]).
fn nearest_two<const D: usize>(p: &[f64; D], centers: &[[f64; D]]) -> (usize, f64, f64) {
    let (mut best, mut d1, mut d2) = (0, f64::INFINITY, f64::INFINITY);
    for (j, c) in centers.iter().enumerate() {
        let d = dist2(p, c);
        if d < d1 {
            d2 = d1;
            (best, d1) = (j, d);
        } else if d < d2 {
            d2 = d;
        }
    }
    (best, d1.sqrt(), d2.sqrt())
}

/// Lloyd's iterations on `sample` from `centers` (updated in place), at most `max_iter`;
/// returns the iterations run and whether the last changed no assignment. Hamerly's bounds
/// (2010) skip the distance computations that cannot change a point's assignment: an upper
/// bound on the distance to its centre and a lower bound on the distance to any other, moved by
/// how far the centres moved. The assignments, and so the centres, are those of plain Lloyd
/// (test `hamerly_bounds_reproduce_plain_lloyd`).
fn lloyd<const D: usize>(sample: &[[f64; D]], centers: &mut [[f64; D]], max_iter: usize) -> (usize, bool) {
    let n = sample.len();
    let mut assign = vec![u32::MAX; n];
    let mut upper = vec![f64::INFINITY; n];
    let mut lower = vec![0.0; n];
    let mut moved = vec![0.0; centers.len()];
    let mut half_gap = vec![0.0; centers.len()];
    let (mut iterations, mut converged) = (0, false);
    while iterations < max_iter {
        iterations += 1;
        // Half the distance from each centre to its nearest other centre.
        for (j, c) in centers.iter().enumerate() {
            let mut m = f64::INFINITY;
            for (i, o) in centers.iter().enumerate() {
                if i != j {
                    m = m.min(dist2(c, o));
                }
            }
            half_gap[j] = 0.5 * m.sqrt();
        }
        let mut changed = false;
        for (i, p) in sample.iter().enumerate() {
            if assign[i] != u32::MAX {
                // Strictly inside the bound (with a margin far above the bounds' rounding), the
                // assigned centre is strictly the nearest: plain Lloyd would keep it too.
                let a = assign[i] as usize;
                let bound = half_gap[a].max(lower[i]) * (1.0 - BOUND_MARGIN);
                if upper[i] < bound {
                    continue;
                }
                upper[i] = dist2(p, &centers[a]).sqrt();
                if upper[i] < bound {
                    continue;
                }
            }
            let (j, d1, d2) = nearest_two(p, centers);
            if assign[i] != j as u32 {
                assign[i] = j as u32;
                changed = true;
            }
            (upper[i], lower[i]) = (d1, d2);
        }
        let before = centers.to_vec();
        let empty = update_centers(sample, &assign, centers);
        if !empty.is_empty() {
            // An empty cluster restarts at the sample point farthest from its centre (that point
            // is then taken out of consideration for the next empty cluster); the distances are
            // the exact ones of this iteration's assignment, to the centres it was made with.
            let mut dist: Vec<f64> = sample
                .iter()
                .zip(&assign)
                .map(|(p, &a)| dist2(p, &before[a as usize]))
                .collect();
            changed |= restart_empty(&empty, &mut dist, sample, centers);
        }
        if !changed {
            converged = true;
            break;
        }
        // Move the bounds by how far the centres moved.
        for (m, (c, b)) in moved.iter_mut().zip(centers.iter().zip(&before)) {
            *m = dist2(c, b).sqrt();
        }
        let (mut first, mut second, mut argmax) = (0.0f64, 0.0f64, usize::MAX);
        for (j, &m) in moved.iter().enumerate() {
            if m > first {
                (second, first, argmax) = (first, m, j);
            } else if m > second {
                second = m;
            }
        }
        for i in 0..n {
            let a = assign[i] as usize;
            upper[i] += moved[a];
            lower[i] -= if a == argmax { second } else { first };
        }
    }
    (iterations, converged)
}

/// Clusters `points` into at most `params.k` groups. Points must be finite. An empty input gives
/// no centres and no assignment; `k = 0` is treated as 1.
pub fn kmeans<const D: usize>(points: &[[f64; D]], params: &KMeansParams) -> KMeans<D> {
    if points.is_empty() {
        return KMeans {
            centers: vec![],
            assignment: vec![],
            iterations: 0,
            converged: true,
        };
    }
    let mut rng = SplitMix64::new(params.seed);
    let sample_idx = subsample(points.len(), params.max_samples.max(1), &mut rng);
    let sample: Vec<[f64; D]> = sample_idx.iter().map(|&i| points[i]).collect();
    let k = params.k.clamp(1, sample.len());
    let mut centers = seed_centers(&sample, k, &mut rng);

    let (iterations, converged) = lloyd(&sample, &mut centers, params.max_iter);

    let assignment: Vec<u32> = points.iter().map(|p| nearest(p, &centers).0 as u32).collect();
    update_centers(points, &assignment, &mut centers);
    KMeans {
        centers,
        assignment,
        iterations,
        converged,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plain Lloyd, as written before Hamerly's bounds: the reference [`lloyd`] must reproduce.
    fn lloyd_reference<const D: usize>(
        sample: &[[f64; D]],
        centers: &mut [[f64; D]],
        max_iter: usize,
    ) -> (usize, bool) {
        let mut assign = vec![u32::MAX; sample.len()];
        let mut dist = vec![0.0; sample.len()];
        let (mut iterations, mut converged) = (0, false);
        while iterations < max_iter {
            iterations += 1;
            let mut changed = false;
            for ((p, a), d) in sample.iter().zip(assign.iter_mut()).zip(dist.iter_mut()) {
                let (j, dj) = nearest(p, centers);
                if *a != j as u32 {
                    *a = j as u32;
                    changed = true;
                }
                *d = dj;
            }
            let empty = update_centers(sample, &assign, centers);
            changed |= restart_empty(&empty, &mut dist, sample, centers);
            if !changed {
                converged = true;
                break;
            }
        }

        (iterations, converged)
    }

    #[test]
    fn hamerly_bounds_reproduce_plain_lloyd() {
        for seed in 0..40u64 {
            let mut rng = SplitMix64::new(1000 + seed);
            // Overlapping blobs in 4-D (as the over-segmentation's [x, y, lambda n]), some
            // duplicate points, k from 2 to 40.
            let n = 200 + (seed as usize * 37) % 900;
            let pts: Vec<[f64; 4]> = (0..n)
                .map(|i| {
                    let b = (i * 13 + seed as usize) % 7;
                    let c = b as f64 * 0.8;
                    if i % 50 == 0 {
                        [c, c, 0.0, 0.0]
                    } else {
                        [
                            c + rng.next_f64(),
                            c * 0.5 + rng.next_f64(),
                            rng.next_f64() - 0.5,
                            rng.next_f64(),
                        ]
                    }
                })
                .collect();
            let k = 2 + (seed as usize * 7) % 39;
            let start = seed_centers(&pts, k, &mut rng);
            let (mut fast, mut slow) = (start.clone(), start);
            let a = lloyd(&pts, &mut fast, 50);
            let b = lloyd_reference(&pts, &mut slow, 50);
            assert_eq!(a, b, "seed {seed}: iterations / converged");
            assert_eq!(fast, slow, "seed {seed}: centres");
        }
    }

    /// Four tight blobs far apart, 250 points each, in shuffled order.
    fn blobs() -> (Vec<[f64; 2]>, Vec<usize>) {
        let centres = [[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]];
        let mut rng = SplitMix64::new(99);
        let mut pts = vec![];
        let mut truth = vec![];
        for i in 0..1000 {
            let b = (i * 7) % 4;
            let c = centres[b];
            pts.push([c[0] + rng.next_f64() - 0.5, c[1] + rng.next_f64() - 0.5]);
            truth.push(b);
        }
        (pts, truth)
    }

    #[test]
    fn recovers_well_separated_blobs() {
        let (pts, truth) = blobs();
        let r = kmeans(
            &pts,
            &KMeansParams {
                k: 4,
                ..Default::default()
            },
        );
        assert!(r.converged);
        assert_eq!(r.centers.len(), 4);
        // Same blob <=> same cluster, for every pair with the first point of each blob.
        for (i, &ti) in truth.iter().enumerate() {
            for (j, &tj) in truth.iter().enumerate().take(8) {
                assert_eq!(ti == tj, r.assignment[i] == r.assignment[j], "points {i}, {j}");
            }
        }
        for c in &r.centers {
            let off = [
                c[0] - (c[0] / 10.0).round() * 10.0,
                c[1] - (c[1] / 10.0).round() * 10.0,
            ];
            assert!(off[0].abs() < 0.1 && off[1].abs() < 0.1, "centre {c:?}");
        }
    }

    #[test]
    fn subsampled_fit_still_recovers_blobs() {
        let (pts, truth) = blobs();
        let params = KMeansParams {
            k: 4,
            max_samples: 100,
            ..Default::default()
        };
        let r = kmeans(&pts, &params);
        for (i, &ti) in truth.iter().enumerate() {
            assert_eq!(ti == truth[0], r.assignment[i] == r.assignment[0]);
        }
    }

    #[test]
    fn deterministic_for_a_seed_and_seed_matters() {
        let mut rng = SplitMix64::new(5);
        let pts: Vec<[f64; 3]> = (0..2000)
            .map(|_| [rng.next_f64(), rng.next_f64(), rng.next_f64()])
            .collect();
        let p = KMeansParams {
            k: 12,
            seed: 3,
            ..Default::default()
        };
        let a = kmeans(&pts, &p);
        let b = kmeans(&pts, &p);
        assert_eq!(a, b);
        let c = kmeans(&pts, &KMeansParams { seed: 4, ..p });
        assert_ne!(
            a.centers, c.centers,
            "uniform cloud: different seeds give different centres"
        );
    }

    #[test]
    fn fewer_points_than_clusters_and_empty_input() {
        let pts = [[0.0, 0.0], [1.0, 0.0], [1.0, 0.0]];
        let r = kmeans(&pts, &KMeansParams::default());
        // Two distinct points: two clusters, duplicates share one.
        assert_eq!(r.centers.len(), 2);
        assert_ne!(r.assignment[0], r.assignment[1]);
        assert_eq!(r.assignment[1], r.assignment[2]);
        let e = kmeans::<2>(&[], &KMeansParams::default());
        assert!(e.centers.is_empty() && e.assignment.is_empty());
    }

    #[test]
    fn empty_cluster_is_reseeded_not_left_dead() {
        // k = 3 on two tight blobs plus one outlier: every centre ends with at least one point.
        let mut pts = vec![[0.0, 0.0]; 50];
        pts.extend(vec![[5.0, 5.0]; 50]);
        pts.push([100.0, 100.0]);
        let r = kmeans(
            &pts,
            &KMeansParams {
                k: 3,
                ..Default::default()
            },
        );
        let mut counts = [0; 3];
        for &a in &r.assignment {
            counts[a as usize] += 1;
        }
        assert_eq!(counts.iter().filter(|&&c| c > 0).count(), 3, "{counts:?}");
    }
}
