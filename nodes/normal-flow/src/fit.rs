//! Least-squares plane `t = gx dx + gy dy + c` through points of a time surface, with iterative
//! rejection of points whose time residual is too large.
//!
//! Coordinates are pixel offsets from the event (`dx`, `dy`), times are seconds relative to the
//! event (`dt <= 0` for older neighbours). `(gx, gy)` is the gradient of the time surface, s/px;
//! a moving edge reaches pixels further along its motion later, so the gradient points along the
//! motion and the normal flow is `(gx, gy) / (gx^2 + gy^2)` px/s (METHOD_NOTES §2 writes the same
//! plane as `a x + b y + t + d = 0`, i.e. `(a, b) = -(gx, gy)` and `v = -(a, b) / (a^2 + b^2)`).

use crate::params::MAX_RADIUS;

/// Most points a neighbourhood can hold: the largest window, `(2 MAX_RADIUS + 1)^2`.
pub const MAX_POINTS: usize = (2 * MAX_RADIUS + 1) * (2 * MAX_RADIUS + 1);

// `fit_plane` keeps its inliers as the bits of a `u128`.
const _: () = assert!(MAX_POINTS <= 128);

/// Points of one fit, fixed size so that no event allocates.
///
/// Offsets are whole pixels, so the sums of the normal equations that involve only offsets
/// (`n`, `sx`, `sy`, `sxx`, `sxy`, `syy`) are kept here as integers while points are added: they
/// equal the `f64` sums of the same points exactly, in any order, and the plane fit then adds
/// only the time terms.
#[derive(Debug, Clone)]
pub struct Neighbourhood {
    /// One slot more than [`MAX_POINTS`]: a point is written before it is known to be kept.
    dx: [f64; MAX_POINTS + 1],
    dy: [f64; MAX_POINTS + 1],
    dt: [f64; MAX_POINTS + 1],
    len: usize,
    /// `[n, sx, sy, sxx, sxy, syy]` of the points, pixels (powers of).
    offset_sums: [i32; 6],
    /// `[st, sxt, syt]` of the points, added in their order as they are pushed (seconds times
    /// pixels): what the fit's first pass would add, so a neighbourhood that starts as a copy of
    /// another continues its sums exactly.
    time_sums: [f64; 3],
}

impl Default for Neighbourhood {
    fn default() -> Self {
        Self {
            dx: [0.0; MAX_POINTS + 1],
            dy: [0.0; MAX_POINTS + 1],
            dt: [0.0; MAX_POINTS + 1],
            len: 0,
            offset_sums: [0; 6],
            time_sums: [0.0; 3],
        }
    }
}

impl Neighbourhood {
    /// Removes every point.
    #[inline]
    pub fn clear(&mut self) {
        self.len = 0;
        self.offset_sums = [0; 6];
        self.time_sums = [0.0; 3];
    }

    /// Number of points.
    #[inline]
    pub fn len(&self) -> usize {
        self.len
    }

    /// True when there is no point.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Makes this neighbourhood a copy of `other` (its points only, not the unused capacity).
    #[inline]
    pub fn copy_from(&mut self, other: &Self) {
        let n = other.len;
        self.dx[..n].copy_from_slice(&other.dx[..n]);
        self.dy[..n].copy_from_slice(&other.dy[..n]);
        self.dt[..n].copy_from_slice(&other.dt[..n]);
        self.len = n;
        self.offset_sums = other.offset_sums;
        self.time_sums = other.time_sums;
    }

    /// Adds a point at pixel offset `(dx, dy)` with time `dt` seconds relative to the event;
    /// returns false (and ignores it) when the neighbourhood is full.
    #[inline]
    pub fn push(&mut self, dx: i32, dy: i32, dt: f64) -> bool {
        if self.len == MAX_POINTS {
            return false;
        }
        self.push_if(true, dx, dy, dt);
        true
    }

    /// Adds the point when `keep` is true and the neighbourhood is not full, without a branch on
    /// `keep` (the gather's test of a neighbour's age is not predictable).
    #[inline(always)]
    pub(crate) fn push_if(&mut self, keep: bool, dx: i32, dy: i32, dt: f64) {
        let len = self.len.min(MAX_POINTS);
        self.dx[len] = f64::from(dx);
        self.dy[len] = f64::from(dy);
        self.dt[len] = dt;
        let keep = keep && len < MAX_POINTS;
        self.len = len + usize::from(keep);
        let k = i32::from(keep);
        let s = &mut self.offset_sums;
        s[0] += k;
        s[1] += k * dx;
        s[2] += k * dy;
        s[3] += k * dx * dx;
        s[4] += k * dx * dy;
        s[5] += k * dy * dy;
        // The sums start at +0 and so never become -0: adding +0 for a point not kept leaves
        // them unchanged.
        let (x, y, t) = if keep {
            (f64::from(dx), f64::from(dy), dt)
        } else {
            (0.0, 0.0, 0.0)
        };
        let ts = &mut self.time_sums;
        ts[0] += t;
        ts[1] += x * t;
        ts[2] += y * t;
    }
}

/// The neighbours of one run of a row of a surface of active events, as
/// [`Neighbourhood::push_if`] would add them one by one (same order, same arithmetic, so the
/// same sums to the bit), with the sums kept in locals for the run instead of in the struct.
pub(crate) struct RowRun<'a> {
    /// Latest timestamps of the run's pixels, seconds.
    pub row: &'a [f64],
    /// Offset of the run's first pixel from the centre along x, pixels.
    pub dx0: i32,
    /// Offset of the row from the centre along y, pixels.
    pub dy: i32,
    /// Index in `row` of the centre's own pixel (always kept, at time 0), or `usize::MAX`.
    pub own: usize,
}

/// Which neighbours a fit takes: ages `t - t_neighbour` (seconds) within `[-lookahead, dt_max]`
/// and at least `dt_min` in magnitude.
pub(crate) struct AgeLimits {
    /// The centre event's time, seconds.
    pub t: f64,
    /// Smallest age magnitude, seconds.
    pub dt_min: f64,
    /// Largest age, seconds.
    pub dt_max: f64,
    /// Largest negative age (neighbours later than the event), seconds.
    pub lookahead: f64,
}

impl Neighbourhood {
    /// Adds the neighbours of `run` whose age is within `ages` (see [`RowRun`]).
    #[inline(always)]
    pub(crate) fn push_run(&mut self, run: &RowRun<'_>, ages: &AgeLimits) {
        let mut len = self.len;
        let [mut n, mut sx, mut sy, mut sxx, mut sxy, mut syy] = self.offset_sums;
        let [mut st, mut sxt, mut syt] = self.time_sums;
        let dy = run.dy;
        for (k, &ts) in run.row.iter().enumerate() {
            let dx = run.dx0 + k as i32;
            let age = ages.t - ts;
            let own_pixel = k == run.own;
            let keep =
                own_pixel || ((age.abs() >= ages.dt_min) & (age <= ages.dt_max) & (age >= -ages.lookahead));
            let dt = if own_pixel { 0.0 } else { -age };
            let at = len.min(MAX_POINTS);
            self.dx[at] = f64::from(dx);
            self.dy[at] = f64::from(dy);
            self.dt[at] = dt;
            let keep = keep && at < MAX_POINTS;
            len = at + usize::from(keep);
            let kk = i32::from(keep);
            n += kk;
            sx += kk * dx;
            sy += kk * dy;
            sxx += kk * dx * dx;
            sxy += kk * dx * dy;
            syy += kk * dy * dy;
            let (x, y, t) = if keep {
                (f64::from(dx), f64::from(dy), dt)
            } else {
                (0.0, 0.0, 0.0)
            };
            st += t;
            sxt += x * t;
            syt += y * t;
        }
        self.len = len;
        self.offset_sums = [n, sx, sy, sxx, sxy, syy];
        self.time_sums = [st, sxt, syt];
    }
}

/// A fitted plane `t = gx dx + gy dy + c` (seconds, pixel offsets).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneFit {
    /// Time-surface gradient along x, seconds per pixel.
    pub gx: f64,
    /// Time-surface gradient along y, seconds per pixel.
    pub gy: f64,
    /// Plane time at the event's pixel, seconds relative to the event.
    pub c: f64,
    /// Points kept after outlier rejection.
    pub inliers: usize,
    /// Points offered to the fit.
    pub points: usize,
    /// Root-mean-square time residual of the inliers, seconds.
    pub rms_s: f64,
    /// Standard deviation of the gradient's direction, radians: the least-squares covariance of
    /// `(gx, gy)` (residual variance `ss / (inliers - 3)`) across the gradient, divided by `|g|`.
    /// The normal flow's length measured along a direction off by `theta` differs from the true
    /// one by about `u_t sin(theta)` (`u_t` the flow along the edge), so this bounds the length
    /// error where the flow along the edge is large. Infinite with 3 inliers or a flat plane.
    pub direction_sd_rad: f64,
}

impl PlaneFit {
    /// The normal flow, pixels per second: `(gx, gy) / (gx^2 + gy^2)`; `None` for a flat plane.
    pub fn normal_flow_px(&self) -> Option<[f64; 2]> {
        let g2 = self.gx * self.gx + self.gy * self.gy;
        if !g2.is_finite() || g2 <= 0.0 {
            return None;
        }
        Some([self.gx / g2, self.gy / g2])
    }

    /// Speed across the edge, pixels per second (`1 / |g|`; infinite for a flat plane).
    pub fn speed_px_s(&self) -> f64 {
        1.0 / (self.gx * self.gx + self.gy * self.gy).sqrt()
    }
}

/// Sums of the normal equations of the plane fit.
#[derive(Debug, Default, Clone, Copy)]
struct Sums {
    n: f64,
    sx: f64,
    sy: f64,
    sxx: f64,
    sxy: f64,
    syy: f64,
    st: f64,
    sxt: f64,
    syt: f64,
}

impl Sums {
    #[inline]
    fn add(&mut self, x: f64, y: f64, t: f64, sign: f64) {
        self.n += sign;
        self.sx += sign * x;
        self.sy += sign * y;
        self.sxx += sign * x * x;
        self.sxy += sign * x * y;
        self.syy += sign * y * y;
        self.st += sign * t;
        self.sxt += sign * x * t;
        self.syt += sign * y * t;
    }

    /// The adjugate of the symmetric normal matrix `[sxx sxy sx; sxy syy sy; sx sy n]` as its
    /// cofactors `[c00, c01, c02, c11, c12, c22]`, and its determinant. The matrix has integer
    /// entries (pixel offsets), so a non-singular one has `|det| >= 1`; below 0.5 the points are
    /// collinear (or fewer than 3), there is no plane, and the answer is `None`.
    #[inline]
    fn adjugate(&self) -> Option<([f64; 6], f64)> {
        let (a, b, c) = (self.sxx, self.sxy, self.sx);
        let (d, e) = (self.syy, self.sy);
        let f = self.n;
        // Symmetric matrix [a b c; b d e; c e f].
        let c00 = d * f - e * e;
        let c01 = c * e - b * f;
        let c02 = b * e - c * d;
        let c11 = a * f - c * c;
        let c12 = b * c - a * e;
        let c22 = a * d - b * b;
        let det = a * c00 + b * c01 + c * c02;
        if det.abs() < 0.5 {
            return None;
        }
        Some(([c00, c01, c02, c11, c12, c22], det))
    }

    /// The upper-left 2 x 2 block of the inverse matrix (the covariance of `(gx, gy)` per unit
    /// residual variance) as `[cxx, cxy, cyy]`; `None` when singular.
    fn gradient_covariance(&self) -> Option<[f64; 3]> {
        let ([c00, c01, _, c11, _, _], det) = self.adjugate()?;
        Some([c00 / det, c01 / det, c11 / det])
    }

    /// Solves `[sxx sxy sx; sxy syy sy; sx sy n] [gx gy c] = [sxt syt st]` by the adjugate;
    /// `None` when singular.
    #[inline]
    fn solve(&self) -> Option<[f64; 3]> {
        let ([c00, c01, c02, c11, c12, c22], det) = self.adjugate()?;
        let (r0, r1, r2) = (self.sxt, self.syt, self.st);
        let inv = 1.0 / det;
        Some([
            (c00 * r0 + c01 * r1 + c02 * r2) * inv,
            (c01 * r0 + c11 * r1 + c12 * r2) * inv,
            (c02 * r0 + c12 * r1 + c22 * r2) * inv,
        ])
    }
}

/// Fits the plane to `nb`, then repeatedly keeps the points with `|residual| <= outlier_s` of the
/// current plane and refits them, until the kept set stops changing (at most `max_refits`
/// refits). The kept set is chosen afresh from all points each time, so a good point rejected
/// while a gross outlier still tilted the plane comes back once the outlier is gone. `None` when
/// fewer than `min_points` points are kept or they do not span a plane.
pub fn fit_plane(
    nb: &Neighbourhood,
    outlier_s: f64,
    max_refits: usize,
    min_points: usize,
) -> Option<PlaneFit> {
    let mut fit = PlaneRefit::default();
    if !(fit.start(nb, min_points) && fit.refit(nb, outlier_s, max_refits, min_points)) {
        return None;
    }
    Some(fit.plane(nb))
}

/// A [`fit_plane`] in progress, which can be continued: [`start`](Self::start), then
/// [`refit`](Self::refit) `a` times, [`plane`](Self::plane), `refit` `b` more times and `plane`
/// give the plane of `fit_plane` with `a` refits and then exactly the one with `a + b` (the
/// scale check's fit continued into the wide fit, which shares its points). Every call takes
/// the same [`Neighbourhood`], unchanged. Reusable: `start` begins afresh.
#[derive(Debug, Clone)]
pub struct PlaneRefit {
    sums: Sums,
    /// Bit `i` set: point `i` is kept (an inlier of the current plane).
    used: u128,
    kept: usize,
    /// The current solution `(gx, gy, c)`.
    sol: [f64; 3],
    /// Time residuals of the points against `sol` when `fresh`.
    res: [f64; MAX_POINTS],
    fresh: bool,
    /// The kept set stopped changing: more refits change nothing.
    stable: bool,
}

impl Default for PlaneRefit {
    fn default() -> Self {
        Self {
            sums: Sums::default(),
            used: 0,
            kept: 0,
            sol: [0.0; 3],
            res: [0.0; MAX_POINTS],
            fresh: false,
            stable: false,
        }
    }
}

impl PlaneRefit {
    /// Fits the plane to every point of `nb`; false when there are fewer than `min_points`
    /// (at least 3) or they do not span a plane.
    #[inline]
    pub fn start(&mut self, nb: &Neighbourhood, min_points: usize) -> bool {
        let n = nb.len;
        if n < min_points.max(3) {
            return false;
        }
        // The offset sums are exact integers; the time sums were added in the points' order, as
        // `Sums::add` would.
        let [s_n, s_x, s_y, s_xx, s_xy, s_yy] = nb.offset_sums.map(f64::from);
        let [st, sxt, syt] = nb.time_sums;
        self.sums = Sums {
            n: s_n,
            sx: s_x,
            sy: s_y,
            sxx: s_xx,
            sxy: s_xy,
            syy: s_yy,
            st,
            sxt,
            syt,
        };
        self.used = if n == 128 { u128::MAX } else { (1u128 << n) - 1 };
        self.kept = n;
        self.fresh = false;
        self.stable = false;
        match self.sums.solve() {
            Some(sol) => {
                self.sol = sol;
                true
            }
            None => false,
        }
    }

    /// Up to `max_refits` more refits (fewer once the kept set stops changing); false when fewer
    /// than `min_points` points stay or they do not span a plane (the fit is then void).
    #[inline]
    pub fn refit(
        &mut self,
        nb: &Neighbourhood,
        outlier_s: f64,
        max_refits: usize,
        min_points: usize,
    ) -> bool {
        let n = nb.len;
        let min_points = min_points.max(3);
        let (dx, dy, dt) = (&nb.dx[..n], &nb.dy[..n], &nb.dt[..n]);
        let res = &mut self.res[..n];
        for _ in 0..max_refits {
            if self.stable {
                break;
            }
            if !self.fresh {
                residuals(&self.sol, dx, dy, dt, res);
            }
            // The inliers as bits, without a branch per point; then only the points that
            // changed side are visited, in ascending order, as a point-by-point pass would add
            // them.
            let mut inliers: u128 = 0;
            for (c, chunk) in res.chunks(64).enumerate() {
                let mut bits: u64 = 0;
                for (i, r) in chunk.iter().enumerate() {
                    bits |= u64::from(r.abs() <= outlier_s) << i;
                }
                inliers |= u128::from(bits) << (64 * c);
            }
            let mut changed = inliers ^ self.used;
            if changed == 0 {
                // `res` still holds the residuals of `sol`.
                self.fresh = true;
                self.stable = true;
                break;
            }
            self.used = inliers;
            while changed != 0 {
                let i = changed.trailing_zeros() as usize;
                changed &= changed - 1;
                let inlier = (inliers >> i) & 1 == 1;
                let sign = if inlier { 1.0 } else { -1.0 };
                self.sums.add(dx[i], dy[i], dt[i], sign);
                if inlier {
                    self.kept += 1;
                } else {
                    self.kept -= 1;
                }
            }
            if self.kept < min_points {
                return false;
            }
            match self.sums.solve() {
                Some(sol) => {
                    self.sol = sol;
                    self.fresh = false;
                }
                None => return false,
            }
        }
        true
    }

    /// The plane as it stands (after a successful [`start`](Self::start) and
    /// [`refit`](Self::refit)).
    #[inline]
    pub fn plane(&mut self, nb: &Neighbourhood) -> PlaneFit {
        let n = nb.len;
        let res = &mut self.res[..n];
        if !self.fresh {
            residuals(&self.sol, &nb.dx[..n], &nb.dy[..n], &nb.dt[..n], res);
            self.fresh = true;
        }
        let mut ss = 0.0;
        for (c, chunk) in res.chunks(64).enumerate() {
            let bits = (self.used >> (64 * c)) as u64;
            for (i, r) in chunk.iter().enumerate() {
                // Adding +0 for a rejected point leaves the sum as it is (it starts at +0).
                let kept_r = if (bits >> i) & 1 == 1 { *r } else { 0.0 };
                ss += kept_r * kept_r;
            }
        }
        plane_fit(self.sol, &self.sums, self.kept, n, ss)
    }
}

/// Time residuals `gx dx + gy dy + c - dt` of the points against `sol`, into `res`.
#[inline]
fn residuals(sol: &[f64; 3], dx: &[f64], dy: &[f64], dt: &[f64], res: &mut [f64]) {
    for i in 0..res.len() {
        res[i] = sol[0] * dx[i] + sol[1] * dy[i] + sol[2] - dt[i];
    }
}

/// The fit's result from its final solution `sol` = `(gx, gy, c)`, the normal equations `sums`
/// of its `kept` inliers among `points` offered, and their residual sum of squares `ss` (s^2).
fn plane_fit(sol: [f64; 3], sums: &Sums, kept: usize, points: usize, ss: f64) -> PlaneFit {
    let g = (sol[0] * sol[0] + sol[1] * sol[1]).sqrt();
    let direction_sd_rad = match sums.gradient_covariance() {
        Some([cxx, cxy, cyy]) if kept > 3 && g > 0.0 => {
            let (qx, qy) = (-sol[1] / g, sol[0] / g);
            let var = ss / (kept - 3) as f64 * (qx * qx * cxx + 2.0 * qx * qy * cxy + qy * qy * cyy);
            var.max(0.0).sqrt() / g
        }
        _ => f64::INFINITY,
    };
    PlaneFit {
        gx: sol[0],
        gy: sol[1],
        c: sol[2],
        inliers: kept,
        points,
        rms_s: (ss / kept as f64).sqrt(),
        direction_sd_rad,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_run_adds_what_point_by_point_pushes_add_to_the_bit() {
        // Rows of ages spread over every case (kept, too old, too new, within dt_min, the own
        // pixel), pushed until past capacity.
        let ages = AgeLimits {
            t: 1.0,
            dt_min: 0.0005,
            dt_max: 0.1,
            lookahead: 0.03,
        };
        let (mut by_run, mut by_point) = (Neighbourhood::default(), Neighbourhood::default());
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        for r in 0..12 {
            let row: Vec<f64> = (0..9).map(|_| 1.0 - 0.16 * next() + 0.04).collect();
            let own = if r == 5 { 4 } else { usize::MAX };
            let (dx0, dy) = (-4, r - 6);
            by_run.push_run(
                &RowRun {
                    row: &row,
                    dx0,
                    dy,
                    own,
                },
                &ages,
            );
            for (k, &ts) in row.iter().enumerate() {
                let age = ages.t - ts;
                let own_pixel = k == own;
                let keep =
                    own_pixel || (age.abs() >= ages.dt_min && age <= ages.dt_max && age >= -ages.lookahead);
                let dt = if own_pixel { 0.0 } else { -age };
                by_point.push_if(keep, dx0 + k as i32, dy, dt);
            }
            assert_eq!(by_run.len, by_point.len, "row {r}");
            let n = by_run.len;
            assert_eq!(by_run.offset_sums, by_point.offset_sums, "row {r}");
            assert_eq!(
                by_run.time_sums.map(f64::to_bits),
                by_point.time_sums.map(f64::to_bits)
            );
            assert_eq!(by_run.dx[..n], by_point.dx[..n]);
            assert_eq!(by_run.dy[..n], by_point.dy[..n]);
            assert!(
                by_run.dt[..n]
                    .iter()
                    .zip(&by_point.dt[..n])
                    .all(|(a, b)| a.to_bits() == b.to_bits())
            );
        }
        assert!(
            by_run.len > 40 && by_run.len <= MAX_POINTS,
            "{} points",
            by_run.len
        );
    }

    fn window(r: i32, f: impl Fn(f64, f64) -> f64) -> Neighbourhood {
        let mut nb = Neighbourhood::default();
        for dy in -r..=r {
            for dx in -r..=r {
                assert!(nb.push(dx, dy, f(dx as f64, dy as f64)));
            }
        }
        nb
    }

    /// The fit as written before the offset sums were kept as integers and the residuals
    /// stored: [`fit_plane`] must reproduce it bit for bit.
    fn fit_plane_reference(
        nb: &Neighbourhood,
        outlier_s: f64,
        max_refits: usize,
        min_points: usize,
    ) -> Option<PlaneFit> {
        let n = nb.len;
        let min_points = min_points.max(3);
        if n < min_points {
            return None;
        }
        let mut used = [true; MAX_POINTS];
        let mut sums = Sums::default();
        for i in 0..n {
            sums.add(nb.dx[i], nb.dy[i], nb.dt[i], 1.0);
        }
        let mut kept = n;
        let mut sol = sums.solve()?;
        for _ in 0..max_refits {
            let mut changed = false;
            for (i, used) in used.iter_mut().enumerate().take(n) {
                let r = sol[0] * nb.dx[i] + sol[1] * nb.dy[i] + sol[2] - nb.dt[i];
                let inlier = r.abs() <= outlier_s;
                if inlier != *used {
                    *used = inlier;
                    changed = true;
                    sums.add(nb.dx[i], nb.dy[i], nb.dt[i], if inlier { 1.0 } else { -1.0 });
                    if inlier {
                        kept += 1;
                    } else {
                        kept -= 1;
                    }
                }
            }
            if !changed {
                break;
            }
            if kept < min_points {
                return None;
            }
            sol = sums.solve()?;
        }
        let mut ss = 0.0;
        for (i, &used) in used.iter().enumerate().take(n) {
            if used {
                let r = sol[0] * nb.dx[i] + sol[1] * nb.dy[i] + sol[2] - nb.dt[i];
                ss += r * r;
            }
        }
        // The result from the solution: the same function as `fit_plane`'s (unchanged by the
        // speed work, which changed how the sums and residuals are formed).
        Some(plane_fit(sol, &sums, kept, n, ss))
    }

    #[test]
    fn fit_reproduces_the_reference_bit_for_bit() {
        // Noisy planes in windows of radius 1 to 4 with missing pixels and old outliers; a
        // fixed linear congruential generator, so the cases are the same on every run.
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state = state
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut fits = 0;
        for case in 0..4000 {
            let r = 1 + case % MAX_RADIUS as i32;
            let (gx, gy) = (0.004 * (next() - 0.5), 0.004 * (next() - 0.5));
            let mut nb = Neighbourhood::default();
            for dy in -r..=r {
                for dx in -r..=r {
                    let u = next();
                    if u < 0.2 && (dx, dy) != (0, 0) {
                        continue;
                    }
                    let t = if u > 0.9 {
                        -0.05 * next()
                    } else {
                        gx * f64::from(dx) + gy * f64::from(dy) + 0.002 * (next() - 0.5)
                    };
                    assert!(nb.push(dx, dy, t));
                }
            }
            let bits = |f: Option<PlaneFit>| {
                f.map(|f| {
                    (
                        [f.gx, f.gy, f.c, f.rms_s, f.direction_sd_rad].map(f64::to_bits),
                        f.inliers,
                        f.points,
                    )
                })
            };
            for refits in [0, 1, 3] {
                let (a, b) = (
                    fit_plane(&nb, 0.002, refits, 5),
                    fit_plane_reference(&nb, 0.002, refits, 5),
                );
                assert_eq!(bits(a), bits(b), "case {case}, {refits} refits");
                fits += usize::from(a.is_some());
            }
            // A fit continued (the scale check's 1 refit, then the wide fit's 3) is the fresh
            // fit with as many refits in all, also after its plane was read in between.
            for (first, more) in [(0, 1), (1, 2), (1, 0), (0, 3)] {
                let mut go = PlaneRefit::default();
                let mut continued = go.start(&nb, 5) && go.refit(&nb, 0.002, first, 5);
                if continued {
                    let midway = go.plane(&nb);
                    assert_eq!(bits(Some(midway)), bits(fit_plane(&nb, 0.002, first, 5)));
                    continued = go.refit(&nb, 0.002, more, 5);
                }
                let fresh = fit_plane(&nb, 0.002, first + more, 5);
                assert_eq!(bits(continued.then(|| go.plane(&nb))), bits(fresh), "case {case}");
            }
        }
        assert!(fits > 5_000, "only {fits} fits succeeded");
    }

    #[test]
    fn exact_plane_is_recovered() {
        let nb = window(2, |x, y| 0.002 * x - 0.001 * y + 0.0005);
        let fit = fit_plane(&nb, 0.005, 3, 5).expect("plane");
        assert!((fit.gx - 0.002).abs() < 1e-12 && (fit.gy + 0.001).abs() < 1e-12);
        assert!((fit.c - 0.0005).abs() < 1e-12);
        assert_eq!((fit.inliers, fit.points), (25, 25));
        assert!(fit.rms_s < 1e-12);
        assert!(fit.direction_sd_rad < 1e-6);
        let [vx, vy] = fit.normal_flow_px().expect("flow");
        // v = g / |g|^2 = (0.002, -0.001) / 5e-6 = (400, -200) px/s.
        assert!((vx - 400.0).abs() < 1e-6 && (vy + 200.0).abs() < 1e-6);
        assert!((fit.speed_px_s() - 1.0 / 5e-6f64.sqrt()).abs() < 1e-6);
    }

    #[test]
    fn outlier_is_rejected() {
        // An old timestamp from a previous edge, 50 ms before, at the fourth point.
        let nb = window(2, |x, y| if (x, y) == (1.0, -2.0) { -0.05 } else { 0.001 * x });
        assert_eq!(nb.dt[3], -0.05);
        let fit = fit_plane(&nb, 0.005, 3, 5).expect("plane");
        assert_eq!(fit.inliers, 24);
        assert!((fit.gx - 0.001).abs() < 1e-12 && fit.gy.abs() < 1e-12);
    }

    #[test]
    fn too_few_or_collinear_points_give_no_plane() {
        let mut nb = Neighbourhood::default();
        for i in 0..4 {
            nb.push(i, 0, 0.001 * i as f64);
        }
        assert!(fit_plane(&nb, 0.005, 3, 5).is_none(), "4 points < min_points 5");
        nb.push(4, 0, 0.004);
        assert!(
            fit_plane(&nb, 0.005, 3, 5).is_none(),
            "collinear points span no plane"
        );
        nb.push(0, 1, 0.0);
        assert!(fit_plane(&nb, 0.005, 3, 5).is_some());
    }

    #[test]
    fn flat_plane_has_no_flow() {
        let nb = window(1, |_, _| 0.0);
        let fit = fit_plane(&nb, 0.005, 3, 5).expect("plane");
        assert!(fit.normal_flow_px().is_none());
        assert!(fit.speed_px_s().is_infinite());
    }

    #[test]
    fn full_neighbourhood_refuses_more_points() {
        let mut nb = window(MAX_RADIUS as i32, |_, _| 0.0);
        assert_eq!(nb.len(), MAX_POINTS);
        assert!(!nb.push(0, 0, 0.0));
        nb.clear();
        assert!(nb.is_empty());
    }
}
