//! Scene description (textured planes and boxes, moving objects, lighting) and its state at a
//! given time.
//!
//! World frame: z up, metres. Camera frame: x right, y down, z forward (optical axis).

use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::math::{self, Mat3, Vec3};
use crate::texture::{Texture, TextureConfig};
use crate::trajectory::{RigidState, RigidTrajectory};

/// An infinite textured plane of the background (a room wall, floor or ceiling). The camera sees
/// the nearest plane along each ray, so a set of planes around the camera forms a closed room.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlaneConfig {
    /// A point of the plane (texture origin), world, m.
    pub origin: Vec3,
    /// Texture u axis, world, unit.
    pub axis_u: Vec3,
    /// Texture v axis, world, unit, orthogonal to `axis_u`; `axis_u x axis_v` is the normal
    /// used for shading and should point into the room.
    pub axis_v: Vec3,
    /// Appearance.
    pub texture: TextureConfig,
}

/// A textured box (six faces). Background furniture and panels are boxes that do not move;
/// moving objects are boxes with their own trajectory (a plate is a thin box).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BoxConfig {
    /// Half sizes along the box's own x, y, z axes, m.
    pub half_extents: Vec3,
    /// Pose of the box centre and axes over time (world frame).
    pub trajectory: RigidTrajectory,
    /// Appearance (each face uses a different part of the texture).
    pub texture: TextureConfig,
}

/// An independently moving object.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ObjectConfig {
    /// Id in masks and per-event truth, 1..=255, unique.
    pub id: u16,
    /// Shape, appearance and motion.
    pub shape: BoxConfig,
}

/// A directional light plus ambient term: a surface with unit normal `n` has brightness factor
/// `ambient + (1 - ambient) * max(0, n . direction)` (so rotating objects change brightness).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Lighting {
    /// Direction towards the light, world (normalized on use).
    pub direction: Vec3,
    /// Ambient share in (0, 1].
    pub ambient: f64,
}

impl Lighting {
    /// Natural log of the brightness factor of a surface with world normal `n` (unit).
    pub fn ln_shade(&self, n: Vec3) -> f64 {
        let l = math::normalize(self.direction);
        (self.ambient + (1.0 - self.ambient) * math::dot(n, l).max(0.0)).ln()
    }
}

/// The static and moving content of the scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SceneContent {
    /// Background planes (id 0).
    pub planes: Vec<PlaneConfig>,
    /// Background boxes (id 0), normally with fixed trajectories.
    pub boxes: Vec<BoxConfig>,
    /// Moving objects (ids 1..).
    pub objects: Vec<ObjectConfig>,
    /// Lighting.
    pub lighting: Lighting,
}

impl SceneContent {
    /// Checks the values.
    pub fn validate(&self) -> Result<(), SimError> {
        if self.planes.is_empty() && self.boxes.is_empty() {
            return Err(SimError::Config("scene has no background planes or boxes".into()));
        }
        for (i, p) in self.planes.iter().enumerate() {
            let what = format!("scene.planes[{i}]");
            let (u, v) = (p.axis_u, p.axis_v);
            if (math::norm(u) - 1.0).abs() > 1e-6
                || (math::norm(v) - 1.0).abs() > 1e-6
                || math::dot(u, v).abs() > 1e-6
            {
                return Err(SimError::Config(format!(
                    "{what}: axis_u and axis_v must be orthonormal"
                )));
            }
            p.texture.validate(&what)?;
        }
        let check_box = |b: &BoxConfig, what: &str| -> Result<(), SimError> {
            if b.half_extents.iter().any(|h| !(h.is_finite() && *h > 0.0)) {
                return Err(SimError::Config(format!("{what}: half_extents must be > 0")));
            }
            b.trajectory
                .validate(&format!("{what}.trajectory"))
                .map_err(SimError::Config)?;
            b.texture.validate(what)
        };
        for (i, b) in self.boxes.iter().enumerate() {
            check_box(b, &format!("scene.boxes[{i}]"))?;
        }
        for (i, o) in self.objects.iter().enumerate() {
            let what = format!("scene.objects[{i}]");
            if o.id == 0 || o.id > 255 {
                return Err(SimError::Config(format!(
                    "{what}: id {} must be in 1..=255",
                    o.id
                )));
            }
            if self.objects[..i].iter().any(|p| p.id == o.id) {
                return Err(SimError::Config(format!("{what}: id {} used twice", o.id)));
            }
            check_box(&o.shape, &what)?;
        }
        if !(self.lighting.ambient > 0.0 && self.lighting.ambient <= 1.0) {
            return Err(SimError::Config(
                "scene.lighting.ambient must be in (0, 1]".into(),
            ));
        }
        Ok(())
    }
}

/// One box of the scene at runtime, with its baked texture.
#[derive(Debug, Clone)]
pub struct SceneBox {
    /// Object id (0 = background).
    pub id: u16,
    /// Half sizes, m.
    pub half: Vec3,
    /// Motion.
    pub trajectory: RigidTrajectory,
    /// Index into [`Scene::textures`].
    pub texture: usize,
    /// First surface key of its six faces.
    pub key_base: u16,
}

/// The scene at runtime: content with baked textures, and the camera trajectory.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Background planes.
    pub planes: Vec<PlaneConfig>,
    /// Texture index of each plane.
    pub plane_texture: Vec<usize>,
    /// All boxes: background first, then objects.
    pub boxes: Vec<SceneBox>,
    /// Baked textures.
    pub textures: Vec<Texture>,
    /// Lighting.
    pub lighting: Lighting,
    /// Camera trajectory (camera -> world).
    pub camera: RigidTrajectory,
    /// Object id of every surface key (planes, then six faces per box).
    pub key_id: Vec<u16>,
    /// Texture index of every surface key.
    pub key_texture: Vec<usize>,
}

impl Scene {
    /// The scene a [`crate::Simulator`] of `cfg` renders: its content, camera trajectory, seed
    /// and log-intensity offset (for tools that re-render what the simulator saw).
    pub fn of_config(cfg: &crate::SceneConfig) -> Self {
        Self::new(
            &cfg.scene,
            cfg.camera_trajectory.clone(),
            cfg.seed,
            cfg.esim.log_eps,
        )
    }

    /// Bakes the textures of `content` for `seed`.
    pub fn new(content: &SceneContent, camera: RigidTrajectory, seed: u64, eps: f64) -> Self {
        let mut textures = Vec::new();
        let mut key_id = Vec::new();
        let mut plane_texture = Vec::new();
        let mut key_texture = Vec::new();
        for (i, p) in content.planes.iter().enumerate() {
            textures.push(Texture::bake(&p.texture, seed ^ (i as u64 + 1) << 20, eps));
            plane_texture.push(textures.len() - 1);
            key_id.push(0);
            key_texture.push(textures.len() - 1);
        }
        let mut boxes = Vec::new();
        let all = content
            .boxes
            .iter()
            .map(|b| (0u16, b))
            .chain(content.objects.iter().map(|o| (o.id, &o.shape)));
        for (j, (id, b)) in all.enumerate() {
            textures.push(Texture::bake(&b.texture, seed ^ (j as u64 + 101) << 20, eps));
            boxes.push(SceneBox {
                id,
                half: b.half_extents,
                trajectory: b.trajectory.clone(),
                texture: textures.len() - 1,
                key_base: key_id.len() as u16,
            });
            key_id.extend([id; 6]);
            key_texture.extend([textures.len() - 1; 6]);
        }
        Self {
            planes: content.planes.clone(),
            plane_texture,
            boxes,
            textures,
            lighting: content.lighting.clone(),
            camera,
            key_id,
            key_texture,
        }
    }

    /// Camera state at `t` (s).
    pub fn camera_state(&self, t: f64) -> RigidState {
        self.camera.state(t)
    }
}

/// Sub-boxes per axis of [`RelativeMotion::speed_bound_box_centred`] (3: 4 to 6 % fewer render
/// steps on the object presets than 1; more gains little).
const BOX_SPLIT: usize = 3;

/// A rigid velocity field in the camera frame: a point `P` (camera frame, m) of the body moves
/// relative to the camera with `V(P) = linear + angular x P` (m/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RelativeMotion {
    /// m/s, camera frame.
    pub linear: Vec3,
    /// rad/s, camera frame.
    pub angular: Vec3,
}

impl RelativeMotion {
    /// Relative motion of a body with world state `body` (or the static world for `None`) seen
    /// from a camera with world state `cam`.
    pub fn new(cam: &RigidState, body: Option<&RigidState>) -> Self {
        let r_cw = math::transpose(&cam.rotation);
        let w_c = cam.omega_body;
        match body {
            None => Self {
                linear: math::scale(math::mul_mv(&r_cw, cam.velocity), -1.0),
                angular: math::scale(w_c, -1.0),
            },
            Some(b) => {
                let w_o = b.omega_world();
                let v = math::add(b.velocity, math::cross(w_o, math::sub(cam.position, b.position)));
                Self {
                    linear: math::mul_mv(&r_cw, math::sub(v, cam.velocity)),
                    angular: math::sub(math::mul_mv(&r_cw, w_o), w_c),
                }
            }
        }
    }

    /// Velocity of the camera-frame point `p` relative to the camera, m/s.
    pub fn velocity(&self, p: Vec3) -> Vec3 {
        math::add(self.linear, math::cross(self.angular, p))
    }

    /// Normalized image flow (1/s) of the camera-frame point `p` (needs `p.z > 0`).
    pub fn normalized_flow(&self, p: Vec3) -> (f64, f64) {
        let v = self.velocity(p);
        let (x, y) = (p[0] / p[2], p[1] / p[2]);
        ((v[0] - x * v[2]) / p[2], (v[1] - y * v[2]) / p[2])
    }

    /// Upper bound of the normalized image speed (1/s) of this body's points within `radius`
    /// (m) of the camera-frame point `center`, at depth `z >= z_min`, seen at image radius
    /// `sqrt(x^2 + y^2) <= r_max` (normalized).
    pub fn speed_bound_ball(&self, center: Vec3, radius: f64, z_min: f64, r_max: f64) -> f64 {
        // |u| = |[[1, 0, -x], [0, 1, -y]] V| / Z <= sqrt(1 + r^2) |V| / Z, and
        // |V(P)| <= |V(center)| + |angular| |P - center|.
        let v = math::norm(self.velocity(center)) + math::norm(self.angular) * radius;
        (1.0 + r_max * r_max).sqrt() * v / z_min
    }

    /// Upper bound of the normalized image speed (1/s) of the points of a box (this body) with
    /// camera-frame `corners`, seen at image radius `<= r_max` (normalized); `None` unless
    /// every corner is at depth > 0.1 m. The image speed of a point `P` is at most
    /// `sqrt(1 + x^2 + y^2) |V(P)| / Z` (the largest singular value of the projection's
    /// Jacobian). `|V|` is convex and `Z` affine and positive over the box, so every sublevel
    /// set `{P : |V(P)| <= c Z(P)}` is convex: `|V| / Z` is quasiconvex and its largest value
    /// over the box is at a corner (not the largest `|V|` over the smallest `Z`, which may be
    /// at different corners). The largest image radius of the projection (the convex hull of
    /// the projected corners) is at a corner too.
    pub fn speed_bound_box(&self, corners: &[Vec3; 8], r_max: f64) -> Option<f64> {
        let z_min = corners.iter().map(|c| c[2]).fold(f64::INFINITY, f64::min);
        if z_min.is_nan() || z_min <= 0.1 {
            return None;
        }
        let v_over_z = corners
            .iter()
            .map(|&c| math::norm(self.velocity(c)) / c[2])
            .fold(0.0, f64::max);
        let r2 = corners
            .iter()
            .map(|c| (c[0] * c[0] + c[1] * c[1]) / (c[2] * c[2]))
            .fold(0.0, f64::max)
            .min(r_max * r_max);
        Some((1.0 + r2).sqrt() * v_over_z)
    }

    /// Upper bound of the normalized image speed (1/s) of the points of a box (this body) with
    /// camera-frame `corners`, without the projection Jacobian's largest singular value that
    /// [`RelativeMotion::speed_bound_box`] pays for the worst image point: the flow of a point
    /// `P` seen at normalized `q = (x, y)` is `(V_xy(P) - q Vz(P)) / Z`. The box is split into
    /// `BOX_SPLIT`^3 sub-boxes. Every projected point of a sub-box lies in the convex hull of its
    /// projected corners, so within `rho` (the largest distance of a projected corner) of the
    /// centre `c` of their bounding rectangle, and the flow's norm is at most
    /// `(|V_xy(P) - c Vz(P)| + rho |Vz(P)|) / Z(P)`. The numerator is convex in `P` (norms of
    /// affine maps) and `Z` affine and positive, so the quotient is quasiconvex and its largest
    /// value over the sub-box is at a corner; the bound is the largest over the sub-boxes
    /// (smaller sub-boxes, smaller `rho`). It is tighter than the other bound when the box is
    /// off the image centre or moves little along the optical axis (a box seen at `r = 0.5`
    /// and moving sideways: about `|V| / Z` instead of `1.12 |V| / Z`); callers take the
    /// smaller. `None` unless every corner is at depth > 0.1 m.
    pub fn speed_bound_box_centred(&self, corners: &[Vec3; 8]) -> Option<f64> {
        let z_min = corners.iter().map(|c| c[2]).fold(f64::INFINITY, f64::min);
        if z_min.is_nan() || z_min <= 0.1 {
            return None;
        }
        const N: usize = BOX_SPLIT;
        const M: usize = N + 1;
        // The (N + 1)^3 grid of sub-box corners (corner bit k of `corners` is the end along
        // the box's axis k): velocity, depth and normalized image point of each.
        let lerp = |a: Vec3, b: Vec3, f: f64| math::add(a, math::scale(math::sub(b, a), f));
        let mut grid = [([0.0f64; 3], 0.0f64, [0.0f64; 2]); M * M * M];
        for (g, item) in grid.iter_mut().enumerate() {
            let f = |d: usize| d as f64 / N as f64;
            let (fi, fj, fk) = (f(g % M), f(g / M % M), f(g / (M * M)));
            let y0 = lerp(
                lerp(corners[0], corners[1], fi),
                lerp(corners[2], corners[3], fi),
                fj,
            );
            let y1 = lerp(
                lerp(corners[4], corners[5], fi),
                lerp(corners[6], corners[7], fi),
                fj,
            );
            let p = lerp(y0, y1, fk);
            *item = (self.velocity(p), p[2], [p[0] / p[2], p[1] / p[2]]);
        }
        let mut bound: f64 = 0.0;
        for s in 0..N * N * N {
            let (i, j, k) = (s % N, s / N % N, s / (N * N));
            let sub = |c: usize| &grid[(i + (c & 1)) + (j + (c >> 1 & 1)) * M + (k + (c >> 2)) * M * M];
            let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
            for c in 0..8 {
                let q = sub(c).2;
                for a in 0..2 {
                    lo[a] = lo[a].min(q[a]);
                    hi[a] = hi[a].max(q[a]);
                }
            }
            let centre = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
            let rho = (0..8)
                .map(|c| (sub(c).2[0] - centre[0]).hypot(sub(c).2[1] - centre[1]))
                .fold(0.0, f64::max);
            for c in 0..8 {
                let (v, z, _) = *sub(c);
                let flow = (v[0] - centre[0] * v[2]).hypot(v[1] - centre[1] * v[2]);
                bound = bound.max((flow + rho * v[2].abs()) / z);
            }
        }
        Some(bound)
    }

    /// Upper bound of the normalized image speed (1/s) of static points (this motion is the
    /// static world's) at depth `>= z_min` seen within `hx`, `hy` (normalized) of `(x, y)`.
    ///
    /// The flow is `R + T / z` with `R`, `T` the rotational and translational flow vectors; at
    /// `(x, y)` its norm is convex in `1 / z`, so largest at `1 / z = 0` or `1 / z_min` (this
    /// keeps partial cancellation of the two parts). Across the window `T` changes by at most
    /// `|v_z| |(hx, hy)|` and each component of `R` by its gradient bound times `(hx, hy)`.
    pub fn static_speed_bound_near(&self, x: f64, y: f64, hx: f64, hy: f64, z_min: f64) -> f64 {
        let (w, v) = (self.angular, self.linear);
        let c = math::cross(w, [x, y, 1.0]);
        let r = (c[0] - x * c[2], c[1] - y * c[2]);
        let t = (v[0] - x * v[2], v[1] - y * v[2]);
        let inv_z = 1.0 / z_min;
        let norm = |a: f64, b: f64| (a * a + b * b).sqrt();
        let centre = norm(r.0, r.1).max(norm(r.0 + t.0 * inv_z, r.1 + t.1 * inv_z));
        // R0 = wy (1 + x^2) - wz y - wx x y, R1 = -wx (1 + y^2) + wz x + wy x y.
        let (xm, ym) = (x.abs() + hx, y.abs() + hy);
        let (ax, ay, az) = (w[0].abs(), w[1].abs(), w[2].abs());
        let d0 = hx * (2.0 * ay * xm + ax * ym) + hy * (az + ax * xm);
        let d1 = hx * (az + ay * ym) + hy * (2.0 * ax * ym + ay * xm);
        centre + norm(d0, d1) + v[2].abs() * norm(hx, hy) * inv_z
    }

    /// [`RelativeMotion::static_speed_bound_near`] of every window `k` (`x[k]`, `y[k]`,
    /// `hx[k]`, `hy[k]`, `z_min[k]`, all of one length) into `out[k]`: the same values, with
    /// AVX2 (detected at run time) 4 windows at a time in the same order of operations.
    pub fn static_speed_bounds_near(
        &self,
        x: &[f64],
        y: &[f64],
        hx: &[f64],
        hy: &[f64],
        z_min: &[f64],
        out: &mut [f64],
    ) {
        let n = out.len();
        let (x, y, hx, hy, z_min) = (&x[..n], &y[..n], &hx[..n], &hy[..n], &z_min[..n]);
        let mut k = 0;
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            k = unsafe { self.static_speed_bounds_near_avx2(x, y, hx, hy, z_min, out) };
        }
        for k in k..n {
            out[k] = self.static_speed_bound_near(x[k], y[k], hx[k], hy[k], z_min[k]);
        }
    }

    /// The whole groups of 4 of [`RelativeMotion::static_speed_bounds_near`] (all slices of
    /// the length of `out`) with AVX2; returns how many windows it did.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn static_speed_bounds_near_avx2(
        &self,
        x: &[f64],
        y: &[f64],
        hx: &[f64],
        hy: &[f64],
        z_min: &[f64],
        out: &mut [f64],
    ) -> usize {
        use std::arch::x86_64::*;
        let (w, v) = (self.angular, self.linear);
        let set = _mm256_set1_pd;
        let abs = |a: __m256d| _mm256_andnot_pd(set(-0.0), a);
        let norm =
            |a: __m256d, b: __m256d| _mm256_sqrt_pd(_mm256_add_pd(_mm256_mul_pd(a, a), _mm256_mul_pd(b, b)));
        let (w0, w1, w2, v0, v1, v2) = (set(w[0]), set(w[1]), set(w[2]), set(v[0]), set(v[1]), set(v[2]));
        let (ax, ay, az, two) = (set(w[0].abs()), set(w[1].abs()), set(w[2].abs()), set(2.0));
        let n = out.len() / 4 * 4;
        for k in (0..n).step_by(4) {
            // SAFETY: k + 4 <= n <= the length of every slice.
            let (x, y, hx, hy, z) = unsafe {
                (
                    _mm256_loadu_pd(x.as_ptr().add(k)),
                    _mm256_loadu_pd(y.as_ptr().add(k)),
                    _mm256_loadu_pd(hx.as_ptr().add(k)),
                    _mm256_loadu_pd(hy.as_ptr().add(k)),
                    _mm256_loadu_pd(z_min.as_ptr().add(k)),
                )
            };
            // cross(w, (x, y, 1)), w times 1 being w.
            let c0 = _mm256_sub_pd(w1, _mm256_mul_pd(w2, y));
            let c1 = _mm256_sub_pd(_mm256_mul_pd(w2, x), w0);
            let c2 = _mm256_sub_pd(_mm256_mul_pd(w0, y), _mm256_mul_pd(w1, x));
            let (r0, r1) = (
                _mm256_sub_pd(c0, _mm256_mul_pd(x, c2)),
                _mm256_sub_pd(c1, _mm256_mul_pd(y, c2)),
            );
            let (t0, t1) = (
                _mm256_sub_pd(v0, _mm256_mul_pd(x, v2)),
                _mm256_sub_pd(v1, _mm256_mul_pd(y, v2)),
            );
            let inv_z = _mm256_div_pd(set(1.0), z);
            let centre = _mm256_max_pd(
                norm(r0, r1),
                norm(
                    _mm256_add_pd(r0, _mm256_mul_pd(t0, inv_z)),
                    _mm256_add_pd(r1, _mm256_mul_pd(t1, inv_z)),
                ),
            );
            let (xm, ym) = (_mm256_add_pd(abs(x), hx), _mm256_add_pd(abs(y), hy));
            let d0 = _mm256_add_pd(
                _mm256_mul_pd(
                    hx,
                    _mm256_add_pd(_mm256_mul_pd(_mm256_mul_pd(two, ay), xm), _mm256_mul_pd(ax, ym)),
                ),
                _mm256_mul_pd(hy, _mm256_add_pd(az, _mm256_mul_pd(ax, xm))),
            );
            let d1 = _mm256_add_pd(
                _mm256_mul_pd(hx, _mm256_add_pd(az, _mm256_mul_pd(ay, ym))),
                _mm256_mul_pd(
                    hy,
                    _mm256_add_pd(_mm256_mul_pd(_mm256_mul_pd(two, ax), ym), _mm256_mul_pd(ay, xm)),
                ),
            );
            let r = _mm256_add_pd(
                _mm256_add_pd(centre, norm(d0, d1)),
                _mm256_mul_pd(_mm256_mul_pd(abs(v2), norm(hx, hy)), inv_z),
            );
            // SAFETY: k + 4 <= the length of `out`.
            unsafe { _mm256_storeu_pd(out.as_mut_ptr().add(k), r) };
        }
        n
    }

    /// Rotational (depth-independent) and translational (times depth) parts of the normalized
    /// flow magnitude at normalized `(x, y)`: `|flow| <= rot + trans / Z`.
    pub fn flow_parts(&self, x: f64, y: f64) -> (f64, f64) {
        let d = [x, y, 1.0];
        let c = math::cross(self.angular, d);
        let v = self.linear;
        let rot = (c[0] - x * c[2]).hypot(c[1] - y * c[2]);
        let trans = (v[0] - x * v[2]).hypot(v[1] - y * v[2]);
        (rot, trans)
    }

    /// Upper bound of the normalized image speed (1/s) of this body's points that lie in front of
    /// the camera at depth `z >= z_min` and inside `|x| <= max_x`, `|y| <= max_y`.
    pub fn speed_bound(&self, z_min: f64, max_x: f64, max_y: f64) -> f64 {
        let v = self.linear;
        let w = self.angular;
        // V(P) = v + w x P with P = Z (x, y, 1): flow = (v_xy - x v_z) / Z + B(x) w-like term.
        let trans = (v[0].abs() + v[1].abs() + (max_x + max_y) * v[2].abs()) / z_min;
        let mut rot: f64 = 0.0;
        for &(x, y) in &[
            (max_x, max_y),
            (max_x, -max_y),
            (-max_x, max_y),
            (-max_x, -max_y),
            (0.0, 0.0),
        ] {
            let c = math::cross(w, [x, y, 1.0]);
            let fx = c[0] - x * c[2];
            let fy = c[1] - y * c[2];
            rot = rot.max(fx.abs() + fy.abs());
        }
        // The rotational flow is quadratic in (x, y); the corners bound it up to the mixed terms,
        // which the 1-norm above over-estimates anyway.
        trans + rot
    }
}

/// Camera-frame pose of a box at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxPose {
    /// Box -> camera rotation.
    pub r_cb: Mat3,
    /// Box centre in the camera frame, m.
    pub center: Vec3,
}

impl BoxPose {
    /// Pose of a box with world state `b` seen from a camera with world state `cam`.
    pub fn new(cam: &RigidState, b: &RigidState) -> Self {
        let r_cw = math::transpose(&cam.rotation);
        Self {
            r_cb: math::mul_mm(&r_cw, &b.rotation),
            center: math::mul_mv(&r_cw, math::sub(b.position, cam.position)),
        }
    }

    /// The 8 corners in the camera frame.
    pub fn corners(&self, half: Vec3) -> [Vec3; 8] {
        let mut out = [[0.0; 3]; 8];
        for (k, c) in out.iter_mut().enumerate() {
            let s = [
                if k & 1 == 0 { -half[0] } else { half[0] },
                if k & 2 == 0 { -half[1] } else { half[1] },
                if k & 4 == 0 { -half[2] } else { half[2] },
            ];
            *c = math::add(self.center, math::mul_mv(&self.r_cb, s));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::trajectory::Signal;

    #[test]
    fn relative_motion_of_static_world_is_minus_camera_motion() {
        let cam = RigidTrajectory {
            position: [
                Signal::linear(0.0, 0.5),
                Signal::constant(0.0),
                Signal::constant(1.0),
            ],
            base_rotation: math::IDENTITY,
            axes: [2, 1, 0],
            angles: [Signal::linear(0.0, 0.3), Signal::default(), Signal::default()],
        }
        .state(0.0);
        let m = RelativeMotion::new(&cam, None);
        assert!((m.linear[0] + 0.5).abs() < 1e-12 && (m.angular[2] + 0.3).abs() < 1e-12);
        // A body moving exactly with the camera has no relative motion.
        let same = RelativeMotion::new(&cam, Some(&cam));
        assert!(math::norm(same.linear) < 1e-12 && math::norm(same.angular) < 1e-12);
    }

    #[test]
    fn ball_bound_covers_points_of_a_tumbling_body() {
        let m = RelativeMotion {
            linear: [0.8, -0.3, 0.2],
            angular: [1.0, 0.5, -0.7],
        };
        let c = [0.3, -0.1, 2.0];
        let b = m.speed_bound_ball(c, 0.3, 1.7, 0.8);
        for i in 0..1000 {
            let a = i as f64 * 0.731;
            let off = [0.17 * a.sin(), 0.17 * (1.3 * a).cos(), 0.2 * (0.7 * a).sin()];
            let p = math::add(c, off);
            let (fx, fy) = m.normalized_flow(p);
            assert!((fx * fx + fy * fy).sqrt() <= b);
        }
    }

    #[test]
    fn speed_bound_covers_sampled_points() {
        let m = RelativeMotion {
            linear: [0.3, -0.2, 0.5],
            angular: [0.4, -0.7, 0.2],
        };
        let b = m.speed_bound(1.5, 0.6, 0.45);
        for i in 0..50 {
            let x = -0.6 + 1.2 * (i as f64 / 49.0);
            for j in 0..50 {
                let y = -0.45 + 0.9 * (j as f64 / 49.0);
                for z in [1.5, 2.0, 7.0] {
                    let (fx, fy) = m.normalized_flow([x * z, y * z, z]);
                    let speed = (fx * fx + fy * fy).sqrt();
                    assert!(speed <= b + 1e-9);
                    let (rot, trans) = m.flow_parts(x, y);
                    assert!(speed <= rot + trans / z + 1e-9);
                }
            }
        }
    }

    #[test]
    fn box_bound_covers_every_point_of_the_box_and_is_tighter_than_the_ball() {
        let m = RelativeMotion {
            linear: [0.8, -0.3, 0.2],
            angular: [1.0, 0.5, -0.7],
        };
        let pose = BoxPose {
            r_cb: math::rot_axis(1, 0.4),
            center: [0.3, -0.1, 2.0],
        };
        let half = [0.25, 0.18, 0.2];
        let corners = pose.corners(half);
        let b = m.speed_bound_box(&corners, 10.0).unwrap();
        let zmin = corners.iter().map(|c| c[2]).fold(f64::INFINITY, f64::min);
        let ball = m.speed_bound_ball(pose.center, math::norm(half), zmin, 10.0);
        let mut fastest = 0.0f64;
        let n = 12;
        for i in 0..=n {
            for j in 0..=n {
                for k in 0..=n {
                    let f = |q: usize| 2.0 * q as f64 / n as f64 - 1.0;
                    let local = [f(i) * half[0], f(j) * half[1], f(k) * half[2]];
                    let p = math::add(pose.center, math::mul_mv(&pose.r_cb, local));
                    let (fx, fy) = m.normalized_flow(p);
                    fastest = fastest.max((fx * fx + fy * fy).sqrt());
                }
            }
        }
        assert!(
            fastest <= b && b < ball,
            "fastest {fastest}, box {b}, ball {ball}"
        );
        // Not far from the true maximum either (the corners and centre of the image).
        assert!(b < 1.6 * fastest, "fastest {fastest}, box {b}");
        // Random boxes and motions: sampled points never exceed the bound, and it is never
        // looser than the largest corner speed over the smallest corner depth.
        let mut rng = crate::rng::Rng::new(11, 3);
        for _ in 0..200 {
            let m = RelativeMotion {
                linear: [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)],
                angular: [rng.range(-2.0, 2.0), rng.range(-2.0, 2.0), rng.range(-2.0, 2.0)],
            };
            let pose = BoxPose {
                r_cb: math::mul_mm(
                    &math::rot_axis(0, rng.range(-3.0, 3.0)),
                    &math::rot_axis(2, rng.range(-3.0, 3.0)),
                ),
                center: [rng.range(-0.8, 0.8), rng.range(-0.6, 0.6), rng.range(1.0, 3.0)],
            };
            let half = [rng.range(0.05, 0.4), rng.range(0.05, 0.4), rng.range(0.02, 0.3)];
            let corners = pose.corners(half);
            let Some(b) = m.speed_bound_box(&corners, 10.0) else {
                continue;
            };
            let v_max = corners
                .iter()
                .map(|&c| math::norm(m.velocity(c)))
                .fold(0.0, f64::max);
            let z_min = corners.iter().map(|c| c[2]).fold(f64::INFINITY, f64::min);
            let r2 = corners
                .iter()
                .map(|c| (c[0] * c[0] + c[1] * c[1]) / (c[2] * c[2]))
                .fold(0.0, f64::max);
            assert!(b <= (1.0 + r2).sqrt() * v_max / z_min * (1.0 + 1e-12));
            let centred = m.speed_bound_box_centred(&corners).unwrap();
            for _ in 0..300 {
                let local = [
                    rng.range(-half[0], half[0]),
                    rng.range(-half[1], half[1]),
                    rng.range(-half[2], half[2]),
                ];
                let p = math::add(pose.center, math::mul_mv(&pose.r_cb, local));
                let (fx, fy) = m.normalized_flow(p);
                assert!(fx.hypot(fy) <= b * (1.0 + 1e-12), "{} > {b}", fx.hypot(fy));
                assert!(
                    fx.hypot(fy) <= centred * (1.0 + 1e-12),
                    "{} > {centred}",
                    fx.hypot(fy)
                );
            }
            // Corners and face centres too (where the largest speeds are).
            for k in 0..27 {
                let f = |d: usize| d as f64 - 1.0;
                let local = [f(k % 3) * half[0], f(k / 3 % 3) * half[1], f(k / 9) * half[2]];
                let p = math::add(pose.center, math::mul_mv(&pose.r_cb, local));
                let (fx, fy) = m.normalized_flow(p);
                assert!(fx.hypot(fy) <= centred * (1.0 + 1e-12));
            }
        }
        // A corner behind the camera: no box bound.
        let near = BoxPose {
            r_cb: math::IDENTITY,
            center: [0.0, 0.0, 0.1],
        };
        assert!(m.speed_bound_box(&near.corners(half), 1.0).is_none());
        assert!(m.speed_bound_box_centred(&near.corners(half)).is_none());
        // Off the image centre and moving sideways, the centred bound is much tighter.
        let side = RelativeMotion {
            linear: [0.8, 0.1, 0.05],
            angular: [0.0, 0.0, 0.0],
        };
        let off = BoxPose {
            r_cb: math::IDENTITY,
            center: [1.0, 0.4, 2.0],
        };
        let (c, o) = (
            side.speed_bound_box_centred(&off.corners(half)).unwrap(),
            side.speed_bound_box(&off.corners(half), 10.0).unwrap(),
        );
        assert!(c < 0.9 * o, "centred {c}, box {o}");
    }

    #[test]
    fn static_bounds_in_lanes_equal_one_by_one() {
        let mut rng = crate::rng::Rng::new(4, 9);
        for _ in 0..50 {
            let m = RelativeMotion {
                linear: [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)],
                angular: [rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)],
            };
            let n = 1 + rng.below(40) as usize;
            let mut draw = |lo: f64, hi: f64| -> Vec<f64> { (0..n).map(|_| rng.range(lo, hi)).collect() };
            let (x, y, hx, hy, z) = (
                draw(-0.7, 0.7),
                draw(-0.5, 0.5),
                draw(0.0, 0.02),
                draw(0.0, 0.02),
                draw(0.3, 8.0),
            );
            let mut out = vec![0.0; n];
            m.static_speed_bounds_near(&x, &y, &hx, &hy, &z, &mut out);
            for k in 0..n {
                let one = m.static_speed_bound_near(x[k], y[k], hx[k], hy[k], z[k]);
                assert_eq!(out[k].to_bits(), one.to_bits(), "{k}");
            }
        }
    }

    #[test]
    fn static_bound_near_covers_every_point_and_depth_of_the_window() {
        let m = RelativeMotion {
            linear: [0.4, -0.1, 0.5],
            angular: [0.3, -0.35, 0.15],
        };
        for (x, y) in [(0.0, 0.0), (0.5, -0.4), (-0.55, 0.42), (0.3, 0.1)] {
            let (hx, hy) = (0.02, 0.015);
            let z_min = 1.3;
            let b = m.static_speed_bound_near(x, y, hx, hy, z_min);
            let mut fastest = 0.0f64;
            for i in 0..=10 {
                for j in 0..=10 {
                    let px = x - hx + 2.0 * hx * i as f64 / 10.0;
                    let py = y - hy + 2.0 * hy * j as f64 / 10.0;
                    for z in [z_min, 1.7, 3.0, 10.0, 1e6] {
                        let (fx, fy) = m.normalized_flow([px * z, py * z, z]);
                        fastest = fastest.max(fx.hypot(fy));
                    }
                }
            }
            let (rot, trans) = m.flow_parts(x, y);
            assert!(fastest <= b, "({x}, {y}): fastest {fastest} > bound {b}");
            assert!(b < 1.3 * fastest, "({x}, {y}): bound {b} loose vs {fastest}");
            // Never looser than the sum of the parts by more than the window terms.
            assert!(b <= rot + trans / z_min + 0.02, "({x}, {y})");
        }
    }
}
