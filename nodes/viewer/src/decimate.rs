//! Choosing which events of a slice are drawn.

/// Indices of the events drawn from a slice of `n` events when at most `max` may be: all of them
/// when `n <= max`, else `floor(i * n / max)` for `i` in `0..max` (evenly spread over the slice's
/// time order, strictly increasing, the first event always included).
pub fn decimate(n: usize, max: usize) -> Vec<usize> {
    if n <= max {
        return (0..n).collect();
    }
    (0..max)
        .map(|i| ((i as u128 * n as u128) / max as u128) as usize)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_slices_are_kept_whole() {
        assert_eq!(decimate(0, 5), Vec::<usize>::new());
        assert_eq!(decimate(3, 5), vec![0, 1, 2]);
        assert_eq!(decimate(5, 5), vec![0, 1, 2, 3, 4]);
    }

    #[test]
    fn large_slices_are_spread_evenly() {
        assert_eq!(decimate(10, 4), vec![0, 2, 5, 7]);
        let d = decimate(1_000_003, 1000);
        assert_eq!(d.len(), 1000);
        assert!(
            d.windows(2)
                .all(|w| w[1] > w[0] && w[1] - w[0] >= 1000 && w[1] - w[0] <= 1001)
        );
        assert!(*d.last().unwrap() < 1_000_003);
    }
}
