//! Threshold crossings of one pixel with their truth (object id and flow per event): between
//! two renders ([`fire`]) and along the interpolated texture path of a pixel that keeps one
//! surface ([`fire_path`]).

use crate::camera::{CameraConfig, Rays};
use crate::engine::RawEvent;
use crate::esim;
use crate::math::{fmax, fmin};
use crate::render::{FrameGeom, Located};
use crate::scene::Scene;
use crate::texture::Texture;

/// What firing needs besides the pixel's state.
pub(crate) struct FireCtx<'a> {
    /// The scene.
    pub scene: &'a Scene,
    /// The camera.
    pub cam: &'a CameraConfig,
    /// Rays of every pixel.
    pub rays: &'a Rays,
    /// Refractory period, s.
    pub refractory: f64,
}

/// What a pixel saw at one render for the truth: the object id, the surface key and the
/// depth (m) the render located (`u16::MAX` and infinite for nothing); its centre ray's
/// surface, or a moving object that covers part of a pixel whose centre sees the background
/// (met by an edge sub-sample, the depth that sub-sample's).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Seen {
    /// Object id.
    pub id: u16,
    /// Surface key.
    pub key: u16,
    /// Depth along the optical axis, m.
    pub z: f32,
}

impl From<Located> for Seen {
    fn from(hit: Located) -> Self {
        Self {
            id: hit.id,
            key: hit.key,
            z: hit.z,
        }
    }
}

/// One end of a pixel's path on one surface: where the pixel's ray met it (a key frame, or a
/// render of an unstable pixel).
pub(crate) struct PathEnd<'a> {
    /// Time, s.
    pub t: f64,
    /// Log intensity.
    pub l: f32,
    /// Texture coordinates, m.
    pub u: f32,
    /// Texture coordinates, m.
    pub v: f32,
    /// Texture footprint, m.
    pub footprint: f32,
    /// Log shading of the surface.
    pub shade: f32,
    /// The scene at `t`.
    pub geom: &'a FrameGeom,
    /// Surface key.
    pub key: u16,
    /// Depth along the optical axis, m.
    pub z: f32,
}

/// Threshold crossings of pixel `i` (object `id`) along the straight texture path between
/// `ends` on one surface (texture `tex`): log intensities at the grid points `j / m`,
/// `j = 1..m`, of the interpolated path (the last is the end's own value). They do not depend
/// on the pixel's reference level, so they are computed first, free of the serial chain of the
/// threshold test, and the test is skipped when none can reach a threshold. `state` is the
/// pixel's reference level and time of its last event; `path` is scratch. Returns the number
/// of interpolated samples and of events.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub(crate) fn fire_path(
    ctx: &FireCtx,
    tex: &Texture,
    ends: (&PathEnd, &PathEnd),
    m: usize,
    i: usize,
    id: u16,
    state: (&mut f32, &mut f64),
    thresholds: (f32, f32),
    batch: &mut Vec<RawEvent>,
    path: &mut Vec<f32>,
) -> (u64, u64) {
    let (a, b) = ends;
    let (reference, last_event) = state;
    let (c_on, c_off) = thresholds;
    let (t0, t1) = (a.t, b.t);
    let (du, dv) = (b.u - a.u, b.v - a.v);
    let dfp = b.footprint - a.footprint;
    let r = *reference;
    let mf = m as f32;
    let (lo, hi) = tex.sample_path(
        [a.u, a.v, a.footprint, a.shade],
        [du, dv, dfp, b.shade - a.shade],
        m,
        path,
    );
    path.push(b.l);
    let samples = (m - 1) as u64;
    let l_start = a.l;
    let (lo, hi) = (fmin(fmin(lo, l_start), b.l), fmax(fmax(hi, l_start), b.l));
    if hi < r + c_on && lo > r - c_off {
        // Strictly inside both thresholds: no crossing, reference unchanged.
        return (samples, 0);
    }
    let before = batch.len();
    // Time of grid point `k` of the path (computed only for the segments that may cross).
    let time = |k: usize| {
        if k == 0 {
            t0
        } else if k == m {
            t1
        } else {
            t0 + (t1 - t0) * (k as f32 / mf) as f64
        }
    };
    let mut l_prev = l_start;
    for (j, &l) in path.iter().enumerate() {
        if esim::may_cross(*reference, l, c_on, c_off) {
            fire_segment(
                ctx,
                reference,
                last_event,
                i,
                l_prev,
                l,
                (time(j), time(j + 1)),
                ends,
                id,
                (c_on, c_off),
                batch,
            );
        }
        l_prev = l;
    }
    (samples, (batch.len() - before) as u64)
}

/// Threshold crossings of pixel `i` from `l0` to `l1` over `span`, with the truth of
/// [`event_truth`] between the renders `geoms` (which saw `seen` at the pixel centre).
#[allow(clippy::too_many_arguments)]
pub(crate) fn fire(
    ctx: &FireCtx,
    reference: &mut f32,
    last_event: &mut f64,
    i: usize,
    l0: f32,
    l1: f32,
    span: (f64, f64),
    geoms: (&FrameGeom, &FrameGeom),
    seen: (Seen, Seen),
    thresholds: (f32, f32),
    batch: &mut Vec<RawEvent>,
) {
    crossings_to_events(
        ctx,
        reference,
        last_event,
        i,
        (l0, l1),
        span,
        thresholds,
        batch,
        |t| event_truth(ctx, i, geoms, seen, fraction(t, span)),
    );
}

/// Like [`fire`] for a sub-segment `span` of a path `ends` of pixel `i` on one surface of
/// object `id` (see [`fire_path`]); the truth interpolates between the ends, with the surface
/// and depth located there (what `FrameGeom::flow` would locate).
#[allow(clippy::too_many_arguments)]
fn fire_segment(
    ctx: &FireCtx,
    reference: &mut f32,
    last_event: &mut f64,
    i: usize,
    l0: f32,
    l1: f32,
    span: (f64, f64),
    ends: (&PathEnd, &PathEnd),
    id: u16,
    thresholds: (f32, f32),
    batch: &mut Vec<RawEvent>,
) {
    crossings_to_events(
        ctx,
        reference,
        last_event,
        i,
        (l0, l1),
        span,
        thresholds,
        batch,
        |t| {
            let (x, y) = (ctx.rays.x[i], ctx.rays.y[i]);
            let flow = |e: &PathEnd| e.geom.flow_at(ctx.cam, x, y, e.key, e.z, id);
            let frac = fraction(t, (ends.0.t, ends.1.t));
            let (fx, fy) = interpolate_flow(flow(ends.0), flow(ends.1), frac);
            (id, fx, fy)
        },
    );
}

/// How far time `t` lies from `span.0` towards `span.1` (0 for an empty span).
fn fraction(t: f64, span: (f64, f64)) -> f32 {
    let (a, b) = span;
    if b > a { ((t - a) / (b - a)) as f32 } else { 0.0 }
}

/// The ESIM threshold crossings of pixel `i` from log intensity `levels.0` to `levels.1` over
/// `span` (seconds) as events in `batch`, each with the object id and flow (px/s) `truth`
/// gives for its time.
#[allow(clippy::too_many_arguments)]
fn crossings_to_events(
    ctx: &FireCtx,
    reference: &mut f32,
    last_event: &mut f64,
    i: usize,
    levels: (f32, f32),
    span: (f64, f64),
    thresholds: (f32, f32),
    batch: &mut Vec<RawEvent>,
    truth: impl Fn(f64) -> (u16, f32, f32),
) {
    esim::crossings(
        reference,
        last_event,
        levels.0,
        levels.1,
        span.0,
        span.1,
        thresholds.0,
        thresholds.1,
        ctx.refractory,
        |t, pol| {
            let (id, fx, fy) = truth(t);
            batch.push(RawEvent {
                t,
                pixel: i as u32,
                p: pol,
                id,
                fx,
                fy,
            });
        },
    );
}

/// Object id and flow (px/s) of an event at pixel `i`, a fraction `frac` of the way from the
/// render at `geoms.0` (which saw `seen.0` at the pixel centre) to the one at `geoms.1`.
/// The id is the object's if it covers the pixel at either render (leading and trailing edges
/// belong to the object); the flow is that surface's motion field at the pixel, interpolated
/// between the two renders when both see it. Where a render saw the event's object at the
/// pixel centre, its surface and depth are what `FrameGeom::flow` would locate (the nearest
/// surface of all is the nearest of its object's), so they are used as they are.
fn event_truth(
    ctx: &FireCtx,
    i: usize,
    geoms: (&FrameGeom, &FrameGeom),
    seen: (Seen, Seen),
    frac: f32,
) -> (u16, f32, f32) {
    let (id_a, id_b) = (seen.0.id, seen.1.id);
    let id = match (id_a, id_b) {
        (0, b) => b,
        (a, 0) => a,
        (a, b) => {
            if frac < 0.5 {
                a
            } else {
                b
            }
        }
    };
    let w = ctx.rays.width;
    let (x, y, u, v) = (ctx.rays.x[i], ctx.rays.y[i], (i % w) as i32, (i / w) as i32);
    let flow = |g: &FrameGeom, s: Seen| {
        if s.id == id {
            g.flow_at(ctx.cam, x, y, s.key, s.z, id)
        } else {
            g.flow(ctx.scene, ctx.cam, x, y, u, v, id)
        }
    };
    let (fx, fy) = interpolate_flow(flow(geoms.0, seen.0), flow(geoms.1, seen.1), frac);
    (id, fx, fy)
}

/// The flow (px/s) a fraction `frac` of the way from flow `fa` to `fb` (either alone when the
/// other is missing, zero when both are).
#[inline]
fn interpolate_flow(fa: Option<(f64, f64)>, fb: Option<(f64, f64)>, frac: f32) -> (f32, f32) {
    let (fx, fy) = match (fa, fb) {
        (Some(a), Some(b)) => {
            let f = frac as f64;
            (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
        }
        (Some(a), None) => a,
        (None, Some(b)) => b,
        (None, None) => (0.0, 0.0),
    };
    (fx as f32, fy as f32)
}
