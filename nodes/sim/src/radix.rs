//! Stable least-significant-digit radix sort by a 64-bit key (the interval's events by time).

/// Bits per digit of the radix passes (a 2048-entry histogram stays in the L1 cache).
const DIGIT_BITS: u32 = 11;
/// Passes over the leading bits of the keys' spread before the exact fix-up (see
/// [`sort_by_key`]).
const COARSE_PASSES: u32 = 3;

/// Sorts `items` by `key`, stable (items with equal keys keep their order); `scratch` is
/// reused between calls. The keys are taken relative to the smallest; when their spread needs
/// more than `COARSE_PASSES` digits, the radix passes sort by its leading
/// `COARSE_PASSES * DIGIT_BITS` bits only and an insertion sort by the full key finishes (the
/// items are then sorted but for ties of the coarse key: a few moves): the same order as a
/// stable sort by the full key, with 3 passes instead of up to 8.
pub fn sort_by_key<T: Copy>(items: &mut Vec<T>, scratch: &mut Vec<T>, key: impl Fn(&T) -> u64) {
    let n = items.len();
    let Some(&first) = items.first() else {
        return;
    };
    let (mut lo, mut hi) = (u64::MAX, 0u64);
    for it in items.iter() {
        let k = key(it);
        lo = lo.min(k);
        hi = hi.max(k);
    }
    let bits = u64::BITS - (hi - lo).leading_zeros();
    let passes = bits.div_ceil(DIGIT_BITS);
    // Bits dropped from the keys for the radix passes.
    let drop = bits.saturating_sub(COARSE_PASSES * DIGIT_BITS);
    scratch.clear();
    scratch.resize(n, first);
    let mask = (1u64 << DIGIT_BITS) - 1;
    for pass in 0..passes.min(COARSE_PASSES) {
        let shift = drop + pass * DIGIT_BITS;
        let digit = |it: &T| (((key(it) - lo) >> shift) & mask) as usize;
        let mut start = [0usize; 1 << DIGIT_BITS];
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
    if drop > 0 {
        // Insertion sort by the full key: stable, and linear when few items share a coarse key.
        for i in 1..n {
            let it = items[i];
            let k = key(&it);
            let mut j = i;
            while j > 0 && key(&items[j - 1]) > k {
                items[j] = items[j - 1];
                j -= 1;
            }
            items[j] = it;
        }
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
        // Keys spread over all 64 bits with ties and near-ties of the coarse key (the fix-up).
        for n in [3usize, 1000, 20000] {
            let items: Vec<(u64, usize)> = (0..n)
                .map(|i| {
                    let base = rng.below(40) << 40;
                    (base | rng.below(1 << 8) << (8 * rng.below(3)), i)
                })
                .chain([(u64::MAX, n), (0, n + 1)])
                .collect();
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
