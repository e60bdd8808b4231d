//! Stable least-significant-digit radix sort by a 64-bit key (the interval's events by time).

/// Sorts `items` by `key`, stable (items with equal keys keep their order), one pass per key
/// byte that differs between items; `scratch` is reused between calls.
pub fn sort_by_key<T: Copy>(items: &mut Vec<T>, scratch: &mut Vec<T>, key: impl Fn(&T) -> u64) {
    let n = items.len();
    let Some(&first) = items.first() else {
        return;
    };
    let (mut any, mut all) = (0u64, !0u64);
    for it in items.iter() {
        let k = key(it);
        any |= k;
        all &= k;
    }
    let varying = any ^ all;
    scratch.clear();
    scratch.resize(n, first);
    for shift in (0..64).step_by(8) {
        if (varying >> shift) & 0xff == 0 {
            continue;
        }
        let digit = |it: &T| ((key(it) >> shift) & 0xff) as usize;
        let mut start = [0usize; 256];
        for it in items.iter() {
            start[digit(it)] += 1;
        }
        let mut sum = 0;
        for s in start.iter_mut() {
            (*s, sum) = (sum, sum + *s);
        }
        for it in items.iter() {
            let d = digit(it);
            scratch[start[d]] = *it;
            start[d] += 1;
        }
        std::mem::swap(items, scratch);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radix_sort_matches_a_stable_sort() {
        let mut rng = crate::rng::Rng::new(5, 1);
        for n in [0usize, 1, 2, 100, 5000] {
            // Few distinct keys (ties) spread over several bytes, with the original position.
            let items: Vec<(u64, usize)> = (0..n).map(|i| (rng.below(50) << (8 * rng.below(4)), i)).collect();
            let mut expected = items.clone();
            expected.sort_by_key(|it| it.0);
            let (mut got, mut scratch) = (items, Vec::new());
            sort_by_key(&mut got, &mut scratch, |it| it.0);
            assert_eq!(got, expected);
        }
        // Non-negative times order like their bit patterns.
        let mut times = vec![0.25f64, 0.0, 1e-9, 0.2500001, 0.1, 0.25];
        let mut expected = times.clone();
        expected.sort_by(f64::total_cmp);
        sort_by_key(&mut times, &mut Vec::new(), |t| t.to_bits());
        assert_eq!(times, expected);
    }
}
