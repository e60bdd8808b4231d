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
    /// Non-causal fitting, seconds: an event is fitted once the events up to
    /// `lookahead_s` after it (within its slice, or also from the next slice, see
    /// `lookahead_across_slices`) are on the surface, so neighbours the edge
    /// reaches after the event take part (ages in `[-lookahead_s, dt_max]`). 0 = causal (each
    /// event fitted right after it is written).
    /// Default 0.03 s (the slice length; within the slice longer changed nothing, and across
    /// slices 20 and 60 ms were worse on the method, crate README): it gives better flow
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
    /// 29.93 %, 35.5 deg). Within a slice it adds no latency; reaching into the next slice
    /// (`lookahead_across_slices`) adds one slice.
    pub lookahead_s: f64,
    /// Let the look-ahead reach into the next slice: the node holds each slice until the next
    /// one arrives and writes that slice's first `lookahead_s` to the surfaces before fitting the
    /// held slice's last events ([`crate::PlaneFitEstimator::process_with_next_into`]), so every
    /// event gets the whole look-ahead, not only those more than `lookahead_s` before the slice's
    /// end. The flow of a slice then leaves the node one slice later (30 ms of latency in live
    /// runs); the last slice of a run is fitted without it. The estimator itself does not read
    /// this field; it tells its callers whether to wait for the next slice. Default true:
    /// the lengths fitted near a slice's end came out too long (median +1.5 to +3.2 % with less
    /// than 2 px of travel left, crate README, "Length noise and the egomotion"), an error shared
    /// by every slice's tail; measured on the method (`method_on_sim`, three sets of fourteen
    /// sequences; crate README, "Look-ahead across slices").
    pub lookahead_across_slices: bool,
    /// Fits whose gradient direction is this uncertain (radians, [`PlaneFit::direction_sd_rad`](
    /// crate::PlaneFit::direction_sd_rad)) or more are invalid: the length of a normal flow
    /// measured along a wrong direction is off by the flow along the edge times the sine of the
    /// error. Infinite = no test. Default: see the crate README (length study).
    pub max_direction_sd_rad: f64,
    /// Half-width, pixels, of a second, larger window whose plane must agree with the event's
    /// own ([`PlaneFitParams::radius`]) fit for the estimate to be valid; 0 = no check. A moving
    /// edge's surface of active events is a plane at every scale, so the two fits agree; where
    /// they do not, the small window saw something else: crossings of several intensity levels
    /// of a smooth or high-contrast texture (each pixel's timestamp then depends on its own
    /// reference level, not only on when the edge passed), two surfaces, or timing noise. Must
    /// exceed `radius`, at most [`MAX_RADIUS`]. The estimate stays the small window's.
    ///
    /// Default 3 (7 x 7 around the 5 x 5). Measured on the simulator (`examples/scale_check.rs`,
    /// seed 11, 1 s; background events that are not object edges; `|e|` the length error along
    /// the estimated direction over the true flow's speed; crate README, "Scale check"):
    /// one-object median `|e|` 0.038 -> 0.033, share with `|e|` > 0.2 0.139 -> 0.086, reversed
    /// directions 0.042 -> 0.021, coverage 0.758 -> 0.675; fast-rotation 0.038 -> 0.031, 0.126
    /// -> 0.050, 0.038 -> 0.003, 0.788 -> 0.669; high-contrast share > 0.2 0.265 -> 0.136. In the
    /// whole method (hierarchical merger's `method_on_sim` with the graph's feedback, six object
    /// presets and camera-only, unseen seeds; every fit checked): seeds 11-13, 2 s, mean IoU
    /// 0.797 -> 0.812, mean median direction error 11.4 -> 10.1 deg; seeds 11-15, 3 s, 0.767 ->
    /// 0.770 and 11.1 -> 9.9 deg (fast-rotation 0.671 -> 0.749, low-contrast 0.727 -> 0.689).
    pub check_radius: usize,
    /// Largest angle, radians, between the two fits' normal-flow directions (default 10 deg;
    /// 5 / 10 / 15 deg with 0.1 / 0.2 / 0.3 for the speed: mean IoU 0.804 / 0.814 / 0.811
    /// on seeds 11-13, 2 s, with the final labels as the planar feedback; 8 deg / 0.15 0.811;
    /// a 9 x 9 check window 0.811).
    pub check_max_angle_rad: f64,
    /// Largest relative difference of the two fits' speeds, `|s / s_check - 1|` (default 0.2).
    pub check_max_speed_diff: f64,
    /// Fits with at least this confidence and at most
    /// [`PlaneFitParams::check_skip_direction_sd_rad`] of direction uncertainty are kept without
    /// the scale check: a second fit on up to 49 points halves the estimator's throughput when
    /// every fit takes it, and the check hardly ever rejects such fits. Default 0.6 (above 1:
    /// every fit is checked); see the direction threshold.
    pub check_skip_confidence: f64,
    /// See [`PlaneFitParams::check_skip_confidence`]. Default 4 deg. `scale_check` (seed 11, 1 s)
    /// with every fit checked / with 0.8 and 2 deg / 0.7 and 3 deg / 0.6 and 4 deg: background
    /// share of `|e|` > 0.2 0.082 / 0.083 / 0.084 / 0.086 (one-object), 0.049 / 0.049 / 0.049 /
    /// 0.050 (fast-rotation), 0.137 / 0.136 / 0.135 / 0.136 (high-contrast), coverage 0.638 /
    /// 0.647 / 0.660 / 0.675 (one-object); throughput (`cargo bench -p evseg-normal-flow --bench
    /// plane_fit`, shared 2-core machine) 1.5 / 2.1 / - / 2.5 M events/s against 3.1 without the
    /// check. `method_on_sim` (seeds 11-15, 3 s): mean IoU 0.770 both, direction error 9.9 /
    /// 10.3 deg.
    pub check_skip_direction_sd_rad: f64,
}

/// Largest supported [`PlaneFitParams::radius`] and [`PlaneFitParams::check_radius`] (a 9 x 9
/// window; fixed-size buffers).
pub const MAX_RADIUS: usize = 4;

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
            lookahead_across_slices: true,
            max_direction_sd_rad: f64::INFINITY,
            check_radius: 3,
            check_max_angle_rad: 10f64.to_radians(),
            check_max_speed_diff: 0.2,
            check_skip_confidence: 0.6,
            check_skip_direction_sd_rad: 4f64.to_radians(),
        }
    }
}

/// Settings of the wide fit ([`PlaneFitEstimator::with_wide_fit`](
/// crate::PlaneFitEstimator::with_wide_fit)): a second plane fit on a larger window for the
/// events whose own fit is fast, which gives a second flow (the wide flow) for consumers that
/// need lengths more than coverage at motion boundaries (the final egomotion). Distances pixels,
/// speeds pixels per second.
///
/// Why: a fast edge crosses the 5 x 5 window in a few milliseconds, so few distinct timestamps
/// carry the plane's slope and the length is noisy; a 7 x 7 window has twice the points across
/// the same edge. Where the flow is slow, the larger window reaches into the older edges of the
/// texture (`dt_max_s`) and the small window is better. The wide window blurs motion
/// boundaries, which costs the segmentation (every stage fed the mixed flow: IoU 0.8565 ->
/// 0.8555) more than it gains; the final egomotion, fitted on the background away from objects,
/// gains (hierarchical merger's `method_on_sim`, mean of fourteen sequences' median direction
/// errors: bench seeds 5.41 -> 4.78 deg, seeds 301-407 6.06 -> 5.59, 501-607 5.76 -> 5.53;
/// docs/scoreboard-history.md, session 43).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WideFitParams {
    /// Half-width of the wide window, pixels. Default 3 (7 x 7), the study's window (also
    /// the small fit's scale-check window, whose points the wide fit then reuses). More than [`PlaneFitParams::radius`], at most [`MAX_RADIUS`].
    pub radius: usize,
    /// Half-width of the wide fit's scale check (as [`PlaneFitParams::check_radius`], with the
    /// same angle and speed tolerances); 0 = no check, else more than `radius`, at most
    /// [`MAX_RADIUS`]. Default 0: the small fit was already checked, and a 9 x 9 check of the
    /// wide fit was both slower and worse (`method_on_sim`, mean of fourteen median direction
    /// errors, 9 x 9 check / none: bench seeds 4.85 / 4.73 deg, seeds 301-407 5.54 / 5.51,
    /// 501-607 5.54 / 5.39; IoU unchanged).
    pub check_radius: usize,
    /// Events whose own (small-window) estimate is faster than this, pixels per second, get the
    /// wide fit; the others keep their own estimate in the wide flow. Default 200 px/s (the
    /// study's mean of median direction errors on the bench seeds at 150 / 200 / 300 / 600 px/s
    /// and everywhere: 4.79 / 4.78 / 5.14 / 5.35 / 5.18 deg).
    pub min_speed_px_s: f64,
    /// Refits of the wide fit after outlier rejection, at most (as
    /// [`PlaneFitParams::max_refits`]).
    pub max_refits: usize,
}

impl Default for WideFitParams {
    fn default() -> Self {
        Self {
            radius: 3,
            check_radius: 0,
            min_speed_px_s: 200.0,
            max_refits: 3,
        }
    }
}

impl WideFitParams {
    /// Checks every field against the small window's settings `own`; the error names the first
    /// bad one.
    pub fn validate(&self, own: &PlaneFitParams) -> Result<(), ParamsError> {
        if self.radius <= own.radius || self.radius > MAX_RADIUS {
            return Err(ParamsError::WideRadius {
                wide: self.radius,
                radius: own.radius,
            });
        }
        if self.check_radius != 0 && (self.check_radius <= self.radius || self.check_radius > MAX_RADIUS) {
            return Err(ParamsError::WideCheckRadius {
                check: self.check_radius,
                wide: self.radius,
            });
        }
        if !(self.min_speed_px_s.is_finite() && self.min_speed_px_s >= 0.0) {
            return Err(ParamsError::Range {
                name: "wide_min_speed_px_s",
                rule: ">= 0",
                value: self.min_speed_px_s,
            });
        }
        Ok(())
    }
}

/// Invalid settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ParamsError {
    /// Radius 0 or above [`MAX_RADIUS`].
    #[error("radius must be 1..={MAX_RADIUS} pixels, got {0}")]
    Radius(usize),
    /// A check window that is not larger than the fit's window, or above [`MAX_RADIUS`].
    #[error(
        "check_radius must be 0 (no check) or in {radius}+1..={MAX_RADIUS} pixels (radius is {radius}), got {check}"
    )]
    CheckRadius {
        /// The value given.
        check: usize,
        /// The fit's radius.
        radius: usize,
    },
    /// A wide window that is not larger than the fit's window, or above [`MAX_RADIUS`].
    #[error("wide_radius must be in {radius}+1..={MAX_RADIUS} pixels (radius is {radius}), got {wide}")]
    WideRadius {
        /// The value given.
        wide: usize,
        /// The fit's radius.
        radius: usize,
    },
    /// A wide check window that is not larger than the wide window, or above [`MAX_RADIUS`].
    #[error(
        "wide_check_radius must be 0 (no check) or in {wide}+1..={MAX_RADIUS} pixels (wide_radius is {wide}), got {check}"
    )]
    WideCheckRadius {
        /// The value given.
        check: usize,
        /// The wide window's radius.
        wide: usize,
    },
    /// `min_points` below 3 (a plane needs 3 points) or above the window size.
    #[error("min_points must be between 3 and {window} (the window's pixels), got {got}")]
    MinPoints {
        /// The value given.
        got: usize,
        /// Pixels in the window.
        window: usize,
    },
    /// A time, angle or speed that must be finite and positive (or >= 0) is not.
    #[error("{name} must be a finite number {rule}, got {value}")]
    Range {
        /// The node's parameter (`evseg-normal-flow --describe`), with its unit in the name.
        name: &'static str,
        /// The rule broken.
        rule: &'static str,
        /// The value given, in the parameter's unit (ms, degrees, px/s).
        value: f64,
    },
}

impl PlaneFitParams {
    /// Checks every field; the error names the first bad one.
    pub fn validate(&self) -> Result<(), ParamsError> {
        if self.radius == 0 || self.radius > MAX_RADIUS {
            return Err(ParamsError::Radius(self.radius));
        }
        if self.check_radius != 0 && (self.check_radius <= self.radius || self.check_radius > MAX_RADIUS) {
            return Err(ParamsError::CheckRadius {
                check: self.check_radius,
                radius: self.radius,
            });
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
                name: "max_direction_sd_deg",
                rule: "> 0 (null = no test)",
                value: self.max_direction_sd_rad.to_degrees(),
            });
        }
        // (the node's parameter, its value in the parameter's unit, the rule holds, the rule):
        // the error speaks of what the user set (`dt_min_ms=-1`, not `dt_min -0.001`).
        let ms = 1e3;
        let checks: [(&'static str, f64, bool, &'static str); 9] = [
            (
                "check_skip_confidence",
                self.check_skip_confidence,
                self.check_skip_confidence >= 0.0,
                ">= 0 (above 1: every fit is checked)",
            ),
            (
                "check_skip_direction_sd_deg",
                self.check_skip_direction_sd_rad.to_degrees(),
                self.check_skip_direction_sd_rad >= 0.0,
                ">= 0",
            ),
            (
                "check_max_angle_deg",
                self.check_max_angle_rad.to_degrees(),
                self.check_max_angle_rad > 0.0,
                "> 0",
            ),
            (
                "check_max_speed_diff",
                self.check_max_speed_diff,
                self.check_max_speed_diff > 0.0,
                "> 0",
            ),
            (
                "lookahead_ms",
                self.lookahead_s * ms,
                self.lookahead_s >= 0.0,
                ">= 0",
            ),
            ("dt_min_ms", self.dt_min_s * ms, self.dt_min_s >= 0.0, ">= 0"),
            (
                "dt_max_ms",
                self.dt_max_s * ms,
                self.dt_max_s > self.dt_min_s,
                "> dt_min_ms",
            ),
            ("outlier_ms", self.outlier_s * ms, self.outlier_s > 0.0, "> 0"),
            (
                "max_speed_px_s",
                self.max_speed_px_s,
                self.max_speed_px_s > 0.0,
                "> 0",
            ),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// An out-of-range setting is reported as the node's parameter, in its unit: what the user
    /// set in graph.yaml (`dt_min_ms=-1`), not the library's field (`dt_min -0.001`).
    #[test]
    fn range_errors_name_the_node_parameter_in_its_unit() {
        let d = PlaneFitParams::default();
        let cases = [
            (
                PlaneFitParams { dt_min_s: -1e-3, ..d },
                "dt_min_ms must be a finite number >= 0, got -1",
            ),
            (
                PlaneFitParams {
                    dt_max_s: d.dt_min_s,
                    ..d
                },
                "dt_max_ms must be a finite number > dt_min_ms",
            ),
            (
                PlaneFitParams {
                    max_direction_sd_rad: -std::f64::consts::PI,
                    ..d
                },
                "max_direction_sd_deg must be a finite number > 0 (null = no test), got -180",
            ),
            (
                PlaneFitParams {
                    check_max_angle_rad: 0.0,
                    ..d
                },
                "check_max_angle_deg must be a finite number > 0, got 0",
            ),
        ];
        for (p, expected) in cases {
            let e = p.validate().map_err(|e| e.to_string()).err().unwrap_or_default();
            assert!(e.starts_with(expected), "`{e}` vs `{expected}`");
        }
        let wide = WideFitParams {
            min_speed_px_s: -1.0,
            ..WideFitParams::default()
        };
        let e = wide
            .validate(&d)
            .map_err(|e| e.to_string())
            .err()
            .unwrap_or_default();
        assert!(e.starts_with("wide_min_speed_px_s must be"), "{e}");
    }
}
