//! The complete, documented parameter set of one simulated sequence.

use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::camera::CameraConfig;
use crate::esim::EsimConfig;
use crate::imu::ImuConfig;
use crate::scene::SceneContent;
use crate::trajectory::RigidTrajectory;

/// How often and how carefully the scene is rendered.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RenderConfig {
    /// Largest image motion of any scene point between two renders, px (0.5: the ESIM rule
    /// that keeps linear interpolation of log intensity accurate).
    pub max_px_per_step: f64,
    /// Factor applied to the bound of the image speed. Default 1.01: the bounds are upper
    /// bounds of every scene point's image speed at both ends of a step (moving boxes: the
    /// centred corner bound over 3 x 3 x 3 sub-boxes; the background: the last key frame's
    /// depths times `depth_safety`), so what is left to cover is the change of the speed
    /// within a step (second order in the step). Measured with the factor at 1.0 (the ignored
    /// test `engine::tests::measure_step_displacements`: every step of the first 1.5 s of every
    /// preset and 3 s of four; background points from every second pixel of each key frame,
    /// a 17 x 17 grid on every face of the moving boxes): the largest displacement of any
    /// point in one step was 0.499998 px (fast-rotation; 0.4999 or less elsewhere), none over
    /// 0.5 px, and none over its local bound. 1.01 leaves 1 % for that change (no sampled
    /// point exceeded the bound at the step's ends times the step); it was 1.1 until the
    /// eighth speed round.
    pub speed_safety: f64,
    /// Longest render step, s (5 ms; used when nothing moves fast).
    pub max_step_s: f64,
    /// Shortest render step, s.
    pub min_step_s: f64,
    /// Render steps per key frame. Every key frame renders all pixels; in between only pixels
    /// that may fire are rendered (see `quiet_margin_log`); 1 renders every pixel every step.
    /// Default 20 (a cost choice: 16 -> 20 was 1.01 to 1.10 times faster, with event counts
    /// as close to rendering every pixel every step, within 0.5 %).
    pub steps_per_keyframe: u32,
    /// Safety margin, log units, of the test that skips pixels between key frames: a pixel is
    /// skipped when the log intensities within the image distance that scene points can move
    /// before the next key frame stay inside its thresholds by this margin (covers sub-pixel
    /// peaks and the slow change of texture filtering with distance).
    pub quiet_margin_log: f64,
    /// Safety margin, log units, of a test by texture bounds along the path of pixels that keep
    /// their surface between key frames. Kept for configuration compatibility; unused since
    /// such pixels are sampled along their whole path (cheaper than bounding it).
    pub path_margin_log: f64,
    /// Factor applied to the smallest background depth seen in the last key frame before it is
    /// used to bound image speeds.
    pub depth_safety: f64,
    /// Anti-alias geometric edges by 2x2 supersampling of edge pixels.
    pub edge_supersampling: bool,
}

impl Default for RenderConfig {
    fn default() -> Self {
        Self {
            max_px_per_step: 0.5,
            speed_safety: 1.01,
            max_step_s: 5e-3,
            min_step_s: 1e-6,
            steps_per_keyframe: 20,
            quiet_margin_log: 0.03,
            path_margin_log: 0.01,
            depth_safety: 0.9,
            edge_supersampling: true,
        }
    }
}

/// Rates of the ground-truth streams.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TruthConfig {
    /// Mask and object-pose rate, Hz (60: the EVIMO2 ground-truth frame rate).
    pub mask_rate_hz: f64,
    /// Camera pose/velocity rate, Hz (200: the EVIMO2 Vicon trajectory rate).
    pub camera_rate_hz: f64,
}

impl Default for TruthConfig {
    fn default() -> Self {
        Self {
            mask_rate_hz: 60.0,
            camera_rate_hz: 200.0,
        }
    }
}

/// Longest sequence the simulator writes, seconds of sensor time (an hour).
pub const MAX_DURATION_S: f64 = 3600.0;

/// Everything that defines one simulated sequence. A preset ([`crate::preset`]) fills it; any
/// field can be changed before [`crate::Simulator::new`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneConfig {
    /// Name (the preset's name, or free text).
    pub name: String,
    /// Seed of every random choice (textures, thresholds, noise, IMU noise).
    pub seed: u64,
    /// Length of the sequence, s.
    pub duration_s: f64,
    /// Camera intrinsics and lens.
    pub camera: CameraConfig,
    /// Camera trajectory (camera -> world; world z up). The camera frame is x right, y down,
    /// z forward.
    pub camera_trajectory: RigidTrajectory,
    /// Background and moving objects.
    pub scene: SceneContent,
    /// Event generation and sensor noise.
    pub esim: EsimConfig,
    /// Render scheduling.
    pub render: RenderConfig,
    /// IMU.
    pub imu: ImuConfig,
    /// Ground-truth rates.
    pub truth: TruthConfig,
}

impl SceneConfig {
    /// The same sequence seen by a camera with `factor` times the resolution (same field of
    /// view: focal lengths and principal point scaled). Useful for quick runs and tests.
    pub fn with_resolution_scale(mut self, factor: f64) -> Self {
        let c = &mut self.camera;
        c.width = ((c.width as f64 * factor).round() as u16).max(8);
        c.height = ((c.height as f64 * factor).round() as u16).max(8);
        c.fx *= factor;
        c.fy *= factor;
        c.cx = (c.cx + 0.5) * factor - 0.5;
        c.cy = (c.cy + 0.5) * factor - 0.5;
        self
    }

    /// Checks every part; the error names the field.
    pub fn validate(&self) -> Result<(), SimError> {
        if !(self.duration_s.is_finite() && self.duration_s > 0.0 && self.duration_s <= MAX_DURATION_S) {
            return Err(SimError::Config(format!(
                "duration_s = {} must be in (0, {MAX_DURATION_S}]",
                self.duration_s
            )));
        }
        self.camera.validate()?;
        self.camera_trajectory
            .validate("camera_trajectory")
            .map_err(SimError::Config)?;
        self.scene.validate()?;
        self.esim.validate()?;
        self.imu.validate()?;
        let r = &self.render;
        let ok = r.max_px_per_step > 0.0
            && r.max_px_per_step <= 5.0
            && r.speed_safety >= 1.0
            && r.min_step_s > 0.0
            && r.max_step_s >= r.min_step_s
            && r.max_step_s <= 0.1
            && (1..=64).contains(&r.steps_per_keyframe)
            && r.quiet_margin_log >= 0.0
            && r.depth_safety > 0.0
            && r.depth_safety <= 1.0;
        if !ok {
            return Err(SimError::Config(format!("render parameters out of range: {r:?}")));
        }
        let t = &self.truth;
        if !(t.mask_rate_hz > 0.0
            && t.mask_rate_hz <= 10_000.0
            && t.camera_rate_hz > 0.0
            && t.camera_rate_hz <= 100_000.0)
        {
            return Err(SimError::Config(format!("truth rates out of range: {t:?}")));
        }
        Ok(())
    }
}
