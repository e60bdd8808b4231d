//! The simulation core: one key-frame interval at a time.
//!
//! Each interval `[t0, t1]` holds up to `steps_per_keyframe` render steps, each short enough
//! that no scene point moves more than `max_px_per_step` pixels. Key frames at `t0` and `t1`
//! ray-cast every pixel. In between, every pixel gets one of three treatments:
//!
//! - **quiet**: it cannot cross a threshold during the interval, so it goes straight from `t0`
//!   to `t1` (a firing there is counted as a violation, the events are kept). The bound is the
//!   range of both key frames' log intensities within the distance any scene point travels in
//!   the interval, with `quiet_margin_log` (plus the shading change of moving objects): whatever
//!   passes the pixel comes from that neighbourhood (brightness constancy; content entering the
//!   view or uncovered is visible in the later key frame).
//! - **stable**: the pixel sees the same surface at both key frames and is not on an edge in
//!   either, so its texture coordinates move smoothly; they are interpolated linearly between
//!   the key frames and the texture is sampled at steps of at most `max_px_per_step` of this
//!   pixel's own image motion (its texture-coordinate change mapped through the pixel-to-texture
//!   Jacobian; no ray casting). When the texels under the paths of a run of neighbouring
//!   pixels on one surface keep a pixel strictly inside its thresholds, no sample is taken
//!   (none could fire: exact; see `run_range`). Otherwise all samples of the pixel are taken
//!   first, 8 at a time (they do not depend on its reference level), and the threshold test
//!   runs only when one of them reaches a threshold. (A bound of the pixel's own path before
//!   sampling no longer paid once samples were taken 8 at a time; it decided the same.)
//! - **unstable** (near a silhouette, crease or seam): ray cast at the render steps that keep
//!   its local image-speed bound within `max_px_per_step` per render (as late as that allows;
//!   see [`crate::local_speed`]), with edge anti-aliasing
//!   ([`FrameGeom::edge_sample`]).

use crate::camera::Rays;
use crate::config::SceneConfig;
use crate::esim::{self, NoiseSource, Thresholds};
use crate::filters;
use crate::firing::{FireCtx, PathEnd, Seen, fire};
use crate::local_speed::{self, LocalSpeed};
use crate::math::{fmax, fmin};
use crate::radix;
use crate::render::FrameGeom;
use crate::scene::{self, Scene};
use crate::stable::ListedPixels;
use crate::unstable::{self, PixelState, UnstableList};
use crate::{SimStats, math};

/// One event with its truth, before it is split into columns.
#[derive(Debug, Clone, Copy)]
pub struct RawEvent {
    /// Time, s.
    pub t: f64,
    /// Row-major pixel index.
    pub pixel: u32,
    /// Polarity 0/1.
    pub p: u8,
    /// Object id.
    pub id: u16,
    /// Flow, px/s.
    pub fx: f32,
    /// Flow, px/s.
    pub fy: f32,
}

/// Every pixel ray cast at one instant.
#[derive(Debug, Clone)]
pub struct KeyFrame {
    /// The scene at this instant.
    pub geom: FrameGeom,
    /// Log intensity (edge pixels supersampled).
    pub l: Vec<f32>,
    /// Surface key of the pixel centre.
    pub key: Vec<u16>,
    /// Object id of the pixel centre.
    pub id: Vec<u16>,
    /// Texture coordinates, m.
    pub u: Vec<f32>,
    /// Texture coordinates, m.
    pub v: Vec<f32>,
    /// Texture footprint, m.
    pub footprint: Vec<f32>,
    /// Depth along the optical axis, m (infinite where nothing was hit; one pixel across the
    /// ray measures `z * geom.inv_f()` on the surface).
    pub z: Vec<f32>,
    /// True where a 4-neighbour sees another surface.
    pub edge: Vec<bool>,
    /// True where the pixel's value mixes surfaces (edge sub-samples on another surface).
    pub mixed: Vec<bool>,
    /// Mixed pixels whose centre sees the background while a sub-sample meets a moving
    /// object, by pixel index (ascending), with what that sub-sample met: the object covers
    /// part of the pixel, so it is the pixel's surface for the truth (see [`KeyFrame::seen`]).
    pub(crate) edge_objects: Vec<(u32, Seen)>,
}

impl KeyFrame {
    /// What pixel `i` saw for the truth: its centre ray's surface, or the moving object that
    /// covers part of a pixel whose centre sees the background (`edge_objects`).
    #[inline]
    pub(crate) fn seen(&self, i: usize) -> Seen {
        if self.mixed[i]
            && self.id[i] == 0
            && let Ok(k) = self.edge_objects.binary_search_by_key(&(i as u32), |e| e.0)
        {
            return self.edge_objects[k].1;
        }
        Seen {
            id: self.id[i],
            key: self.key[i],
            z: self.z[i],
        }
    }

    /// Pixel `i` as one end of a path on its surface, at time `t` (this key frame's).
    #[inline]
    pub(crate) fn path_end(&self, i: usize, t: f64) -> PathEnd<'_> {
        let key = self.key[i];
        PathEnd {
            t,
            l: self.l[i],
            u: self.u[i],
            v: self.v[i],
            footprint: self.footprint[i],
            shade: self.geom.shade_by_key[key as usize],
            geom: &self.geom,
            key,
            z: self.z[i],
        }
    }

    /// A key frame of `n` pixels at `geom`, not cast yet.
    pub(crate) fn new(geom: FrameGeom, n: usize) -> Self {
        Self {
            geom,
            l: vec![0.0; n],
            key: vec![0; n],
            id: vec![0; n],
            u: vec![0.0; n],
            v: vec![0.0; n],
            footprint: vec![0.0; n],
            z: vec![0.0; n],
            edge: vec![false; n],
            mixed: vec![false; n],
            edge_objects: Vec::new(),
        }
    }
}

/// Side of the square pixel blocks whose smallest background depth bounds image speeds.
const BLOCK: usize = 16;

/// One block of the background depth summary of the last key frame.
#[derive(Debug, Clone, Copy)]
struct DepthBlock {
    /// Normalized coordinates of the block centre.
    x: f64,
    y: f64,
    /// Half extents of the block in normalized coordinates (farthest pixel from the centre).
    hx: f64,
    hy: f64,
    /// Smallest background depth in the block, m (infinite if none).
    zmin: f64,
    /// The same at the key frame before.
    zmin_prev: f64,
}

/// Rays located and shaded together in a key frame (see `FrameGeom::locate_lanes` and
/// `FrameGeom::shade_lanes`).
const KEY_LANES: usize = crate::texture::LANES;

/// Pixel classes of an interval (see the module documentation).
pub(crate) const QUIET: u8 = 0;
/// See [`QUIET`].
pub(crate) const STABLE: u8 = 1;
/// See [`QUIET`].
const UNSTABLE: u8 = 2;

/// The per-pixel state and the key frames.
#[derive(Debug, Clone)]
pub struct Engine {
    pub(crate) scene: Scene,
    pub(crate) rays: Rays,
    thresholds: Thresholds,
    noise: NoiseSource,
    reference: Vec<f32>,
    last_event: Vec<f64>,
    kf0: KeyFrame,
    kf1: KeyFrame,
    class: Vec<u8>,
    /// Unstable pixels of the current interval.
    unstable: UnstableList,
    /// Event buffer of the current interval.
    batch: Vec<RawEvent>,
    /// Scratch of the event sort.
    sort_scratch: Vec<RawEvent>,
    /// Quiet pixels that may cross at the closing key frame and stable pixels, in pixel order.
    work: Vec<u32>,
    /// 1 for the pixels of `work`, per pixel (see `classify_pixels`).
    listed: Vec<u8>,
    // Filter buffers.
    lo: Vec<f32>,
    hi: Vec<f32>,
    scratch: Vec<f32>,
    blocks: Vec<DepthBlock>,
    /// The blocks' `x`, `y`, `hx` and `hy`, field by field (for the speed bounds in lanes).
    block_geometry: [Vec<f64>; 4],
    zmin_bg: f64,
    last_dt: f64,
    /// Time of `kf0`, s.
    pub(crate) t: f64,
    pub(crate) stats: SimStats,
}

impl Engine {
    /// Bakes the scene and renders the key frame at t = 0 (references start at its intensities).
    pub fn new(cfg: &SceneConfig) -> Self {
        let scene = Scene::of_config(cfg);
        let rays = Rays::new(&cfg.camera);
        let n = rays.width * rays.height;
        let mut rng = crate::rng::Rng::new(cfg.seed, 0x7e5);
        let thresholds = Thresholds::draw(&cfg.esim, n, &mut rng);
        let noise = NoiseSource::new(&cfg.esim, n, cfg.seed);
        let geom = FrameGeom::new(&scene, &cfg.camera, 0.0);
        let mut e = Self {
            kf0: KeyFrame::new(geom.clone(), n),
            kf1: KeyFrame::new(geom, n),
            scene,
            rays,
            thresholds,
            noise,
            reference: vec![0.0; n],
            last_event: vec![f64::NEG_INFINITY; n],
            class: vec![QUIET; n],
            unstable: UnstableList::default(),
            batch: Vec::new(),
            sort_scratch: Vec::new(),
            work: Vec::new(),
            listed: Vec::new(),
            lo: vec![0.0; n],
            hi: vec![0.0; n],
            scratch: Vec::new(),
            blocks: Vec::new(),
            block_geometry: Default::default(),
            zmin_bg: 1.0,
            last_dt: cfg.render.max_step_s,
            t: 0.0,
            stats: SimStats::default(),
        };
        e.render_keyframe(cfg);
        std::mem::swap(&mut e.kf0, &mut e.kf1);
        e.reference.copy_from_slice(&e.kf0.l);
        e
    }

    /// Bound of the image speed (px/s) of any scene point at time `t`: the background from the
    /// depths of the last key frame (per 16x16 block, times `depth_safety`), each object from a
    /// ball around its centre.
    fn speed_bound(&self, cfg: &SceneConfig, t: f64) -> f64 {
        let cam = self.scene.camera_state(t);
        let (mx, my) = (self.rays.max_abs_x, self.rays.max_abs_y);
        let r_max = mx.hypot(my);
        let bg = scene::RelativeMotion::new(&cam, None);
        let safety = cfg.render.depth_safety;
        let z: Vec<f64> = self
            .blocks
            .iter()
            .map(|b| {
                let z = if b.zmin.is_finite() {
                    b.zmin.min(self.zmin_bg * 4.0)
                } else {
                    self.zmin_bg
                };
                z * safety
            })
            .collect();
        let mut bounds = vec![0.0; z.len()];
        let g = &self.block_geometry;
        bg.static_speed_bounds_near(&g[0], &g[1], &g[2], &g[3], &z, &mut bounds);
        let mut s = bounds.iter().fold(0.0f64, |s, &b| s.max(b));
        for b in self.scene.boxes.iter().filter(|b| b.id != 0) {
            let bs = b.trajectory.state(t);
            let pose = scene::BoxPose::new(&cam, &bs);
            let corners = pose.corners(b.half);
            let zmax = corners.iter().map(|c| c[2]).fold(f64::NEG_INFINITY, f64::max);
            if zmax <= 0.0 {
                continue;
            }
            // Skip objects well outside the field of view (55 px at f = 550): every corner
            // beyond the plane through the camera at normalized `lim + 0.1` on one side. Tested
            // as a half-space (`x > k z`, not `x / z > k`), so it holds for a box reaching
            // behind the image plane too: a box 10 m beside the camera with a corner at depth
            // 0.05 m was bounded as if it were at 0.1 m in front of it (15 000 steps per
            // second with nothing in view, session 47).
            let out = |k: usize, lim: f64| {
                corners.iter().all(|c| c[k] > (lim + 0.1) * c[2])
                    || corners.iter().all(|c| c[k] < -(lim + 0.1) * c[2])
            };
            if out(0, mx) || out(1, my) {
                continue;
            }
            let m = scene::RelativeMotion::new(&cam, Some(&bs));
            s = s.max(object_speed(&m, &pose, &corners, b.half, r_max));
        }
        let c = &cfg.camera;
        s * c.fx.max(c.fy) * self.rays.max_jacobian
    }

    /// Local image-speed bounds (px/s, with `speed_safety`) over an interval rendered at
    /// `geoms` (see [`local_speed`]): per block the background's from the smaller of the last
    /// two key frames' depths of the 3 x 3 blocks around it, maxed over 3 x 3 blocks; every
    /// moving object's from a ball around its centre, over the union of its pixel bounding
    /// boxes.
    fn local_speeds(&self, cfg: &SceneConfig, geoms: &[FrameGeom]) -> LocalSpeed {
        let (w, h) = (self.rays.width, self.rays.height);
        let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
        let c = &cfg.camera;
        let to_px = c.fx.max(c.fy) * self.rays.max_jacobian * cfg.render.speed_safety;
        let zb: Vec<f64> = self
            .blocks
            .iter()
            .map(|b| {
                let z = b.zmin.min(b.zmin_prev);
                if z.is_finite() {
                    z.min(self.zmin_bg * 4.0)
                } else {
                    self.zmin_bg
                }
            })
            .collect();
        let around = |v: &[f64], i: usize, pick: fn(f64, f64) -> f64, init: f64| {
            let (bx, by) = (i % bw, i / bw);
            let mut r = init;
            for y in by.saturating_sub(1)..(by + 2).min(bh) {
                for x in bx.saturating_sub(1)..(bx + 2).min(bw) {
                    r = pick(r, v[y * bw + x]);
                }
            }
            r
        };
        let safety = cfg.render.depth_safety;
        let z3: Vec<f64> = (0..bw * bh)
            .map(|i| around(&zb, i, f64::min, f64::INFINITY) * safety)
            .collect();
        let mut own = vec![0.0f64; bw * bh];
        let mut bounds = vec![0.0f64; bw * bh];
        let bl = &self.block_geometry;
        for g in geoms {
            g.motions[0].static_speed_bounds_near(&bl[0], &bl[1], &bl[2], &bl[3], &z3, &mut bounds);
            for (o, &b) in own.iter_mut().zip(&bounds) {
                *o = o.max(b);
            }
        }
        let background = (0..bw * bh)
            .map(|i| (around(&own, i, f64::max, 0.0) * to_px) as f32)
            .collect();
        let r_max = self.rays.max_abs_x.hypot(self.rays.max_abs_y);
        let mut objects = Vec::new();
        for b in self.scene.boxes.iter().filter(|b| b.id != 0) {
            let mut bbox: Option<[i32; 4]> = None;
            let mut speed = 0.0f64;
            for g in geoms {
                let Some((_, bb)) = g.object_bboxes().find(|(id, _)| *id == b.id) else {
                    continue;
                };
                bbox = Some(bbox.map_or(bb, |a| {
                    [a[0].min(bb[0]), a[1].min(bb[1]), a[2].max(bb[2]), a[3].max(bb[3])]
                }));
                let bs = b.trajectory.state(g.t);
                let pose = scene::BoxPose::new(&g.cam, &bs);
                let m = scene::RelativeMotion::new(&g.cam, Some(&bs));
                speed = speed.max(object_speed(&m, &pose, &pose.corners(b.half), b.half, r_max));
            }
            if let Some(bb) = bbox {
                objects.push((bb, (speed * to_px) as f32));
            }
        }
        LocalSpeed {
            blocks_x: bw,
            block: BLOCK,
            background,
            objects,
        }
    }

    /// Render times of the next interval and the bound (px) of how far any scene point moves.
    fn plan(&mut self, cfg: &SceneConfig) -> (Vec<f64>, f64) {
        let r = &cfg.render;
        let dur = cfg.duration_s;
        let mut times = vec![self.t];
        let mut travel = 0.0;
        for _ in 0..r.steps_per_keyframe {
            let t = times[times.len() - 1];
            if t >= dur {
                break;
            }
            let bound = self
                .speed_bound(cfg, t)
                .max(self.speed_bound(cfg, (t + self.last_dt).min(dur)));
            let speed = bound * r.speed_safety;
            let mut dt = if speed > 0.0 {
                (r.max_px_per_step / speed).clamp(r.min_step_s, r.max_step_s)
            } else {
                r.max_step_s
            };
            if t + dt > dur - 0.5 * r.min_step_s {
                dt = dur - t;
            }
            self.last_dt = dt;
            travel += speed * dt;
            times.push(t + dt);
        }
        (times, travel)
    }

    /// Largest change of any moving object's face shading (log units) between two times.
    fn shade_change(&self, t0: f64, t1: f64) -> f32 {
        let mut worst = 0.0f64;
        for b in self.scene.boxes.iter().filter(|b| b.id != 0) {
            let (r0, r1) = (b.trajectory.state(t0).rotation, b.trajectory.state(t1).rotation);
            for face in 0..6 {
                let mut n = [0.0; 3];
                n[face / 2] = if face % 2 == 0 { -1.0 } else { 1.0 };
                let l = &self.scene.lighting;
                let d = l.ln_shade(math::mul_mv(&r0, n)) - l.ln_shade(math::mul_mv(&r1, n));
                worst = worst.max(d.abs());
            }
        }
        worst as f32
    }

    /// Ray casts every pixel at `kf1.geom` into `kf1` (edge pixels supersampled) and updates
    /// the background depth summary.
    fn render_keyframe(&mut self, cfg: &SceneConfig) {
        let (w, h) = (self.rays.width, self.rays.height);
        let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
        if self.blocks.is_empty() {
            // Largest change of the normalized ray per pixel along either image axis.
            let (mut gx, mut gy) = (0.0f64, 0.0f64);
            for (a, b) in self.rays.d_du.iter().zip(&self.rays.d_dv) {
                gx = gx.max((a[0].abs() + b[0].abs()) as f64);
                gy = gy.max((a[1].abs() + b[1].abs()) as f64);
            }
            for by in 0..bh {
                for bx in 0..bw {
                    let (cu, cv) = (
                        (bx * BLOCK + BLOCK / 2).min(w - 1),
                        (by * BLOCK + BLOCK / 2).min(h - 1),
                    );
                    let i = cv * w + cu;
                    let (x, y) = (self.rays.x[i] as f64, self.rays.y[i] as f64);
                    // Farthest pixel of the block from its centre, px, along either axis.
                    let reach = |c: usize, b: usize, n: usize| {
                        let (lo, hi) = (b * BLOCK, ((b + 1) * BLOCK).min(n) - 1);
                        (c - lo).max(hi - c) as f64
                    };
                    let off = reach(cu, bx, w).max(reach(cv, by, h));
                    self.blocks.push(DepthBlock {
                        x,
                        y,
                        hx: off * gx,
                        hy: off * gy,
                        zmin: f64::INFINITY,
                        zmin_prev: f64::INFINITY,
                    });
                }
            }
        }
        if self.block_geometry[0].len() != self.blocks.len() {
            let b = &self.blocks;
            self.block_geometry = [
                b.iter().map(|b| b.x).collect(),
                b.iter().map(|b| b.y).collect(),
                b.iter().map(|b| b.hx).collect(),
                b.iter().map(|b| b.hy).collect(),
            ];
        }
        let mut block_z = vec![f32::INFINITY; bw * bh];
        cast_keyframe(&mut self.kf1, &self.scene, &self.rays, &mut block_z);
        let kf = &mut self.kf1;
        let mut zmin = f32::INFINITY;
        for (b, z) in self.blocks.iter_mut().zip(&block_z) {
            b.zmin_prev = b.zmin;
            b.zmin = *z as f64;
            zmin = zmin.min(*z);
        }
        if zmin.is_finite() && zmin > 0.0 {
            self.zmin_bg = zmin as f64;
        }
        // Edges row by row without branches: outside the image a pixel is compared with
        // itself (never different).
        kf.mixed.fill(false);
        kf.edge_objects.clear();
        for y in 0..h {
            let row = &kf.key[y * w..(y + 1) * w];
            let up = if y > 0 { &kf.key[(y - 1) * w..y * w] } else { row };
            let down = if y + 1 < h {
                &kf.key[(y + 1) * w..(y + 2) * w]
            } else {
                row
            };
            let edge = &mut kf.edge[y * w..(y + 1) * w];
            // Interior columns as shifted slices (vectorised), then the border columns.
            let inner = w.saturating_sub(2);
            let cols = edge[1..1 + inner]
                .iter_mut()
                .zip(&row[1..1 + inner])
                .zip(row[..inner].iter().zip(&row[2.min(w)..]))
                .zip(up[1..1 + inner].iter().zip(&down[1..1 + inner]));
            for (((e, &k), (&left, &right)), (&u, &d)) in cols {
                *e = (left != k) | (right != k) | (u != k) | (d != k);
            }
            for x in [0, w - 1] {
                let k = row[x];
                let (left, right) = (row[x.saturating_sub(1)], row[(x + 1).min(w - 1)]);
                edge[x] = (left != k) | (right != k) | (up[x] != k) | (down[x] != k);
            }
        }
        if cfg.render.edge_supersampling {
            // Edge pixels are a few percent: blocks of 64 without one are skipped whole.
            let n = w * h;
            let blocks = (0..n)
                .step_by(64)
                .filter(|&b| kf.edge[b..(b + 64).min(n)].contains(&true));
            for i in blocks.flat_map(|b| b..(b + 64).min(n)) {
                if kf.edge[i] {
                    let r = &self.rays;
                    let (x, y) = ((i % w) as i32, (i / w) as i32);
                    let value = kf.geom.edge_sample(
                        &self.scene,
                        r.x[i],
                        r.y[i],
                        r.d_du[i],
                        r.d_dv[i],
                        x,
                        y,
                        (kf.l[i], kf.key[i]),
                    );
                    (kf.l[i], kf.mixed[i]) = (value.l, value.mixed);
                    if let Some(o) = value.truth_object(kf.id[i]) {
                        kf.edge_objects.push((i as u32, Seen::from(o)));
                    }
                    self.stats.supersampled += 1;
                }
            }
        }
        self.stats.pixel_renders += (w * h) as u64;
        self.stats.keyframes += 1;
    }

    /// Simulates one interval; appends its events (sorted by time) to `out`.
    pub fn advance(&mut self, cfg: &SceneConfig, out: &mut Vec<RawEvent>) {
        let (times, travel) = self.plan(cfg);
        let k = times.len() - 1;
        if k == 0 {
            self.t = cfg.duration_s;
            return;
        }
        let (t0, t1) = (times[0], times[k]);
        self.stats.steps += k as u64;
        self.kf1.geom = FrameGeom::new(&self.scene, &cfg.camera, t1);
        self.render_keyframe(cfg);
        let radius = (travel.ceil() as usize + 1).min(256);
        let shade = self.shade_change(t0, t1);
        self.classify(cfg, radius, shade);
        let listed = ListedPixels {
            kf0: &self.kf0,
            kf1: &self.kf1,
            scene: &self.scene,
            class: &self.class,
            thresholds: &self.thresholds,
            span: (t0, t1),
            max_px: cfg.render.max_px_per_step as f32,
            width: self.rays.width,
        };

        // The interval's events (buffer reused across intervals).
        let mut batch = std::mem::take(&mut self.batch);
        batch.clear();
        let ctx = FireCtx {
            scene: &self.scene,
            cam: &cfg.camera,
            rays: &self.rays,
            refractory: cfg.esim.refractory_s,
        };
        // Geometry of every render step (unstable pixels, noise labels).
        let mut geoms: Vec<FrameGeom> = Vec::with_capacity(k + 1);
        geoms.push(self.kf0.geom.clone());
        for &t in &times[1..k] {
            geoms.push(FrameGeom::new(&self.scene, &cfg.camera, t));
        }
        geoms.push(self.kf1.geom.clone());

        // Quiet and stable pixels.
        let mut path: Vec<f32> = Vec::new();
        let counts = listed.fire(
            &ctx,
            &self.work,
            (&mut self.reference, &mut self.last_event),
            &mut batch,
            &mut path,
        );
        let (violations, mut fired) = (counts.violations, counts.fired);
        self.stats.skip_violations += violations;
        self.stats.interpolated_samples += counts.samples;

        // Unstable pixels: ray cast at the steps their local speed bound needs.
        let speeds = self.local_speeds(cfg, &geoms);
        let u = &mut self.unstable;
        u.gather(
            &self.class,
            UNSTABLE,
            &PixelState {
                rays: &self.rays,
                reference: &self.reference,
                last_event: &self.last_event,
                c_on: &self.thresholds.on,
                c_off: &self.thresholds.off,
                kf0: &self.kf0,
            },
        );
        let w = self.rays.width;
        // Every pixel waits in the bucket of its next render slot.
        let mut schedules = local_speed::Schedules::new(&times, cfg.render.max_px_per_step);
        let key_slot = schedules.key_slot();
        let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); key_slot];
        for (j, &p) in u.pixel.iter().enumerate() {
            let p = p as usize;
            let sch = schedules.of(speeds.at(p % w, p / w));
            u.schedule[j] = sch;
            let first = schedules.lists[sch as usize][0] as usize;
            if first < key_slot {
                buckets[first].push(j as u32);
            }
        }
        // Geometry of the render slots inside steps that some schedule uses.
        let mut sub_geoms: Vec<Option<FrameGeom>> = vec![None; key_slot];
        for list in &schedules.lists {
            for &q in list {
                let q = q as usize;
                if !q.is_multiple_of(local_speed::SUBSTEPS) && sub_geoms[q].is_none() {
                    let t = local_speed::slot_time(&times, q);
                    sub_geoms[q] = Some(FrameGeom::new(&self.scene, &cfg.camera, t));
                }
            }
        }
        let geom_at = |q: usize| -> &FrameGeom {
            if q.is_multiple_of(local_speed::SUBSTEPS) {
                &geoms[q / local_speed::SUBSTEPS]
            } else {
                sub_geoms[q].as_ref().expect("geometry of a scheduled slot")
            }
        };
        for q in 1..=key_slot {
            if q < key_slot {
                if buckets[q].is_empty() {
                    continue;
                }
                u.active = std::mem::take(&mut buckets[q]);
                let ss = u.render(&self.scene, geom_at(q), w, cfg.render.edge_supersampling);
                self.stats.pixel_renders += u.active.len() as u64;
                self.stats.supersampled += ss;
            }
            let ctx = FireCtx {
                scene: &self.scene,
                cam: &cfg.camera,
                rays: &self.rays,
                refractory: cfg.esim.refractory_s,
            };
            let count = if q < key_slot { u.active.len() } else { u.len() };
            let tq = local_speed::slot_time(&times, q);
            // The list's columns as slices of one length, so that one test of `j` covers
            // every access below (`active` holds list indices: the test never skips).
            let n = u.len();
            let UnstableList {
                pixel,
                reference,
                last_event,
                c_on,
                c_off,
                l_prev,
                seen_prev,
                l,
                key,
                id,
                z,
                edge_object,
                schedule,
                next,
                s_prev,
                active,
                ..
            } = &mut *u;
            let (pixel, c_on, c_off, l, key, id, z) = (
                &pixel[..n],
                &c_on[..n],
                &c_off[..n],
                &l[..n],
                &key[..n],
                &id[..n],
                &z[..n],
            );
            let (edge_object, schedule) = (&edge_object[..n], &schedule[..n]);
            let (reference, last_event, l_prev) =
                (&mut reference[..n], &mut last_event[..n], &mut l_prev[..n]);
            let (seen_prev, next, s_prev) = (&mut seen_prev[..n], &mut next[..n], &mut s_prev[..n]);
            // Slot renders in bucket order, the closing key frame in list order.
            let order = if q < key_slot { &active[..count] } else { &[][..] };
            for a in 0..count {
                let j = order.get(a).map_or(a, |&j| j as usize);
                if j >= n {
                    continue;
                }
                let i = pixel[j] as usize;
                let (l1, seen1) = if q < key_slot {
                    (l[j], unstable::seen_at(edge_object, id, key, z, j))
                } else {
                    (self.kf1.l[i], self.kf1.seen(i))
                };
                let sp = s_prev[j] as usize;
                if esim::may_cross(reference[j], l1, c_on[j], c_off[j]) {
                    let before = batch.len();
                    fire(
                        &ctx,
                        &mut reference[j],
                        &mut last_event[j],
                        i,
                        l_prev[j],
                        l1,
                        (local_speed::slot_time(&times, sp), tq),
                        (geom_at(sp), geom_at(q)),
                        (seen_prev[j], seen1),
                        (c_on[j], c_off[j]),
                        &mut batch,
                    );
                    fired += (batch.len() - before) as u64;
                }
                l_prev[j] = l1;
                seen_prev[j] = seen1;
                s_prev[j] = q as u32;
                if q < key_slot {
                    next[j] += 1;
                    let nq = schedules.lists[schedule[j] as usize][next[j] as usize] as usize;
                    if nq < key_slot {
                        buckets[nq].push(j as u32);
                    }
                }
            }
        }
        u.scatter(&mut self.reference, &mut self.last_event);
        self.stats.model_events += fired + violations;

        // Noise, labelled with the surface at its pixel at the nearest render step.
        let w = self.rays.width;
        let mut noise = 0u64;
        let (scene, rays, cam) = (&self.scene, &self.rays, &cfg.camera);
        self.noise.until(t1, |t, p, pol| {
            let s = times.partition_point(|&x| x < t).min(k);
            let s = if s > 0 && (t - times[s - 1]) < (times[s] - t) {
                s - 1
            } else {
                s
            };
            let g = &geoms[s];
            let i = p as usize;
            let (x, y, u, v) = (rays.x[i], rays.y[i], (i % w) as i32, (i / w) as i32);
            let hit = g.cast(scene, x, y, u, v, None);
            let (fx, fy) = g.flow(scene, cam, x, y, u, v, hit.id).unwrap_or((0.0, 0.0));
            batch.push(RawEvent {
                t,
                pixel: p,
                p: pol,
                id: hit.id,
                fx: fx as f32,
                fy: fy as f32,
            });
            noise += 1;
        });
        self.stats.noise_events += noise;

        if batch.iter().any(|e| e.t.is_sign_negative()) {
            batch.sort_by(|a, b| a.t.total_cmp(&b.t));
        } else {
            // Non-negative times order like their bit patterns (a stable sort, as above).
            radix::sort_by_key(&mut batch, &mut self.sort_scratch, |e| e.t.to_bits());
        }
        out.extend_from_slice(&batch);
        self.batch = batch;
        std::mem::swap(&mut self.kf0, &mut self.kf1);
        self.t = t1;
    }

    /// Sorts every pixel into quiet, stable or unstable for the interval.
    fn classify(&mut self, cfg: &SceneConfig, radius: usize, shade_margin: f32) {
        let (w, h) = (self.rays.width, self.rays.height);
        let (kf0, kf1) = (&self.kf0, &self.kf1);
        // Zipped slices: no bounds checks or reloads of the vectors per pixel (vectorised).
        let n = w * h;
        let ends = self.lo[..n].iter_mut().zip(&mut self.hi[..n]);
        for ((lo, hi), (&a, &b)) in ends.zip(kf0.l[..n].iter().zip(&kf1.l[..n])) {
            *lo = fmin(a, b);
            *hi = fmax(a, b);
        }
        filters::window_min_max_in_place(&mut self.lo, &mut self.hi, w, h, radius, &mut self.scratch);
        let margin = cfg.render.quiet_margin_log as f32;
        let (on, off, reference) = (
            &self.thresholds.on[..n],
            &self.thresholds.off[..n],
            &self.reference[..n],
        );
        let inputs = ClassInputs {
            lo: &self.lo[..n],
            hi: &self.hi[..n],
            on,
            off,
            reference,
            l1: &kf1.l[..n],
            id0: &kf0.id[..n],
            id1: &kf1.id[..n],
            key0: &kf0.key[..n],
            key1: &kf1.key[..n],
            mixed0: &kf0.mixed[..n],
            mixed1: &kf1.mixed[..n],
        };
        self.listed.resize(n, 0);
        classify_pixels(
            &inputs,
            margin,
            shade_margin,
            &mut self.class[..n],
            &mut self.listed[..n],
        );
        // The work list through a cursor that advances only for listed pixels (no branch per
        // pixel).
        self.work.clear();
        self.work.resize(n, 0);
        let work = &mut self.work[..];
        let mut listed = 0usize;
        for (i, &f) in self.listed[..n].iter().enumerate() {
            work[listed] = i as u32;
            listed += usize::from(f);
        }
        self.work.truncate(listed);
    }
}

/// The per-pixel arrays [`classify_pixels`] reads (all of one length).
struct ClassInputs<'a> {
    /// Window minimum and maximum of both key frames' log intensities.
    lo: &'a [f32],
    hi: &'a [f32],
    /// Thresholds and reference levels.
    on: &'a [f32],
    off: &'a [f32],
    reference: &'a [f32],
    /// Log intensities of the closing key frame.
    l1: &'a [f32],
    /// Object ids, surface keys and mixed flags of both key frames.
    id0: &'a [u16],
    id1: &'a [u16],
    key0: &'a [u16],
    key1: &'a [u16],
    mixed0: &'a [bool],
    mixed1: &'a [bool],
}

/// The class of every pixel (`QUIET`, `STABLE` or `UNSTABLE`) into `class`, and into `listed`
/// 1 for the pixels `Engine::advance` visits (stable pixels and quiet pixels that may cross at
/// the closing key frame), else 0. Without branches: with AVX2 (detected at run time) the
/// loop runs in vector registers; the same comparisons, so the same classes.
fn classify_pixels(c: &ClassInputs, margin: f32, shade_margin: f32, class: &mut [u8], listed: &mut [u8]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is available (checked just above).
        return unsafe { classify_pixels_avx2(c, margin, shade_margin, class, listed) };
    }
    classify_pixels_with(c, margin, shade_margin, class, listed);
}

/// [`classify_pixels`] compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn classify_pixels_avx2(
    c: &ClassInputs,
    margin: f32,
    shade_margin: f32,
    class: &mut [u8],
    listed: &mut [u8],
) {
    classify_pixels_with(c, margin, shade_margin, class, listed);
}

/// The body of [`classify_pixels`].
#[inline(always)]
fn classify_pixels_with(
    c: &ClassInputs,
    margin: f32,
    shade_margin: f32,
    class: &mut [u8],
    listed: &mut [u8],
) {
    let n = class.len().min(listed.len());
    let (lo, hi, on, off, reference, l1s) = (
        &c.lo[..n],
        &c.hi[..n],
        &c.on[..n],
        &c.off[..n],
        &c.reference[..n],
        &c.l1[..n],
    );
    let (id0, id1, key0, key1, mixed0, mixed1) = (
        &c.id0[..n],
        &c.id1[..n],
        &c.key0[..n],
        &c.key1[..n],
        &c.mixed0[..n],
        &c.mixed1[..n],
    );
    let (class, listed) = (&mut class[..n], &mut listed[..n]);
    // Non-short-circuit `&` and `|` keep the tests branch-free.
    for i in 0..n {
        let m = margin + if (id0[i] | id1[i]) != 0 { shade_margin } else { 0.0 };
        let r = reference[i];
        let quiet = (hi[i] + m < r + on[i]) & (lo[i] - m > r - off[i]);
        // The same surface at both key frames, without the other surface of a nearby edge
        // inside the pixel: its texture coordinates move smoothly in between (edges move
        // by under a pixel per render step and do not turn back within an interval).
        let same = (key0[i] == key1[i]) & !mixed0[i] & !mixed1[i] & (key0[i] != u16::MAX);
        // QUIET, else STABLE or UNSTABLE.
        class[i] = u8::from(!quiet) * (STABLE + u8::from(!same));
        // Quiet pixels whose key-frame value is strictly inside the thresholds cannot
        // cross; the others (and stable pixels) are visited by `advance`, in pixel order.
        let l1 = l1s[i];
        let settled = quiet & (l1 < r + on[i]) & (l1 > r - off[i]);
        listed[i] = u8::from(!settled & (quiet | same));
    }
}

/// Ray casts every pixel of `rays` at `kf.geom` into `kf` (before edge sampling) and lowers
/// `block_z` (per `BLOCK` x `BLOCK` block) to the background depths seen. With AVX2 (detected
/// at run time) the same code is compiled for it: the same arithmetic, so the same values
/// (no fused multiply-adds), with the lane samples inlined.
fn cast_keyframe(kf: &mut KeyFrame, scene: &Scene, rays: &Rays, block_z: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is available (checked just above).
        return unsafe { cast_keyframe_avx2(kf, scene, rays, block_z) };
    }
    cast_keyframe_with(kf, scene, rays, block_z);
}

/// [`cast_keyframe`] compiled with AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn cast_keyframe_avx2(kf: &mut KeyFrame, scene: &Scene, rays: &Rays, block_z: &mut [f32]) {
    cast_keyframe_with(kf, scene, rays, block_z);
}

/// The body of [`cast_keyframe`].
#[inline(always)]
fn cast_keyframe_with(kf: &mut KeyFrame, scene: &Scene, rays: &Rays, block_z: &mut [f32]) {
    let (w, h) = (rays.width, rays.height);
    let bw = w.div_ceil(BLOCK);
    for v in 0..h {
        let brow = (v / BLOCK) * bw;
        let row = v * w;
        // Rays are cast a group of `KEY_LANES` at a time along the row (see
        // `FrameGeom::cast_lanes`), the rest one by one. Plain loops: `array::from_fn` and
        // `array::map` closures were left out of line.
        let mut u = 0;
        while u + KEY_LANES <= w {
            let i = row + u;
            let x: &[f32; KEY_LANES] = rays.x[i..i + KEY_LANES].try_into().expect("lane slice");
            let y: &[f32; KEY_LANES] = rays.y[i..i + KEY_LANES].try_into().expect("lane slice");
            let mut px = [0i32; KEY_LANES];
            for (l, p) in px.iter_mut().enumerate() {
                *p = (u + l) as i32;
            }
            let h = kf.geom.cast_lanes(scene, x, y, &px, &[v as i32; KEY_LANES]);
            // Whole lanes at a time (scalar stores to seven arrays cost as much as shading).
            let span = i..i + KEY_LANES;
            kf.l[span.clone()].copy_from_slice(&h.l);
            kf.key[span.clone()].copy_from_slice(&h.key);
            kf.id[span.clone()].copy_from_slice(&h.id);
            kf.u[span.clone()].copy_from_slice(&h.u);
            kf.v[span.clone()].copy_from_slice(&h.v);
            kf.footprint[span.clone()].copy_from_slice(&h.footprint);
            kf.z[span].copy_from_slice(&h.z);
            for l in 0..KEY_LANES {
                if h.id[l] == 0 {
                    let b = &mut block_z[brow + (u + l) / BLOCK];
                    *b = b.min(h.z[l]);
                }
            }
            u += KEY_LANES;
        }
        for u in u..w {
            let i = row + u;
            let hit = kf
                .geom
                .cast(scene, rays.x[i], rays.y[i], u as i32, v as i32, None);
            kf.l[i] = hit.l;
            kf.key[i] = hit.key;
            kf.id[i] = hit.id;
            kf.u[i] = hit.u;
            kf.v[i] = hit.v;
            kf.footprint[i] = hit.footprint;
            kf.z[i] = hit.z;
            if hit.id == 0 {
                let b = &mut block_z[brow + u / BLOCK];
                *b = b.min(hit.z);
            }
        }
    }
}

/// Bound of the normalized image speed (1/s) of a moving box with motion `m` relative to the
/// camera, camera-frame `pose` and `corners`, half extents `half` (m), at image radius
/// `<= r_max`: the smallest of the corner bound, the centred corner bound (see
/// `RelativeMotion::speed_bound_box_centred`) and the bound of its circumscribed ball.
fn object_speed(
    m: &scene::RelativeMotion,
    pose: &scene::BoxPose,
    corners: &[math::Vec3; 8],
    half: math::Vec3,
    r_max: f64,
) -> f64 {
    let zmin = corners.iter().map(|c| c[2]).fold(f64::INFINITY, f64::min);
    let ball = m.speed_bound_ball(pose.center, math::norm(half), zmin.max(0.1), r_max);
    let b = m.speed_bound_box(corners, r_max).map_or(ball, |b| b.min(ball));
    m.speed_bound_box_centred(corners).map_or(b, |c| c.min(b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::RenderConfig;
    use crate::presets::preset;

    /// For every camera-frame point of `pts(t)` in the image at either end of the step
    /// `[ta, tb]`: its largest image distance (px) from its position at `ta` over four later
    /// instants of the step, its position at `ta` and its image displacement (px) over the
    /// step, appended to `out`.
    #[allow(clippy::needless_range_loop)]
    fn excursion(
        cam: &crate::camera::CameraConfig,
        pts: &dyn Fn(f64) -> Vec<math::Vec3>,
        ta: f64,
        tb: f64,
        out: &mut Vec<(f64, f64, f64, f64)>,
    ) {
        let (w, h) = (cam.width as f64, cam.height as f64);
        let inside = |p: Option<(f64, f64)>| {
            p.is_some_and(|(x, y)| x >= -0.5 && y >= -0.5 && x <= w - 0.5 && y <= h - 0.5)
        };
        let sub: Vec<Vec<math::Vec3>> = (0..=4).map(|s| pts(ta + (tb - ta) * s as f64 / 4.0)).collect();
        for j in 0..sub[0].len() {
            let p0 = cam.project(sub[0][j]);
            let p1 = cam.project(sub[4][j]);
            if !(inside(p0) || inside(p1)) {
                continue;
            }
            let (Some(a), Some(b)) = (p0, p1) else { continue };
            let mut m: f64 = 0.0;
            for s in 1..=4 {
                if let Some(q) = cam.project(sub[s][j]) {
                    m = m.max((q.0 - a.0).hypot(q.1 - a.1));
                }
            }
            out.push((m, a.0, a.1, (b.0 - a.0).hypot(b.1 - a.1)));
        }
    }

    /// Measurement (ignored by default; prints, checks nothing): the largest image
    /// displacement of any sampled scene point per render step against `max_px_per_step`
    /// (background points from every second pixel of each interval's opening key frame, back
    /// projected with its depths; moving boxes from a 17 x 17 grid on every face), and each
    /// point's displacement over the step against the local speed bound (unstable pixels'
    /// schedules) at its pixel at the step's start. `SIM_MEASURE_PRESETS` (comma separated),
    /// `SIM_MEASURE_SECONDS`, `SIM_MEASURE_SAFETY` (`speed_safety`). Run with
    /// `cargo test --release -p evseg-sim --lib measure_step -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn measure_step_displacements() {
        let names = std::env::var("SIM_MEASURE_PRESETS").unwrap_or("one-object".into());
        let secs: f64 = std::env::var("SIM_MEASURE_SECONDS")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(0.5);
        let safety: f64 = std::env::var("SIM_MEASURE_SAFETY")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(RenderConfig::default().speed_safety);
        for name in names.split(',') {
            let mut cfg = preset(name, 1).unwrap();
            cfg.render.speed_safety = safety;
            cfg.duration_s = cfg.duration_s.min(secs);
            let mut e = Engine::new(&cfg);
            let cam = cfg.camera.clone();
            let (w, h) = (e.rays.width, e.rays.height);
            let mut out = Vec::new();
            let (mut worst_bg, mut worst_obj, mut worst_local) = (0.0f64, 0.0f64, 0.0f64);
            let (mut sum_step_worst, mut n_steps, mut over) = (0.0f64, 0usize, 0usize);
            let mut local_over = 0usize;
            let mut steps = 0usize;
            while e.t < cfg.duration_s - 1e-12 {
                let last_dt = e.last_dt;
                let (times, _) = e.plan(&cfg);
                e.last_dt = last_dt;
                let geoms: Vec<FrameGeom> =
                    times.iter().map(|&t| FrameGeom::new(&e.scene, &cam, t)).collect();
                let speeds = e.local_speeds(&cfg, &geoms);
                // Background points of the opening key frame, in the world frame.
                let c0 = e.scene.camera_state(times[0]);
                let mut world = Vec::new();
                for v in (0..h).step_by(2) {
                    for u in (0..w).step_by(2) {
                        let i = v * w + u;
                        let z = e.kf0.z[i] as f64;
                        if e.kf0.id[i] != 0 || !z.is_finite() {
                            continue;
                        }
                        let p = [e.rays.x[i] as f64 * z, e.rays.y[i] as f64 * z, z];
                        world.push(math::add(math::mul_mv(&c0.rotation, p), c0.position));
                    }
                }
                let scene = &e.scene;
                let bg = |t: f64| -> Vec<math::Vec3> {
                    let c = scene.camera_state(t);
                    let r = math::transpose(&c.rotation);
                    world
                        .iter()
                        .map(|x| math::mul_mv(&r, math::sub(*x, c.position)))
                        .collect()
                };
                let obj = |t: f64| -> Vec<math::Vec3> {
                    let c = scene.camera_state(t);
                    let mut pts = Vec::new();
                    for b in scene.boxes.iter().filter(|b| b.id != 0) {
                        let pose = scene::BoxPose::new(&c, &b.trajectory.state(t));
                        for f in 0..6 {
                            let (ax, sign) = (f / 2, if f % 2 == 0 { -1.0 } else { 1.0 });
                            let (a1, a2) = ((ax + 1) % 3, (ax + 2) % 3);
                            for i in 0..17 {
                                for j in 0..17 {
                                    let mut s = [0.0; 3];
                                    s[ax] = sign * b.half[ax];
                                    s[a1] = b.half[a1] * (i as f64 / 8.0 - 1.0);
                                    s[a2] = b.half[a2] * (j as f64 / 8.0 - 1.0);
                                    pts.push(math::add(pose.center, math::mul_mv(&pose.r_cb, s)));
                                }
                            }
                        }
                    }
                    pts
                };
                for k in 0..times.len() - 1 {
                    let (ta, tb) = (times[k], times[k + 1]);
                    let (mut rb, mut ro) = (Vec::new(), Vec::new());
                    excursion(&cam, &bg, ta, tb, &mut rb);
                    excursion(&cam, &obj, ta, tb, &mut ro);
                    let mut step_worst: f64 = 0.0;
                    for (set, worst) in [(&rb, &mut worst_bg), (&ro, &mut worst_obj)] {
                        for &(m, x, y, chord) in set.iter() {
                            *worst = worst.max(m);
                            step_worst = step_worst.max(m);
                            over += usize::from(m > cfg.render.max_px_per_step);
                            // Local bound at the start pixel (px/s, safety included).
                            let (xi, yi) = (
                                x.round().clamp(0.0, (w - 1) as f64),
                                y.round().clamp(0.0, (h - 1) as f64),
                            );
                            let local = speeds.at(xi as usize, yi as usize) as f64;
                            let r = chord / ((tb - ta) * local);
                            worst_local = worst_local.max(r);
                            local_over += usize::from(r > 1.0);
                        }
                    }
                    sum_step_worst += step_worst;
                    n_steps += 1;
                }
                steps += times.len() - 1;
                e.advance(&cfg, &mut out);
                out.clear();
            }
            println!(
                "{name} safety {safety}: {steps} steps, events {}; largest excursion per step px: background {worst_bg:.6}, objects {worst_obj:.6}; mean of per-step largest {:.4}; points over {}: {over}; largest chord / local bound {worst_local:.6} ({local_over} over)",
                e.stats.model_events,
                sum_step_worst / n_steps as f64,
                cfg.render.max_px_per_step,
            );
        }
    }
}
