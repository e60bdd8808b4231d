//! Named, seeded scene presets. Each returns a complete [`SceneConfig`] whose every field can
//! be changed before building the simulator.
//!
//! All presets share one room (walls 3 m either side, back wall 6 m ahead, floor 1.2 m below
//! the camera, furniture boxes at 2.5..5.5 m), a 640x480 camera with fx = fy = 550 px, and a
//! hand-held-like camera motion (0.3..0.6 m/s translation with forward drift, 0.2..0.4 rad/s
//! rotation) unless stated. The seed picks textures, noise and the phases of every motion.
//!
//! Textures are calm, like the mostly large structures of EVIMO2 scenes: walls with 3 cm
//! texels (finest noise octave 24 cm), log contrast 0.15..0.2, objects with 15..20 cm
//! checker squares or blobs at contrast 0.3. At 640x480 the presets produce about 0.4..1.9 M
//! events per second of sensor time (`low-contrast` halves every contrast, `high-contrast`
//! multiplies it by 1.6); see the crate README for the measured figures.

use evseg_schemas::Distortion;

use crate::SimError;
use crate::camera::CameraConfig;
use crate::config::{RenderConfig, SceneConfig, TruthConfig};
use crate::esim::EsimConfig;
use crate::imu::ImuConfig;
use crate::math::{self, Mat3, Vec3};
use crate::rng::Rng;
use crate::scene::{BoxConfig, Lighting, ObjectConfig, PlaneConfig, SceneContent};
use crate::texture::{Pattern, TextureConfig};
use crate::trajectory::{RigidTrajectory, Signal};

/// Names accepted by [`preset`].
pub const PRESET_NAMES: &[&str] = &[
    "one-object",
    "two-objects",
    "three-objects",
    "fast-rotation",
    "enter-leave",
    "camera-only",
    "low-contrast",
    "high-contrast",
    "distorted-lens",
];

/// Camera -> world rotation of a camera looking along world +y with world z up (camera x =
/// world x, camera y = world -z).
pub const CAMERA_LOOKING_FORWARD: Mat3 = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];

/// Seconds the presets' camera walks forward before turning back (see
/// [`crate::trajectory::Signal::reverse_every_s`]): it turns over the last
/// [`crate::trajectory::REVERSAL_S`] of each such period.
pub const CAMERA_WALK_S: f64 = 6.0;

/// The configuration of preset `name` with `seed`.
pub fn preset(name: &str, seed: u64) -> Result<SceneConfig, SimError> {
    let mut b = Builder::new(name, seed);
    let cfg = match name {
        "one-object" => {
            // One large box (0.5 x 0.36 x 0.4 m) 1.8 m ahead, swinging sideways at up to 1 m/s.
            let o = b.object(
                1,
                [0.25, 0.18, 0.2],
                [0.0, 1.8, 1.1],
                [0.55, 0.2, 0.15],
                0.3,
                b.checker_texture(1),
            );
            b.finish(vec![o], 3.0)
        }
        "two-objects" => {
            let o1 = b.object(
                1,
                [0.2, 0.15, 0.15],
                [-0.2, 1.6, 1.0],
                [0.5, 0.15, 0.12],
                0.33,
                b.checker_texture(1),
            );
            let mut o2 = b.object(
                2,
                [0.3, 0.05, 0.25],
                [0.3, 2.6, 1.4],
                [0.35, 0.25, 0.3],
                0.27,
                b.blob_texture(2),
            );
            // The second moves mostly up and down, against the first.
            o2.shape.trajectory.position[2].terms[0].amplitude = 0.35;
            o2.shape.trajectory.position[0].terms[0].amplitude = 0.25;
            b.finish(vec![o1, o2], 3.0)
        }
        "three-objects" => {
            // The most objects the issue asks for: a box on the left, a thin plate on the right
            // and a smaller box further back, each with its own swing and tumble, so that the
            // merger must keep three motions apart and the tracker three ids. Added after the
            // bench set (evseg-bench-v3) was fixed, as a scene the method was not tuned on.
            let o1 = b.object(
                1,
                [0.18, 0.14, 0.14],
                [-0.5, 1.7, 1.0],
                [0.3, 0.15, 0.1],
                0.3,
                b.checker_texture(1),
            );
            let o2 = b.object(
                2,
                [0.25, 0.03, 0.2],
                [0.55, 2.2, 1.3],
                [0.25, 0.2, 0.25],
                0.25,
                b.blob_texture(2),
            );
            let o3 = b.object(
                3,
                [0.12, 0.12, 0.12],
                [0.0, 3.0, 0.75],
                [0.6, 0.2, 0.12],
                0.2,
                b.checker_texture(3),
            );
            b.finish(vec![o1, o2, o3], 3.0)
        }
        "fast-rotation" => {
            // Strong rotation (up to ~1.0 rad/s yaw, ~0.6 rad/s pitch, 3x the other presets)
            // with translation, one object.
            b.camera.angles[0] = Signal::constant(0.0).with(0.2, 0.8, b.phase());
            b.camera.angles[1] = Signal::constant(-0.12).with(0.09, 1.1, b.phase());
            b.camera.angles[2] = Signal::constant(0.0).with(0.08, 0.7, b.phase());
            let o = b.object(
                1,
                [0.2, 0.15, 0.15],
                [0.0, 1.8, 1.1],
                [0.45, 0.15, 0.12],
                0.3,
                b.checker_texture(1),
            );
            b.finish(vec![o], 3.0)
        }
        "enter-leave" => {
            // Object 1 crosses left to right (in view about 0.4..2.1 s), object 2 right to left
            // (about 2.6..4.5 s): stretches with no moving object at the start, middle and end.
            let mut o1 = b.object(
                1,
                [0.2, 0.15, 0.15],
                [-2.0, 2.0, 1.0],
                [0.0, 0.1, 0.1],
                0.4,
                b.checker_texture(1),
            );
            // Both cross and come back (turning over the sixth second, like the camera's
            // walk), and so on: the same as one crossing each for the first 5 s, and within
            // a few metres of the view however long a sequence runs. (Flying on, a box 10 m
            // to the side reached the camera's image plane as it yawed, and its speed bound
            // took 15 000 render steps per sensor-second with no object in view.)
            o1.shape.trajectory.position[0].rate = 1.6;
            o1.shape.trajectory.position[0].reverse_every_s = Some(CAMERA_WALK_S);
            let mut o2 = b.object(
                2,
                [0.25, 0.12, 0.2],
                [5.0, 2.3, 1.3],
                [0.0, 0.1, 0.12],
                0.35,
                b.blob_texture(2),
            );
            o2.shape.trajectory.position[0].rate = -1.4;
            o2.shape.trajectory.position[0].reverse_every_s = Some(CAMERA_WALK_S);
            b.finish(vec![o1, o2], 5.0)
        }
        "camera-only" => b.finish(Vec::new(), 3.0),
        "low-contrast" => {
            let o = b.object(
                1,
                [0.22, 0.16, 0.18],
                [0.0, 1.8, 1.1],
                [0.5, 0.2, 0.15],
                0.3,
                b.checker_texture(1),
            );
            let mut cfg = b.finish(vec![o], 3.0);
            scale_contrast(&mut cfg, 0.5);
            cfg
        }
        "high-contrast" => {
            let o = b.object(
                1,
                [0.22, 0.16, 0.18],
                [0.0, 1.8, 1.1],
                [0.5, 0.2, 0.15],
                0.3,
                b.checker_texture(1),
            );
            let mut cfg = b.finish(vec![o], 3.0);
            scale_contrast(&mut cfg, 1.6);
            cfg
        }
        "distorted-lens" => {
            b.camera_cfg.fx = 560.0;
            b.camera_cfg.fy = 560.0;
            b.camera_cfg.distortion = Distortion::RadTan {
                k1: -0.22,
                k2: 0.06,
                p1: 0.0006,
                p2: -0.0008,
                k3: 0.0,
            };
            let o = b.object(
                1,
                [0.22, 0.16, 0.18],
                [0.0, 1.8, 1.1],
                [0.5, 0.2, 0.15],
                0.3,
                b.checker_texture(1),
            );
            b.finish(vec![o], 3.0)
        }
        _ => {
            return Err(SimError::UnknownPreset {
                name: name.to_string(),
                valid: PRESET_NAMES.join(", "),
            });
        }
    };
    Ok(cfg)
}

/// Multiplies the contrast of every texture by `factor` (capped at 5).
pub fn scale_contrast(cfg: &mut SceneConfig, factor: f64) {
    let s = &mut cfg.scene;
    for t in s
        .planes
        .iter_mut()
        .map(|p| &mut p.texture)
        .chain(s.boxes.iter_mut().map(|b| &mut b.texture))
        .chain(s.objects.iter_mut().map(|o| &mut o.shape.texture))
    {
        t.contrast = (t.contrast * factor).min(5.0);
    }
}

struct Builder {
    name: String,
    seed: u64,
    rng: Rng,
    camera: RigidTrajectory,
    camera_cfg: CameraConfig,
}

fn plane(origin: Vec3, u: Vec3, v: Vec3, texture: TextureConfig) -> PlaneConfig {
    PlaneConfig {
        origin,
        axis_u: u,
        axis_v: v,
        texture,
    }
}

fn wall_texture(pattern: Pattern, contrast: f64, albedo: f64, seed: u64) -> TextureConfig {
    TextureConfig {
        pattern,
        size: 512,
        texel_m: 0.03,
        mean_albedo: albedo,
        contrast,
        noise_weight: 0.15,
        noise_feature_m: 1.5,
        seed,
    }
}

impl Builder {
    fn new(name: &str, seed: u64) -> Self {
        let mut rng = Rng::new(seed, 0x9e5e7);
        let mut ph = || rng.range(0.0, std::f64::consts::TAU);
        let camera = RigidTrajectory {
            position: [
                Signal::constant(0.0).with(0.12, 0.5, ph()),
                // Forward at 0.15 m/s, turning over the sixth second and walking back, and
                // so on: the same as a steady walk for the first 5 s (every bench sequence),
                // and at most 0.8 m from the start however long a sequence runs. (A steady
                // walk took the camera into the objects after 8-10 s: one-object at 1 to
                // 0.3 m from the box, and the simulator 20 times slower.)
                Signal::linear(0.0, 0.15)
                    .reversing_every(CAMERA_WALK_S)
                    .with(0.06, 0.7, ph()),
                Signal::constant(1.2).with(0.05, 0.8, ph()),
            ],
            base_rotation: CAMERA_LOOKING_FORWARD,
            // Yaw about camera y, pitch about camera x (negative looks down), roll about z.
            axes: [1, 0, 2],
            angles: [
                Signal::constant(0.0).with(0.12, 0.4, ph()),
                Signal::constant(-0.12).with(0.06, 0.6, ph()),
                Signal::constant(0.0).with(0.04, 0.5, ph()),
            ],
        };
        Self {
            name: name.to_string(),
            seed,
            rng,
            camera,
            camera_cfg: CameraConfig {
                width: 640,
                height: 480,
                fx: 550.0,
                fy: 550.0,
                cx: 319.5,
                cy: 239.5,
                distortion: Distortion::None,
            },
        }
    }

    fn phase(&mut self) -> f64 {
        self.rng.range(0.0, std::f64::consts::TAU)
    }

    fn checker_texture(&self, seed: u64) -> TextureConfig {
        TextureConfig {
            pattern: Pattern::Checker { square_m: 0.2 },
            size: 256,
            texel_m: 0.008,
            mean_albedo: 0.45,
            contrast: 0.3,
            noise_weight: 0.2,
            noise_feature_m: 0.25,
            seed: 1000 + seed,
        }
    }

    fn blob_texture(&self, seed: u64) -> TextureConfig {
        TextureConfig {
            pattern: Pattern::Blobs {
                per_m2: 40.0,
                radius_m: 0.06,
            },
            size: 256,
            texel_m: 0.008,
            mean_albedo: 0.5,
            contrast: 0.3,
            noise_weight: 0.2,
            noise_feature_m: 0.3,
            seed: 1000 + seed,
        }
    }

    /// A box object with half sizes `half` swinging around `center` (world) with amplitudes
    /// `swing` (m) at about `freq` Hz, and tumbling at up to ~1 rad/s.
    fn object(
        &mut self,
        id: u16,
        half: Vec3,
        center: Vec3,
        swing: Vec3,
        freq: f64,
        texture: TextureConfig,
    ) -> ObjectConfig {
        let pos = |c: f64, a: f64, f: f64, rng: &mut Rng| {
            let mut s = Signal::constant(c);
            if a > 0.0 {
                s = s.with(a, f, rng.range(0.0, std::f64::consts::TAU));
            }
            s
        };
        let rng = &mut self.rng;
        let position = [
            pos(center[0], swing[0], freq, rng),
            pos(center[1], swing[1], freq * 1.37, rng),
            pos(center[2], swing[2], freq * 1.71, rng),
        ];
        let angles = [
            Signal::linear(rng.range(-0.5, 0.5), rng.range(0.4, 0.8)).with(0.2, 0.5, rng.range(0.0, 6.0)),
            Signal::constant(rng.range(-0.3, 0.3)).with(0.25, 0.4, rng.range(0.0, 6.0)),
            Signal::constant(rng.range(-0.3, 0.3)).with(0.2, 0.3, rng.range(0.0, 6.0)),
        ];
        ObjectConfig {
            id,
            shape: BoxConfig {
                half_extents: half,
                trajectory: RigidTrajectory {
                    position,
                    base_rotation: math::IDENTITY,
                    axes: [2, 1, 0],
                    angles,
                },
                texture,
            },
        }
    }

    fn room(&self) -> SceneContent {
        let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
        let clutter = Pattern::Blobs {
            per_m2: 2.0,
            radius_m: 0.15,
        };
        let planes = vec![
            // Floor (z = 0) with large tiles.
            plane(
                [0.0, 0.0, 0.0],
                x,
                y,
                wall_texture(Pattern::Checker { square_m: 0.5 }, 0.15, 0.35, 1),
            ),
            // Ceiling (z = 3).
            plane([0.0, 0.0, 3.0], y, x, wall_texture(Pattern::Noise, 0.15, 0.6, 2)),
            // Back wall (y = 6), cluttered.
            plane([0.0, 6.0, 0.0], x, z, wall_texture(clutter, 0.2, 0.5, 3)),
            // Wall behind the camera (y = -3).
            plane([0.0, -3.0, 0.0], z, x, wall_texture(Pattern::Noise, 0.15, 0.5, 4)),
            // Left wall (x = -3).
            plane([-3.0, 0.0, 0.0], y, z, wall_texture(clutter, 0.2, 0.45, 5)),
            // Right wall (x = 3).
            plane(
                [3.0, 0.0, 0.0],
                z,
                y,
                wall_texture(Pattern::Stripes { period_m: 0.6 }, 0.15, 0.5, 6),
            ),
        ];
        let furniture = |center: Vec3, half: Vec3, yaw: f64, pattern: Pattern, seed: u64| BoxConfig {
            half_extents: half,
            trajectory: RigidTrajectory::fixed(center, math::rot_axis(2, yaw)),
            texture: TextureConfig {
                pattern,
                size: 256,
                texel_m: 0.016,
                mean_albedo: 0.45,
                contrast: 0.2,
                noise_weight: 0.2,
                noise_feature_m: 0.5,
                seed,
            },
        };
        let boxes = vec![
            furniture(
                [-2.0, 3.5, 0.7],
                [0.5, 0.35, 0.7],
                0.3,
                Pattern::Blobs {
                    per_m2: 8.0,
                    radius_m: 0.1,
                },
                11,
            ),
            furniture(
                [1.6, 3.0, 0.45],
                [0.6, 0.4, 0.45],
                -0.2,
                Pattern::Stripes { period_m: 0.25 },
                12,
            ),
            furniture(
                [0.3, 5.2, 1.6],
                [0.9, 0.03, 0.6],
                0.0,
                Pattern::Blobs {
                    per_m2: 10.0,
                    radius_m: 0.09,
                },
                13,
            ),
            furniture(
                [2.3, 4.5, 1.0],
                [0.2, 0.2, 1.0],
                0.5,
                Pattern::Checker { square_m: 0.2 },
                14,
            ),
        ];
        SceneContent {
            planes,
            boxes,
            objects: Vec::new(),
            lighting: Lighting {
                direction: [-0.3, -0.5, 0.8],
                ambient: 0.6,
            },
        }
    }

    fn finish(self, objects: Vec<ObjectConfig>, duration_s: f64) -> SceneConfig {
        let mut scene = self.room();
        scene.objects = objects;
        SceneConfig {
            name: self.name,
            seed: self.seed,
            duration_s,
            camera: self.camera_cfg,
            camera_trajectory: self.camera,
            scene,
            esim: EsimConfig::default(),
            render: RenderConfig::default(),
            imu: ImuConfig::default(),
            truth: TruthConfig::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// However long a preset runs (60 s here), its camera stays within 0.95 m of its start
    /// and every object's centre within 7.5 m to the side and 0.3 m or more in front of the
    /// camera (the first 5 s already come to 0.5 m at the crossings' ends): a steady walk took the camera into the
    /// objects after 8-10 s, and `enter-leave`'s boxes flew on to 10 m beside the camera,
    /// where they reached its image plane and slowed the simulator 20 times.
    #[test]
    fn long_sequences_stay_bounded() {
        for name in PRESET_NAMES {
            for seed in 1..=4 {
                let cfg = preset(name, seed).unwrap();
                let start = cfg.camera_trajectory.state(0.0).position;
                for k in 0..=1200 {
                    let t = k as f64 * 0.05;
                    let cam = cfg.camera_trajectory.state(t);
                    let forward = cam.position[1] - start[1];
                    assert!(
                        forward.abs() < 0.95,
                        "{name} {seed} t {t}: camera {forward:.2} m forward"
                    );
                    for o in &cfg.scene.objects {
                        let pose = crate::scene::BoxPose::new(&cam, &o.shape.trajectory.state(t));
                        let c = pose.center;
                        assert!(
                            c[0].abs() < 7.5 && c[2] > 0.3,
                            "{name} {seed} t {t}: object {} at {c:?} (camera frame)",
                            o.id
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn every_preset_is_valid_and_unknown_names_list_the_valid_ones() {
        for name in PRESET_NAMES {
            let cfg = preset(name, 3).unwrap();
            cfg.validate().unwrap();
            assert!(cfg.duration_s >= 3.0);
            assert_eq!((cfg.camera.width, cfg.camera.height), (640, 480));
            // Camera translation is never trivial: mean speed over the sequence 0.3..1 m/s.
            let n = 300;
            let mean: f64 = (0..n)
                .map(|i| {
                    math::norm(
                        cfg.camera_trajectory
                            .state(i as f64 / n as f64 * cfg.duration_s)
                            .velocity,
                    )
                })
                .sum::<f64>()
                / n as f64;
            eprintln!("{name}: mean camera speed {mean:.2} m/s");
            assert!((0.3..1.0).contains(&mean), "{name}: mean speed {mean}");
        }
        let err = preset("no-such", 1).unwrap_err().to_string();
        assert!(
            err.contains("no-such") && err.contains("one-object") && err.contains("camera-only"),
            "{err}"
        );
        // Same seed, same config; different seed, different phases.
        assert_eq!(
            preset("two-objects", 5).unwrap(),
            preset("two-objects", 5).unwrap()
        );
        assert_ne!(
            preset("two-objects", 5).unwrap(),
            preset("two-objects", 6).unwrap()
        );
    }
}
