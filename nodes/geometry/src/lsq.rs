//! Small dense least squares through the normal equations, with optional Tikhonov
//! regularization: minimise `sum_i w_i (g_i . p - b_i)^2 + lambda |p|^2`.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

/// Accumulates the normal equations of an `N`-parameter linear least-squares problem.
#[derive(Debug, Clone)]
pub struct NormalEquations<const N: usize> {
    /// Upper triangle of `A^T W A`, row by row (`ata[i][j]` for `j >= i`; the rest stays 0), in
    /// plain arrays so that `add`'s inner loop runs over contiguous memory.
    ata: [[f64; N]; N],
    atb: [f64; N],
    count: usize,
    weight: f64,
}

impl<const N: usize> Default for NormalEquations<N> {
    fn default() -> Self {
        Self {
            ata: [[0.0; N]; N],
            atb: [0.0; N],
            count: 0,
            weight: 0.0,
        }
    }
}

impl<const N: usize> NormalEquations<N> {
    /// Adds the equation `g . p = b` with weight `w`.
    #[inline]
    pub fn add(&mut self, g: &[f64; N], b: f64, w: f64) {
        for i in 0..N {
            let wg = w * g[i];
            self.atb[i] += wg * b;
            let row = &mut self.ata[i];
            for j in i..N {
                row[j] += wg * g[j];
            }
        }
        self.count += 1;
        self.weight += w;
    }

    /// Equations added.
    pub fn count(&self) -> usize {
        self.count
    }

    /// Adds another accumulator's equations.
    pub fn merge(&mut self, other: &Self) {
        for (row, other) in self.ata.iter_mut().zip(&other.ata) {
            for (a, b) in row.iter_mut().zip(other) {
                *a += b;
            }
        }
        for (a, b) in self.atb.iter_mut().zip(&other.atb) {
            *a += b;
        }
        self.count += other.count;
        self.weight += other.weight;
    }

    /// The information per unit weight, `A^T W A / sum w` (upper triangle, row by row, as
    /// stored); `None` before any weight was added.
    pub fn information(&self) -> Option<[[f64; N]; N]> {
        (self.weight > 0.0).then(|| self.ata.map(|row| row.map(|v| v / self.weight)))
    }

    /// Sum of the weights added.
    pub fn total_weight(&self) -> f64 {
        self.weight
    }

    /// Adds a Gaussian prior on the parameters: `weight (p - center)^T info (p - center)` joins
    /// the sum minimised (`info` symmetric, upper triangle as [`Self::information`] gives it).
    /// Counts as no equation ([`Self::count`]) and no weight.
    pub fn add_prior(&mut self, info: &[[f64; N]; N], center: &[f64; N], weight: f64) {
        // `info` is symmetric and stored as its upper triangle: entry (i, j) is at
        // [min(i, j)][max(i, j)].
        let at = |i: usize, j: usize| if j >= i { info[i][j] } else { info[j][i] };
        for (i, (row, b)) in self.ata.iter_mut().zip(&mut self.atb).enumerate() {
            for (j, a) in row.iter_mut().enumerate().skip(i) {
                *a += weight * at(i, j);
            }
            *b += weight * center.iter().enumerate().map(|(j, c)| at(i, j) * c).sum::<f64>();
        }
    }

    /// Solves with regularization `lambda` (>= 0); `None` when the system is singular.
    pub fn solve(&self, lambda: f64) -> Option<[f64; N]> {
        let mut m = SMatrix::<f64, N, N>::zeros();
        for i in 0..N {
            for j in i..N {
                m[(i, j)] = self.ata[i][j];
                m[(j, i)] = self.ata[i][j];
            }
            m[(i, i)] += lambda;
        }
        // Symmetric positive definite unless the equations do not determine every parameter
        // (then `None`; a positive `lambda` always makes it definite).
        let sol = m.cholesky().map(|c| c.solve(&SVector::from(self.atb)))?;
        let out: [f64; N] = sol.into();
        out.iter().all(|v| v.is_finite()).then_some(out)
    }
}

/// Solves a general least-squares problem `min |M p - b|` by SVD (for sizes known at run time).
pub fn solve_svd(m: &DMatrix<f64>, b: &DVector<f64>) -> Option<DVector<f64>> {
    m.clone().svd(true, true).solve(b, 1e-12).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The accumulation as written before the plain arrays (a nalgebra matrix, upper triangle
    /// filled per equation): [`NormalEquations`] must give the same solution bit for bit.
    fn solve_reference<const N: usize>(eqs: &[([f64; N], f64, f64)], lambda: f64) -> Option<[f64; N]> {
        let (mut ata, mut atb) = (SMatrix::<f64, N, N>::zeros(), SVector::<f64, N>::zeros());
        for (g, b, w) in eqs {
            for (i, gi) in g.iter().enumerate() {
                let wg = w * gi;
                atb[i] += wg * b;
                for (j, gj) in g.iter().enumerate().skip(i) {
                    ata[(i, j)] += wg * gj;
                }
            }
        }
        for i in 0..N {
            for j in 0..i {
                ata[(i, j)] = ata[(j, i)];
            }
            ata[(i, i)] += lambda;
        }
        let out: [f64; N] = ata.cholesky().map(|c| c.solve(&atb))?.into();
        out.iter().all(|v| v.is_finite()).then_some(out)
    }

    #[test]
    fn solution_is_the_reference_bit_for_bit() {
        let mut state = 3u64;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for case in 0..50 {
            let eqs: Vec<([f64; 8], f64, f64)> = (0..20 + case * 7)
                .map(|_| (std::array::from_fn(|_| next() - 0.5), next(), 0.5 + next()))
                .collect();
            let (mut a, mut b) = (NormalEquations::<8>::default(), NormalEquations::<8>::default());
            for (k, (g, rhs, w)) in eqs.iter().enumerate() {
                // Half in a second accumulator, merged: as the stages that fit per cell do.
                if k % 2 == 0 {
                    a.add(g, *rhs, *w)
                } else {
                    b.add(g, *rhs, *w)
                }
            }
            let mut all = NormalEquations::<8>::default();
            for (g, rhs, w) in &eqs {
                all.add(g, *rhs, *w);
            }
            let bits = |s: Option<[f64; 8]>| s.map(|s| s.map(f64::to_bits));
            assert_eq!(
                bits(all.solve(1e-9)),
                bits(solve_reference(&eqs, 1e-9)),
                "case {case}"
            );
            a.merge(&b);
            assert_eq!(a.count(), eqs.len());
        }
    }

    #[test]
    fn recovers_exact_parameters_and_regularization_shrinks() {
        let p = [0.5, -2.0, 3.0];
        let mut ne = NormalEquations::<3>::default();
        for i in 0..20 {
            let g = [1.0, i as f64 * 0.1, (i as f64 * 0.7).sin()];
            let b: f64 = g.iter().zip(&p).map(|(a, b)| a * b).sum();
            ne.add(&g, b, 1.0);
        }
        let s = ne.solve(0.0).unwrap();
        for (a, b) in s.iter().zip(&p) {
            assert!((a - b).abs() < 1e-9);
        }
        let r = ne.solve(1e3).unwrap();
        assert!(r.iter().map(|v| v * v).sum::<f64>() < s.iter().map(|v| v * v).sum::<f64>());
        assert!(NormalEquations::<3>::default().solve(0.0).is_none());
    }

    /// Equations that fix only the first parameter: the prior sets the second, and where the
    /// equations do fix a parameter a weak prior barely moves it. `information` is the
    /// normal matrix per unit weight.
    #[test]
    fn a_prior_holds_the_directions_the_equations_leave_open() {
        let mut ne = NormalEquations::<2>::default();
        for k in 0..10 {
            ne.add(&[1.0, 0.0], 3.0, 0.5 + f64::from(k) * 0.1);
        }
        assert!(ne.solve(0.0).is_none(), "the second parameter is undetermined");
        assert!((ne.total_weight() - 9.5).abs() < 1e-12);
        let info = ne.information().unwrap();
        assert!((info[0][0] - 1.0).abs() < 1e-12 && info[0][1] == 0.0 && info[1][1] == 0.0);
        let prior_info = [[1.0, 0.5], [0.0, 2.0]];
        let mut with = ne.clone();
        with.add_prior(&prior_info, &[2.0, -7.0], 1e-3);
        assert_eq!(with.count(), 10);
        let p = with.solve(0.0).unwrap();
        // The first parameter: the equations' 3 (the prior pulls by about 1e-3 / 9.5).
        assert!((p[0] - 3.0).abs() < 1e-3, "{p:?}");
        // The second: the prior's -7, shifted by its correlation with the first: the prior's
        // conditional mean -7 - (0.5 / 2) (3 - 2).
        assert!((p[1] - (-7.0 - 0.25 * (p[0] - 2.0))).abs() < 1e-9, "{p:?}");
        assert!(NormalEquations::<2>::default().information().is_none());
    }
}
