//! The 8-parameter planar normal-flow fit (paper eq. 6-8): every event gives one equation
//! `(C(x)^T n0) . a = n`, solved by (optionally robust, iteratively reweighted) least squares.

use evseg_geometry::c_matrix;
use evseg_geometry::lsq::NormalEquations;

/// How outlying equations are down-weighted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Robust {
    /// Plain least squares, as the paper states (every equation weight 1).
    LeastSquares,
    /// Huber weights `min(1, k s / |r|)` with `s` the robust residual scale (1.4826 * median
    /// |r|); `k = 1.345` gives 95% efficiency on Gaussian noise.
    Huber {
        /// Threshold in robust standard deviations.
        k: f64,
    },
    /// Tukey biweight `(1 - (r / (c s))^2)^2` inside `c s`, 0 outside; `c = 4.685` gives 95%
    /// efficiency on Gaussian noise. Rejects outliers completely, but can lock onto a wrong fit
    /// when the first (least-squares) fit is poor.
    Tukey {
        /// Cut-off in robust standard deviations.
        c: f64,
    },
}

/// Settings of [`fit_planar`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitParams {
    /// Weighting (default plain least squares, as in the paper: on the simulator's one-object and
    /// two-objects presets with ideal flow it gave a higher IoU than Huber or Tukey, see the
    /// crate docs; the robust fits recover the background model better when it is truly planar).
    pub robust: Robust,
    /// Reweighting rounds after the first plain fit (default 5; the weights settle in 3-5 on
    /// the test scenes). Ignored for [`Robust::LeastSquares`].
    pub iterations: usize,
    /// Tikhonov regularization per equation, added as `ridge * count` to the diagonal
    /// (default 1e-9: only stops a singular system from failing, far below the size of the
    /// quadratic columns, ~1e-2 per equation, in normalized coordinates).
    pub ridge: f64,
}

impl Default for FitParams {
    fn default() -> Self {
        Self {
            robust: Robust::LeastSquares,
            iterations: 5,
            ridge: 1e-9,
        }
    }
}

/// One equation `g . a = b` with `g = C(x)^T n0`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Equation {
    /// `C(x)^T n0`.
    pub g: [f64; 8],
    /// Observed (derotated) normal-flow length along `n0`, normalized units/s.
    pub b: f64,
}

impl Equation {
    /// The equation of an event at normalized `(x, y)` with unit normal direction `n0` and
    /// normal-flow length `b` along it.
    pub fn new(x: f64, y: f64, n0: [f64; 2], b: f64) -> Self {
        let c = c_matrix(x, y);
        let mut g = [0.0; 8];
        for (k, gk) in g.iter_mut().enumerate() {
            *gk = c[0][k] * n0[0] + c[1][k] * n0[1];
        }
        Self { g, b }
    }

    /// Residual `b - g . a`.
    pub fn residual(&self, a: &[f64; 8]) -> f64 {
        self.b - self.g.iter().zip(a).map(|(g, a)| g * a).sum::<f64>()
    }
}

/// The weighted least-squares solution and the information per unit weight of the equations
/// (without the prior).
fn solve(
    eqs: &[Equation],
    weights: Option<&[f64]>,
    ridge: f64,
    prior: Option<(&PlanarPrior, f64)>,
) -> Option<([f64; 8], [[f64; 8]; 8])> {
    let mut ne = NormalEquations::<8>::default();
    for (i, e) in eqs.iter().enumerate() {
        let w = weights.map_or(1.0, |w| w[i]);
        if w > 0.0 {
            ne.add(&e.g, e.b, w);
        }
    }
    let info = ne.information()?;
    if let Some((prior, forget)) = prior {
        ne.add_prior(&prior.info, &prior.a, forget * ne.total_weight());
    }
    Some((ne.solve(ridge * ne.count() as f64)?, info))
}

/// A previous fit carried into the next one (recursive least squares with forgetting): the
/// previous model `a` and its information per unit weight `M = sum w g g^T / sum w`, added to
/// the next fit's normal equations as the prior `forget W (a' - a)^T M (a' - a)`, `W` the next
/// fit's total weight. Where the new slice's equations determine the model they dominate; in
/// the directions they leave open (a background seen in only part of the image, the rest
/// behind an object) the previous model holds.
#[derive(Debug, Clone, PartialEq)]
pub struct PlanarPrior {
    /// The previous model.
    pub a: [f64; 8],
    /// Upper triangle of its information per unit weight, row by row.
    pub info: [[f64; 8]; 8],
}

/// `1.4826 * median(|r|)`: the standard deviation of Gaussian residuals, robust to outliers.
fn robust_scale(residuals: impl Iterator<Item = f64>) -> f64 {
    let mut abs: Vec<f64> = residuals.map(f64::abs).collect();
    if abs.is_empty() {
        return 0.0;
    }
    let mid = abs.len() / 2;
    let (_, m, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
    1.4826 * *m
}

/// Fits `a` to the equations. `None` when they do not determine it (fewer than 8 independent
/// equations).
pub fn fit_planar(eqs: &[Equation], params: &FitParams) -> Option<[f64; 8]> {
    fit_planar_weighted(eqs, None, params)
}

/// [`fit_planar`] with a prior weight per equation (`base`, same length as `eqs`, >= 0; the
/// robust weights multiply it). The robust scale is measured on the equations in the fit
/// (base weight > 0) only: equations weighted 0 (e.g. the planar segmenter's previous
/// foreground) must not set how far the fitted ones may lie from the model.
pub fn fit_planar_weighted(eqs: &[Equation], base: Option<&[f64]>, params: &FitParams) -> Option<[f64; 8]> {
    fit_planar_with_prior(eqs, base, params, None).map(|fit| fit.a)
}

/// [`fit_planar_weighted`] with a previous fit as a prior, weighing `forget` times the total
/// base weight of `eqs` (see [`PlanarPrior`]; `None` or a weight of 0: no prior). Returns the
/// model (`a`) with its own information per unit weight (final weights): the next fit's prior.
pub fn fit_planar_with_prior(
    eqs: &[Equation],
    base: Option<&[f64]>,
    params: &FitParams,
    prior: Option<(&PlanarPrior, f64)>,
) -> Option<PlanarPrior> {
    if eqs.len() < 8 || base.is_some_and(|b| b.len() != eqs.len()) {
        return None;
    }
    let prior = prior.filter(|(_, forget)| forget.is_finite() && *forget > 0.0);
    let (mut a, mut info) = solve(eqs, base, params.ridge, prior)?;
    if params.robust == Robust::LeastSquares {
        return Some(PlanarPrior { a, info });
    }
    let mut weights = base.map_or_else(|| vec![1.0; eqs.len()], <[f64]>::to_vec);
    for _ in 0..params.iterations {
        let r: Vec<f64> = eqs.iter().map(|e| e.residual(&a)).collect();
        let in_fit = |i: usize| base.is_none_or(|b| b[i] > 0.0);
        let s = robust_scale(r.iter().enumerate().filter(|&(i, _)| in_fit(i)).map(|(_, &r)| r));
        if s.is_nan() || s <= 0.0 {
            break; // exact fit of at least half the equations: nothing to reweight
        }
        for (w, r) in weights.iter_mut().zip(&r) {
            let u = r.abs() / s;
            *w = match params.robust {
                Robust::LeastSquares => 1.0,
                Robust::Huber { k } => {
                    if u <= k {
                        1.0
                    } else {
                        k / u
                    }
                }
                Robust::Tukey { c } => {
                    if u < c {
                        let q = 1.0 - (u / c) * (u / c);
                        q * q
                    } else {
                        0.0
                    }
                }
            };
        }
        if let Some(b) = base {
            for (w, b) in weights.iter_mut().zip(b) {
                *w *= b;
            }
        }
        match solve(eqs, Some(&weights), params.ridge, prior) {
            Some(next) => (a, info) = next,
            None => break, // too many equations rejected; keep the last fit
        }
    }
    Some(PlanarPrior { a, info })
}
