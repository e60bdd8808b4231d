//! Times full-frame ray casting of a preset (development aid).
//!
//! `cargo run --release -p evseg-sim --example render_timing -- one-object`

use std::time::Instant;

/// CPU time (s) of the calling thread ([`thread_cpu_seconds`]), else wall time since the first
/// call.
fn cpu_now() -> f64 {
    static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    let start = *START.get_or_init(Instant::now);
    thread_cpu_seconds().unwrap_or_else(|| start.elapsed().as_secs_f64())
}

use evseg_sim::camera::Rays;
use evseg_sim::render::FrameGeom;
use evseg_sim::scene::Scene;
use evseg_sim::throughput::thread_cpu_seconds;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let name = std::env::args().nth(1).unwrap_or_else(|| "one-object".into());
    let cfg = evseg_sim::preset(&name, 1)?;
    let scene = Scene::of_config(&cfg);
    let rays = Rays::new(&cfg.camera);
    let (w, h) = (rays.width, rays.height);
    let mut sum = 0.0f32;
    let frames = 20;
    let t0 = cpu_now();
    for f in 0..frames {
        let geom = FrameGeom::new(&scene, &cfg.camera, f as f64 * 0.001);
        for v in 0..h {
            for u in 0..w {
                let i = v * w + u;
                sum += geom
                    .cast(&scene, rays.x[i], rays.y[i], u as i32, v as i32, None)
                    .l;
            }
        }
    }
    let dt = cpu_now() - t0;
    println!(
        "{:.1} ns (CPU) per ray ({} frames, checksum {sum})",
        dt / (frames * w * h) as f64 * 1e9,
        frames
    );
    texture_only(&scene);
    lanes_timing(&scene);
    kf_parts(&scene, &rays, &cfg);
    kf_lanes(&scene, &rays, &cfg);
    Ok(())
}

fn texture_only(scene: &Scene) {
    let tex = &scene.textures[2];
    let t0 = cpu_now();
    let mut sum = 0.0f32;
    for f in 0..20 {
        for v in 0..480 {
            for u in 0..640 {
                sum += tex.sample(u as f32 * 0.009 + f as f32 * 0.001, v as f32 * 0.009, 0.004);
            }
        }
    }
    let dt = cpu_now() - t0;
    println!(
        "texture only: {:.1} ns (CPU) per sample (checksum {sum})",
        dt / (20.0 * 640.0 * 480.0) * 1e9
    );
    let t0 = cpu_now();
    for f in 0..20 {
        for v in 0..480 {
            for u in 0..640 {
                sum += tex.sample(u as f32 * 0.009 + f as f32 * 0.001, v as f32 * 0.009, 0.02);
            }
        }
    }
    let dt = cpu_now() - t0;
    println!(
        "texture trilinear: {:.1} ns (CPU) per sample (checksum {sum})",
        dt / (20.0 * 640.0 * 480.0) * 1e9
    );
}

fn lanes_timing(scene: &Scene) {
    let tex = &scene.textures[2];
    for fp in [0.004f32, 0.02] {
        let t0 = cpu_now();
        let mut sum = 0.0f32;
        for f in 0..20 {
            for v in 0..480 {
                for u in (0..640).step_by(8) {
                    let uu = std::array::from_fn(|l| (u + l) as f32 * 0.009 + f as f32 * 0.001);
                    let vv = [v as f32 * 0.009; 8];
                    let s = tex.sample_lanes(&uu, &vv, &[fp; 8]);
                    sum += s.iter().sum::<f32>();
                }
            }
        }
        let dt = cpu_now() - t0;
        println!(
            "lanes fp {fp}: {:.2} ns per sample ({sum})",
            dt / (20.0 * 640.0 * 480.0) * 1e9
        );
    }
}

/// One group of 8 neighbouring rays of a row: index of the first, ray directions, pixel
/// columns and row.
struct LaneGroup<'a> {
    i: usize,
    x: &'a [f32; 8],
    y: &'a [f32; 8],
    px: [i32; 8],
    py: [i32; 8],
}

/// Calls `each` with the frame geometry at each of `times` and every group of 8 rays of it.
fn for_each_lane_group(
    scene: &Scene,
    rays: &Rays,
    cfg: &evseg_sim::SceneConfig,
    times: impl Iterator<Item = f64>,
    mut each: impl FnMut(&FrameGeom, &LaneGroup<'_>),
) {
    let (w, h) = (rays.width, rays.height);
    for t in times {
        let geom = FrameGeom::new(scene, &cfg.camera, t);
        for v in 0..h {
            for u in (0..w).step_by(8) {
                let i = v * w + u;
                let group = LaneGroup {
                    i,
                    x: rays.x[i..i + 8].try_into().expect("rows are multiples of 8 rays"),
                    y: rays.y[i..i + 8].try_into().expect("rows are multiples of 8 rays"),
                    px: std::array::from_fn(|l| (u + l) as i32),
                    py: [v as i32; 8],
                };
                each(&geom, &group);
            }
        }
    }
}

fn kf_parts(scene: &Scene, rays: &Rays, cfg: &evseg_sim::SceneConfig) {
    let (w, h) = (rays.width, rays.height);
    let frames = 20;
    let times = || (0..frames).map(|f| 0.2 + f as f64 * 0.001);
    let mut sum = 0.0f32;
    let t0 = cpu_now();
    for_each_lane_group(scene, rays, cfg, times(), |geom, g| {
        let found = geom.locate_lanes(g.x, g.y, &g.px, &g.py);
        sum += found.iter().map(|l| l.z).sum::<f32>();
    });
    let t1 = cpu_now();
    for_each_lane_group(scene, rays, cfg, times(), |geom, g| {
        let found = geom.locate_lanes(g.x, g.y, &g.px, &g.py);
        for (l, hit) in found.iter().enumerate() {
            sum += geom.shade(scene, g.x[l], g.y[l], hit).l;
        }
    });
    let t2 = cpu_now();
    let n = (frames * w * h) as f64;
    println!(
        "locate_lanes {:.1} ns, +shade {:.1} ns per pixel ({sum})",
        (t1 - t0) / n * 1e9,
        (t2 - t1) / n * 1e9
    );
}

fn kf_lanes(scene: &Scene, rays: &Rays, cfg: &evseg_sim::SceneConfig) {
    let (w, h) = (rays.width, rays.height);
    let frames = 20;
    let times = || (0..frames).map(|f| 0.2 + f as f64 * 0.001);
    let mut sum = 0.0f32;
    let t0 = cpu_now();
    for_each_lane_group(scene, rays, cfg, times(), |geom, g| {
        let hits = geom.cast_lanes(scene, g.x, g.y, &g.px, &g.py);
        sum += hits.l.iter().sum::<f32>();
    });
    let t1 = cpu_now();
    let n = (frames * w * h) as f64;
    println!("cast_lanes {:.1} ns per pixel ({sum})", (t1 - t0) / n * 1e9);
    // The same with the key frame's stores.
    let mut l = vec![0.0f32; w * h];
    let mut key = vec![0u16; w * h];
    let mut id = vec![0u16; w * h];
    let mut uu = vec![0.0f32; w * h];
    let mut vv = vec![0.0f32; w * h];
    let mut fp = vec![0.0f32; w * h];
    let mut ps = vec![0.0f32; w * h];
    let t0 = cpu_now();
    for_each_lane_group(scene, rays, cfg, times(), |geom, g| {
        let hits = geom.cast_lanes(scene, g.x, g.y, &g.px, &g.py);
        for k in 0..8 {
            let (hit, i) = (hits.get(k), g.i + k);
            l[i] = hit.l;
            key[i] = hit.key;
            id[i] = hit.id;
            uu[i] = hit.u;
            vv[i] = hit.v;
            fp[i] = hit.footprint;
            ps[i] = hit.z * 0.001;
        }
    });
    let t1 = cpu_now();
    println!(
        "cast_lanes with stores {:.1} ns per pixel ({})",
        (t1 - t0) / n * 1e9,
        l[1000] + uu[5] + vv[7] + fp[9] + ps[11] + (key[3] + id[4]) as f32
    );
    for t in [0.0, 0.1, 0.3, 0.45] {
        let t0 = cpu_now();
        for_each_lane_group(scene, rays, cfg, std::iter::repeat_n(t, 5), |geom, g| {
            let hits = geom.cast_lanes(scene, g.x, g.y, &g.px, &g.py);
            sum += hits.l.iter().sum::<f32>();
        });
        let t1 = cpu_now();
        println!(
            "cast_lanes at t {t}: {:.1} ns per pixel ({sum})",
            (t1 - t0) / (5 * w * h) as f64 * 1e9
        );
    }
}
