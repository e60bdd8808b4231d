//! Settings of the local plane fit.

/// Settings of [`PlaneFitEstimator`](crate::PlaneFitEstimator). Times are seconds, distances
/// pixels, speeds pixels per second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFitParams {
    /// Half-width of the square neighbourhood, pixels: the window is `(2 r + 1)^2` pixels.
    /// Default 2 (5 x 5), the larger of the two windows in METHOD_NOTES §2 (3 x 3 or 5 x 5); 1 is
    /// the 3 x 3 option. At most [`MAX_RADIUS`].
    pub radius: usize,
    /// Neighbours younger than this (age `t_event - t_neighbour`, seconds) are left out (the
    /// event's own pixel is always used).
    /// Default 0: METHOD_NOTES §2 quotes `[3 ms, 300 ms]` from the reference C code, where the
    /// lower bound drops events *more recent* than 3 ms. Applied literally it removes every
    /// neighbour on the same edge and, for edges faster than `2 r / 3 ms` (667 px/s at r = 2),
    /// every neighbour at all. Measured on the simulator (0.3 s, see the crate README) 3 ms
    /// lowered coverage (two-objects 0.764 -> 0.728, fast-rotation 0.666 -> 0.534) and did not
    /// raise the sign-correct rate (0.855 -> 0.851, 0.798 -> 0.776), though it lowered the
    /// magnitude error; so the default keeps all recent neighbours.
    pub dt_min_s: f64,
    /// Neighbours older than this (seconds) are left out. Default 0.1 s (was 0.3 s, the upper
    /// bound of METHOD_NOTES §2, `[3 ms, 300 ms]`): an edge at 100 px/s crosses the 5 x 5
    /// window in 50 ms, so older neighbours mostly belong to an earlier edge of the texture and
    /// bend the plane (on the simulator 11-15 % of the background's estimates were more than
    /// 30 % off in length, a third of those with the wrong sign). With the neighbourhood
    /// consensus on, `evseg bench` (evseg-bench-v1) scored IoU mask 40.33 / 42.53 / 42.53 % and
    /// median direction error 23.9 / 22.5 / 21.4 deg at 300 / 100 / 50 ms (per-object 38.02 /
    /// 40.30 / 39.36 %); 100 ms keeps edges down to about 50 px/s fully in the window.
    pub dt_max_s: f64,
    /// Fewest surface points (the event included) a plane is fitted to, before and after outlier
    /// rejection. Default 5: METHOD_NOTES §2 says "at least 3 points (better 5 or more)".
    pub min_points: usize,
    /// Points whose time residual exceeds this (seconds) are rejected and the plane refitted.
    /// Default 0.005 s, METHOD_NOTES §2 ("reject points with |residual| > 5 ms").
    pub outlier_s: f64,
    /// Refits after outlier rejection, at most. Default 3: the notes refit "until the parameters
    /// stop changing"; the fit stops earlier as soon as the inlier set is stable, and 3 bounds
    /// the work per event (the task's limit).
    pub max_refits: usize,
    /// Fits whose normal speed exceeds this (pixels per second) are invalid. Default 20 000 px/s:
    /// above it the whole 5 x 5 window is crossed in 0.2 ms, where timestamp jitter dominates the
    /// fit (the reference C code rejects speeds above `1 / dt_min`).
    pub max_speed_px_s: f64,
    /// Fits with a confidence (inlier share times `1 - rms / outlier_s`) at or below this are
    /// marked invalid. Default 0.5: measured on the simulator (two-objects, 0.3 s, README) it
    /// raises the sign-correct rate from 0.855 to 0.977 for a coverage of 0.636 instead of 0.764
    /// (0.8: 0.983 at 0.430). 0 keeps every fit.
    pub min_confidence: f64,
    /// Non-causal fitting within a slice, seconds: an event is fitted once the events up to
    /// `lookahead_s` after it (and within its slice) are on the surface, so neighbours the edge
    /// reaches after the event take part (ages in `[-lookahead_s, dt_max]`). 0 = causal (each
    /// event fitted right after it is written).
    /// Default 0.03 s (the slice length; longer changes nothing): it gives better flow
    /// on every measure: the causal fit keeps, at the edge front, only the pixels that fired
    /// early, which compresses the surface along the motion (+3 % median speed on the simulator
    /// background, +5 % on a jittered synthetic edge, test
    /// `causal_fit_overestimates_jittered_speed_and_lookahead_removes_it`); with 30 ms the median
    /// relative magnitude error fell from 0.044-0.082 to 0.022-0.028 and coverage rose by 0.10 to
    /// 0.26 (score_presets, seeds 1 and 2, four presets), about 12 % slower. End to end the
    /// method's egomotion improved but its IoU fell (`evseg bench`: IoU mask 25.25 -> 23.11 %,
    /// direction error 45.5 -> 34.9 deg; crate README, length study) until the egomotion left
    /// out the background next to objects (`egomotion_clear_px` 24 of both mergers): with
    /// both, IoU mask 25.25 -> 29.62 %, direction error 45.5 -> 26.7 deg (clearance alone
    /// 29.93 %, 35.5 deg). No latency beyond the slice: the look-ahead stays inside the slice.
    pub lookahead_s: f64,
    /// Fits whose gradient direction is this uncertain (radians, [`PlaneFit::direction_sd_rad`](
    /// crate::PlaneFit::direction_sd_rad)) or more are invalid: the length of a normal flow
    /// measured along a wrong direction is off by the flow along the edge times the sine of the
    /// error. Infinite = no test. Default: see the crate README (length study).
    pub max_direction_sd_rad: f64,
}

/// Largest supported [`PlaneFitParams::radius`] (a 7 x 7 window; fixed-size buffers).
pub const MAX_RADIUS: usize = 3;

impl Default for PlaneFitParams {
    fn default() -> Self {
        Self {
            radius: 2,
            dt_min_s: 0.0,
            dt_max_s: 0.1,
            min_points: 5,
            outlier_s: 0.005,
            max_refits: 3,
            max_speed_px_s: 20_000.0,
            min_confidence: 0.5,
            lookahead_s: 0.03,
            max_direction_sd_rad: f64::INFINITY,
        }
    }
}

/// Invalid settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamsError {
    /// Radius 0 or above [`MAX_RADIUS`].
    #[error("radius must be 1..={MAX_RADIUS} pixels, got {0}")]
    Radius(usize),
    /// `min_points` below 3 (a plane needs 3 points) or above the window size.
    #[error("min_points must be between 3 and {window} (the window's pixels), got {got}")]
    MinPoints {
        /// The value given.
        got: usize,
        /// Pixels in the window.
        window: usize,
    },
    /// A time or speed that must be finite and positive (or >= 0) is not.
    #[error("{name} must be a finite number {rule}, got {value}")]
    Range {
        /// Parameter name.
        name: &'static str,
        /// The rule broken.
        rule: &'static str,
        /// The value given.
        value: f64,
    },
}

impl PlaneFitParams {
    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ParamsError> {
        if self.radius == 0 || self.radius > MAX_RADIUS {
            return Err(ParamsError::Radius(self.radius));
        }
        let window = (2 * self.radius + 1).pow(2);
        if self.min_points < 3 || self.min_points > window {
            return Err(ParamsError::MinPoints {
                got: self.min_points,
                window,
            });
        }
        if self.max_direction_sd_rad.is_nan() || self.max_direction_sd_rad <= 0.0 {
            return Err(ParamsError::Range {
                name: "max_direction_sd",
                rule: "> 0 (infinite = no test)",
                value: self.max_direction_sd_rad,
            });
        }
        let checks: [(&'static str, f64, bool, &'static str); 5] = [
            ("lookahead", self.lookahead_s, self.lookahead_s >= 0.0, ">= 0"),
            ("dt_min", self.dt_min_s, self.dt_min_s >= 0.0, ">= 0"),
            ("dt_max", self.dt_max_s, self.dt_max_s > self.dt_min_s, "> dt_min"),
            ("outlier", self.outlier_s, self.outlier_s > 0.0, "> 0"),
            ("max_speed", self.max_speed_px_s, self.max_speed_px_s > 0.0, "> 0"),
        ];
        if !(0.0..1.0).contains(&self.min_confidence) {
            return Err(ParamsError::Range {
                name: "min_confidence",
                rule: "in [0, 1)",
                value: self.min_confidence,
            });
        }
        for (name, value, ok, rule) in checks {
            if !value.is_finite() || !ok {
                return Err(ParamsError::Range { name, rule, value });
            }
        }
        Ok(())
    }
}
