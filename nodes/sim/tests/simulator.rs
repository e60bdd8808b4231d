//! End-to-end tests of the simulator with known answers.
#![allow(clippy::needless_range_loop)]

use evseg_schemas::Distortion;
use evseg_sim::camera::Rays;
use evseg_sim::presets::CAMERA_LOOKING_FORWARD;
use evseg_sim::render::{FrameGeom, sub_sample_rays};
use evseg_sim::scene::Scene;
use evseg_sim::{
    BoxConfig, CameraConfig, EsimConfig, Lighting, Pattern, PlaneConfig, RigidTrajectory, SceneConfig,
    SceneContent, Signal, SimChunk, Simulator, TextureConfig, preset,
};

fn texture(contrast: f64) -> TextureConfig {
    TextureConfig {
        pattern: Pattern::Blobs {
            per_m2: 8.0,
            radius_m: 0.12,
        },
        size: 256,
        texel_m: 0.02,
        mean_albedo: 0.4,
        contrast,
        noise_weight: 0.3,
        noise_feature_m: 1.0,
        seed: 9,
    }
}

/// A camera at the world origin looking along +y at a fronto-parallel wall `depth` metres ahead.
fn wall_scene(depth: f64, velocity: [f64; 3], noise: bool) -> SceneConfig {
    let mut cfg = preset("camera-only", 1).unwrap().with_resolution_scale(0.2);
    cfg.duration_s = 0.3;
    cfg.scene = SceneContent {
        planes: vec![PlaneConfig {
            origin: [0.0, depth, 0.0],
            axis_u: [1.0, 0.0, 0.0],
            axis_v: [0.0, 0.0, 1.0],
            texture: texture(0.8),
        }],
        boxes: Vec::new(),
        objects: Vec::new(),
        lighting: Lighting {
            direction: [0.0, -1.0, 0.0],
            ambient: 0.6,
        },
    };
    let mut tr = RigidTrajectory::fixed([0.0, 0.0, 0.0], CAMERA_LOOKING_FORWARD);
    for k in 0..3 {
        tr.position[k] = Signal::linear(0.0, velocity[k]);
    }
    cfg.camera_trajectory = tr;
    if !noise {
        cfg.esim.noise_rate_hz = 0.0;
        cfg.esim.hot_pixels = 0;
    }
    cfg
}

fn run(sim: &mut Simulator, step: f64) -> SimChunk {
    let mut all = SimChunk::default();
    let mut t = 0.0;
    while !sim.is_finished() {
        t += step;
        let c = sim.next_chunk(t);
        all.events.extend_from(&c.events, 0..c.events.len());
        all.truth.event_object.extend(c.truth.event_object);
        all.truth.flow_x.extend(c.truth.flow_x);
        all.truth.flow_y.extend(c.truth.flow_y);
        all.truth.masks.extend(c.truth.masks);
        all.truth.camera.extend(c.truth.camera);
        all.truth.objects.extend(c.truth.objects);
        all.imu.extend(c.imu);
    }
    all
}

fn check_stream(c: &SimChunk, w: u16, h: u16) {
    let n = c.events.len();
    assert!(c.events.is_consistent());
    assert_eq!(c.truth.event_object.len(), n);
    assert_eq!(c.truth.flow_x.len(), n);
    assert_eq!(c.truth.flow_y.len(), n);
    for i in 0..n {
        assert!(c.events.x[i] < w && c.events.y[i] < h);
        assert!(c.events.p[i] <= 1);
        assert!(c.truth.flow_x[i].is_finite() && c.truth.flow_y[i].is_finite());
        if i > 0 {
            assert!(c.events.t[i] >= c.events.t[i - 1], "unsorted at {i}");
        }
    }
}

#[test]
fn static_scene_gives_no_events_without_noise_and_only_noise_with_it() {
    let cfg = wall_scene(3.0, [0.0; 3], false);
    let mut sim = Simulator::new(cfg.clone()).unwrap();
    let out = run(&mut sim, 0.05);
    assert_eq!(out.events.len(), 0);

    let mut noisy = cfg;
    noisy.esim.noise_rate_hz = 5.0;
    noisy.esim.hot_pixels = 3;
    noisy.esim.hot_pixel_rate_hz = 100.0;
    let pixels = noisy.camera.width as f64 * noisy.camera.height as f64;
    let expected = noisy.duration_s * (pixels * 5.0 + 300.0);
    let mut sim = Simulator::new(noisy).unwrap();
    let out = run(&mut sim, 0.05);
    let n = out.events.len() as f64;
    assert!(
        (n - expected).abs() < 5.0 * expected.sqrt() + 5.0,
        "{n} vs {expected}"
    );
    assert_eq!(sim.stats().model_events, 0);
}

#[test]
fn flow_truth_matches_the_motion_field_of_a_translating_camera() {
    // World velocity (0.4, 0.5, -0.3): camera frame (x right, y down, z forward) = (0.4, 0.3, 0.5).
    let depth = 3.0;
    let cfg = wall_scene(depth, [0.4, 0.5, -0.3], false);
    let cam = cfg.camera.clone();
    let mut sim = Simulator::new(cfg).unwrap();
    let out = run(&mut sim, 0.1);
    check_stream(&out, cam.width, cam.height);
    assert!(out.events.len() > 1000, "{}", out.events.len());
    let t_cam = [0.4, 0.3, 0.5];
    let mut checked = 0;
    let mut worst: f64 = 0.0;
    for i in (0..out.events.len()).step_by(37) {
        let t = out.events.t[i];
        let z = depth - 0.5 * t;
        let x = (out.events.x[i] as f64 - cam.cx) / cam.fx;
        let y = (out.events.y[i] as f64 - cam.cy) / cam.fy;
        // u = A(x) t / Z with the camera moving by t: flow = (-tx + x tz, -ty + y tz) / Z.
        let ux = cam.fx * (-t_cam[0] + x * t_cam[2]) / z;
        let uy = cam.fy * (-t_cam[1] + y * t_cam[2]) / z;
        let (fx, fy) = (out.truth.flow_x[i] as f64, out.truth.flow_y[i] as f64);
        worst = worst.max((fx - ux).abs().max((fy - uy).abs()));
        assert!(
            (fx - ux).abs() < 0.01 * ux.abs().max(10.0),
            "event {i}: {fx} vs {ux}"
        );
        assert!(
            (fy - uy).abs() < 0.01 * uy.abs().max(10.0),
            "event {i}: {fy} vs {uy}"
        );
        assert_eq!(out.truth.event_object[i], 0);
        checked += 1;
    }
    eprintln!("{checked} events checked, largest flow error {worst:.4} px/s");
    assert!(checked > 30);
}

#[test]
fn event_object_ids_agree_with_the_masks() {
    let mut cfg = preset("one-object", 4).unwrap().with_resolution_scale(0.25);
    cfg.duration_s = 0.5;
    let (w, h) = (cfg.camera.width as usize, cfg.camera.height as usize);
    let mut sim = Simulator::new(cfg).unwrap();
    let out = run(&mut sim, 0.05);
    check_stream(&out, w as u16, h as u16);
    assert_eq!(out.truth.masks.len(), 30);
    let (mut in_mask, mut in_mask_ok, mut outside, mut outside_ok) = (0usize, 0usize, 0usize, 0usize);
    for i in 0..out.events.len() {
        let t = out.events.t[i];
        let m = &out.truth.masks[((t * 60.0).round() as usize).min(out.truth.masks.len() - 1)];
        let (x, y) = (out.events.x[i] as usize, out.events.y[i] as usize);
        let id = m.ids[y * w + x];
        // Only judge events whose 3x3 neighbourhood has one label in the mask (the mask is up
        // to 1/120 s away from the event, so edges move between them).
        let mut uniform = true;
        for dy in -1i64..=1 {
            for dx in -1i64..=1 {
                let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                if xx >= 0 && yy >= 0 && (xx as usize) < w && (yy as usize) < h {
                    uniform &= m.ids[yy as usize * w + xx as usize] == id;
                }
            }
        }
        if !uniform {
            continue;
        }
        if id != 0 {
            in_mask += 1;
            in_mask_ok += usize::from(out.truth.event_object[i] == id);
        } else {
            outside += 1;
            outside_ok += usize::from(out.truth.event_object[i] == 0);
        }
    }
    assert!(in_mask > 1000 && outside > 1000, "{in_mask} {outside}");
    let a = in_mask_ok as f64 / in_mask as f64;
    let b = outside_ok as f64 / outside as f64;
    eprintln!("id agreement: object {a:.4} ({in_mask} events), background {b:.4} ({outside} events)");
    assert!(a > 0.95, "object agreement {a}");
    assert!(b > 0.95, "background agreement {b}");
}

#[test]
fn objects_covering_part_of_a_pixel_own_its_events() {
    // An object's silhouette crossing a pixel changes the pixel's (anti-aliased) value while
    // the pixel centre may still see the background: those events are the object's. Count
    // background-labelled events whose 2 x 2 edge sub-samples (the ones the renderer averages)
    // meet the object at the event's time (within 0.25 ms). Before the truth looked at the
    // sub-samples these were 5 to 6 % of the object's events.
    let mut cfg = preset("one-object", 4).unwrap().with_resolution_scale(0.5);
    cfg.duration_s = 0.3;
    let scene = Scene::of_config(&cfg);
    let rays = Rays::new(&cfg.camera);
    let cam = cfg.camera.clone();
    let mut sim = Simulator::new(cfg).unwrap();
    let out = run(&mut sim, 0.1);
    let (ev, ids) = (&out.events, &out.truth.event_object);
    let w = rays.width;
    let bin = 0.0005;
    let (mut object, mut covered) = (0usize, 0usize);
    let mut geom: Option<(i64, FrameGeom)> = None;
    for i in 0..ev.len() {
        if ids[i] != 0 {
            object += 1;
            continue;
        }
        let b = (ev.t[i] / bin).floor() as i64;
        if geom.as_ref().is_none_or(|g| g.0 != b) {
            geom = Some((b, FrameGeom::new(&scene, &cam, (b as f64 + 0.5) * bin)));
        }
        let Some((_, g)) = &geom else { unreachable!() };
        let (u, v) = (i32::from(ev.x[i]), i32::from(ev.y[i]));
        let k = v as usize * w + u as usize;
        let (x, y, du, dv) = (rays.x[k], rays.y[k], rays.d_du[k], rays.d_dv[k]);
        let touched = sub_sample_rays(x, y, du, dv)
            .iter()
            .any(|&(sx, sy)| g.locate(sx, sy, u, v, None).id != 0);
        covered += usize::from(touched);
    }
    let share = covered as f64 / object as f64;
    eprintln!("background events on partly covered pixels: {covered} of {object} object events");
    assert!(object > 10_000, "{object} object events");
    assert!(
        share < 0.005,
        "{covered} background events on pixels the object covers in part"
    );
}

#[test]
fn gyro_reads_rate_plus_bias_and_maps_to_the_camera_rate() {
    let mut cfg = wall_scene(3.0, [0.3, 0.0, 0.0], false);
    // Constant camera rates about camera y (yaw), x (pitch) and z (roll).
    cfg.camera_trajectory.axes = [1, 0, 2];
    cfg.camera_trajectory.angles[0] = Signal::linear(0.0, 0.3);
    cfg.camera_trajectory.angles[1] = Signal::default();
    cfg.camera_trajectory.angles[2] = Signal::default();
    cfg.duration_s = 0.25;
    let bias = cfg.imu.gyro_bias;
    let mut sim = Simulator::new(cfg).unwrap();
    let info = sim.camera_info();
    let out = run(&mut sim, 0.1);
    assert_eq!(out.imu.len(), 250);
    let mut mean = [0.0; 3];
    for s in &out.imu {
        for k in 0..3 {
            mean[k] += s.gyro[k] / out.imu.len() as f64;
        }
    }
    // Pure yaw about camera y: w_cam = (0, 0.3, 0); EVIMO2 axes: w_imu = (-w_cam.y, w_cam.x, w_cam.z).
    let expect_imu = [-0.3 + bias[0], bias[1], bias[2]];
    for k in 0..3 {
        assert!((mean[k] - expect_imu[k]).abs() < 0.0015, "axis {k}: {mean:?}");
    }
    let r = info.imu_to_camera;
    let unbiased = [mean[0] - bias[0], mean[1] - bias[1], mean[2] - bias[2]];
    let w_cam: Vec<f64> = (0..3)
        .map(|i| (0..3).map(|j| r[3 * i + j] * unbiased[j]).sum())
        .collect();
    assert!(
        (w_cam[1] - 0.3).abs() < 0.0015 && w_cam[0].abs() < 0.0015 && w_cam[2].abs() < 0.0015,
        "{w_cam:?}"
    );
    assert_eq!(info.imu_time_offset_s, 0.0);
    // Camera-motion truth carries the same rate, in the camera frame.
    let cm = &out.truth.camera[10];
    let w = cm.angular_velocity.unwrap();
    assert!((w[1] - 0.3).abs() < 1e-9 && w[0].abs() < 1e-9);
    let v = cm.linear_velocity.unwrap();
    assert!(v.iter().all(|c| c.is_finite()));
    assert_eq!(out.truth.camera.len(), 50);
}

#[test]
fn output_does_not_depend_on_chunk_sizes() {
    let mut cfg = preset("two-objects", 2).unwrap().with_resolution_scale(0.2);
    cfg.duration_s = 0.3;
    let a = run(&mut Simulator::new(cfg.clone()).unwrap(), 0.01);
    let b = run(&mut Simulator::new(cfg.clone()).unwrap(), 0.037);
    let c = run(&mut Simulator::new(cfg).unwrap(), 10.0);
    assert!(a.events.len() > 1000);
    for other in [&b, &c] {
        assert_eq!(a.events, other.events);
        assert_eq!(a.truth, other.truth);
        assert_eq!(a.imu, other.imu);
    }
}

#[test]
fn skipping_quiet_pixels_matches_rendering_every_pixel() {
    let mut cfg = preset("one-object", 3).unwrap().with_resolution_scale(0.2);
    cfg.duration_s = 0.25;
    cfg.esim.noise_rate_hz = 0.0;
    cfg.esim.hot_pixels = 0;
    let mut full = cfg.clone();
    full.render.steps_per_keyframe = 1;
    let mut sim = Simulator::new(cfg).unwrap();
    let a = run(&mut sim, 0.05);
    assert_eq!(sim.stats().skip_violations, 0);
    let b = run(&mut Simulator::new(full).unwrap(), 0.05);
    let (na, nb) = (a.events.len() as f64, b.events.len() as f64);
    eprintln!("events with skipping {na}, rendering every pixel every step {nb}");
    // Sampling differs (step times follow key-frame depths; interpolated texture coordinates),
    // so a few events near threshold flip; a broken skip test loses far more.
    assert!(nb > 5000.0 && (na - nb).abs() < 0.025 * nb, "{na} vs {nb}");
}

#[test]
fn every_preset_runs_and_streams_are_well_formed() {
    for name in evseg_sim::PRESET_NAMES {
        let mut cfg = preset(name, 1).unwrap().with_resolution_scale(0.2);
        cfg.duration_s = 0.2;
        let (w, h) = (cfg.camera.width, cfg.camera.height);
        let objects = cfg.scene.objects.len();
        let mut sim = Simulator::new(cfg).unwrap();
        let out = run(&mut sim, 0.07);
        check_stream(&out, w, h);
        assert!(out.events.len() > 100, "{name}: {} events", out.events.len());
        assert_eq!(out.truth.masks.len(), 12, "{name}");
        assert_eq!(out.truth.objects.len(), 12 * objects, "{name}");
        assert_eq!(out.truth.camera.len(), 40, "{name}");
        assert_eq!(out.imu.len(), 200, "{name}");
        for m in &out.truth.masks {
            assert_eq!(m.ids.len(), w as usize * h as usize);
            assert!(m.ids.iter().all(|&i| i as usize <= objects));
        }
    }
}

#[test]
fn three_objects_puts_three_distinct_objects_in_view_and_each_fires_events() {
    let mut cfg = preset("three-objects", 1).unwrap().with_resolution_scale(0.25);
    cfg.duration_s = 0.3;
    assert_eq!(cfg.scene.objects.len(), 3);
    let out = run(&mut Simulator::new(cfg).unwrap(), 0.05);
    for id in 1..=3u16 {
        let in_masks = out.truth.masks.iter().filter(|m| m.ids.contains(&id)).count();
        assert_eq!(
            in_masks,
            out.truth.masks.len(),
            "object {id} in view in {in_masks} masks"
        );
        let events = out.truth.event_object.iter().filter(|&&o| o == id).count();
        assert!(events > 50, "object {id}: {events} events");
    }
}

#[test]
fn invalid_configurations_are_rejected_with_the_field_named() {
    let good = preset("one-object", 1).unwrap();
    let mut bad = good.clone();
    bad.esim.c_on = -0.1;
    assert!(Simulator::new(bad).unwrap_err().to_string().contains("esim.c_on"));
    let mut bad = good.clone();
    bad.duration_s = f64::NAN;
    assert!(
        Simulator::new(bad)
            .unwrap_err()
            .to_string()
            .contains("duration_s")
    );
    let mut bad = good.clone();
    bad.camera = CameraConfig {
        fx: 0.0,
        ..bad.camera
    };
    assert!(Simulator::new(bad).unwrap_err().to_string().contains("fx"));
    let mut bad = good.clone();
    bad.camera.distortion = Distortion::Equidistant {
        k1: 0.0,
        k2: 0.0,
        k3: 0.0,
        k4: 0.0,
    };
    assert!(
        Simulator::new(bad)
            .unwrap_err()
            .to_string()
            .contains("Equidistant")
    );
    let mut bad = good.clone();
    bad.scene.objects[0].id = 0;
    assert!(
        Simulator::new(bad)
            .unwrap_err()
            .to_string()
            .contains("objects[0]")
    );
    let mut bad = good.clone();
    bad.scene.planes[1].axis_u = [1.0, 1.0, 0.0];
    assert!(Simulator::new(bad).unwrap_err().to_string().contains("planes[1]"));
    let mut bad = good.clone();
    bad.scene.boxes.push(BoxConfig {
        half_extents: [0.1, -0.1, 0.1],
        trajectory: RigidTrajectory::fixed([0.0; 3], evseg_sim::math::IDENTITY),
        texture: texture(0.5),
    });
    assert!(
        Simulator::new(bad)
            .unwrap_err()
            .to_string()
            .contains("half_extents")
    );
    let mut bad = good;
    bad.esim = EsimConfig {
        refractory_s: f64::INFINITY,
        ..EsimConfig::default()
    };
    assert!(Simulator::new(bad).is_err());
    // A config from JSON with a wrong type is a serde error, not a panic.
    assert!(serde_json::from_str::<SceneConfig>("{\"name\": 3}").is_err());
}

/// A box far outside the view, beside the camera with a corner behind its image plane, does not
/// set the render steps: it cannot be seen, and is skipped like any box well outside the view.
/// enter-leave's boxes flying on (as they did until session 47) passed 10-14 m beside the
/// camera after 7 s, and its yaw brought a corner to the image plane: the box was bounded as if
/// it were 0.1 m in front of the camera, 9 780 and 17 100 render steps in 7-8 s and 9-10 s
/// against about 500 with nothing in view.
#[test]
fn a_box_beside_the_camera_out_of_view_does_not_set_the_steps() {
    let mut cfg = preset("enter-leave", 7).unwrap().with_resolution_scale(0.25);
    cfg.duration_s = 10.0;
    for o in &mut cfg.scene.objects {
        o.shape.trajectory.position[0].reverse_every_s = None;
    }
    let mut sim = Simulator::new(cfg).unwrap();
    let mut steps_per_second = Vec::new();
    let mut t = 0.0;
    while t < 10.0 - 1e-9 {
        let before = sim.stats().steps;
        let end = t + 1.0;
        while t < end - 1e-9 {
            t = (t + 0.1f64).min(end);
            sim.next_chunk(t);
        }
        steps_per_second.push(sim.stats().steps - before);
    }
    let first = steps_per_second[..5].iter().max().copied().unwrap_or(0);
    let late = steps_per_second[7..].iter().max().copied().unwrap_or(0);
    assert!(late <= first, "steps per second {steps_per_second:?}");
}
