//! Smooth 6-DoF trajectories: positions and Euler-chain angles that are sums of sinusoids plus a
//! constant rate, so that velocities and accelerations are analytic.

use serde::{Deserialize, Serialize};

use crate::math::{self, Mat3, Vec3};

/// One term `amplitude * sin(2 pi freq_hz t + phase_rad)`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sinusoid {
    /// Amplitude (metres for positions, radians for angles).
    pub amplitude: f64,
    /// Frequency, Hz.
    pub freq_hz: f64,
    /// Phase, rad.
    pub phase_rad: f64,
}

/// A smooth scalar signal `offset + rate * t + sum of sinusoids` (t in seconds).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Signal {
    /// Value at t = 0 apart from the sinusoids (m or rad).
    pub offset: f64,
    /// Constant rate (m/s or rad/s).
    pub rate: f64,
    /// Sinusoidal terms.
    pub terms: Vec<Sinusoid>,
}

impl Signal {
    /// A constant signal.
    pub fn constant(offset: f64) -> Self {
        Self {
            offset,
            rate: 0.0,
            terms: Vec::new(),
        }
    }

    /// `offset + rate t`.
    pub fn linear(offset: f64, rate: f64) -> Self {
        Self {
            offset,
            rate,
            terms: Vec::new(),
        }
    }

    /// Adds a sinusoid (builder style).
    pub fn with(mut self, amplitude: f64, freq_hz: f64, phase_rad: f64) -> Self {
        self.terms.push(Sinusoid {
            amplitude,
            freq_hz,
            phase_rad,
        });
        self
    }

    /// Value, first and second time derivatives at `t` (s).
    pub fn eval(&self, t: f64) -> (f64, f64, f64) {
        let mut v = self.offset + self.rate * t;
        let mut d = self.rate;
        let mut dd = 0.0;
        for s in &self.terms {
            let w = std::f64::consts::TAU * s.freq_hz;
            let (sn, cs) = (w * t + s.phase_rad).sin_cos();
            v += s.amplitude * sn;
            d += s.amplitude * w * cs;
            dd -= s.amplitude * w * w * sn;
        }
        (v, d, dd)
    }

    /// An upper bound of |first derivative| over all time.
    pub fn max_rate(&self) -> f64 {
        self.rate.abs()
            + self
                .terms
                .iter()
                .map(|s| (s.amplitude * std::f64::consts::TAU * s.freq_hz).abs())
                .sum::<f64>()
    }
}

/// Kinematic state of a rigid body at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidState {
    /// Body -> world rotation.
    pub rotation: Mat3,
    /// Body origin in the world, m.
    pub position: Vec3,
    /// Linear velocity of the origin, m/s, world frame.
    pub velocity: Vec3,
    /// Linear acceleration of the origin, m/s², world frame.
    pub acceleration: Vec3,
    /// Angular velocity, rad/s, body frame.
    pub omega_body: Vec3,
}

impl RigidState {
    /// Angular velocity, rad/s, world frame.
    pub fn omega_world(&self) -> Vec3 {
        math::mul_mv(&self.rotation, self.omega_body)
    }
}

/// A smooth rigid-body trajectory in the world frame (z up).
///
/// Orientation (body -> world) is
/// `base_rotation * R(axes[0], angles[0]) * R(axes[1], angles[1]) * R(axes[2], angles[2])`
/// where `R(a, theta)` rotates about body axis `a` (0 = x, 1 = y, 2 = z).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RigidTrajectory {
    /// World position of the body origin, per world axis, m.
    pub position: [Signal; 3],
    /// Fixed rotation applied first (body -> world), row-major.
    pub base_rotation: Mat3,
    /// Axis (0 = x, 1 = y, 2 = z) of each of the three chained rotations.
    pub axes: [usize; 3],
    /// Angle of each chained rotation, rad.
    pub angles: [Signal; 3],
}

impl RigidTrajectory {
    /// A body resting at `position` with rotation `base_rotation`.
    pub fn fixed(position: Vec3, base_rotation: Mat3) -> Self {
        Self {
            position: position.map(Signal::constant),
            base_rotation,
            axes: [2, 1, 0],
            angles: [Signal::default(), Signal::default(), Signal::default()],
        }
    }

    /// State at time `t` (s).
    pub fn state(&self, t: f64) -> RigidState {
        let p = [
            self.position[0].eval(t),
            self.position[1].eval(t),
            self.position[2].eval(t),
        ];
        let a = [
            self.angles[0].eval(t),
            self.angles[1].eval(t),
            self.angles[2].eval(t),
        ];
        let r1 = math::rot_axis(self.axes[0], a[0].0);
        let r2 = math::rot_axis(self.axes[1], a[1].0);
        let r3 = math::rot_axis(self.axes[2], a[2].0);
        let rotation = math::mul_mm(&math::mul_mm(&self.base_rotation, &r1), &math::mul_mm(&r2, &r3));
        let e = |axis: usize, v: f64| {
            let mut u = [0.0; 3];
            u[axis.min(2)] = v;
            u
        };
        // omega_body = R3^T R2^T e1 a1' + R3^T e2 a2' + e3 a3'.
        let w1 = math::mul_mtv(&r3, math::mul_mtv(&r2, e(self.axes[0], a[0].1)));
        let w2 = math::mul_mtv(&r3, e(self.axes[1], a[1].1));
        let w3 = e(self.axes[2], a[2].1);
        RigidState {
            rotation,
            position: [p[0].0, p[1].0, p[2].0],
            velocity: [p[0].1, p[1].1, p[2].1],
            acceleration: [p[0].2, p[1].2, p[2].2],
            omega_body: math::add(math::add(w1, w2), w3),
        }
    }

    /// Upper bound of the linear speed over all time, m/s.
    pub fn max_speed(&self) -> f64 {
        self.position
            .iter()
            .map(|s| s.max_rate().powi(2))
            .sum::<f64>()
            .sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wobbly() -> RigidTrajectory {
        RigidTrajectory {
            position: [
                Signal::linear(0.1, 0.2).with(0.3, 0.7, 0.1),
                Signal::constant(1.0).with(0.2, 1.3, 2.0),
                Signal::linear(0.0, -0.1).with(0.05, 2.0, 0.0),
            ],
            base_rotation: math::rot_axis(0, 0.4),
            axes: [1, 0, 2],
            angles: [
                Signal::linear(0.2, 0.3).with(0.4, 0.9, 0.3),
                Signal::constant(-0.1).with(0.2, 1.7, 1.0),
                Signal::constant(0.05).with(0.3, 0.5, 2.0),
            ],
        }
    }

    #[test]
    #[allow(clippy::needless_range_loop)]
    fn velocities_match_finite_differences() {
        let tr = wobbly();
        let h = 1e-6;
        for &t in &[0.0, 0.37, 1.9] {
            let s0 = tr.state(t - h);
            let s1 = tr.state(t + h);
            let s = tr.state(t);
            for k in 0..3 {
                let v = (s1.position[k] - s0.position[k]) / (2.0 * h);
                assert!((v - s.velocity[k]).abs() < 1e-6);
                let a = (s1.velocity[k] - s0.velocity[k]) / (2.0 * h);
                assert!((a - s.acceleration[k]).abs() < 1e-5);
            }
            // R^T dR/dt = [omega_body]x.
            let mut d = [[0.0; 3]; 3];
            for i in 0..3 {
                for j in 0..3 {
                    d[i][j] = (s1.rotation[i][j] - s0.rotation[i][j]) / (2.0 * h);
                }
            }
            let sk = math::mul_mm(&math::transpose(&s.rotation), &d);
            let w = [sk[2][1], sk[0][2], sk[1][0]];
            for k in 0..3 {
                assert!(
                    (w[k] - s.omega_body[k]).abs() < 1e-6,
                    "{w:?} vs {:?}",
                    s.omega_body
                );
            }
        }
    }
}
