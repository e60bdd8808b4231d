//! 2-means on scalars (Lloyd in one dimension), deterministic: the centres start at the smallest
//! and largest value.

/// Result of [`two_means`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TwoMeans {
    /// Lower and upper centre.
    pub centers: [f64; 2],
    /// Values `<= threshold` belong to the lower cluster (midpoint of the centres).
    pub threshold: f64,
}

/// Splits finite `values` into two clusters; `None` when empty.
pub fn two_means(values: &[f64], max_iter: usize) -> Option<TwoMeans> {
    let lo = values.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !(lo.is_finite() && hi.is_finite()) {
        return None;
    }
    let mut c = [lo, hi];
    for _ in 0..max_iter {
        let thr = 0.5 * (c[0] + c[1]);
        let (mut s, mut n) = ([0.0; 2], [0usize; 2]);
        for &v in values {
            let k = usize::from(v > thr);
            s[k] += v;
            n[k] += 1;
        }
        let next = [
            if n[0] > 0 { s[0] / n[0] as f64 } else { c[0] },
            if n[1] > 0 { s[1] / n[1] as f64 } else { c[1] },
        ];
        if next == c {
            break;
        }
        c = next;
    }
    Some(TwoMeans {
        centers: c,
        threshold: 0.5 * (c[0] + c[1]),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splits_two_groups_at_the_gap() {
        let mut v: Vec<f64> = (0..90).map(|i| 0.01 * f64::from(i % 10)).collect();
        v.extend((0..10).map(|i| 5.0 + 0.1 * f64::from(i)));
        let t = two_means(&v, 100).unwrap();
        assert!((t.centers[0] - 0.045).abs() < 1e-12, "{t:?}");
        assert!((t.centers[1] - 5.45).abs() < 1e-12);
        assert!(t.threshold > 0.09 && t.threshold < 5.0);
        assert!(two_means(&[], 10).is_none());
        assert_eq!(two_means(&[2.0, 2.0], 10).unwrap().centers, [2.0, 2.0]);
    }
}
