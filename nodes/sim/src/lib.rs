//! Event-camera simulator (ESIM model) with ground truth.
//!
//! A pinhole camera (optionally with radial-tangential distortion; the event pixel grid is the
//! distorted image) moves on a smooth 6-DoF trajectory through a room of textured planes and
//! boxes, with up to a few independently moving textured boxes. The scene is ray cast per
//! pixel, log intensities are interpolated linearly between renders and every crossing of a
//! per-pixel contrast threshold fires an event (ESIM, Rebecq et al. 2018). Ground truth comes
//! with every event (object id, optical flow) and as streams (masks, camera motion, object
//! poses, IMU).
//!
//! Usage: [`preset`] gives a [`SceneConfig`]; [`Simulator::new`] then repeated
//! [`Simulator::next_chunk`] stream the sequence in batches of any size (the output does not
//! depend on the batch sizes).
//!
//! Render schedule: steps are chosen so that no scene point moves more than
//! `render.max_px_per_step` pixels between renders. Every `render.steps_per_keyframe` steps all
//! pixels are rendered (a key frame); in between only pixels that could cross a threshold are:
//! a pixel is skipped when the log intensities of the previous key frame within the distance
//! scene points can travel until the next key frame all stay inside the pixel's thresholds
//! (with a margin), and it is not near a surface edge or the image border. Skipped pixels are
//! still fed to the event model between key frames, so a wrong skip would shift events in time
//! but never lose them; [`SimStats::skip_violations`] counts such cases.

pub mod camera;
pub mod config;
pub mod esim;
pub mod imu;
pub mod math;
pub mod presets;
pub mod render;
pub mod rng;
pub mod scene;
pub mod texture;
pub mod trajectory;
pub mod truth;

use evseg_schemas::{CameraInfo, Events, ImuSample, Truth};

pub use camera::CameraConfig;
pub use config::{RenderConfig, SceneConfig, TruthConfig};
pub use esim::EsimConfig;
pub use imu::{IMU_TO_CAMERA, ImuConfig};
pub use presets::{PRESET_NAMES, preset};
pub use scene::{BoxConfig, Lighting, ObjectConfig, PlaneConfig, SceneContent};
pub use texture::{Pattern, TextureConfig};
pub use trajectory::{RigidTrajectory, Signal, Sinusoid};

use camera::Rays;
use esim::{NoiseSource, Thresholds};
use imu::ImuSampler;
use render::FrameGeom;
use scene::Scene;

/// Errors of the simulator.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// A configuration value is out of range; the message names the field.
    #[error("invalid simulator configuration: {0}")]
    Config(String),
    /// No preset has this name.
    #[error("unknown simulator preset '{name}'; valid presets: {valid}")]
    UnknownPreset {
        /// The name asked for.
        name: String,
        /// Comma-separated list of valid names.
        valid: String,
    },
}

/// One batch of simulated output covering `[previous t_end, t_end)`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimChunk {
    /// Events, sorted by time.
    pub events: Events,
    /// Ground truth: per-event object id and flow aligned with `events`, plus the masks,
    /// camera-motion samples and object poses whose time falls in the batch.
    pub truth: Truth,
    /// IMU samples (IMU frame, see [`IMU_TO_CAMERA`]) whose time falls in the batch.
    pub imu: Vec<ImuSample>,
}

/// Counters of the work done so far.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SimStats {
    /// Render steps (time instants at which pixels were rendered).
    pub steps: u64,
    /// Key frames (all pixels rendered).
    pub keyframes: u64,
    /// Rays cast for pixel centres (key frames plus active pixels between them).
    pub pixel_renders: u64,
    /// Pixels supersampled for edge anti-aliasing.
    pub supersampled: u64,
    /// Events from the threshold model.
    pub model_events: u64,
    /// Noise events.
    pub noise_events: u64,
    /// Skipped pixels that nevertheless fired between two key frames (should stay near 0).
    pub skip_violations: u64,
}

/// Side of the square pixel blocks whose smallest background depth bounds image speeds.
const BLOCK: usize = 16;

/// One block of the background depth summary of the last key frame.
#[derive(Debug, Clone, Copy)]
struct DepthBlock {
    /// Normalized coordinates of the block centre.
    x: f64,
    y: f64,
    /// Factor covering the change of rotational flow across the block.
    rot_margin: f64,
    /// Smallest background depth in the block, m (infinite if none).
    zmin: f64,
}

#[derive(Debug, Clone, Copy)]
struct RawEvent {
    t: f64,
    pixel: u32,
    p: u8,
    id: u16,
    fx: f32,
    fy: f32,
}

/// Per-pixel buffers, row-major.
#[derive(Debug, Clone)]
struct Pixels {
    reference: Vec<f32>,
    last_event: Vec<f64>,
    l_prev: Vec<f32>,
    id_prev: Vec<u16>,
    l_now: Vec<f32>,
    id_now: Vec<u16>,
    key_now: Vec<u16>,
    stamp: Vec<u32>,
    active: Vec<bool>,
    tmp_a: Vec<f32>,
    tmp_b: Vec<f32>,
    lo: Vec<f32>,
    hi: Vec<f32>,
    band: Vec<u8>,
    band_tmp: Vec<u8>,
}

/// The streaming simulator.
#[derive(Debug, Clone)]
pub struct Simulator {
    cfg: SceneConfig,
    scene: Scene,
    rays: Rays,
    thresholds: Thresholds,
    noise: NoiseSource,
    imu: ImuSampler,
    px: Pixels,
    stamp_counter: u32,
    /// Time up to which events have been generated (the last key frame).
    t_sim: f64,
    key_geom: FrameGeom,
    last_dt: f64,
    zmin_bg: f64,
    blocks: Vec<DepthBlock>,
    /// Start of the next chunk.
    t_emitted: f64,
    pending: Vec<RawEvent>,
    pending_head: usize,
    next_mask: u64,
    next_camera: u64,
    stats: SimStats,
}

impl Simulator {
    /// Validates `config`, bakes the textures and renders the first key frame at t = 0.
    pub fn new(config: SceneConfig) -> Result<Self, SimError> {
        config.validate()?;
        let scene = Scene::new(&config.scene, config.camera_trajectory.clone(), config.seed, config.esim.log_eps);
        let rays = Rays::new(&config.camera);
        let n = rays.width * rays.height;
        let mut rng = rng::Rng::new(config.seed, 0x7e5);
        let thresholds = Thresholds::draw(&config.esim, n, &mut rng);
        let noise = NoiseSource::new(&config.esim, n, config.seed);
        let imu = ImuSampler::new(config.imu.clone(), config.seed);
        let px = Pixels {
            reference: vec![0.0; n],
            last_event: vec![f64::NEG_INFINITY; n],
            l_prev: vec![0.0; n],
            id_prev: vec![0; n],
            l_now: vec![0.0; n],
            id_now: vec![0; n],
            key_now: vec![0; n],
            stamp: vec![0; n],
            active: vec![false; n],
            tmp_a: vec![0.0; n],
            tmp_b: vec![0.0; n],
            lo: vec![0.0; n],
            hi: vec![0.0; n],
            band: vec![0; n],
            band_tmp: vec![0; n],
        };
        let key_geom = FrameGeom::new(&scene, &config.camera, 0.0);
        let mut sim = Self {
            last_dt: config.render.max_step_s,
            cfg: config,
            scene,
            rays,
            thresholds,
            noise,
            imu,
            px,
            stamp_counter: 0,
            t_sim: 0.0,
            key_geom,
            zmin_bg: 1.0,
            blocks: Vec::new(),
            t_emitted: 0.0,
            pending: Vec::new(),
            pending_head: 0,
            next_mask: 0,
            next_camera: 0,
            stats: SimStats::default(),
        };
        let geom = sim.key_geom.clone();
        sim.render_keyframe(&geom);
        let p = &mut sim.px;
        p.reference.copy_from_slice(&p.l_now);
        p.l_prev.copy_from_slice(&p.l_now);
        p.id_prev.copy_from_slice(&p.id_now);
        Ok(sim)
    }

    /// The simulated camera's calibration (IMU axes: [`IMU_TO_CAMERA`], time offset 0).
    pub fn camera_info(&self) -> CameraInfo {
        let c = &self.cfg.camera;
        let r = IMU_TO_CAMERA;
        CameraInfo {
            width: c.width,
            height: c.height,
            fx: c.fx,
            fy: c.fy,
            cx: c.cx,
            cy: c.cy,
            distortion: c.distortion,
            imu_to_camera: [r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2]],
            imu_time_offset_s: 0.0,
            time_origin_us: 0,
            sensor: format!("simulator:{}", self.cfg.name),
        }
    }

    /// The configuration in use.
    pub fn config(&self) -> &SceneConfig {
        &self.cfg
    }

    /// Length of the sequence, s.
    pub fn duration(&self) -> f64 {
        self.cfg.duration_s
    }

    /// End of the last chunk returned (start of the next), s.
    pub fn time(&self) -> f64 {
        self.t_emitted
    }

    /// True once the whole sequence has been returned.
    pub fn is_finished(&self) -> bool {
        self.t_emitted >= self.cfg.duration_s
    }

    /// Work counters.
    pub fn stats(&self) -> SimStats {
        self.stats
    }

    /// Simulates up to `t_end` (s, clamped to the duration) and returns everything in
    /// `[previous t_end, t_end)`; the last chunk also holds events at exactly the duration.
    /// Calls with `t_end` at or before the previous one return an empty chunk.
    pub fn next_chunk(&mut self, t_end: f64) -> SimChunk {
        let dur = self.cfg.duration_s;
        let t_end = if t_end.is_nan() { self.t_emitted } else { t_end.min(dur) };
        let mut chunk = SimChunk::default();
        if t_end <= self.t_emitted {
            return chunk;
        }
        let last = t_end >= dur;
        while self.t_sim < t_end {
            self.advance_keyframe();
        }
        // Events.
        let start = self.pending_head;
        let mut end = start;
        while end < self.pending.len() && (last || self.pending[end].t < t_end) {
            end += 1;
        }
        let n = end - start;
        chunk.events = Events::with_capacity(n);
        chunk.truth.event_object.reserve(n);
        chunk.truth.flow_x.reserve(n);
        chunk.truth.flow_y.reserve(n);
        let w = self.rays.width as u32;
        for e in &self.pending[start..end] {
            chunk.events.push(e.t, (e.pixel % w) as u16, (e.pixel / w) as u16, e.p);
            chunk.truth.event_object.push(e.id);
            chunk.truth.flow_x.push(e.fx);
            chunk.truth.flow_y.push(e.fy);
        }
        self.pending_head = end;
        if self.pending_head > 4096 && self.pending_head * 2 > self.pending.len() {
            self.pending.drain(..self.pending_head);
            self.pending_head = 0;
        }
        // Truth streams on fixed grids.
        loop {
            let t = self.next_camera as f64 / self.cfg.truth.camera_rate_hz;
            if t >= t_end {
                break;
            }
            chunk.truth.camera.push(truth::camera_motion(t, &self.scene.camera_state(t)));
            self.next_camera += 1;
        }
        loop {
            let t = self.next_mask as f64 / self.cfg.truth.mask_rate_hz;
            if t >= t_end {
                break;
            }
            let geom = FrameGeom::new(&self.scene, &self.cfg.camera, t);
            chunk.truth.masks.push(truth::mask(&self.scene, &self.rays, &geom));
            truth::object_poses(t, &self.scene, &geom.cam, &mut chunk.truth.objects);
            self.next_mask += 1;
        }
        let scene = &self.scene;
        self.imu.until(t_end, |t| scene.camera_state(t), &mut chunk.imu);
        self.t_emitted = t_end;
        chunk
    }

    /// Bound of the image speed (px/s) of any scene point at time `t`: the background from the
    /// depths of the last key frame (per 16x16 block, times `depth_safety`), each object from a
    /// ball around its centre.
    fn speed_bound(&self, t: f64) -> f64 {
        let cam = self.scene.camera_state(t);
        let (mx, my) = (self.rays.max_abs_x, self.rays.max_abs_y);
        let r_max = mx.hypot(my);
        let bg = scene::RelativeMotion::new(&cam, None);
        let safety = self.cfg.render.depth_safety;
        let mut s: f64 = 0.0;
        for b in &self.blocks {
            let z = if b.zmin.is_finite() { b.zmin.min(self.zmin_bg * 4.0) } else { self.zmin_bg } * safety;
            let (rot, trans) = bg.flow_parts(b.x, b.y);
            s = s.max(rot * b.rot_margin + trans / z);
        }
        for b in self.scene.boxes.iter().filter(|b| b.id != 0) {
            let bs = b.trajectory.state(t);
            let pose = scene::BoxPose::new(&cam, &bs);
            let corners = pose.corners(b.half);
            let zmin = corners.iter().map(|c| c[2]).fold(f64::INFINITY, f64::min);
            let zmax = corners.iter().map(|c| c[2]).fold(f64::NEG_INFINITY, f64::max);
            if zmax <= 0.0 {
                continue;
            }
            if zmin > 0.1 {
                // Skip objects well outside the field of view (55 px at f = 550).
                let out = |k: usize, lim: f64| {
                    corners.iter().all(|c| c[k] / c[2] > lim + 0.1) || corners.iter().all(|c| c[k] / c[2] < -lim - 0.1)
                };
                if out(0, mx) || out(1, my) {
                    continue;
                }
            }
            let m = scene::RelativeMotion::new(&cam, Some(&bs));
            s = s.max(m.speed_bound_ball(pose.center, math::norm(b.half), zmin.max(0.1), r_max));
        }
        let c = &self.cfg.camera;
        s * c.fx.max(c.fy) * self.rays.max_jacobian
    }

    /// Render times of the next key-frame interval and the bound (px) of how far any scene point
    /// moves during it.
    fn plan(&mut self) -> (Vec<f64>, f64) {
        let r = &self.cfg.render;
        let (safety, max_px, min_dt, max_dt) = (r.speed_safety, r.max_px_per_step, r.min_step_s, r.max_step_s);
        let dur = self.cfg.duration_s;
        let mut times = vec![self.t_sim];
        let mut travel = 0.0;
        for _ in 0..self.cfg.render.steps_per_keyframe {
            let t = times[times.len() - 1];
            if t >= dur {
                break;
            }
            let speed = self.speed_bound(t).max(self.speed_bound((t + self.last_dt).min(dur))) * safety;
            let mut dt = if speed > 0.0 { (max_px / speed).clamp(min_dt, max_dt) } else { max_dt };
            if t + dt > dur - 0.5 * min_dt {
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

    /// Simulates one key-frame interval.
    fn advance_keyframe(&mut self) {
        let (times, travel) = self.plan();
        let k = times.len() - 1;
        if k == 0 {
            // Only reachable at the end of the sequence.
            self.t_sim = self.cfg.duration_s;
            return;
        }
        let (t0, t1) = (times[0], times[k]);
        let radius = (travel.ceil() as usize + 1).min(64);
        let shade = self.shade_change(t0, t1);
        self.select_active(radius, shade);
        let active: Vec<u32> =
            (0..self.px.active.len() as u32).filter(|&i| self.px.active[i as usize]).collect();
        let mut batch: Vec<RawEvent> = Vec::new();
        let mut prev_geom = self.key_geom.clone();
        for i in 1..k {
            let geom = FrameGeom::new(&self.scene, &self.cfg.camera, times[i]);
            self.render_list(&geom, &active);
            self.fire(&active, &prev_geom, &geom, times[i - 1], times[i], &mut batch, None);
            self.add_noise(&prev_geom, &geom, times[i], &mut batch);
            prev_geom = geom;
        }
        let geom = FrameGeom::new(&self.scene, &self.cfg.camera, t1);
        self.render_keyframe(&geom);
        let all: Vec<u32> = (0..self.px.active.len() as u32).collect();
        let key_geom = std::mem::replace(&mut self.key_geom, geom.clone());
        let t_before_last = times[k - 1];
        self.fire(&all, &prev_geom, &geom, t_before_last, t1, &mut batch, Some((&key_geom, t0)));
        self.add_noise(&prev_geom, &geom, t1, &mut batch);
        batch.sort_by(|a, b| a.t.total_cmp(&b.t));
        self.pending.extend_from_slice(&batch);
        self.t_sim = t1;
    }

    /// Marks the pixels to render between the key frames: near edges or the border, or not
    /// provably quiet.
    fn select_active(&mut self, radius: usize, shade_margin: f32) {
        let (w, h) = (self.rays.width, self.rays.height);
        let p = &mut self.px;
        if self.cfg.render.steps_per_keyframe <= 1 {
            p.active.fill(true);
            return;
        }
        // Edge pixels of the last key frame.
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let k = p.key_now[i];
                let e = (x + 1 < w && p.key_now[i + 1] != k)
                    || (x > 0 && p.key_now[i - 1] != k)
                    || (y + 1 < h && p.key_now[i + w] != k)
                    || (y > 0 && p.key_now[i - w] != k);
                p.band[i] = u8::from(e);
            }
        }
        dilate(&mut p.band, &mut p.band_tmp, w, h, radius);
        window_min_max(&p.l_prev, &mut p.lo, &mut p.hi, &mut p.tmp_a, &mut p.tmp_b, w, h, radius);
        let margin = self.cfg.render.quiet_margin_log as f32;
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let border = x < radius || y < radius || x + radius >= w || y + radius >= h;
                let m = margin + if p.id_prev[i] != 0 { shade_margin } else { 0.0 };
                let quiet = p.hi[i] + m < p.reference[i] + self.thresholds.on[i]
                    && p.lo[i] - m > p.reference[i] - self.thresholds.off[i];
                p.active[i] = border || p.band[i] != 0 || !quiet;
            }
        }
    }

    fn next_stamp(&mut self) -> u32 {
        self.stamp_counter = self.stamp_counter.wrapping_add(1);
        if self.stamp_counter == 0 {
            self.px.stamp.fill(0);
            self.stamp_counter = 1;
        }
        self.stamp_counter
    }

    /// Renders every pixel at `geom` into `l_now`/`id_now`/`key_now` (with edge
    /// supersampling) and updates the background depth bound.
    fn render_keyframe(&mut self, geom: &FrameGeom) {
        let stamp = self.next_stamp();
        let (w, h) = (self.rays.width, self.rays.height);
        let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
        if self.blocks.is_empty() {
            for by in 0..bh {
                for bx in 0..bw {
                    let (cu, cv) = ((bx * BLOCK + BLOCK / 2).min(w - 1), (by * BLOCK + BLOCK / 2).min(h - 1));
                    let i = cv * w + cu;
                    let (x, y) = (self.rays.x[i] as f64, self.rays.y[i] as f64);
                    // Rotational flow grows like 1 + r^2; half a block further out is covered
                    // by this factor.
                    let step = BLOCK as f64 * 0.5 / self.cfg.camera.fx.min(self.cfg.camera.fy);
                    let r = x.hypot(y);
                    let rot_margin = (1.0 + (r + step).powi(2)) / (1.0 + r * r) * 1.02;
                    self.blocks.push(DepthBlock { x, y, rot_margin, zmin: f64::INFINITY });
                }
            }
        }
        let mut block_z = vec![f32::INFINITY; bw * bh];
        let mut zmin = f32::INFINITY;
        for v in 0..h {
            let brow = (v / BLOCK) * bw;
            for u in 0..w {
                let i = v * w + u;
                let hit = geom.cast(&self.scene, self.rays.x[i], self.rays.y[i], u as i32, v as i32, None);
                self.px.l_now[i] = hit.l;
                self.px.id_now[i] = hit.id;
                self.px.key_now[i] = hit.key;
                self.px.stamp[i] = stamp;
                if hit.id == 0 {
                    let b = &mut block_z[brow + u / BLOCK];
                    *b = b.min(hit.z);
                }
            }
        }
        for (b, z) in self.blocks.iter_mut().zip(&block_z) {
            b.zmin = *z as f64;
            zmin = zmin.min(*z);
        }
        if zmin.is_finite() && zmin > 0.0 {
            self.zmin_bg = zmin as f64;
        }
        self.stats.pixel_renders += (w * h) as u64;
        self.stats.steps += 1;
        self.stats.keyframes += 1;
        if self.cfg.render.edge_supersampling {
            for i in 0..w * h {
                self.supersample_if_edge(geom, i, stamp);
            }
        }
    }

    /// Renders the listed pixels at `geom` (with edge supersampling).
    fn render_list(&mut self, geom: &FrameGeom, list: &[u32]) {
        let stamp = self.next_stamp();
        let w = self.rays.width;
        for &p in list {
            let i = p as usize;
            let hit =
                geom.cast(&self.scene, self.rays.x[i], self.rays.y[i], (i % w) as i32, (i / w) as i32, None);
            self.px.l_now[i] = hit.l;
            self.px.id_now[i] = hit.id;
            self.px.key_now[i] = hit.key;
            self.px.stamp[i] = stamp;
        }
        self.stats.pixel_renders += list.len() as u64;
        self.stats.steps += 1;
        if self.cfg.render.edge_supersampling {
            for &p in list {
                self.supersample_if_edge(geom, p as usize, stamp);
            }
        }
    }

    #[inline]
    fn supersample_if_edge(&mut self, geom: &FrameGeom, i: usize, stamp: u32) {
        let w = self.rays.width;
        let (x, y) = (i % w, i / w);
        let p = &self.px;
        let k = p.key_now[i];
        let differs = |j: usize| p.stamp[j] == stamp && p.key_now[j] != k;
        let edge = (x + 1 < w && differs(i + 1))
            || (x > 0 && differs(i - 1))
            || (i + w < p.stamp.len() && differs(i + w))
            || (y > 0 && differs(i - w));
        if edge {
            let r = &self.rays;
            self.px.l_now[i] = geom.supersample(&self.scene, r.x[i], r.y[i], r.d_du[i], r.d_dv[i], x as i32, y as i32);
            self.stats.supersampled += 1;
        }
    }

    /// Runs the threshold model on the listed pixels from `l_prev` (at `t_a`, or at the key
    /// frame `skipped.1` for pixels that were skipped) to `l_now` (at `t_b`).
    #[allow(clippy::too_many_arguments)]
    fn fire(
        &mut self,
        list: &[u32],
        geom_a: &FrameGeom,
        geom_b: &FrameGeom,
        t_a: f64,
        t_b: f64,
        batch: &mut Vec<RawEvent>,
        skipped: Option<(&FrameGeom, f64)>,
    ) {
        let refractory = self.cfg.esim.refractory_s;
        let w = self.rays.width;
        let mut model_events = 0u64;
        let mut violations = 0u64;
        for &p in list {
            let i = p as usize;
            let was_skipped = skipped.is_some() && !self.px.active[i];
            let (ga, ta) = match skipped {
                Some((g, t)) if was_skipped => (g, t),
                _ => (geom_a, t_a),
            };
            let (l0, l1) = (self.px.l_prev[i], self.px.l_now[i]);
            let (id_a, id_b) = (self.px.id_prev[i], self.px.id_now[i]);
            let before = batch.len();
            {
                let scene = &self.scene;
                let cam = &self.cfg.camera;
                let rays = &self.rays;
                esim::crossings(
                    &mut self.px.reference[i],
                    &mut self.px.last_event[i],
                    l0,
                    l1,
                    ta,
                    t_b,
                    self.thresholds.on[i],
                    self.thresholds.off[i],
                    refractory,
                    |t, pol| {
                        let frac = if t_b > ta { ((t - ta) / (t_b - ta)) as f32 } else { 0.0 };
                        let (id, fx, fy) = event_truth(scene, cam, rays, i, w, ga, geom_b, id_a, id_b, frac);
                        batch.push(RawEvent { t, pixel: p, p: pol, id, fx, fy });
                    },
                );
            }
            let fired = (batch.len() - before) as u64;
            model_events += fired;
            if was_skipped && fired > 0 {
                violations += 1;
            }
            self.px.l_prev[i] = l1;
            self.px.id_prev[i] = id_b;
        }
        self.stats.model_events += model_events;
        self.stats.skip_violations += violations;
    }

    /// Adds the noise events up to `t_end` (exclusive), labelled with the surface at their pixel.
    fn add_noise(&mut self, geom_a: &FrameGeom, geom_b: &FrameGeom, t_end: f64, batch: &mut Vec<RawEvent>) {
        let w = self.rays.width;
        let scene = &self.scene;
        let cam = &self.cfg.camera;
        let rays = &self.rays;
        let (ta, tb) = (geom_a.t, geom_b.t);
        let mut count = 0u64;
        self.noise.until(t_end, |t, p, pol| {
            let i = p as usize;
            let g = if (t - ta).abs() <= (tb - t).abs() { geom_a } else { geom_b };
            let hit = g.cast(scene, rays.x[i], rays.y[i], (i % w) as i32, (i / w) as i32, None);
            let (fx, fy) = g.flow(scene, cam, rays.x[i], rays.y[i], (i % w) as i32, (i / w) as i32, hit.id).unwrap_or((0.0, 0.0));
            batch.push(RawEvent { t, pixel: p, p: pol, id: hit.id, fx: fx as f32, fy: fy as f32 });
            count += 1;
        });
        self.stats.noise_events += count;
    }
}

/// Object id and flow (px/s) of an event at pixel `i`, a fraction `frac` of the way from the
/// render at `ga` (object `id_a` at the pixel centre) to the one at `gb` (object `id_b`).
/// The id is the object's if it covers the pixel at either render (leading and trailing edges
/// belong to the object); the flow is that surface's motion field at the pixel, interpolated
/// between the two renders when both see it.
#[allow(clippy::too_many_arguments)]
fn event_truth(
    scene: &Scene,
    cam: &CameraConfig,
    rays: &Rays,
    i: usize,
    w: usize,
    ga: &FrameGeom,
    gb: &FrameGeom,
    id_a: u16,
    id_b: u16,
    frac: f32,
) -> (u16, f32, f32) {
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
    let (x, y, u, v) = (rays.x[i], rays.y[i], (i % w) as i32, (i / w) as i32);
    let fa = ga.flow(scene, cam, x, y, u, v, id);
    let fb = gb.flow(scene, cam, x, y, u, v, id);
    let (fx, fy) = match (fa, fb) {
        (Some(a), Some(b)) => {
            let f = frac as f64;
            (a.0 + f * (b.0 - a.0), a.1 + f * (b.1 - a.1))
        }
        (Some(a), None) => a,
        (None, Some(b)) => b,
        (None, None) => (0.0, 0.0),
    };
    (id, fx as f32, fy as f32)
}

/// Binary dilation of `mask` by a square of radius `r` (separable).
fn dilate(mask: &mut [u8], tmp: &mut [u8], w: usize, h: usize, r: usize) {
    for y in 0..h {
        let row = &mask[y * w..(y + 1) * w];
        let out = &mut tmp[y * w..(y + 1) * w];
        // Running count of set pixels in the window.
        let mut count = 0usize;
        for x in 0..r.min(w) {
            count += row[x] as usize;
        }
        for x in 0..w {
            if x + r < w {
                count += row[x + r] as usize;
            }
            if x > r {
                count -= row[x - r - 1] as usize;
            }
            out[x] = u8::from(count > 0);
        }
    }
    for x in 0..w {
        let mut count = 0usize;
        for y in 0..r.min(h) {
            count += tmp[y * w + x] as usize;
        }
        for y in 0..h {
            if y + r < h {
                count += tmp[(y + r) * w + x] as usize;
            }
            if y > r {
                count -= tmp[(y - r - 1) * w + x] as usize;
            }
            mask[y * w + x] = u8::from(count > 0);
        }
    }
}

/// Minimum and maximum of `src` over a square window of radius `r` (separable, van Herk /
/// Gil-Werman: three comparisons per pixel and pass whatever the radius).
#[allow(clippy::too_many_arguments)]
fn window_min_max(src: &[f32], lo: &mut [f32], hi: &mut [f32], ta: &mut [f32], tb: &mut [f32], w: usize, h: usize, r: usize) {
    // Horizontal pass into ta (min) / tb (max).
    let mut line_in = Vec::new();
    let mut line_min = Vec::new();
    let mut line_max = Vec::new();
    for y in 0..h {
        line_in.clear();
        line_in.extend_from_slice(&src[y * w..(y + 1) * w]);
        running_min_max(&line_in, r, &mut line_min, &mut line_max);
        ta[y * w..(y + 1) * w].copy_from_slice(&line_min);
        tb[y * w..(y + 1) * w].copy_from_slice(&line_max);
    }
    let mut col = Vec::new();
    let mut dummy = Vec::new();
    for x in 0..w {
        col.clear();
        col.extend((0..h).map(|y| ta[y * w + x]));
        running_min_max(&col, r, &mut line_min, &mut dummy);
        for y in 0..h {
            lo[y * w + x] = line_min[y];
        }
        col.clear();
        col.extend((0..h).map(|y| tb[y * w + x]));
        running_min_max(&col, r, &mut dummy, &mut line_max);
        for y in 0..h {
            hi[y * w + x] = line_max[y];
        }
    }
}

/// Sliding-window min and max of radius `r` over one line (window clipped at the ends).
fn running_min_max(v: &[f32], r: usize, out_min: &mut Vec<f32>, out_max: &mut Vec<f32>) {
    let n = v.len();
    let k = 2 * r + 1;
    // Pad with +inf / -inf so windows at the ends are clipped.
    let padded = n + 2 * r;
    let get = |j: usize, fill: f32| if j < r || j >= r + n { fill } else { v[j - r] };
    let mut pre_min = vec![0.0f32; padded];
    let mut suf_min = vec![0.0f32; padded];
    let mut pre_max = vec![0.0f32; padded];
    let mut suf_max = vec![0.0f32; padded];
    for j in 0..padded {
        let (a, b) = (get(j, f32::INFINITY), get(j, f32::NEG_INFINITY));
        if j % k == 0 {
            pre_min[j] = a;
            pre_max[j] = b;
        } else {
            pre_min[j] = pre_min[j - 1].min(a);
            pre_max[j] = pre_max[j - 1].max(b);
        }
    }
    for j in (0..padded).rev() {
        let (a, b) = (get(j, f32::INFINITY), get(j, f32::NEG_INFINITY));
        if j % k == k - 1 || j == padded - 1 {
            suf_min[j] = a;
            suf_max[j] = b;
        } else {
            suf_min[j] = suf_min[j + 1].min(a);
            suf_max[j] = suf_max[j + 1].max(b);
        }
    }
    out_min.clear();
    out_max.clear();
    for c in 0..n {
        // Window [c, c + 2r] in padded coordinates.
        let (s, e) = (c, c + 2 * r);
        out_min.push(suf_min[s].min(pre_min[e]));
        out_max.push(suf_max[s].max(pre_max[e]));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn running_min_max_matches_brute_force() {
        let v: Vec<f32> = (0..37).map(|i| ((i * 7919) % 23) as f32 - 11.0).collect();
        for r in [0usize, 1, 3, 5, 40] {
            let (mut lo, mut hi) = (Vec::new(), Vec::new());
            running_min_max(&v, r, &mut lo, &mut hi);
            for c in 0..v.len() {
                let a = c.saturating_sub(r);
                let b = (c + r).min(v.len() - 1);
                let mn = v[a..=b].iter().cloned().fold(f32::INFINITY, f32::min);
                let mx = v[a..=b].iter().cloned().fold(f32::NEG_INFINITY, f32::max);
                assert_eq!((lo[c], hi[c]), (mn, mx), "r {r} c {c}");
            }
        }
    }

    #[test]
    fn dilation_matches_brute_force() {
        let (w, h) = (13usize, 9usize);
        let mut m = vec![0u8; w * h];
        m[2 * w + 3] = 1;
        m[8 * w + 12] = 1;
        let orig = m.clone();
        let mut tmp = vec![0u8; w * h];
        dilate(&mut m, &mut tmp, w, h, 2);
        for y in 0..h {
            for x in 0..w {
                let mut any = false;
                for yy in y.saturating_sub(2)..=(y + 2).min(h - 1) {
                    for xx in x.saturating_sub(2)..=(x + 2).min(w - 1) {
                        any |= orig[yy * w + xx] != 0;
                    }
                }
                assert_eq!(m[y * w + x] != 0, any, "{x} {y}");
            }
        }
    }
}
