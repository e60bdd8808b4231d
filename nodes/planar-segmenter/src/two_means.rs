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

/// Smallest value [`two_means_on_power`] distinguishes (keeps the logarithm finite; far below
/// any residual the planar segmenter can measure, normalized units/s).
pub const POWER_FLOOR: f64 = 1e-6;

/// [`two_means`] of `values^power` (non-negative values, e.g. residual magnitudes; `power` in
/// [0, 1], 0 = the logarithm), with the centres and the threshold mapped back to the values'
/// scale. Power 1 is [`two_means`]; a smaller power lowers the threshold towards the lower
/// centre (two tight groups at `a < b`: threshold `((a^p + b^p) / 2)^(1/p)`, the geometric
/// mean at 0). Values below [`POWER_FLOOR`] count as it.
pub fn two_means_on_power(values: &[f64], power: f64, max_iter: usize) -> Option<TwoMeans> {
    if power == 1.0 {
        return two_means(values, max_iter);
    }
    let to = |v: f64| {
        let v = v.max(POWER_FLOOR);
        if power == 0.0 { v.ln() } else { v.powf(power) }
    };
    let back = |u: f64| {
        if power == 0.0 {
            u.exp()
        } else {
            u.max(0.0).powf(1.0 / power)
        }
    };
    let scaled: Vec<f64> = values.iter().map(|&v| to(v)).collect();
    two_means(&scaled, max_iter).map(|s| TwoMeans {
        centers: [back(s.centers[0]), back(s.centers[1])],
        threshold: back(s.threshold),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_smaller_power_moves_the_threshold_towards_the_lower_group() {
        let mut v = vec![0.01; 90];
        v.extend([0.09; 10]);
        let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
        for (power, threshold) in [(1.0, 0.05), (0.5, 0.04), (0.0, 0.03)] {
            let t = two_means_on_power(&v, power, 100).unwrap();
            assert!(
                close(t.centers[0], 0.01) && close(t.centers[1], 0.09),
                "{power}: {t:?}"
            );
            assert!(close(t.threshold, threshold), "{power}: {t:?}");
        }
        // Zeros are clamped to the floor, not a NaN from the logarithm.
        let t = two_means_on_power(&[0.0, 0.0, 1.0], 0.0, 100).unwrap();
        assert!(
            close(t.centers[0], POWER_FLOOR) && close(t.centers[1], 1.0),
            "{t:?}"
        );
        assert!(two_means_on_power(&[], 0.5, 10).is_none());
    }

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
