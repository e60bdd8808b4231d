//! The ESIM pixel model (Rebecq et al. 2018): per-pixel contrast thresholds, threshold crossings
//! of linearly interpolated log intensity, refractory period, and sensor noise.

use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::rng::Rng;

/// Event-generation parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EsimConfig {
    /// Nominal ON contrast threshold, log-intensity units (0.2: middle of the 0.15..0.5 range
    /// of the ESIM paper, close to DVS/Prophesee defaults).
    pub c_on: f64,
    /// Nominal OFF contrast threshold, log-intensity units.
    pub c_off: f64,
    /// Relative standard deviation of the per-pixel thresholds (0.03 = 3 %, the
    /// pixel-to-pixel mismatch ESIM uses).
    pub c_sigma: f64,
    /// Smallest threshold any pixel may get, log units (guards the normal tails).
    pub c_min: f64,
    /// Refractory period, s (0.1 ms, the ESIM default). A crossing within this time of the
    /// pixel's previous event still moves the reference level but emits no event.
    pub refractory_s: f64,
    /// Offset of the log: `L = ln(eps + I)` with I the intensity (albedo x shading in 0..1).
    pub log_eps: f64,
    /// Background-activity noise rate per pixel, Hz (0.1 Hz: typical of modern sensors in a
    /// lit room).
    pub noise_rate_hz: f64,
    /// Number of hot pixels.
    pub hot_pixels: u32,
    /// Event rate of each hot pixel, Hz.
    pub hot_pixel_rate_hz: f64,
}

impl Default for EsimConfig {
    fn default() -> Self {
        Self {
            c_on: 0.2,
            c_off: 0.2,
            c_sigma: 0.03,
            c_min: 0.01,
            refractory_s: 1e-4,
            log_eps: 0.01,
            noise_rate_hz: 0.1,
            hot_pixels: 5,
            hot_pixel_rate_hz: 200.0,
        }
    }
}

/// Largest background-activity or hot-pixel rate accepted, events per pixel per second. Real
/// sensors' background activity is 0.01-10 Hz per pixel and hot pixels fire at up to a few kHz;
/// a VGA sensor at this rate everywhere would make 300 M noise events per second, which the
/// simulator holds in memory per chunk.
pub const MAX_NOISE_RATE_HZ: f64 = 1000.0;

/// Largest number of hot pixels accepted.
pub const MAX_HOT_PIXELS: u32 = 100_000;

impl EsimConfig {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), SimError> {
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(SimError::Config(format!(
                    "esim.{name} = {v} must be finite and > 0"
                )))
            }
        };
        let nonneg = |name: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(SimError::Config(format!(
                    "esim.{name} = {v} must be finite and >= 0"
                )))
            }
        };
        pos("c_on", self.c_on)?;
        pos("c_off", self.c_off)?;
        pos("c_min", self.c_min)?;
        pos("log_eps", self.log_eps)?;
        nonneg("c_sigma", self.c_sigma)?;
        nonneg("refractory_s", self.refractory_s)?;
        nonneg("noise_rate_hz", self.noise_rate_hz)?;
        nonneg("hot_pixel_rate_hz", self.hot_pixel_rate_hz)?;
        for (name, v) in [
            ("noise_rate_hz", self.noise_rate_hz),
            ("hot_pixel_rate_hz", self.hot_pixel_rate_hz),
        ] {
            if v > MAX_NOISE_RATE_HZ {
                return Err(SimError::Config(format!(
                    "esim.{name} = {v} Hz per pixel is above the {MAX_NOISE_RATE_HZ} Hz the simulator accepts"
                )));
            }
        }
        if self.hot_pixels > MAX_HOT_PIXELS {
            return Err(SimError::Config(format!(
                "esim.hot_pixels = {} is above the {MAX_HOT_PIXELS} the simulator accepts",
                self.hot_pixels
            )));
        }
        Ok(())
    }
}

/// Per-pixel contrast thresholds, drawn once per simulation.
#[derive(Debug, Clone)]
pub struct Thresholds {
    /// ON threshold per pixel, row-major.
    pub on: Vec<f32>,
    /// OFF threshold per pixel, row-major.
    pub off: Vec<f32>,
}

impl Thresholds {
    /// Draws `n` pixels' thresholds.
    pub fn draw(cfg: &EsimConfig, n: usize, rng: &mut Rng) -> Self {
        let mut draw = |c: f64| -> f32 { (c * (1.0 + cfg.c_sigma * rng.normal())).max(cfg.c_min) as f32 };
        let on = (0..n).map(|_| draw(cfg.c_on)).collect();
        let off = (0..n).map(|_| draw(cfg.c_off)).collect();
        Self { on, off }
    }
}

/// False when [`crossings`] to `l1` can do nothing (no event, no reference change) whatever the
/// start: `l1` lies strictly inside the thresholds around `reference` (a rising segment fires
/// only if it reaches `reference + c_on`, a falling one only if it reaches `reference - c_off`).
#[inline(always)]
pub fn may_cross(reference: f32, l1: f32, c_on: f32, c_off: f32) -> bool {
    (l1 >= reference + c_on) | (l1 <= reference - c_off)
}

/// Threshold crossings of one pixel whose log intensity goes linearly from `l0` at `t0` to `l1`
/// at `t1`. `reference` is the pixel's reference level, `last_event` the time of its last
/// emitted event (both updated). Calls `emit(t, polarity)` for every emitted event, in time order.
#[allow(clippy::too_many_arguments)]
#[inline]
pub fn crossings(
    reference: &mut f32,
    last_event: &mut f64,
    l0: f32,
    l1: f32,
    t0: f64,
    t1: f64,
    c_on: f32,
    c_off: f32,
    refractory: f64,
    mut emit: impl FnMut(f64, u8),
) {
    let dl = l1 - l0;
    if dl > 0.0 {
        while *reference + c_on <= l1 {
            *reference += c_on;
            let f = ((*reference - l0) / dl).clamp(0.0, 1.0) as f64;
            let t = t0 + (t1 - t0) * f;
            if t - *last_event >= refractory {
                emit(t, 1);
                *last_event = t;
            }
        }
    } else if dl < 0.0 {
        while *reference - c_off >= l1 {
            *reference -= c_off;
            let f = ((*reference - l0) / dl).clamp(0.0, 1.0) as f64;
            let t = t0 + (t1 - t0) * f;
            if t - *last_event >= refractory {
                emit(t, 0);
                *last_event = t;
            }
        }
    }
}

/// Background-activity and hot-pixel noise as Poisson processes in continuous time, so the
/// events do not depend on how time is cut into steps.
#[derive(Debug, Clone)]
pub struct NoiseSource {
    rng: Rng,
    pixels: u64,
    ba_rate: f64,
    hot: Vec<u32>,
    hot_rate: f64,
    next_ba: f64,
    next_hot: f64,
}

impl NoiseSource {
    /// Noise for `pixels` pixels; the hot pixels are drawn here.
    pub fn new(cfg: &EsimConfig, pixels: usize, seed: u64) -> Self {
        let mut rng = Rng::new(seed, 0x4015e);
        let hot: Vec<u32> = (0..cfg.hot_pixels)
            .map(|_| rng.below(pixels as u64) as u32)
            .collect();
        let ba_rate = cfg.noise_rate_hz * pixels as f64;
        let hot_rate = cfg.hot_pixel_rate_hz * hot.len() as f64;
        let next_ba = rng.exponential(ba_rate);
        let next_hot = rng.exponential(hot_rate);
        Self {
            rng,
            pixels: pixels as u64,
            ba_rate,
            hot,
            hot_rate,
            next_ba,
            next_hot,
        }
    }

    /// The hot pixels (row-major indices).
    pub fn hot_pixels(&self) -> &[u32] {
        &self.hot
    }

    /// Emits `(t, pixel, polarity)` for every noise event with `t < t_end`, in time order.
    pub fn until(&mut self, t_end: f64, mut emit: impl FnMut(f64, u32, u8)) {
        loop {
            if self.next_ba < t_end && self.next_ba <= self.next_hot {
                let t = self.next_ba;
                let p = self.rng.below(self.pixels) as u32;
                let pol = (self.rng.next_u64() & 1) as u8;
                emit(t, p, pol);
                self.next_ba = t + self.rng.exponential(self.ba_rate);
            } else if self.next_hot < t_end {
                let t = self.next_hot;
                let p = self.hot[self.rng.below(self.hot.len() as u64) as usize];
                let pol = (self.rng.next_u64() & 1) as u8;
                emit(t, p, pol);
                self.next_hot = t + self.rng.exponential(self.hot_rate);
            } else {
                break;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(l: &[f32], dt: f64, c: f32, refr: f64) -> Vec<(f64, u8)> {
        let mut reference = l[0];
        let mut last = f64::NEG_INFINITY;
        let mut out = Vec::new();
        for k in 1..l.len() {
            let (t0, t1) = ((k - 1) as f64 * dt, k as f64 * dt);
            crossings(
                &mut reference,
                &mut last,
                l[k - 1],
                l[k],
                t0,
                t1,
                c,
                c,
                refr,
                |t, p| out.push((t, p)),
            );
        }
        out
    }

    #[test]
    fn ramp_of_k_thresholds_gives_k_events_at_interpolated_times() {
        let c = 0.2f32;
        // One render step rising by 3.5 C over 1 ms: events at 1/3.5, 2/3.5, 3/3.5 ms.
        let ev = run(&[0.0, 3.5 * c], 1e-3, c, 0.0);
        assert_eq!(ev.len(), 3);
        for (k, (t, p)) in ev.iter().enumerate() {
            assert_eq!(*p, 1);
            assert!((t - (k + 1) as f64 / 3.5 * 1e-3).abs() < 1e-8, "{t}");
        }
        // Falling ramp over several steps: -4.2 C in 7 steps of 0.6 C -> 4 OFF events at
        // t = k C / (0.6 C / step).
        let l: Vec<f32> = (0..8).map(|k| -0.6 * c * k as f32).collect();
        let ev = run(&l, 1e-3, c, 0.0);
        assert_eq!(ev.len(), 4);
        for (k, (t, p)) in ev.iter().enumerate() {
            assert_eq!(*p, 0);
            assert!((t - (k + 1) as f64 / 0.6 * 1e-3).abs() < 1e-7, "{t}");
        }
        // Up then down: reference follows, polarities in order.
        let ev = run(&[0.0, 0.45, 0.0], 1e-3, c, 0.0);
        let pols: Vec<u8> = ev.iter().map(|e| e.1).collect();
        assert_eq!(pols, vec![1, 1, 0, 0]);
    }

    #[test]
    fn refractory_period_drops_close_events() {
        // Five crossings within 0.1 ms, refractory 0.05 ms -> events at 0.02 ms spacing,
        // only every third one survives.
        let ev = run(&[0.0, 1.0], 1e-4, 0.2, 5e-5);
        assert_eq!(ev.len(), 2, "{ev:?}");
        assert!(ev[1].0 - ev[0].0 >= 5e-5);
    }

    #[test]
    fn noise_rate_matches_configuration() {
        let cfg = EsimConfig {
            noise_rate_hz: 2.0,
            hot_pixels: 2,
            hot_pixel_rate_hz: 100.0,
            ..Default::default()
        };
        let mut src = NoiseSource::new(&cfg, 10_000, 5);
        let hot = src.hot_pixels().to_vec();
        let (mut n, mut n_hot, mut last) = (0usize, 0usize, 0.0);
        src.until(10.0, |t, p, _| {
            assert!(t >= last);
            last = t;
            n += 1;
            if hot.contains(&p) {
                n_hot += 1;
            }
        });
        // Expect 200k background + 2k hot over 10 s.
        assert!((n as f64 - 202_000.0).abs() < 2_000.0, "{n}");
        assert!((n_hot as f64 - 2_000.0).abs() < 200.0, "{n_hot}");
    }
}
