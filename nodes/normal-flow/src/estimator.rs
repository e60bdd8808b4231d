//! The causal plane-fit estimator: a surface of active events per polarity, kept across slices,
//! and one plane fit per event.

use evseg_geometry::Camera;
use evseg_geometry::cache::{PREFETCH_AHEAD, prefetch};
use evseg_schemas::{CameraInfo, Events, NormalFlow};

use crate::fit::{AgeLimits, Neighbourhood, PlaneFit, PlaneRefit, RowRun, fit_plane};
use crate::params::{ParamsError, PlaneFitParams, WideFitParams};

/// Refits after outlier rejection of the scale check's larger window (at most; the fit's own
/// `max_refits` if smaller): one re-selection of the inliers removes what a first fit over all
/// points shows to be far off, which is what the comparison needs.
const CHECK_REFITS: usize = 1;

/// Errors of the estimator.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EstimatorError {
    /// Bad settings.
    #[error(transparent)]
    Params(#[from] ParamsError),
    /// The camera has no pixels.
    #[error("camera has an empty sensor ({width} x {height} pixels)")]
    EmptySensor {
        /// Width, pixels.
        width: u16,
        /// Height, pixels.
        height: u16,
    },
    /// The four event columns have different lengths.
    #[error("event columns have different lengths (t {t}, x {x}, y {y}, p {p})")]
    Columns {
        /// Length of `t`.
        t: usize,
        /// Length of `x`.
        x: usize,
        /// Length of `y`.
        y: usize,
        /// Length of `p`.
        p: usize,
    },
}

/// Counters over every event seen so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EstimatorStats {
    /// Events offered.
    pub events: u64,
    /// Events with a valid estimate (confidence > 0).
    pub valid: u64,
    /// Events outside the sensor, ignored (no surface update, confidence 0).
    pub out_of_sensor: u64,
    /// Events with a non-finite timestamp, ignored.
    pub bad_time: u64,
    /// Events older than an event processed before them (input not time-ordered); still
    /// processed, but the surface never moves back in time.
    pub out_of_order: u64,
    /// Fits left invalid because the plane of the larger check window disagreed
    /// ([`PlaneFitParams::check_radius`]).
    pub disagreed: u64,
    /// Wide fits made ([`PlaneFitEstimator::with_wide_fit`]): valid estimates faster than
    /// [`WideFitParams::min_speed_px_s`].
    pub wide_fits: u64,
    /// Wide fits that gave a valid (and agreed) estimate, which the wide flow then carries.
    pub wide_valid: u64,
}

/// One event's estimate in pixel units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PixelEstimate {
    /// Normal flow, pixels per second (0 when invalid).
    pub flow_px: [f64; 2],
    /// Confidence in [0, 1] (0 = invalid).
    pub confidence: f64,
}

impl PixelEstimate {
    /// No estimate.
    pub const INVALID: Self = Self {
        flow_px: [0.0, 0.0],
        confidence: 0.0,
    };
}

/// Local plane-fit normal flow (Benosman et al. 2014), causal and stateful: events are processed
/// in the order given, each one first written to the surface of active events of its polarity
/// (latest timestamp per pixel) and then fitted with its same-polarity neighbours. The surfaces
/// persist between calls, so consecutive slices continue each other.
#[derive(Debug, Clone)]
pub struct PlaneFitEstimator {
    params: PlaneFitParams,
    camera: CameraInfo,
    width: usize,
    height: usize,
    /// Latest timestamp per pixel, seconds, row-major; index 0 = OFF, 1 = ON.
    /// `NEG_INFINITY` where no event has been seen.
    surface: [Vec<f64>; 2],
    /// Pixel flow to normalized flow per pixel, see [`jacobian_table`].
    jacobian: Vec<[f32; 4]>,
    /// The small window's fit's buffers.
    own: FitBuffers,
    last_t: f64,
    stats: EstimatorStats,
    last_fit: Option<PlaneFit>,
    /// The wide fit's settings, when on.
    wide: Option<WideFitParams>,
    /// The wide fit's buffers.
    wide_buffers: FitBuffers,
    /// The wide estimate of the last event fitted ([`PixelEstimate::INVALID`] when none).
    last_wide: PixelEstimate,
    /// Per event of the slice in progress: written to its surface (reused buffer).
    written: Vec<bool>,
}

impl PlaneFitEstimator {
    /// An estimator for `camera` with empty surfaces.
    pub fn new(camera: &CameraInfo, params: PlaneFitParams) -> Result<Self, EstimatorError> {
        params.validate()?;
        let (width, height) = (camera.width as usize, camera.height as usize);
        if width == 0 || height == 0 {
            return Err(EstimatorError::EmptySensor {
                width: camera.width,
                height: camera.height,
            });
        }
        let jacobian = jacobian_table(camera);
        Ok(Self {
            params,
            camera: camera.clone(),
            width,
            height,
            surface: [
                vec![f64::NEG_INFINITY; width * height],
                vec![f64::NEG_INFINITY; width * height],
            ],
            jacobian,
            own: FitBuffers::default(),
            last_t: f64::NEG_INFINITY,
            stats: EstimatorStats::default(),
            last_fit: None,
            wide: None,
            wide_buffers: FitBuffers::default(),
            last_wide: PixelEstimate::INVALID,
            written: Vec::new(),
        })
    }

    /// Turns the wide fit on: every valid estimate faster than
    /// [`WideFitParams::min_speed_px_s`] is fitted again on the wide window, and
    /// [`process_wide_into`](Self::process_wide_into) gives that estimate as the event's wide
    /// flow. The small window's flow is unchanged.
    pub fn with_wide_fit(mut self, wide: WideFitParams) -> Result<Self, EstimatorError> {
        wide.validate(&self.params)?;
        self.wide = Some(wide);
        Ok(self)
    }

    /// The wide fit's settings, when on.
    pub fn wide_fit(&self) -> Option<&WideFitParams> {
        self.wide.as_ref()
    }

    /// The settings in use.
    pub fn params(&self) -> &PlaneFitParams {
        &self.params
    }

    /// The camera the estimator was built for.
    pub fn camera(&self) -> &CameraInfo {
        &self.camera
    }

    /// Counters so far.
    pub fn stats(&self) -> EstimatorStats {
        self.stats
    }

    /// The plane fitted to the last event given to [`push_event`](Self::push_event) (also when
    /// the estimate was then judged invalid); `None` when no plane could be fitted. For
    /// diagnostics (`examples/length_error.rs`).
    pub fn last_fit(&self) -> Option<PlaneFit> {
        self.last_fit
    }

    /// Forgets every event seen (empty surfaces, counters kept).
    pub fn reset(&mut self) {
        for s in &mut self.surface {
            s.fill(f64::NEG_INFINITY);
        }
        self.last_t = f64::NEG_INFINITY;
    }

    /// Processes `events` in order and returns their normal flow in normalized units per second,
    /// aligned with them (confidence 0 and flow 0 where there is no valid estimate).
    pub fn process(&mut self, events: &Events) -> Result<NormalFlow, EstimatorError> {
        let mut out = NormalFlow::default();
        self.process_into(events, &mut out)?;
        Ok(out)
    }

    /// As [`process`](Self::process), writing into `out` (cleared first; reuses its buffers).
    pub fn process_into(&mut self, events: &Events, out: &mut NormalFlow) -> Result<(), EstimatorError> {
        self.process_with_next_into(events, None, out)
    }

    /// As [`process_into`](Self::process_into), with the look-ahead reaching into `next` (the
    /// following slice's events, or any prefix of them): its events up to
    /// [`PlaneFitParams::lookahead_s`] after the last event of `events` are written to the
    /// surfaces before the last fits, so that the events at the end of the slice see as much of
    /// the future as those in its middle. They are neither fitted nor counted here; give them
    /// again with their own slice, whose fits then read the same surfaces. Without it the last
    /// `lookahead_s` of each slice is fitted on a shorter look-ahead, and those lengths come out
    /// too long (normal-flow README, "Look-ahead across slices").
    pub fn process_with_next_into(
        &mut self,
        events: &Events,
        next: Option<&Events>,
        out: &mut NormalFlow,
    ) -> Result<(), EstimatorError> {
        self.process_wide_into(events, next, out, None)
    }

    /// As [`process_with_next_into`](Self::process_with_next_into), also writing the wide flow
    /// into `wide` when given (cleared first, aligned with `events`): each event's wide estimate
    /// where the wide fit ([`with_wide_fit`](Self::with_wide_fit)) gave one, else its own
    /// estimate (the same as in `out`; everywhere when the wide fit is off).
    pub fn process_wide_into(
        &mut self,
        events: &Events,
        next: Option<&Events>,
        out: &mut NormalFlow,
        mut wide: Option<&mut NormalFlow>,
    ) -> Result<(), EstimatorError> {
        check_columns(events)?;
        if let Some(next) = next {
            check_columns(next)?;
        }
        let n = events.len();
        out.reset_invalid(n);
        if let Some(w) = wide.as_deref_mut() {
            w.reset_invalid(n);
        }
        let width = self.width;
        let jacobian = std::mem::take(&mut self.jacobian);
        // Writes estimate `est` of event `i` to `f`, in normalized units.
        let write = |f: &mut NormalFlow, i: usize, est: &PixelEstimate| {
            let idx = events.y[i] as usize * width + events.x[i] as usize;
            let [j00, j01, j10, j11] = jacobian[idx];
            let [fu, fv] = [est.flow_px[0] as f32, est.flow_px[1] as f32];
            f.nx[i] = j00 * fu + j01 * fv;
            f.ny[i] = j10 * fu + j11 * fv;
            f.confidence[i] = est.confidence as f32;
        };
        self.run(events, next, |i, est, wide_est, _| {
            let ahead = i + PREFETCH_AHEAD;
            if let (Some(&x), Some(&y)) = (events.x.get(ahead), events.y.get(ahead))
                && let Some(j) = jacobian.get(y as usize * width + x as usize)
            {
                prefetch(j);
            }
            if est.confidence > 0.0 {
                write(out, i, &est);
                if let Some(w) = wide.as_deref_mut() {
                    let chosen = if wide_est.confidence > 0.0 {
                        &wide_est
                    } else {
                        &est
                    };
                    write(w, i, chosen);
                }
            }
        });
        self.jacobian = jacobian;
        Ok(())
    }

    /// Processes `events` in order and returns their normal flow in pixels per second.
    pub fn process_pixels(&mut self, events: &Events) -> Result<Vec<PixelEstimate>, EstimatorError> {
        check_columns(events)?;
        let mut out = vec![PixelEstimate::INVALID; events.len()];
        self.run(events, None, |i, est, _, _| out[i] = est);
        Ok(out)
    }

    /// As [`process_pixels`](Self::process_pixels), with each event's fitted plane (also when
    /// the estimate was judged invalid; `None` when no plane could be fitted). For diagnostics
    /// (`examples/length_error.rs`).
    pub fn process_with_fits(
        &mut self,
        events: &Events,
    ) -> Result<Vec<(PixelEstimate, Option<PlaneFit>)>, EstimatorError> {
        check_columns(events)?;
        let mut out = vec![(PixelEstimate::INVALID, None); events.len()];
        self.run(events, None, |i, est, _, fit| out[i] = (est, fit));
        Ok(out)
    }

    /// Writes every event of the slice to the surfaces and fits it, handing `(index, estimate,
    /// wide estimate, plane)` to `sink` (the wide estimate [`PixelEstimate::INVALID`] when there
    /// is none). Causal (each event fitted right after it is written) when `lookahead_s` is 0;
    /// otherwise an event is fitted once the first event later than `t + lookahead_s` arrives
    /// (or at the end of the slice), with the neighbours written up to then. The events of
    /// `next` within `lookahead_s` of the slice's last event are written (not fitted) after the
    /// slice's own, so that its last events get the whole look-ahead too.
    fn run(
        &mut self,
        events: &Events,
        next_slice: Option<&Events>,
        mut sink: impl FnMut(usize, PixelEstimate, PixelEstimate, Option<PlaneFit>),
    ) {
        let n = events.len();
        let la = self.params.lookahead_s;
        if la <= 0.0 {
            for i in 0..n {
                let est = self.push_event(events.t[i], events.x[i], events.y[i], events.p[i]);
                sink(i, est, self.last_wide, self.last_fit);
            }
            return;
        }
        let mut written = std::mem::take(&mut self.written);
        written.clear();
        written.resize(n, false);
        let mut next = 0;
        for j in 0..n {
            self.fit_pending(events, &written, &mut next, j, events.t[j], &mut sink);
            self.prefetch_pixel(events, j + PREFETCH_AHEAD);
            written[j] = self.write_event(events.t[j], events.x[j], events.y[j], events.p[j]);
        }
        if let (Some(ahead), Some(&t_last)) = (next_slice, events.t.last()) {
            for j in 0..ahead.len() {
                let t = ahead.t[j];
                if !t.is_finite() {
                    // Not a time: skipped (the event is counted with its own slice).
                    continue;
                }
                if t > t_last + la {
                    // Past the look-ahead of the slice's last event.
                    break;
                }
                self.fit_pending(events, &written, &mut next, n, t, &mut sink);
                self.write_ahead(t, ahead.x[j], ahead.y[j], ahead.p[j]);
            }
        }
        // Every written event has a finite time, so nothing stays pending at an infinite one.
        self.fit_pending(events, &written, &mut next, n, f64::INFINITY, &mut sink);
        self.written = written;
    }

    /// Fits, in order from `*next` up to (not including) `end`, the events of the slice whose
    /// look-ahead has passed: an event whose time plus `lookahead_s` is before `until`
    /// (seconds, the time of the event about to be written), or one that was not written
    /// (`written`), which needs no neighbours. Leaves `*next` at the first event not fitted.
    fn fit_pending(
        &mut self,
        events: &Events,
        written: &[bool],
        next: &mut usize,
        end: usize,
        until: f64,
        sink: &mut impl FnMut(usize, PixelEstimate, PixelEstimate, Option<PlaneFit>),
    ) {
        let la = self.params.lookahead_s;
        while *next < end && (!written[*next] || events.t[*next] + la < until) {
            self.prefetch_window(events, *next + PREFETCH_AHEAD);
            let est = self.fit_written(written[*next], events, *next, la);
            sink(*next, est, self.last_wide, self.last_fit);
            *next += 1;
        }
    }

    /// Asks the cache for the surface pixel of event `i` (if any), which its write will read.
    #[inline]
    fn prefetch_pixel(&self, events: &Events, i: usize) {
        if let (Some(&x), Some(&y), Some(&p)) = (events.x.get(i), events.y.get(i), events.p.get(i)) {
            let surface = &self.surface[usize::from(p != 0)];
            if let Some(v) = surface.get(y as usize * self.width + x as usize) {
                prefetch(v);
            }
        }
    }

    /// Asks the cache for the rows of event `i`'s fit window (the check window's when there is
    /// one), so that the gather of a later event does not wait for memory: the surfaces (two
    /// 640 x 480 `f64` planes, 4.9 MB) do not fit in the core's cache, and the look-ahead fit
    /// reads them about 30 ms of events after they were written.
    #[inline]
    fn prefetch_window(&self, events: &Events, i: usize) {
        let (Some(&x), Some(&y), Some(&p)) = (events.x.get(i), events.y.get(i), events.p.get(i)) else {
            return;
        };
        let (xu, yu) = (x as usize, y as usize);
        if xu >= self.width || yu >= self.height {
            return;
        }
        let wide = self.wide.map_or(0, |w| w.radius.max(w.check_radius));
        let r = self.params.radius.max(self.params.check_radius).max(wide);
        let (x0, x1) = (xu.saturating_sub(r), (xu + r).min(self.width - 1));
        let surface = &self.surface[usize::from(p != 0)];
        for yy in yu.saturating_sub(r)..=(yu + r).min(self.height - 1) {
            let row = yy * self.width;
            prefetch(&surface[row + x0]);
            prefetch(&surface[row + x1]);
        }
    }

    fn fit_written(&mut self, written: bool, events: &Events, i: usize, lookahead: f64) -> PixelEstimate {
        self.last_fit = None;
        self.last_wide = PixelEstimate::INVALID;
        if !written {
            return PixelEstimate::INVALID;
        }
        self.fit_event(events.t[i], events.x[i], events.y[i], events.p[i], lookahead)
    }

    /// Adds one event (`t` seconds, pixel `(x, y)`, polarity `p`, non-zero = ON) to its surface
    /// and fits its plane (causally: `lookahead_s` applies to [`process`](Self::process) only).
    pub fn push_event(&mut self, t: f64, x: u16, y: u16, p: u8) -> PixelEstimate {
        self.last_fit = None;
        self.last_wide = PixelEstimate::INVALID;
        if !self.write_event(t, x, y, p) {
            return PixelEstimate::INVALID;
        }
        self.fit_event(t, x, y, p, 0.0)
    }

    /// Writes an event of the next slice to its surface for the look-ahead of this slice's last
    /// fits: no counters and no clock (the event is counted when its own slice comes); events
    /// outside the sensor or without a finite time are skipped.
    fn write_ahead(&mut self, t: f64, x: u16, y: u16, p: u8) {
        let (xu, yu) = (x as usize, y as usize);
        if xu < self.width && yu < self.height && t.is_finite() {
            let own = &mut self.surface[usize::from(p != 0)][yu * self.width + xu];
            *own = own.max(t);
        }
    }

    /// Counts the event and writes it to its surface; false when it is ignored.
    fn write_event(&mut self, t: f64, x: u16, y: u16, p: u8) -> bool {
        self.stats.events += 1;
        let (xu, yu) = (x as usize, y as usize);
        if xu >= self.width || yu >= self.height {
            self.stats.out_of_sensor += 1;
            return false;
        }
        if !t.is_finite() {
            self.stats.bad_time += 1;
            return false;
        }
        if t < self.last_t {
            self.stats.out_of_order += 1;
        } else {
            self.last_t = t;
        }
        let pol = usize::from(p != 0);
        let own = &mut self.surface[pol][yu * self.width + xu];
        *own = own.max(t);
        true
    }

    /// Fits the plane of a written event to the neighbours on its surface whose age is within
    /// `[-lookahead, dt_max]` (and at least `dt_min` in magnitude); with a check window
    /// ([`PlaneFitParams::check_radius`]) a valid estimate is kept only when that window's plane
    /// agrees with it. With the wide fit on ([`with_wide_fit`](Self::with_wide_fit)) a fast
    /// valid estimate also gets the wide window's, left in `last_wide`.
    fn fit_event(&mut self, t: f64, x: u16, y: u16, p: u8, lookahead: f64) -> PixelEstimate {
        let site = Site {
            surface: &self.surface[usize::from(p != 0)],
            width: self.width,
            height: self.height,
            params: &self.params,
            at: Centre {
                t,
                x: x as usize,
                y: y as usize,
                lookahead,
            },
        };
        let own = fit_own(&site, &mut self.own);
        self.last_fit = own.plane;
        self.last_wide = PixelEstimate::INVALID;
        if own.disagreed {
            self.stats.disagreed += 1;
        }
        let Some(estimate) = own.estimate else {
            return PixelEstimate::INVALID;
        };
        self.stats.valid += 1;
        if let Some(wide) = &self.wide
            // Squared, not `hypot`: libm's costs 1 % of the node's time.
            && estimate.flow_px[0] * estimate.flow_px[0] + estimate.flow_px[1] * estimate.flow_px[1]
                > wide.min_speed_px_s * wide.min_speed_px_s
        {
            self.stats.wide_fits += 1;
            if let Some(w) = fit_wide(&site, wide, &own, &mut self.own, &mut self.wide_buffers) {
                self.stats.wide_valid += 1;
                self.last_wide = w;
            }
        }
        estimate
    }
}

/// One event's fitting context: the surface of its polarity (latest timestamp per pixel,
/// seconds, row-major, `width` x `height` pixels), the settings and the event.
struct Site<'a> {
    surface: &'a [f64],
    width: usize,
    height: usize,
    params: &'a PlaneFitParams,
    at: Centre,
}

impl Site<'_> {
    /// The square window of half-width `radius` pixels around the event, clipped to the sensor.
    #[inline]
    fn window(&self, radius: usize) -> Window {
        Window {
            x0: self.at.x.saturating_sub(radius),
            x1: (self.at.x + radius).min(self.width - 1),
            y0: self.at.y.saturating_sub(radius),
            y1: (self.at.y + radius).min(self.height - 1),
        }
    }
}

/// One window's fit buffers, so that no event allocates: the window's points, and its scale
/// check's points and fit in progress (the small window's check fit is what the wide fit
/// continues when its window is the check's; the wide window's points stay unused then).
#[derive(Debug, Clone, Default)]
struct FitBuffers {
    points: Neighbourhood,
    check: Neighbourhood,
    check_fit: PlaneRefit,
}

/// The small window's fit of the event at `site` ([`PlaneFitParams::radius`]), judged and
/// checked on the larger window ([`PlaneFitParams::check_radius`]).
fn fit_own(site: &Site<'_>, bufs: &mut FitBuffers) -> Checked {
    let params = site.params;
    let (r, rc) = (params.radius, params.check_radius);
    bufs.points.clear();
    gather(&mut bufs.points, site, site.window(r), None);
    let plane = fit_plane(
        &bufs.points,
        params.outlier_s,
        params.max_refits,
        params.min_points,
    );
    let ring = Ring {
        points: &mut bufs.check,
        fit: &mut bufs.check_fit,
        window: (rc > r).then(|| site.window(rc)),
    };
    check_fit(plane, &bufs.points, ring, site, site.window(r), params.max_refits)
}

/// The wide fit ([`PlaneFitEstimator::with_wide_fit`]) of the event at `site`, whose small
/// window's fit `own` (with buffers `own_bufs`) gave a fast valid estimate: its estimate when
/// valid (and, with a wide check, agreed).
fn fit_wide(
    site: &Site<'_>,
    wide: &WideFitParams,
    own: &Checked,
    own_bufs: &mut FitBuffers,
    bufs: &mut FitBuffers,
) -> Option<PixelEstimate> {
    let params = site.params;
    let (outlier, min_points) = (params.outlier_s, params.min_points);
    // The wide window's points: those of the check just done when it is the same window, else
    // the small window's and the ring around them. Its plane: the check's fit continued when it
    // can be (the same points, fewer refits so far), which is the plane a fresh fit with the
    // wide fit's refits would give.
    let same_window = own.ring_filled && wide.radius == params.check_radius;
    let (points, plane) = match own.ring_refits {
        Some(done) if same_window && done <= wide.max_refits => {
            let check = &own_bufs.check;
            let ok = own_bufs
                .check_fit
                .refit(check, outlier, wide.max_refits - done, min_points);
            (check, ok.then(|| own_bufs.check_fit.plane(check)))
        }
        _ if same_window => {
            let check = &own_bufs.check;
            (check, fit_plane(check, outlier, wide.max_refits, min_points))
        }
        _ => {
            bufs.points.copy_from(&own_bufs.points);
            let inner = site.window(params.radius);
            gather(&mut bufs.points, site, site.window(wide.radius), Some(inner));
            let plane = fit_plane(&bufs.points, outlier, wide.max_refits, min_points);
            (&bufs.points, plane)
        }
    };
    let ring = Ring {
        points: &mut bufs.check,
        fit: &mut bufs.check_fit,
        window: (wide.check_radius > wide.radius).then(|| site.window(wide.check_radius)),
    };
    check_fit(
        plane,
        points,
        ring,
        site,
        site.window(wide.radius),
        wide.max_refits,
    )
    .estimate
}

/// The scale check's larger window ([`check_fit`]): its `window` (`None` = no check), and the
/// buffers its points and its fit in progress go to.
struct Ring<'a> {
    points: &'a mut Neighbourhood,
    fit: &'a mut PlaneRefit,
    window: Option<Window>,
}

/// One window's fit judged and checked ([`check_fit`]).
struct Checked {
    /// The plane fitted to the window's points (also when judged invalid).
    plane: Option<PlaneFit>,
    /// The estimate, when valid and (with a check) agreed.
    estimate: Option<PixelEstimate>,
    /// The check window's plane disagreed with a valid estimate.
    disagreed: bool,
    /// The check ran: the ring's `points` hold the check window's points.
    ring_filled: bool,
    /// Refits the check window's fit made, when it ran and gave a plane: the ring's `fit`
    /// holds it in progress, for a fit of the same points with more refits to continue.
    ring_refits: Option<usize>,
}

/// Judges `plane`, the fit of `points` (the window `inner`'s neighbours of the event at `site`,
/// with at most `refits` refits), ([`judge`]); with a larger check window (`ring`), a valid
/// estimate that is not clearly planar ([`PlaneFitParams::check_skip_confidence`]) stands only
/// when the plane of the check window (`points` and the ring around them) agrees with it
/// ([`agrees`]).
fn check_fit(
    plane: Option<PlaneFit>,
    points: &Neighbourhood,
    ring: Ring<'_>,
    site: &Site<'_>,
    inner: Window,
    refits: usize,
) -> Checked {
    let params = site.params;
    let (outlier, min_points) = (params.outlier_s, params.min_points);
    let mut out = Checked {
        plane,
        estimate: plane.and_then(|fit| judge(params, &fit)),
        disagreed: false,
        ring_filled: false,
        ring_refits: None,
    };
    let clearly_planar = |e: &PixelEstimate| {
        e.confidence >= params.check_skip_confidence
            && plane.is_some_and(|f| f.direction_sd_rad <= params.check_skip_direction_sd_rad)
    };
    if let (Some(e), Some(check)) = (out.estimate, ring.window)
        && !clearly_planar(&e)
    {
        ring.points.copy_from(points);
        gather(ring.points, site, check, Some(inner));
        out.ring_filled = true;
        let check_refits = CHECK_REFITS.min(refits);
        let fitted = ring.fit.start(ring.points, min_points)
            && ring.fit.refit(ring.points, outlier, check_refits, min_points);
        let check_plane = fitted.then(|| ring.fit.plane(ring.points));
        out.ring_refits = fitted.then_some(check_refits);
        let agreed = check_plane
            .and_then(|f| f.normal_flow_px())
            .is_some_and(|c| agrees(params, e.flow_px, c));
        if !agreed {
            out.disagreed = true;
            out.estimate = None;
        }
    }
    out
}

/// True when normal flows `a` and `b` (pixels/s) point within
/// [`PlaneFitParams::check_max_angle_rad`] of each other and their lengths differ by at most
/// [`PlaneFitParams::check_max_speed_diff`] of `b`'s.
fn agrees(params: &PlaneFitParams, a: [f64; 2], b: [f64; 2]) -> bool {
    let (sa, sb) = (
        (a[0] * a[0] + a[1] * a[1]).sqrt(),
        (b[0] * b[0] + b[1] * b[1]).sqrt(),
    );
    if !(sa > 0.0 && sb > 0.0) {
        return false;
    }
    let cos = (a[0] * b[0] + a[1] * b[1]) / (sa * sb);
    cos >= params.check_max_angle_rad.cos() && (sa / sb - 1.0).abs() <= params.check_max_speed_diff
}

/// Turns a fit into an estimate, or `None` when it is too fast, flat, or its confidence is at
/// or below `min_confidence` (and never 0). Confidence is the inlier share times
/// `1 - rms / outlier_s` (1 for a perfect plane through every point).
fn judge(params: &PlaneFitParams, fit: &PlaneFit) -> Option<PixelEstimate> {
    let flow = fit.normal_flow_px()?;
    let speed = fit.speed_px_s();
    if speed.is_nan() || speed > params.max_speed_px_s {
        return None;
    }
    if fit.direction_sd_rad.is_nan() || fit.direction_sd_rad >= params.max_direction_sd_rad {
        return None;
    }
    let inlier_share = fit.inliers as f64 / fit.points as f64;
    let quality = (1.0 - fit.rms_s / params.outlier_s).clamp(0.0, 1.0);
    let confidence = inlier_share * quality;
    if confidence.is_nan() || confidence <= params.min_confidence.max(0.0) {
        return None;
    }
    Some(PixelEstimate {
        flow_px: flow,
        confidence,
    })
}

/// An inclusive pixel window `[x0, x1] x [y0, y1]`.
#[derive(Debug, Clone, Copy)]
struct Window {
    x0: usize,
    x1: usize,
    y0: usize,
    y1: usize,
}

/// The event a neighbourhood is gathered for: time (s), pixel, and how far ahead neighbours may
/// lie (s).
struct Centre {
    t: f64,
    x: usize,
    y: usize,
    lookahead: f64,
}

/// Adds to `nb` the pixels of `window` on the site's surface whose age relative to the site's
/// event is within `[-lookahead, dt_max]` and at least `dt_min` in magnitude (the event's own
/// pixel always, at time 0), leaving out the pixels of `skip` (already added), in row-major
/// order.
fn gather(nb: &mut Neighbourhood, site: &Site<'_>, window: Window, skip: Option<Window>) {
    let (surface, width, params, at) = (site.surface, site.width, site.params, &site.at);
    let ages = AgeLimits {
        t: at.t,
        dt_min: params.dt_min_s,
        dt_max: params.dt_max_s,
        lookahead: at.lookahead,
    };
    // The run of `row` starting at column `x0`, `dy` rows from the centre.
    fn run(row: &[f64], x0: usize, cx: usize, own_x: usize, dy: i32) -> RowRun<'_> {
        RowRun {
            row,
            dx0: x0 as i32 - cx as i32,
            dy,
            own: own_x.wrapping_sub(x0),
        }
    }
    for yy in window.y0..=window.y1 {
        let row = yy * width;
        let dy = yy as i32 - at.y as i32;
        // The own pixel is in the centre row (`dy` 0) only.
        let own_x = if dy == 0 { at.x } else { usize::MAX };
        match skip {
            Some(s) if (s.y0..=s.y1).contains(&yy) => {
                let left = &surface[row + window.x0..row + s.x0];
                nb.push_run(&run(left, window.x0, at.x, own_x, dy), &ages);
                let right = &surface[row + s.x1 + 1..=row + window.x1];
                nb.push_run(&run(right, s.x1 + 1, at.x, own_x, dy), &ages);
            }
            _ => {
                let all = &surface[row + window.x0..=row + window.x1];
                nb.push_run(&run(all, window.x0, at.x, own_x, dy), &ages);
            }
        }
    }
}

/// The Jacobian d(normalized)/d(pixel) of every pixel, row-major, each `[j00, j01, j10, j11]`
/// (normalized flow = `[j00 fu + j01 fv, j10 fu + j11 fv]` for pixel flow `(fu, fv)`), from
/// [`Camera::pixel_flow_to_normalized`] (undistortion included).
pub fn jacobian_table(camera: &CameraInfo) -> Vec<[f32; 4]> {
    let cam = Camera::new(camera);
    let (width, height) = (camera.width as usize, camera.height as usize);
    let mut jacobian = Vec::with_capacity(width * height);
    for v in 0..height {
        for u in 0..width {
            let (u, v) = (u as f64, v as f64);
            let [j00, j10] = cam.pixel_flow_to_normalized(u, v, 1.0, 0.0);
            let [j01, j11] = cam.pixel_flow_to_normalized(u, v, 0.0, 1.0);
            jacobian.push([j00 as f32, j01 as f32, j10 as f32, j11 as f32]);
        }
    }
    jacobian
}

pub(crate) fn check_columns(events: &Events) -> Result<(), EstimatorError> {
    if events.is_consistent() {
        return Ok(());
    }
    Err(EstimatorError::Columns {
        t: events.t.len(),
        x: events.x.len(),
        y: events.y.len(),
        p: events.p.len(),
    })
}
