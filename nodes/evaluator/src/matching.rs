//! Matching predicted segments (labels) to ground-truth objects, and per-object IoU.
//!
//! Matching is **Hungarian** (optimal one-to-one assignment maximising the summed IoU over all
//! pairs); a pair with IoU 0 is not a match. Each ground-truth object's IoU is then the IoU of
//! its events with the events of the matched label (0 when unmatched).

use std::collections::BTreeMap;

use serde::Serialize;

/// One ground-truth object of a slice and the predicted label matched to it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectMatch {
    /// Ground-truth object id.
    pub object: u16,
    /// Matched predicted label (track id), `None` when no label overlaps it in the assignment.
    pub label: Option<u32>,
    /// IoU of the object's events with the matched label's events (0 when unmatched).
    pub iou: f64,
    /// Events of the object.
    pub truth_events: u64,
    /// Events of the matched label (0 when unmatched).
    pub predicted_events: u64,
    /// Events in both.
    pub intersection: u64,
}

/// Matches labels to objects over `(predicted label, ground-truth id)` pairs, one per event.
/// Label 0 and id 0 are background and never matched. Objects come out in id order.
pub fn match_objects(pairs: impl Iterator<Item = (u32, u16)>) -> Vec<ObjectMatch> {
    let mut joint: BTreeMap<(u16, u32), u64> = BTreeMap::new();
    let mut per_object: BTreeMap<u16, u64> = BTreeMap::new();
    let mut per_label: BTreeMap<u32, u64> = BTreeMap::new();
    for (label, id) in pairs {
        if id != 0 {
            *per_object.entry(id).or_default() += 1;
        }
        if label != 0 {
            *per_label.entry(label).or_default() += 1;
        }
        if id != 0 && label != 0 {
            *joint.entry((id, label)).or_default() += 1;
        }
    }
    let objects: Vec<(u16, u64)> = per_object.into_iter().collect();
    let labels: Vec<(u32, u64)> = per_label.into_iter().collect();
    let iou = |oi: usize, li: usize| -> (f64, u64) {
        let n = joint.get(&(objects[oi].0, labels[li].0)).copied().unwrap_or(0);
        let union = objects[oi].1 + labels[li].1 - n;
        (if union == 0 { 0.0 } else { n as f64 / union as f64 }, n)
    };
    let weights: Vec<Vec<f64>> = (0..objects.len())
        .map(|oi| (0..labels.len()).map(|li| iou(oi, li).0).collect())
        .collect();
    let assignment = assign_max(&weights);
    objects
        .iter()
        .enumerate()
        .map(|(oi, &(object, truth_events))| {
            let matched = assignment[oi].filter(|&li| weights[oi][li] > 0.0);
            match matched {
                Some(li) => {
                    let (v, n) = iou(oi, li);
                    ObjectMatch {
                        object,
                        label: Some(labels[li].0),
                        iou: v,
                        truth_events,
                        predicted_events: labels[li].1,
                        intersection: n,
                    }
                }
                None => ObjectMatch {
                    object,
                    label: None,
                    iou: 0.0,
                    truth_events,
                    predicted_events: 0,
                    intersection: 0,
                },
            }
        })
        .collect()
}

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

    #[test]
    fn per_object_iou_after_matching() {
        // Object 1: events 0..4; object 2: events 4..6; background: 6..8.
        let ids = [1u16, 1, 1, 1, 2, 2, 0, 0];
        // Label 7 covers object 1 plus one background event; label 9 covers half of object 2.
        let labels = [7u32, 7, 7, 7, 9, 0, 7, 0];
        let m = match_objects(labels.iter().copied().zip(ids.iter().copied()));
        assert_eq!(m.len(), 2);
        assert_eq!((m[0].object, m[0].label), (1, Some(7)));
        assert!((m[0].iou - 4.0 / 5.0).abs() < 1e-12);
        assert_eq!((m[1].object, m[1].label), (2, Some(9)));
        assert!((m[1].iou - 0.5).abs() < 1e-12);
        // Swapped label values give the same matching quality: label ids are arbitrary.
        let all_bg = match_objects([0u32; 8].iter().copied().zip(ids.iter().copied()));
        assert!(all_bg.iter().all(|o| o.label.is_none() && o.iou == 0.0));
    }

    #[test]
    fn one_label_covering_two_objects_matches_only_one() {
        let ids = [1u16, 1, 1, 2];
        let labels = [5u32, 5, 5, 5];
        let m = match_objects(labels.iter().copied().zip(ids.iter().copied()));
        assert_eq!(m[0].label, Some(5));
        assert!((m[0].iou - 0.75).abs() < 1e-12);
        assert_eq!(m[1].label, None);
        assert_eq!(m[1].iou, 0.0);
    }
}
