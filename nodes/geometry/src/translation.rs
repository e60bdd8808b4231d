//! Translation of one image region with depth fixed to 1 (paper section 3.5): the
//! Tikhonov-regularized least squares `sum_i (X_i X_i^T + lambda I) t = sum_i X_i n_derot_i`
//! with `X_i = n0_i^T A(x_i)`.

use crate::lsq::NormalEquations;
use crate::samples::FlowSample;

/// Normal equations of a region's translation; merge two regions by [`TranslationFit::merge`].
#[derive(Debug, Clone, Default)]
pub struct TranslationFit {
    eq: NormalEquations<3>,
}

impl TranslationFit {
    /// Adds one sample's equation `X . t = n_derot`.
    pub fn add(&mut self, s: &FlowSample) {
        self.eq.add(&s.x_row(), s.n_derot, 1.0);
    }

    /// Adds another region's equations.
    pub fn merge(&mut self, other: &Self) {
        self.eq.merge(&other.eq);
    }

    /// Samples added.
    pub fn count(&self) -> usize {
        self.eq.count()
    }

    /// The translation with depth 1, normalized units/s, camera frame; the paper's `lambda` is
    /// added to the diagonal **per sample** (`sum_i lambda I`, as its formula reads). `None`
    /// without samples.
    pub fn solve(&self, lambda: f64) -> Option<[f64; 3]> {
        if self.count() == 0 {
            return None;
        }
        self.eq.solve(lambda * self.count() as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::translational_flow;

    #[test]
    fn a_fronto_parallel_patch_at_depth_one_gives_its_translation() {
        let t = [0.3, -0.1, 0.5];
        let mut fit = TranslationFit::default();
        for i in 0..400 {
            let (x, y) = (f64::from(i % 20) * 0.01 - 0.1, f64::from(i / 20) * 0.01 - 0.1);
            let u = translational_flow(x, y, t, 1.0);
            let ang = f64::from(i) * 0.7;
            let n0 = [ang.cos(), ang.sin()];
            let n = u[0] * n0[0] + u[1] * n0[1];
            fit.add(&FlowSample {
                index: i as usize,
                x,
                y,
                n0,
                n,
                n_derot: n,
                confidence: 1.0,
            });
        }
        let got = fit.solve(1e-6).unwrap();
        for k in 0..3 {
            assert!((got[k] - t[k]).abs() < 1e-3, "{got:?}");
        }
        assert!(TranslationFit::default().solve(1e-6).is_none());
    }
}
