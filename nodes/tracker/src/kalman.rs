//! Constant-velocity Kalman filter on an image centroid.
//!
//! State `[x, y, vx, vy]`: position in pixels, velocity in pixels per second (image frame, x
//! right, y down). Process model: piecewise constant white acceleration with standard deviation
//! `σ_a` px/s² per axis (Bar-Shalom, Li, Kirubarajan, *Estimation with Applications to Tracking
//! and Navigation*, 2001, section 6.3.3): `Q = σ_a² G Gᵀ`, `G = [dt²/2, dt]` per axis.
//! Measurement: the position, with independent noise of standard deviation `σ_z = [σ_x, σ_y]` px
//! per axis (the caller sets it per measurement, for example from the segment's size).

use nalgebra::{Matrix2, Matrix2x4, Matrix4, Vector2, Vector4};

/// A constant-velocity Kalman filter (state and covariance).
#[derive(Debug, Clone, PartialEq)]
pub struct CvKalman {
    /// State `[x, y, vx, vy]`: pixels and pixels per second.
    x: Vector4<f64>,
    /// State covariance (pixels², pixels²/s, pixels²/s²).
    p: Matrix4<f64>,
}

/// The measurement matrix: the position part of the state.
fn h() -> Matrix2x4<f64> {
    Matrix2x4::new(1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
}

/// Diagonal measurement covariance from per-axis standard deviations (pixels), pixels².
fn measurement_cov(std: [f64; 2]) -> Matrix2<f64> {
    Matrix2::new(std[0] * std[0], 0.0, 0.0, std[1] * std[1])
}

/// A predicted measurement: where the centroid should be and how uncertain that is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Innovation {
    /// Measured minus predicted position, pixels.
    pub residual: Vector2<f64>,
    /// Innovation covariance `H P Hᵀ + R`, pixels².
    pub covariance: Matrix2<f64>,
}

impl Innovation {
    /// Squared Mahalanobis distance `rᵀ S⁻¹ r` (unitless); infinite if `S` is singular.
    pub fn mahalanobis2(&self) -> f64 {
        match self.covariance.try_inverse() {
            Some(inv) => (self.residual.transpose() * inv * self.residual)[(0, 0)],
            None => f64::INFINITY,
        }
    }
}

impl CvKalman {
    /// A filter at `position` (pixels) with velocity 0 and standard deviations `position_std`
    /// (pixels) and `velocity_std` (pixels per second).
    pub fn new(position: [f64; 2], position_std: f64, velocity_std: f64) -> Self {
        let (pv, vv) = (position_std * position_std, velocity_std * velocity_std);
        Self {
            x: Vector4::new(position[0], position[1], 0.0, 0.0),
            p: Matrix4::from_diagonal(&Vector4::new(pv, pv, vv, vv)),
        }
    }

    /// Position, pixels.
    pub fn position(&self) -> [f64; 2] {
        [self.x[0], self.x[1]]
    }

    /// Velocity, pixels per second.
    pub fn velocity(&self) -> [f64; 2] {
        [self.x[2], self.x[3]]
    }

    /// Position covariance, pixels².
    pub fn position_covariance(&self) -> Matrix2<f64> {
        self.p.fixed_view::<2, 2>(0, 0).into_owned()
    }

    /// Propagates the state by `dt` seconds with acceleration standard deviation `accel_std`
    /// (px/s²).
    pub fn predict(&mut self, dt: f64, accel_std: f64) {
        let mut f = Matrix4::identity();
        f[(0, 2)] = dt;
        f[(1, 3)] = dt;
        let q2 = accel_std * accel_std;
        let (a, b, c) = (dt.powi(4) / 4.0 * q2, dt.powi(3) / 2.0 * q2, dt * dt * q2);
        #[rustfmt::skip]
        let q = Matrix4::new(
            a,   0.0, b,   0.0,
            0.0, a,   0.0, b,
            b,   0.0, c,   0.0,
            0.0, b,   0.0, c,
        );
        self.x = f * self.x;
        self.p = f * self.p * f.transpose() + q;
    }

    /// The innovation of a position measurement `z` (pixels) with noise standard deviations
    /// `measurement_std` (pixels, per axis), against the current (predicted) state.
    pub fn innovation(&self, z: [f64; 2], measurement_std: [f64; 2]) -> Innovation {
        let r = measurement_cov(measurement_std);
        let predicted = self.position();
        Innovation {
            residual: Vector2::new(z[0] - predicted[0], z[1] - predicted[1]),
            covariance: self.position_covariance() + r,
        }
    }

    /// Corrects the state with the position measurement `z` (pixels, noise standard deviations
    /// `measurement_std` pixels per axis). Joseph-form covariance update, which stays symmetric
    /// and positive definite. A singular innovation covariance (impossible with
    /// `measurement_std > 0`) leaves the state unchanged.
    pub fn update(&mut self, z: [f64; 2], measurement_std: [f64; 2]) {
        let inn = self.innovation(z, measurement_std);
        let Some(s_inv) = inn.covariance.try_inverse() else {
            return;
        };
        let h = h();
        let k = self.p * h.transpose() * s_inv;
        self.x += k * inn.residual;
        let i_kh = Matrix4::identity() - k * h;
        let r = measurement_cov(measurement_std);
        self.p = i_kh * self.p * i_kh.transpose() + k * r * k.transpose();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prediction_moves_by_velocity_times_dt_and_grows_uncertainty() {
        let mut kf = CvKalman::new([10.0, 20.0], 2.0, 100.0);
        kf.x[2] = 50.0;
        kf.x[3] = -30.0;
        let before = kf.position_covariance()[(0, 0)];
        kf.predict(0.1, 0.0);
        let p = kf.position();
        assert!((p[0] - 15.0).abs() < 1e-12 && (p[1] - 17.0).abs() < 1e-12);
        // Var(x) = 4 + dt² · 100² = 4 + 100 with no process noise.
        assert!((kf.position_covariance()[(0, 0)] - (before + 100.0)).abs() < 1e-9);
    }

    #[test]
    fn process_noise_matches_the_white_acceleration_model() {
        // From zero covariance, one step gives Var(x) = σ² dt⁴/4, Var(v) = σ² dt², Cov = σ² dt³/2.
        let mut kf = CvKalman::new([0.0, 0.0], 0.0, 0.0);
        kf.predict(0.2, 10.0);
        let p = kf.p;
        assert!((p[(0, 0)] - 100.0 * 0.0016 / 4.0).abs() < 1e-12);
        assert!((p[(2, 2)] - 100.0 * 0.04).abs() < 1e-12);
        assert!((p[(0, 2)] - 100.0 * 0.008 / 2.0).abs() < 1e-12);
        assert_eq!(p[(0, 1)], 0.0);
    }

    #[test]
    fn update_with_equal_variances_lands_halfway() {
        // Prior Var = 9 and measurement Var = 9: the posterior is the midpoint, Var 4.5.
        let mut kf = CvKalman::new([0.0, 0.0], 3.0, 1.0);
        kf.update([6.0, -2.0], [3.0, 3.0]);
        let p = kf.position();
        assert!((p[0] - 3.0).abs() < 1e-12 && (p[1] + 1.0).abs() < 1e-12);
        assert!((kf.position_covariance()[(0, 0)] - 4.5).abs() < 1e-12);
    }

    #[test]
    fn velocity_converges_on_a_constant_velocity_track() {
        let mut kf = CvKalman::new([0.0, 0.0], 1.0, 500.0);
        let dt = 0.03;
        for k in 1..40 {
            kf.predict(dt, 100.0);
            let t = k as f64 * dt;
            kf.update([200.0 * t, -100.0 * t], [1.0, 1.0]);
        }
        let v = kf.velocity();
        assert!((v[0] - 200.0).abs() < 2.0, "{v:?}");
        assert!((v[1] + 100.0).abs() < 2.0, "{v:?}");
    }

    #[test]
    fn mahalanobis_distance_of_a_known_innovation() {
        // S = diag(4 + 1, 4 + 1) = 5 I; r = (3, 4): d² = 25 / 5 = 5.
        let kf = CvKalman::new([0.0, 0.0], 2.0, 1.0);
        let inn = kf.innovation([3.0, 4.0], [1.0, 1.0]);
        assert!((inn.mahalanobis2() - 5.0).abs() < 1e-12);
        // Per-axis noise: S = diag(4 + 5, 4 + 12) = diag(9, 16): d² = 9/9 + 16/16 = 2.
        let inn = kf.innovation([3.0, 4.0], [5f64.sqrt(), 12f64.sqrt()]);
        assert!((inn.mahalanobis2() - 2.0).abs() < 1e-12);
    }
}
