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
}

impl<const N: usize> Default for NormalEquations<N> {
    fn default() -> Self {
        Self {
            ata: [[0.0; N]; N],
            atb: [0.0; N],
            count: 0,
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
}
