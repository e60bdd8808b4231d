//! Times full-frame ray casting of a preset (development aid).
//!
//! `cargo run --release -p evseg-sim --example render_timing -- one-object`

use std::time::Instant;

use evseg_sim::camera::Rays;
use evseg_sim::render::FrameGeom;
use evseg_sim::scene::Scene;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let name = std::env::args().nth(1).unwrap_or_else(|| "one-object".into());
    let cfg = evseg_sim::preset(&name, 1)?;
    let scene = Scene::new(
        &cfg.scene,
        cfg.camera_trajectory.clone(),
        cfg.seed,
        cfg.esim.log_eps,
    );
    let rays = Rays::new(&cfg.camera);
    let (w, h) = (rays.width, rays.height);
    let mut sum = 0.0f32;
    let frames = 20;
    let t0 = Instant::now();
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
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "{:.1} ns per ray ({} frames, checksum {sum})",
        dt / (frames * w * h) as f64 * 1e9,
        frames
    );
    texture_only(&scene);
    Ok(())
}

#[allow(dead_code)]
fn texture_only(scene: &Scene) {
    let tex = &scene.textures[2];
    let t0 = Instant::now();
    let mut sum = 0.0f32;
    for f in 0..20 {
        for v in 0..480 {
            for u in 0..640 {
                sum += tex.sample(u as f32 * 0.009 + f as f32 * 0.001, v as f32 * 0.009, 0.004);
            }
        }
    }
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "texture only: {:.1} ns per sample (checksum {sum})",
        dt / (20.0 * 640.0 * 480.0) * 1e9
    );
    let t0 = Instant::now();
    for f in 0..20 {
        for v in 0..480 {
            for u in 0..640 {
                sum += tex.sample(u as f32 * 0.009 + f as f32 * 0.001, v as f32 * 0.009, 0.02);
            }
        }
    }
    let dt = t0.elapsed().as_secs_f64();
    println!(
        "texture trilinear: {:.1} ns per sample (checksum {sum})",
        dt / (20.0 * 640.0 * 480.0) * 1e9
    );
}
