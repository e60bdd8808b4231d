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
//! Render schedule: see [`engine`]. Steps are chosen so that no scene point moves more than
//! `render.max_px_per_step` pixels between renders; every pixel is ray cast at key frames, and in
//! between only pixels near edges are (each at the pace of its local image speed); the others
//! interpolate their texture coordinates or are skipped when they provably cannot fire. [`SimStats::skip_violations`] counts skipped pixels
//! that fired anyway (their events are kept, with times spread over the interval).
//!
//! Speed: about 0.45 to 1.5 sensor-seconds per CPU-second on one core at 640x480 (0.4 to 1.9 M
//! events per sensor second; the presets near 1 M events per second about 0.8 to 0.95 over
//! their first 0.5 s and about real time over whole sequences on a quiet machine). Figures,
//! how to reproduce them and what remains are in the crate README.

#![warn(missing_docs)]

pub mod camera;
pub mod config;
pub mod engine;
pub mod esim;
pub mod filters;
mod firing;
pub mod imu;
pub mod local_speed;
pub mod math;
pub mod presets;
pub mod radix;
pub mod render;
pub mod rng;
pub mod scene;
pub mod settings;
mod stable;
pub mod texture;
pub mod throughput;
pub mod trajectory;
pub mod truth;
pub mod unstable;

use evseg_schemas::{CameraInfo, Events, ImuSample, Truth};

pub use camera::CameraConfig;
pub use config::{MAX_DURATION_S, RenderConfig, SceneConfig, TruthConfig};
pub use esim::EsimConfig;
pub use imu::{IMU_TO_CAMERA, ImuConfig};
pub use presets::{PRESET_NAMES, preset, scale_contrast};
pub use scene::{BoxConfig, Lighting, ObjectConfig, PlaneConfig, SceneContent};
pub use settings::{SETTINGS, apply_setting, setting_names};
pub use texture::{Pattern, TextureConfig};
pub use trajectory::{RigidTrajectory, Signal, Sinusoid};

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
    /// Texture samples of interpolated (stable) pixels between key frames.
    pub interpolated_samples: u64,
}

use engine::{Engine, RawEvent};
use imu::ImuSampler;
use render::FrameGeom;

/// The streaming simulator.
#[derive(Debug, Clone)]
pub struct Simulator {
    cfg: SceneConfig,
    engine: Engine,
    imu: ImuSampler,
    /// Start of the next chunk, s.
    t_emitted: f64,
    pending: Vec<RawEvent>,
    pending_head: usize,
    next_mask: u64,
    next_camera: u64,
}

impl Simulator {
    /// Validates `config`, bakes the textures and renders the first key frame at t = 0.
    pub fn new(config: SceneConfig) -> Result<Self, SimError> {
        config.validate()?;
        let engine = Engine::new(&config);
        let imu = ImuSampler::new(config.imu.clone(), config.seed);
        Ok(Self {
            cfg: config,
            engine,
            imu,
            t_emitted: 0.0,
            pending: Vec::new(),
            pending_head: 0,
            next_mask: 0,
            next_camera: 0,
        })
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
            imu_to_camera: [
                r[0][0], r[0][1], r[0][2], r[1][0], r[1][1], r[1][2], r[2][0], r[2][1], r[2][2],
            ],
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
        self.engine.stats
    }

    /// Simulates up to `t_end` (s, clamped to the duration) and returns everything in
    /// `[previous t_end, t_end)`; the last chunk also holds events at exactly the duration.
    /// Calls with `t_end` at or before the previous one (or NaN) return an empty chunk.
    pub fn next_chunk(&mut self, t_end: f64) -> SimChunk {
        let dur = self.cfg.duration_s;
        let mut chunk = SimChunk::default();
        if t_end.is_nan() {
            return chunk;
        }
        let t_end = t_end.min(dur);
        if t_end <= self.t_emitted {
            return chunk;
        }
        let last = t_end >= dur;
        while self.engine.t < t_end {
            self.engine.advance(&self.cfg, &mut self.pending);
        }
        // Events.
        let start = self.pending_head;
        let end = if last {
            self.pending.len()
        } else {
            start + self.pending[start..].partition_point(|e| e.t < t_end)
        };
        let n = end - start;
        chunk.events = Events::with_capacity(n);
        chunk.truth.event_object.reserve(n);
        chunk.truth.flow_x.reserve(n);
        chunk.truth.flow_y.reserve(n);
        let w = self.cfg.camera.width as u32;
        for e in &self.pending[start..end] {
            chunk
                .events
                .push(e.t, (e.pixel % w) as u16, (e.pixel / w) as u16, e.p);
            chunk.truth.event_object.push(e.id);
            chunk.truth.flow_x.push(e.fx);
            chunk.truth.flow_y.push(e.fy);
        }
        self.pending_head = end;
        if self.pending_head * 2 >= self.pending.len() {
            self.pending.drain(..self.pending_head);
            self.pending_head = 0;
        }
        // Truth streams on fixed grids.
        let scene = &self.engine.scene;
        loop {
            let t = self.next_camera as f64 / self.cfg.truth.camera_rate_hz;
            if t >= t_end {
                break;
            }
            chunk
                .truth
                .camera
                .push(truth::camera_motion(t, &scene.camera_state(t)));
            self.next_camera += 1;
        }
        loop {
            let t = self.next_mask as f64 / self.cfg.truth.mask_rate_hz;
            if t >= t_end {
                break;
            }
            let geom = FrameGeom::new(scene, &self.cfg.camera, t);
            chunk
                .truth
                .masks
                .push(truth::mask(scene, &self.engine.rays, &geom));
            truth::object_poses(t, scene, &geom.cam, &mut chunk.truth.objects);
            self.next_mask += 1;
        }
        self.imu.until(t_end, |t| scene.camera_state(t), &mut chunk.imu);
        self.t_emitted = t_end;
        chunk
    }
}
