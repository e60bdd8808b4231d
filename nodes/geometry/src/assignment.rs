//! Optimal one-to-one assignment (Hungarian algorithm).
//!
//! Used by the evaluator (matching predicted labels to ground-truth objects by IoU) and by the
//! tracker (matching predicted tracks to the segments of a slice). Weights are unitless: each
//! caller documents what its weights mean.

/// Optimal assignment of rows to columns maximising the summed weight (Hungarian algorithm with
/// potentials, O(n² m)). Returns the column of each row; with more rows than columns some rows
/// get `None`. Weights must be finite.
pub fn assign_max(weights: &[Vec<f64>]) -> Vec<Option<usize>> {
    let n = weights.len();
    let m = weights.first().map_or(0, |r| r.len());
    if n == 0 || m == 0 {
        return vec![None; n];
    }
    if n > m {
        // Solve the transpose (rows <= columns) and invert.
        let t: Vec<Vec<f64>> = (0..m).map(|c| (0..n).map(|r| weights[r][c]).collect()).collect();
        let cols = assign_max(&t);
        let mut out = vec![None; n];
        for (c, r) in cols.into_iter().enumerate() {
            if let Some(r) = r {
                out[r] = Some(c);
            }
        }
        return out;
    }
    // Minimise cost = -weight. 1-based arrays as in the classic formulation.
    let cost = |i: usize, j: usize| -weights[i - 1][j - 1];
    let (mut u, mut v) = (vec![0.0; n + 1], vec![0.0; m + 1]);
    let mut p = vec![0usize; m + 1];
    let mut way = vec![0usize; m + 1];
    for i in 1..=n {
        p[0] = i;
        let mut j0 = 0;
        let mut minv = vec![f64::INFINITY; m + 1];
        let mut used = vec![false; m + 1];
        loop {
            used[j0] = true;
            let i0 = p[j0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0;
            for j in 1..=m {
                if !used[j] {
                    let cur = cost(i0, j) - u[i0] - v[j];
                    if cur < minv[j] {
                        minv[j] = cur;
                        way[j] = j0;
                    }
                    if minv[j] < delta {
                        delta = minv[j];
                        j1 = j;
                    }
                }
            }
            for j in 0..=m {
                if used[j] {
                    u[p[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if p[j0] == 0 {
                break;
            }
        }
        loop {
            let j1 = way[j0];
            p[j0] = p[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut out = vec![None; n];
    for j in 1..=m {
        if p[j] != 0 {
            out[p[j] - 1] = Some(j - 1);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn total(w: &[Vec<f64>], a: &[Option<usize>]) -> f64 {
        a.iter().enumerate().filter_map(|(r, c)| c.map(|c| w[r][c])).sum()
    }

    #[test]
    fn hungarian_beats_greedy_on_the_classic_trap() {
        // Greedy takes (0,0)=0.9 then (1,1)=0.1: 1.0. Optimal is (0,1)+(1,0) = 0.8+0.8.
        let w = vec![vec![0.9, 0.8], vec![0.8, 0.1]];
        let a = assign_max(&w);
        assert_eq!(a, vec![Some(1), Some(0)]);
        assert!((total(&w, &a) - 1.6).abs() < 1e-12);
    }

    #[test]
    fn hungarian_matches_brute_force_on_rectangular_cases() {
        // Deterministic pseudo-random weights; compare with all permutations.
        let mut s = 12345u64;
        let mut rnd = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        for (n, m) in [(3, 3), (2, 4), (4, 2), (4, 4), (1, 3)] {
            let w: Vec<Vec<f64>> = (0..n).map(|_| (0..m).map(|_| rnd()).collect()).collect();
            let a = assign_max(&w);
            // Brute force over injective maps from the smaller side to the larger one.
            let mut best = 0.0f64;
            let (small, large) = (n.min(m), n.max(m));
            let larger: Vec<usize> = (0..large).collect();
            permute(&larger, small, &mut vec![], &mut |pick| {
                let v: f64 = pick
                    .iter()
                    .enumerate()
                    .map(|(k, &j)| if n <= m { w[k][j] } else { w[j][k] })
                    .sum();
                best = best.max(v);
            });
            assert!(
                (total(&w, &a) - best).abs() < 1e-9,
                "{n}x{m}: {} vs {best}",
                total(&w, &a)
            );
            let used: Vec<usize> = a.iter().flatten().copied().collect();
            let mut dedup = used.clone();
            dedup.sort();
            dedup.dedup();
            assert_eq!(used.len(), dedup.len(), "one-to-one");
            assert_eq!(used.len(), n.min(m));
        }
    }

    fn permute(items: &[usize], k: usize, cur: &mut Vec<usize>, f: &mut dyn FnMut(&[usize])) {
        if cur.len() == k {
            f(cur);
            return;
        }
        for &i in items {
            if !cur.contains(&i) {
                cur.push(i);
                permute(items, k, cur, f);
                cur.pop();
            }
        }
    }
}
