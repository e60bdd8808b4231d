//! Direction of camera translation from derotated normal flow by a linear SVM (Yuan et al. 2024;
//! METHOD_NOTES section 3).
//!
//! For positive depth, `sign(X . t) = sign(n_derot)` with `X = n0^T A(x)`. The direction `t` is
//! the normal of a separating plane through the origin: a linear SVM without intercept on the
//! samples `[X; -X]` with labels `[sign r; -sign r]` and sample weights `|r|`, squared hinge loss,
//! L2 penalty, cost `C`. The primal is minimised here by Newton's method on its generalized
//! Hessian (exact for this piecewise-quadratic, strongly convex objective; a handful of 3x3
//! solves), which gives the same optimum as liblinear's dual solver without its tolerance.

use nalgebra::{Matrix3, Vector3};

use crate::samples::FlowSample;

/// Settings of the SVM.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SvmParams {
    /// Cost `C` of the squared hinge loss (default 1, METHOD_NOTES section 3).
    pub c: f64,
    /// Most Newton iterations (default 50; it converges in under 10 on every test and scene).
    pub max_iter: usize,
    /// Samples with `|n_derot|` below this, normalized units/s, are left out: their sign is noise
    /// (default 0: every sample, as in the reference; the weight `|r|` already discounts them).
    pub min_abs_flow: f64,
}

impl Default for SvmParams {
    fn default() -> Self {
        Self {
            c: 1.0,
            max_iter: 50,
            min_abs_flow: 0.0,
        }
    }
}

/// The SVM's answer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SvmDirection {
    /// Unit translation direction, camera frame.
    pub direction: [f64; 3],
    /// The SVM weight vector before normalisation (its length grows with the margin).
    pub weight: [f64; 3],
    /// Weighted fraction of samples on the correct side, in [0, 1].
    pub agreement: f64,
    /// Samples used.
    pub samples: usize,
}

/// Estimates the translation direction from `samples` (their derotated normal flow), each with a
/// prior weight (1 for the reference method; it multiplies the `|r|` weight). `None` with fewer
/// than 3 usable samples or a zero solution (no translation signal).
pub fn translation_direction<'a>(
    samples: impl IntoIterator<Item = (&'a FlowSample, f64)>,
    p: &SvmParams,
) -> Option<SvmDirection> {
    // (X * s, weight) per sample; the mirrored half [-X, -s] gives the same term, hence the 2.
    let rows: Vec<(Vector3<f64>, f64)> = samples
        .into_iter()
        .filter(|(s, w)| {
            s.n_derot.is_finite() && s.n_derot.abs() > p.min_abs_flow && s.n_derot != 0.0 && *w > 0.0
        })
        .map(|(s, w)| {
            let x = Vector3::from(s.x_row());
            (x * s.n_derot.signum(), s.n_derot.abs() * w)
        })
        .collect();
    if rows.len() < 3 {
        return None;
    }
    let cw = 2.0 * p.c;
    let objective = |w: &Vector3<f64>| {
        let loss: f64 = rows
            .iter()
            .map(|(z, c)| {
                let m = 1.0 - z.dot(w);
                if m > 0.0 { c * m * m } else { 0.0 }
            })
            .sum();
        0.5 * w.norm_squared() + cw * loss
    };
    let mut w = Vector3::zeros();
    let mut f = objective(&w);
    for _ in 0..p.max_iter {
        let mut grad = w;
        let mut hess = Matrix3::identity();
        for (z, c) in &rows {
            let m = 1.0 - z.dot(&w);
            if m > 0.0 {
                grad -= 2.0 * cw * c * m * z;
                hess += 2.0 * cw * c * z * z.transpose();
            }
        }
        let Some(step) = hess.cholesky().map(|ch| ch.solve(&grad)) else {
            break;
        };
        // Backtracking line search on the exact objective.
        let mut alpha = 1.0;
        let mut improved = false;
        while alpha > 1e-8 {
            let cand = w - alpha * step;
            let fc = objective(&cand);
            if fc <= f - 1e-4 * alpha * grad.dot(&step) {
                w = cand;
                f = fc;
                improved = true;
                break;
            }
            alpha *= 0.5;
        }
        if !improved || (alpha * step.norm()) <= 1e-12 * (1.0 + w.norm()) {
            break;
        }
    }
    let norm = w.norm();
    if !(norm.is_finite() && norm > 0.0) {
        return None;
    }
    let (mut good, mut total) = (0.0, 0.0);
    for (z, c) in &rows {
        total += c;
        if z.dot(&w) > 0.0 {
            good += c;
        }
    }
    Some(SvmDirection {
        direction: (w / norm).into(),
        weight: w.into(),
        agreement: if total > 0.0 { good / total } else { 0.0 },
        samples: rows.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::translational_flow;

    /// Samples of a static scene at random depths seen by a camera translating along `t`.
    fn scene(t: [f64; 3], noise: f64, n: usize) -> Vec<FlowSample> {
        let mut state = 12345u64;
        let mut rnd = move || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64) / ((1u64 << 53) as f64)
        };
        (0..n)
            .map(|i| {
                let (x, y) = (rnd() - 0.5, (rnd() - 0.5) * 0.75);
                let inv_z = 0.2 + rnd();
                let u = translational_flow(x, y, t, inv_z);
                let ang = rnd() * std::f64::consts::TAU;
                let n0 = [ang.cos(), ang.sin()];
                let nf = u[0] * n0[0] + u[1] * n0[1] + noise * (rnd() - 0.5);
                // Normal flow is reported with a positive length along its own direction.
                let (n0, nf) = if nf < 0.0 {
                    ([-n0[0], -n0[1]], -nf)
                } else {
                    (n0, nf)
                };
                FlowSample {
                    index: i,
                    x,
                    y,
                    n0,
                    n: nf,
                    n_derot: nf,
                    confidence: 1.0,
                }
            })
            .collect()
    }

    fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
        let (va, vb) = (Vector3::from(a), Vector3::from(b));
        (va.dot(&vb) / (va.norm() * vb.norm()))
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees()
    }

    #[test]
    fn separable_samples_give_the_direction() {
        for t in [
            [1.0, 0.0, 0.0],
            [0.0, 0.3, 1.0],
            [-0.5, 0.5, 0.2],
            [0.2, -1.0, -0.4],
        ] {
            let s = scene(t, 0.0, 2000);
            let d = translation_direction(s.iter().map(|x| (x, 1.0)), &SvmParams::default()).unwrap();
            assert!(angle_deg(d.direction, t) < 3.0, "t {t:?} got {:?}", d.direction);
            assert!(d.agreement > 0.999);
        }
    }

    #[test]
    fn noisy_samples_still_give_the_direction() {
        let t = [0.6, -0.2, 0.8];
        let s = scene(t, 0.2, 4000);
        let d = translation_direction(s.iter().map(|x| (x, 1.0)), &SvmParams::default()).unwrap();
        assert!(angle_deg(d.direction, t) < 6.0, "got {:?}", d.direction);
    }

    #[test]
    fn too_few_samples_or_no_signal_is_none() {
        let s = scene([1.0, 0.0, 0.0], 0.0, 2);
        assert!(translation_direction(s.iter().map(|x| (x, 1.0)), &SvmParams::default()).is_none());
        let mut s = scene([1.0, 0.0, 0.0], 0.0, 50);
        for x in &mut s {
            x.n_derot = 0.0;
        }
        assert!(translation_direction(s.iter().map(|x| (x, 1.0)), &SvmParams::default()).is_none());
    }
}
