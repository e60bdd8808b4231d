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

/// Seconds over which a signal's rate reverses when it has [`Signal::reverse_every_s`] (a
/// half-cosine from `+rate` to `-rate`, ending at each multiple of the period).
pub const REVERSAL_S: f64 = 1.0;

/// A smooth scalar signal `offset + rate * t + sum of sinusoids` (t in seconds); with
/// [`Signal::reverse_every_s`] the rate part goes forth and back instead of growing for ever.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Signal {
    /// Value at t = 0 apart from the sinusoids (m or rad).
    pub offset: f64,
    /// Constant rate (m/s or rad/s).
    pub rate: f64,
    /// Sinusoidal terms.
    pub terms: Vec<Sinusoid>,
    /// When set (seconds, above [`REVERSAL_S`]), the rate reverses smoothly over the
    /// [`REVERSAL_S`] before every multiple of this period, alternately to `-rate` and back
    /// to `rate`: identical to `rate * t` until `reverse_every_s - REVERSAL_S`, and bounded
    /// (a walk forth and back) however long the signal runs. `None`: a constant rate.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reverse_every_s: Option<f64>,
}

impl Signal {
    /// A constant signal.
    pub fn constant(offset: f64) -> Self {
        Self {
            offset,
            rate: 0.0,
            terms: Vec::new(),
            reverse_every_s: None,
        }
    }

    /// `offset + rate t`.
    pub fn linear(offset: f64, rate: f64) -> Self {
        Self {
            offset,
            rate,
            terms: Vec::new(),
            reverse_every_s: None,
        }
    }

    /// The rate part reversing every `period_s` (builder style, see
    /// [`Signal::reverse_every_s`]).
    pub fn reversing_every(mut self, period_s: f64) -> Self {
        self.reverse_every_s = Some(period_s);
        self
    }

    /// Checks [`Signal::reverse_every_s`]: finite and above [`REVERSAL_S`].
    pub fn validate(&self) -> Result<(), String> {
        match self.reverse_every_s {
            Some(p) if !(p.is_finite() && p > REVERSAL_S) => Err(format!(
                "reverse_every_s = {p} must be a finite number of seconds above {REVERSAL_S}"
            )),
            _ => Ok(()),
        }
    }

    /// The rate part per unit rate: its value, first and second derivatives at `t` (s).
    fn ramp(&self, t: f64) -> (f64, f64, f64) {
        let Some(period) = self.reverse_every_s else {
            return (t, 1.0, 0.0);
        };
        // Within one cycle of two periods: forth (rate 1), a half-cosine turn over the last
        // REVERSAL_S of the period, back (rate -1), and a turn again; each cycle ends where
        // it began, so the value stays within [0, period - REVERSAL_S + REVERSAL_S / pi].
        let (tau, pi) = (REVERSAL_S, std::f64::consts::PI);
        let u = t.rem_euclid(2.0 * period);
        let straight = period - tau;
        if u <= straight {
            (u, 1.0, 0.0)
        } else if u <= period {
            let a = pi * (u - straight) / tau;
            (straight + tau / pi * a.sin(), a.cos(), -pi / tau * a.sin())
        } else if u <= 2.0 * period - tau {
            (straight - (u - period), -1.0, 0.0)
        } else {
            let a = pi * (u - (2.0 * period - tau)) / tau;
            (-tau / pi * a.sin(), -a.cos(), pi / tau * a.sin())
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
        let (r, dr, ddr) = self.ramp(t);
        let mut v = self.offset + self.rate * r;
        let mut d = self.rate * dr;
        let mut dd = self.rate * ddr;
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
    /// Checks every signal (see [`Signal::validate`]); the error names the field under `what`.
    pub fn validate(&self, what: &str) -> Result<(), String> {
        for (k, sig) in self.position.iter().enumerate() {
            sig.validate().map_err(|e| format!("{what}.position[{k}]: {e}"))?;
        }
        for (k, sig) in self.angles.iter().enumerate() {
            sig.validate().map_err(|e| format!("{what}.angles[{k}]: {e}"))?;
        }
        Ok(())
    }

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

    #[test]
    fn a_reversing_rate_is_a_steady_walk_first_then_smooth_and_bounded() {
        let steady = Signal::linear(0.3, 0.15).with(0.06, 0.7, 0.4);
        let walk = steady.clone().reversing_every(6.0);
        // The same as the steady walk until the first turn begins.
        for k in 0..=500 {
            let t = k as f64 * 0.01;
            assert_eq!(walk.eval(t), steady.eval(t), "t = {t}");
        }
        // Derivatives agree with finite differences everywhere (turns included), the value is
        // continuous, and the rate part stays within [0, (6 - 1 + 1 / pi) 0.15] plus the sinusoid.
        let h = 1e-5;
        let top = 0.3 + 0.15 * (5.0 + 1.0 / std::f64::consts::PI) + 0.06 + 1e-9;
        let mut last = walk.eval(0.0).0;
        for k in 1..60_000 {
            let t = k as f64 * 0.001;
            let (v, d, dd) = walk.eval(t);
            let (vp, dp, _) = walk.eval(t + h);
            let (vm, dm, _) = walk.eval(t - h);
            assert!(((vp - vm) / (2.0 * h) - d).abs() < 1e-4, "t = {t}");
            assert!(((dp - dm) / (2.0 * h) - dd).abs() < 1e-2, "t = {t}");
            assert!((v - last).abs() < 1e-3, "jump at t = {t}");
            assert!(
                v <= top && v >= 0.3 - 0.15 / std::f64::consts::PI - 0.06 - 1e-9,
                "t = {t}: {v}"
            );
            assert!(d.abs() <= walk.max_rate() + 1e-12);
            last = v;
        }
        assert!(Signal::linear(0.0, 1.0).reversing_every(0.5).validate().is_err());
        assert!(
            Signal::linear(0.0, 1.0)
                .reversing_every(f64::NAN)
                .validate()
                .is_err()
        );
        assert!(walk.validate().is_ok());
    }

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
