//! Small dense least squares through the normal equations, with optional Tikhonov
//! regularization: minimise `sum_i w_i (g_i . p - b_i)^2 + lambda |p|^2`.

use nalgebra::{DMatrix, DVector, SMatrix, SVector};

/// Accumulates the normal equations of an `N`-parameter linear least-squares problem.
#[derive(Debug, Clone)]
pub struct NormalEquations<const N: usize> {
    ata: SMatrix<f64, N, N>,
    atb: SVector<f64, N>,
    count: usize,
}

impl<const N: usize> Default for NormalEquations<N> {
    fn default() -> Self {
        Self {
            ata: SMatrix::zeros(),
            atb: SVector::zeros(),
            count: 0,
        }
    }
}

impl<const N: usize> NormalEquations<N> {
    /// Adds the equation `g . p = b` with weight `w`.
    pub fn add(&mut self, g: &[f64; N], b: f64, w: f64) {
        for (i, gi) in g.iter().enumerate() {
            let wg = w * gi;
            self.atb[i] += wg * b;
            for (j, gj) in g.iter().enumerate().skip(i) {
                self.ata[(i, j)] += wg * gj;
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
        self.ata += other.ata;
        self.atb += other.atb;
        self.count += other.count;
    }

    /// Solves with regularization `lambda` (>= 0); `None` when the system is singular.
    pub fn solve(&self, lambda: f64) -> Option<[f64; N]> {
        let mut m = self.ata;
        for i in 0..N {
            for j in 0..i {
                m[(i, j)] = m[(j, i)];
            }
            m[(i, i)] += lambda;
        }
        // Symmetric positive definite unless the equations do not determine every parameter
        // (then `None`; a positive `lambda` always makes it definite).
        let sol = m.cholesky().map(|c| c.solve(&self.atb))?;
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
