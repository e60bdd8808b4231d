//! Ray casting of the scene at one instant: per pixel the nearest surface, its object id, its
//! depth and its log intensity.
//!
//! Anti-aliasing: textures are filtered analytically (trilinear mip-mapping, see `texture`).
//! Geometric edges (object silhouettes, wall seams, box creases) are anti-aliased by 2x2
//! supersampling of only those pixels whose centre surface differs from a 4-neighbour's; the
//! four sub-samples at (+-1/4, +-1/4) px are averaged in linear intensity. This keeps the cost
//! near one ray per pixel while an edge sweeping over a pixel changes its intensity in several
//! steps instead of one jump.

use crate::camera::CameraConfig;
use crate::math::{self, Vec3};
use crate::scene::{BoxPose, RelativeMotion, Scene};
use crate::texture::LANES;
use crate::trajectory::RigidState;

#[cfg(target_arch = "x86_64")]
mod lane_search;

/// Texture coordinate offsets (m) that make the six faces of a box show different parts of its
/// texture.
const FACE_OFFSET: [[f32; 2]; 6] = [
    [0.0, 0.0],
    [0.37, 0.11],
    [0.71, 0.53],
    [0.13, 0.91],
    [0.59, 0.29],
    [0.97, 0.77],
];
/// Offsets (px, along the row and down the column) of the 2x2 edge sub-samples.
const SUBSAMPLES: [(f32, f32); 4] = [(-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)];

/// The normalized rays of the 2x2 sub-samples of a pixel whose centre ray is `(x, y)` and whose
/// ray changes by `du` per pixel along the row and `dv` down the column (the points the edge
/// anti-aliasing averages: [`FrameGeom::supersample`], [`FrameGeom::edge_sample`]).
#[inline(always)]
pub fn sub_sample_rays(x: f32, y: f32, du: [f32; 2], dv: [f32; 2]) -> [(f32, f32); 4] {
    SUBSAMPLES.map(|(ou, ov)| (x + ou * du[0] + ov * dv[0], y + ou * du[1] + ov * dv[1]))
}
/// Smallest cosine of incidence used for the texture footprint (caps the blur at grazing view).
const MIN_COS: f32 = 0.25;
/// Fewest lanes of [`FrameGeom::shade_lanes`] on one texture sampled together (fewer are
/// sampled one by one).
const MIN_GROUP: u32 = 3;
/// Allowance (normalized image units, about 0.03 px at f = 550) of [`FrameGeom::edge_free`]
/// against the f32 rounding of `locate`: its slab and plane tests place an edge within about
/// 1e-6 of the exact geometry.
const EDGE_EPS: f32 = 5e-5;
/// Deepest (m) a box's corner may reach through a background plane for
/// [`FrameGeom::edge_free`] to treat the box as in front of the planes (furniture stands on
/// the floor: its corners lie on it up to rounding).
const ROOM_TOLERANCE: f64 = 1e-5;

/// Where a ray meets a surface's texture (see [`FrameGeom::shade`]).
#[derive(Debug, Clone, Copy)]
struct TexturePoint {
    /// Texture index in the scene (`usize::MAX`: no surface).
    tex: usize,
    /// Texture coordinates, m (face offsets included).
    u: f32,
    v: f32,
    /// Pixel footprint on the surface, m.
    footprint: f32,
    /// Log shading of the surface.
    ln_shade: f32,
}

impl TexturePoint {
    /// No surface.
    const NONE: Self = Self {
        tex: usize::MAX,
        u: 0.0,
        v: 0.0,
        footprint: 1.0,
        ln_shade: 0.0,
    };

    /// The hit of `loc` with log intensity `l`.
    #[inline(always)]
    fn hit(&self, loc: &Located, l: f32) -> Hit {
        Hit {
            l,
            key: loc.key,
            id: loc.id,
            z: loc.z,
            u: self.u,
            v: self.v,
            footprint: self.footprint,
        }
    }
}

/// Result of casting one ray.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Log intensity.
    pub l: f32,
    /// Surface key (plane index, or box face key); `u16::MAX` when nothing was hit.
    pub key: u16,
    /// Object id (0 = background).
    pub id: u16,
    /// Depth along the optical axis, m (infinite when nothing was hit).
    pub z: f32,
    /// Texture coordinates of the hit, m (face offsets included).
    pub u: f32,
    /// Texture coordinates of the hit, m.
    pub v: f32,
    /// Pixel footprint on the surface, m (selects the mip level).
    pub footprint: f32,
}

impl Hit {
    /// A ray that hits no surface.
    pub const NONE: Self = Self {
        l: 0.0,
        key: u16::MAX,
        id: 0,
        z: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        footprint: 1.0,
    };
}

/// [`Hit`]s of [`LANES`] rays, field by field (see [`FrameGeom::cast_lanes`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct HitLanes {
    /// Log intensities.
    pub l: [f32; LANES],
    /// Surface keys.
    pub key: [u16; LANES],
    /// Object ids.
    pub id: [u16; LANES],
    /// Depths, m.
    pub z: [f32; LANES],
    /// Texture coordinates, m.
    pub u: [f32; LANES],
    /// Texture coordinates, m.
    pub v: [f32; LANES],
    /// Pixel footprints on the surfaces, m.
    pub footprint: [f32; LANES],
}

impl HitLanes {
    /// The hit of lane `l`.
    pub fn get(&self, l: usize) -> Hit {
        Hit {
            l: self.l[l],
            key: self.key[l],
            id: self.id[l],
            z: self.z[l],
            u: self.u[l],
            v: self.v[l],
            footprint: self.footprint[l],
        }
    }
}

/// Which surface a ray hits (see [`FrameGeom::locate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Surface {
    /// Nothing (the ray leaves the scene).
    Nothing,
    /// Background plane, by index in the frame's plane list.
    Plane(usize),
    /// Box face, by index in the frame's (visible) box list.
    Box {
        /// Index in the frame's visible box list.
        index: usize,
        /// Face 0..6 (axis `face / 2`, negative side for even faces).
        face: usize,
        /// Ray direction in box coordinates.
        db: [f32; 3],
    },
}

/// The nearest surface on a ray, before texturing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Located {
    /// The surface.
    pub surface: Surface,
    /// Surface key (plane index, or box face key); `u16::MAX` when nothing was hit.
    pub key: u16,
    /// Object id (0 = background).
    pub id: u16,
    /// Depth along the optical axis, m (infinite when nothing was hit).
    pub z: f32,
}

impl Located {
    /// A ray that hits no surface.
    pub const NOTHING: Self = Self {
        surface: Surface::Nothing,
        key: u16::MAX,
        id: 0,
        z: f32::INFINITY,
    };
}

/// The result of [`FrameGeom::search_lanes`] lane by lane.
struct LaneSearch<const N: usize> {
    /// Nearest plane (`u32::MAX`: none in front).
    best_plane: [u32; N],
    /// Nearest box hit nearer than the plane (`u32::MAX`: none).
    best_box: [u32; N],
    /// Face of that box.
    box_face: [u32; N],
    /// Ray direction in that box's coordinates, component by component.
    box_db: [[f32; N]; 3],
    /// Depth of the nearest surface (infinite: none).
    s: [f32; N],
}

impl<const N: usize> LaneSearch<N> {
    /// The lanes as [`Located`] surfaces of `g`.
    #[inline(always)]
    fn located(&self, g: &FrameGeom) -> [Located; N] {
        let mut out = [Located::NOTHING; N];
        for (l, o) in out.iter_mut().enumerate() {
            *o = self.located_lane(g, l);
        }
        out
    }

    /// The surface key of lane `l` (as in [`LaneSearch::located`]).
    #[inline(always)]
    fn key(&self, g: &FrameGeom, l: usize) -> u16 {
        if self.best_box[l] != u32::MAX {
            g.boxes[self.best_box[l] as usize].key_base + self.box_face[l] as u16
        } else if self.best_plane[l] == u32::MAX {
            u16::MAX
        } else {
            g.planes[self.best_plane[l] as usize].key
        }
    }

    /// Lane `l` as a [`Located`] surface of `g`.
    #[inline(always)]
    fn located_lane(&self, g: &FrameGeom, l: usize) -> Located {
        {
            if self.best_box[l] != u32::MAX {
                let b = &g.boxes[self.best_box[l] as usize];
                let face = self.box_face[l] as usize;
                Located {
                    surface: Surface::Box {
                        index: self.best_box[l] as usize,
                        face,
                        db: [self.box_db[0][l], self.box_db[1][l], self.box_db[2][l]],
                    },
                    key: b.key_base + face as u16,
                    id: b.id,
                    z: self.s[l],
                }
            } else if self.best_plane[l] == u32::MAX {
                Located::NOTHING
            } else {
                let p = &g.planes[self.best_plane[l] as usize];
                Located {
                    surface: Surface::Plane(self.best_plane[l] as usize),
                    key: p.key,
                    id: 0,
                    z: self.s[l],
                }
            }
        }
    }
}

#[derive(Debug, Clone)]
struct PlaneGeom {
    /// Camera-frame normal divided by the signed plane offset: inverse depth = a . d.
    a: [f32; 3],
    /// Camera-frame unit normal.
    n: [f32; 3],
    e1: [f32; 3],
    off1: f32,
    e2: [f32; 3],
    off2: f32,
    ln_shade: f32,
    tex: usize,
    key: u16,
}

#[derive(Debug, Clone)]
struct BoxGeom {
    /// Camera -> box rotation, rows.
    r_bc: [[f32; 3]; 3],
    /// Camera origin in box coordinates.
    o_b: [f32; 3],
    half: [f32; 3],
    ln_shade: [f32; 6],
    tex: usize,
    key_base: u16,
    id: u16,
    /// Pixel bounding box `[u0, v0, u1, v1]` (inclusive) of the projection, with margin.
    bbox: [i32; 4],
    /// Index of the box's motion in [`FrameGeom::motions`].
    motion: usize,
    /// Projected edges for [`FrameGeom::edge_free`] (`None` when a corner is near or behind
    /// the camera, the camera is inside the box, or the box reaches through a background plane
    /// by more than `ROOM_TOLERANCE`).
    outline: Option<Outline>,
}

/// A box's projected edges: each edge as the unit normal of the plane through the camera centre
/// and the edge (the edge's image line is `n . (x, y, 1) = 0`), four per face and the
/// silhouette's (padded with `(0, 0, 1)`, which no pixel crosses), field by field in lanes.
#[derive(Debug, Clone)]
struct Outline {
    /// Edges of each face (the boundary of its projection).
    face: [[[f32; 4]; 3]; 6],
    /// Edges between a front-facing and a back-facing face (the boundary of the box's
    /// projection), padded.
    silhouette: [[f32; 8]; 3],
    /// Smallest and largest distance (m) of a corner from the camera centre.
    dist: (f32, f32),
}

impl Outline {
    /// The outline of a box with camera-frame `corners` (ordered as [`BoxPose::corners`]),
    /// camera-frame origin `o_b` in box coordinates and half extents `half`, or `None` (see
    /// [`BoxGeom::outline`]); `planes` are the background planes (`a . X < 1` on the camera's
    /// side).
    fn new(corners: &[Vec3; 8], o_b: Vec3, half: Vec3, planes: &[PlaneGeom]) -> Option<Self> {
        if corners.iter().any(|c| c[2] <= 0.05) || (0..3).all(|k| o_b[k].abs() <= half[k]) {
            return None;
        }
        for p in planes {
            // Distance to the plane on the camera's side: (1 - a . c) |h| with |a| = 1 / |h|.
            let inv_h = math::norm([p.a[0] as f64, p.a[1] as f64, p.a[2] as f64]);
            for c in corners {
                let ac = p.a[0] as f64 * c[0] + p.a[1] as f64 * c[1] + p.a[2] as f64 * c[2];
                if (1.0 - ac) < -ROOM_TOLERANCE * inv_h {
                    return None;
                }
            }
        }
        let normal = |a: usize, b: usize| {
            let n = math::cross(corners[a], corners[b]);
            math::scale(n, 1.0 / math::norm(n))
        };
        // Faces 2k (side -half[k], corner bit k clear) and 2k + 1 (bit k set); a face is front
        // facing when the camera is outside its side.
        let front = |face: usize| {
            let k = face / 2;
            if face.is_multiple_of(2) {
                o_b[k] < -half[k]
            } else {
                o_b[k] > half[k]
            }
        };
        let mut face = [[[0.0f32; 4]; 3]; 6];
        let mut silhouette = [[0.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], [0.0; 8], [1.0; 8]];
        let mut n_sil = 0;
        let mut n_face = [0usize; 6];
        for axis in 0..3 {
            for c in 0..8usize {
                if c >> axis & 1 == 1 {
                    continue;
                }
                let n = normal(c, c | 1 << axis);
                // The two faces along this edge: one per other axis, on the side of `c`'s bits.
                let mut faces = [0usize; 2];
                for (i, other) in [(axis + 1) % 3, (axis + 2) % 3].into_iter().enumerate() {
                    faces[i] = 2 * other + (c >> other & 1);
                }
                for &f in &faces {
                    for k in 0..3 {
                        face[f][k][n_face[f]] = n[k] as f32;
                    }
                    n_face[f] += 1;
                }
                if front(faces[0]) != front(faces[1]) {
                    if n_sil == 8 {
                        return None;
                    }
                    for k in 0..3 {
                        silhouette[k][n_sil] = n[k] as f32;
                    }
                    n_sil += 1;
                }
            }
        }
        let d = corners.iter().map(|c| math::norm(*c));
        let (lo, hi) = d.fold((f64::INFINITY, 0.0f64), |(lo, hi), d| (lo.min(d), hi.max(d)));
        Some(Self {
            face,
            silhouette,
            dist: (lo as f32, hi as f32),
        })
    }
}

/// True when no line `n . (x, y, 1) = 0` of the `N` lanes `n` (normals field by field) passes
/// within `EDGE_EPS` of the parallelogram of the edge sub-samples around `(x, y)` (offsets
/// +-1/4 of `du` and `dv`): the sub-samples' side of every line is the centre's.
#[inline(always)]
fn clear_of<const N: usize>(n: &[[f32; N]; 3], x: f32, y: f32, du: [f32; 2], dv: [f32; 2]) -> bool {
    let mut ok = true;
    for ((&nx, &ny), &nz) in n[0].iter().zip(&n[1]).zip(&n[2]) {
        let e = nx * x + ny * y + nz;
        let (a, b) = (nx * du[0] + ny * du[1], nx * dv[0] + ny * dv[1]);
        ok &= e.abs() > 0.25 * (a.abs() + b.abs()) + EDGE_EPS;
    }
    ok
}

/// The value of an edge pixel ([`FrameGeom::edge_sample`]) and what its sub-samples saw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeValue {
    /// Log intensity of the pixel (its sub-samples averaged in linear intensity).
    pub l: f32,
    /// True when the value mixes surfaces (a sub-sample on another surface than the centre's).
    pub mixed: bool,
    /// The nearest moving object (id > 0) a sub-sample on another surface than the centre's
    /// met, with its depth there (m): the object covers part of the pixel, so a change of the
    /// pixel's value may be its edge even where the centre sees something else.
    pub object: Option<Located>,
}

impl EdgeValue {
    /// The centre's value `l` where every sub-sample sees the centre's surface.
    #[inline]
    pub fn unmixed(l: f32) -> Self {
        Self {
            l,
            mixed: false,
            object: None,
        }
    }

    /// The moving object that owns the pixel for the event truth instead of what its centre
    /// sees (object id `centre_id`): `object`, where the centre sees the background.
    #[inline]
    pub fn truth_object(&self, centre_id: u16) -> Option<Located> {
        self.object.filter(|_| centre_id == 0)
    }
}

/// Everything needed to cast rays at one instant, in the camera frame.
#[derive(Debug, Clone)]
pub struct FrameGeom {
    /// Time, s.
    pub t: f64,
    /// Camera state (world).
    pub cam: RigidState,
    planes: Vec<PlaneGeom>,
    boxes: Vec<BoxGeom>,
    inv_f: f32,
    /// Allowance of [`FrameGeom::edge_free`] for the f32 rounding of the planes' inverse depths.
    plane_eps: f32,
    /// Relative motion of the background (index 0) and of every box (index 1 + box index).
    pub motions: Vec<RelativeMotion>,
    /// Camera-frame pose of every box.
    pub box_poses: Vec<BoxPose>,
    /// Log shading of every surface key.
    pub shade_by_key: Vec<f32>,
}

fn f3(v: Vec3) -> [f32; 3] {
    [v[0] as f32, v[1] as f32, v[2] as f32]
}

#[inline]
fn dot3(a: &[f32; 3], x: f32, y: f32) -> f32 {
    a[0] * x + a[1] * y + a[2]
}

impl FrameGeom {
    /// The scene at time `t` (s) seen by camera `cam`.
    pub fn new(scene: &Scene, cam: &CameraConfig, t: f64) -> Self {
        let cs = scene.camera_state(t);
        let r_cw = math::transpose(&cs.rotation);
        let mut planes = Vec::with_capacity(scene.planes.len());
        for (i, p) in scene.planes.iter().enumerate() {
            let n_w = math::cross(p.axis_u, p.axis_v);
            let n_c = math::mul_mv(&r_cw, n_w);
            let rel = math::sub(cs.position, p.origin);
            // Plane: n_c . X + rel . n_w = 0 -> X = s d with s = h / (n_c . d), h = -rel . n_w.
            let h = -math::dot(rel, n_w);
            let h = if h.abs() < 1e-9 { 1e-9_f64.copysign(h) } else { h };
            planes.push(PlaneGeom {
                a: f3(math::scale(n_c, 1.0 / h)),
                n: f3(n_c),
                e1: f3(math::mul_mv(&r_cw, p.axis_u)),
                off1: math::dot(rel, p.axis_u) as f32,
                e2: f3(math::mul_mv(&r_cw, p.axis_v)),
                off2: math::dot(rel, p.axis_v) as f32,
                ln_shade: scene.lighting.ln_shade(n_w) as f32,
                tex: scene.plane_texture[i],
                key: i as u16,
            });
        }
        let mut shade_by_key: Vec<f32> = planes.iter().map(|p| p.ln_shade).collect();
        let mut motions = vec![RelativeMotion::new(&cs, None)];
        let mut boxes = Vec::with_capacity(scene.boxes.len());
        let mut box_poses = Vec::with_capacity(scene.boxes.len());
        for (j, b) in scene.boxes.iter().enumerate() {
            let bs = b.trajectory.state(t);
            motions.push(RelativeMotion::new(&cs, Some(&bs)));
            let pose = BoxPose::new(&cs, &bs);
            box_poses.push(pose);
            let r_bc = math::transpose(&pose.r_cb);
            let o_b = math::scale(math::mul_mv(&r_bc, pose.center), -1.0);
            let mut ln_shade = [0.0f32; 6];
            for (face, s) in ln_shade.iter_mut().enumerate() {
                let mut n = [0.0; 3];
                n[face / 2] = if face % 2 == 0 { -1.0 } else { 1.0 };
                *s = scene.lighting.ln_shade(math::mul_mv(&bs.rotation, n)) as f32;
            }
            shade_by_key.extend_from_slice(&ln_shade);
            let Some(bbox) = box_bbox(cam, &pose, b.half) else {
                continue;
            };
            let outline = Outline::new(&pose.corners(b.half), o_b, b.half, &planes);
            boxes.push(BoxGeom {
                r_bc: [f3(r_bc[0]), f3(r_bc[1]), f3(r_bc[2])],
                o_b: f3(o_b),
                half: f3(b.half),
                ln_shade,
                tex: b.texture,
                key_base: b.key_base,
                id: b.id,
                bbox,
                motion: j + 1,
                outline,
            });
        }
        let inv_f = (2.0 / (cam.fx + cam.fy)) as f32;
        let a_max = planes
            .iter()
            .map(|p| p.a.iter().map(|a| a.abs()).sum::<f32>())
            .fold(0.0f32, f32::max);
        Self {
            t,
            cam: cs,
            planes,
            boxes,
            inv_f,
            plane_eps: 1e-5 * a_max,
            motions,
            box_poses,
            shade_by_key,
        }
    }

    /// Size of one pixel across the ray per metre of depth (1 / focal length, px).
    pub fn inv_f(&self) -> f32 {
        self.inv_f
    }

    /// Pixel bounding boxes `[u0, v0, u1, v1]` of the visible moving objects, with their ids.
    pub fn object_bboxes(&self) -> impl Iterator<Item = (u16, [i32; 4])> + '_ {
        self.boxes.iter().filter(|b| b.id != 0).map(|b| (b.id, b.bbox))
    }

    /// Casts the ray through undistorted normalized `(x, y)` of pixel `(px, py)`; `only` limits
    /// the search to surfaces of one object id (background planes and boxes for 0).
    #[inline]
    pub fn cast(&self, scene: &Scene, x: f32, y: f32, px: i32, py: i32, only: Option<u16>) -> Hit {
        self.shade(scene, x, y, &self.locate(x, y, px, py, only))
    }

    /// The nearest surface on the ray through undistorted normalized `(x, y)` of pixel
    /// `(px, py)` (geometry only, no texture sample); `only` as in [`FrameGeom::cast`].
    #[inline]
    pub fn locate(&self, x: f32, y: f32, px: i32, py: i32, only: Option<u16>) -> Located {
        let mut best_inv = 0.0f32;
        let mut best_plane = usize::MAX;
        if only.is_none_or(|id| id == 0) {
            for (i, p) in self.planes.iter().enumerate() {
                let inv = dot3(&p.a, x, y);
                if inv > best_inv {
                    best_inv = inv;
                    best_plane = i;
                }
            }
        }
        let mut s = if best_plane == usize::MAX {
            f32::INFINITY
        } else {
            1.0 / best_inv
        };
        let mut best_box = usize::MAX;
        let mut box_face = 0usize;
        let mut box_db = [0.0f32; 3];
        for (j, b) in self.boxes.iter().enumerate() {
            if px < b.bbox[0] || px > b.bbox[2] || py < b.bbox[1] || py > b.bbox[3] {
                continue;
            }
            if only.is_some_and(|id| id != b.id) {
                continue;
            }
            let db = [
                dot3(&b.r_bc[0], x, y),
                dot3(&b.r_bc[1], x, y),
                dot3(&b.r_bc[2], x, y),
            ];
            let mut t_in = f32::NEG_INFINITY;
            let mut t_out = f32::INFINITY;
            let mut axis = 0usize;
            for (k, &dk) in db.iter().enumerate() {
                let inv = 1.0 / dk;
                let t1 = (-b.half[k] - b.o_b[k]) * inv;
                let t2 = (b.half[k] - b.o_b[k]) * inv;
                let (lo, hi) = if t1 < t2 { (t1, t2) } else { (t2, t1) };
                if lo > t_in {
                    t_in = lo;
                    axis = k;
                }
                t_out = t_out.min(hi);
            }
            if t_in <= t_out && t_in > 0.0 && t_in < s {
                s = t_in;
                best_box = j;
                box_face = 2 * axis + usize::from(db[axis] < 0.0);
                box_db = db;
            }
        }
        if best_box != usize::MAX {
            let b = &self.boxes[best_box];
            Located {
                surface: Surface::Box {
                    index: best_box,
                    face: box_face,
                    db: box_db,
                },
                key: b.key_base + box_face as u16,
                id: b.id,
                z: s,
            }
        } else if best_plane == usize::MAX {
            Located::NOTHING
        } else {
            Located {
                surface: Surface::Plane(best_plane),
                key: self.planes[best_plane].key,
                id: 0,
                z: s,
            }
        }
    }

    /// [`FrameGeom::locate`] (without `only`) of `N` rays `(x[l], y[l])` of pixels
    /// `(px[l], py[l])` at once: the same arithmetic lane by lane (so the same
    /// results), arranged so the compiler can run the lanes in SIMD registers and the
    /// per-surface branches of the scalar search become selects.
    #[inline(always)]
    pub fn locate_lanes<const N: usize>(
        &self,
        x: &[f32; N],
        y: &[f32; N],
        px: &[i32; N],
        py: &[i32; N],
    ) -> [Located; N] {
        self.search_lanes(x, y, px, py).located(self)
    }

    /// The object ids of [`FrameGeom::locate_lanes`] (0 for the background and for nothing),
    /// without assembling the located surfaces.
    #[inline(always)]
    pub fn object_ids_lanes(
        &self,
        x: &[f32; LANES],
        y: &[f32; LANES],
        px: &[i32; LANES],
        py: &[i32; LANES],
    ) -> [u16; LANES] {
        let found = self.search_lanes(x, y, px, py);
        let mut ids = [0u16; LANES];
        for (l, id) in ids.iter_mut().enumerate() {
            if found.best_box[l] != u32::MAX {
                *id = self.boxes[found.best_box[l] as usize].id;
            }
        }
        ids
    }

    /// The search of [`FrameGeom::locate_lanes`], lane by lane in arrays. With `LANES` rays
    /// and AVX2 (detected at run time) in vector registers (see `lane_search`): the same
    /// results.
    #[inline(always)]
    fn search_lanes<const N: usize>(
        &self,
        x: &[f32; N],
        y: &[f32; N],
        px: &[i32; N],
        py: &[i32; N],
    ) -> LaneSearch<N> {
        #[cfg(target_arch = "x86_64")]
        if N == LANES && std::is_x86_feature_detected!("avx2") {
            // The same arrays at their fixed length (N == LANES: copies the optimiser drops).
            let (mut x8, mut y8, mut px8, mut py8) =
                ([0.0f32; LANES], [0.0f32; LANES], [0i32; LANES], [0i32; LANES]);
            for l in 0..LANES {
                (x8[l], y8[l], px8[l], py8[l]) = (x[l], y[l], px[l], py[l]);
            }
            // SAFETY: AVX2 is available (checked just above).
            let r = unsafe { self.search_lanes_avx2(&x8, &y8, &px8, &py8) };
            let mut out = LaneSearch {
                best_plane: [0; N],
                best_box: [0; N],
                box_face: [0; N],
                box_db: [[0.0; N]; 3],
                s: [0.0; N],
            };
            for l in 0..N {
                out.best_plane[l] = r.best_plane[l];
                out.best_box[l] = r.best_box[l];
                out.box_face[l] = r.box_face[l];
                for k in 0..3 {
                    out.box_db[k][l] = r.box_db[k][l];
                }
                out.s[l] = r.s[l];
            }
            return out;
        }
        let mut best_inv = [0.0f32; N];
        let mut best_plane = [u32::MAX; N];
        for (i, p) in self.planes.iter().enumerate() {
            for l in 0..N {
                let inv = dot3(&p.a, x[l], y[l]);
                let better = inv > best_inv[l];
                best_inv[l] = if better { inv } else { best_inv[l] };
                best_plane[l] = if better { i as u32 } else { best_plane[l] };
            }
        }
        let mut s = [0.0f32; N];
        for l in 0..N {
            s[l] = if best_plane[l] == u32::MAX {
                f32::INFINITY
            } else {
                1.0 / best_inv[l]
            };
        }
        let mut best_box = [u32::MAX; N];
        let mut box_face = [0u32; N];
        let mut box_db = [[0.0f32; N]; 3];
        for (j, b) in self.boxes.iter().enumerate() {
            let mut inside = [false; N];
            for l in 0..N {
                inside[l] =
                    px[l] >= b.bbox[0] && px[l] <= b.bbox[2] && py[l] >= b.bbox[1] && py[l] <= b.bbox[3];
            }
            if !inside.contains(&true) {
                continue;
            }
            let mut db = [[0.0f32; N]; 3];
            for (k, row) in db.iter_mut().enumerate() {
                for l in 0..N {
                    row[l] = dot3(&b.r_bc[k], x[l], y[l]);
                }
            }
            let mut t_in = [f32::NEG_INFINITY; N];
            let mut t_out = [f32::INFINITY; N];
            let mut axis = [0u32; N];
            for (k, row) in db.iter().enumerate() {
                let (lo_k, hi_k) = (-b.half[k] - b.o_b[k], b.half[k] - b.o_b[k]);
                for l in 0..N {
                    let inv = 1.0 / row[l];
                    let t1 = lo_k * inv;
                    let t2 = hi_k * inv;
                    let (lo, hi) = if t1 < t2 { (t1, t2) } else { (t2, t1) };
                    let later = lo > t_in[l];
                    t_in[l] = if later { lo } else { t_in[l] };
                    axis[l] = if later { k as u32 } else { axis[l] };
                    t_out[l] = t_out[l].min(hi);
                }
            }
            for l in 0..N {
                if inside[l] && t_in[l] <= t_out[l] && t_in[l] > 0.0 && t_in[l] < s[l] {
                    s[l] = t_in[l];
                    best_box[l] = j as u32;
                    let a = axis[l] as usize;
                    box_face[l] = 2 * axis[l] + u32::from(db[a][l] < 0.0);
                    for k in 0..3 {
                        box_db[k][l] = db[k][l];
                    }
                }
            }
        }
        LaneSearch {
            best_plane,
            best_box,
            box_face,
            box_db,
            s,
        }
    }

    /// [`FrameGeom::cast`] of `LANES` rays `(x[l], y[l])` of pixels `(px[l], py[l])`: located
    /// together ([`FrameGeom::locate_lanes`]); when all lanes hit one plane or one box face,
    /// shaded in arrays the compiler vectorises, else by [`FrameGeom::shade_lanes`]. The same
    /// values.
    #[inline(always)]
    pub fn cast_lanes(
        &self,
        scene: &Scene,
        x: &[f32; LANES],
        y: &[f32; LANES],
        px: &[i32; LANES],
        py: &[i32; LANES],
    ) -> HitLanes {
        let found = self.search_lanes(x, y, px, py);
        let (first, first_box, first_face) = (found.best_plane[0], found.best_box[0], found.box_face[0]);
        // Lane comparisons without early exits (folded with `&`, vector compares).
        let (mut no_box, mut same_plane, mut same_box, mut same_face) = (true, true, true, true);
        for l in 0..LANES {
            no_box &= found.best_box[l] == u32::MAX;
            same_plane &= found.best_plane[l] == first;
            same_box &= found.best_box[l] == first_box;
            same_face &= found.box_face[l] == first_face;
        }
        let one_plane = no_box & same_plane & (first != u32::MAX);
        let one_face = same_box & same_face & (first_box != u32::MAX);
        if one_face {
            return self.shade_face_lanes(scene, x, y, &found);
        }
        if !one_plane {
            let hits = self.shade_lanes(scene, x, y, &found.located(self));
            let mut out = HitLanes::default();
            for (l, h) in hits.iter().enumerate() {
                (out.l[l], out.key[l], out.id[l], out.z[l]) = (h.l, h.key, h.id, h.z);
                (out.u[l], out.v[l], out.footprint[l]) = (h.u, h.v, h.footprint);
            }
            return out;
        }
        let p = &self.planes[first as usize];
        let s = &found.s;
        let (mut u, mut v, mut fp) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        // `texture_point` of a plane, lane by lane, in loops the compiler vectorises (the
        // select is `max(MIN_COS)`, NaN included).
        let mut cos = [0.0f32; LANES];
        for l in 0..LANES {
            let (x, y) = (x[l], y[l]);
            let dn = (x * x + y * y + 1.0).sqrt();
            u[l] = s[l] * dot3(&p.e1, x, y) + p.off1;
            v[l] = s[l] * dot3(&p.e2, x, y) + p.off2;
            let c = dot3(&p.n, x, y).abs() / dn;
            cos[l] = if c > MIN_COS { c } else { MIN_COS };
        }
        for l in 0..LANES {
            fp[l] = s[l] * self.inv_f / cos[l];
        }
        let t = scene.textures[p.tex].sample_lanes(&u, &v, &fp);
        let mut l_out = [0.0f32; LANES];
        for l in 0..LANES {
            l_out[l] = t[l] + p.ln_shade;
        }
        HitLanes {
            l: l_out,
            key: [p.key; LANES],
            id: [0; LANES],
            z: *s,
            u,
            v,
            footprint: fp,
        }
    }

    /// The shading of [`FrameGeom::cast_lanes`] when all lanes hit one face of one box
    /// (`texture_point` of a box face, lane by lane).
    #[inline(always)]
    fn shade_face_lanes(
        &self,
        scene: &Scene,
        x: &[f32; LANES],
        y: &[f32; LANES],
        found: &LaneSearch<LANES>,
    ) -> HitLanes {
        let b = &self.boxes[found.best_box[0] as usize];
        let face = found.box_face[0] as usize;
        let axis = face / 2;
        let (j, k) = ((axis + 1) % 3, (axis + 2) % 3);
        let off = FACE_OFFSET[face];
        let s = &found.s;
        let (mut u, mut v, mut cos) = ([0.0f32; LANES], [0.0f32; LANES], [0.0f32; LANES]);
        for l in 0..LANES {
            let db = [found.box_db[0][l], found.box_db[1][l], found.box_db[2][l]];
            let dn = (x[l] * x[l] + y[l] * y[l] + 1.0).sqrt();
            u[l] = (b.o_b[j] + s[l] * db[j]) + off[0];
            v[l] = (b.o_b[k] + s[l] * db[k]) + off[1];
            let c = db[axis].abs() / dn;
            cos[l] = if c > MIN_COS { c } else { MIN_COS };
        }
        let mut fp = [0.0f32; LANES];
        for l in 0..LANES {
            fp[l] = s[l] * self.inv_f / cos[l];
        }
        let t = scene.textures[b.tex].sample_lanes(&u, &v, &fp);
        let mut l_out = [0.0f32; LANES];
        for l in 0..LANES {
            l_out[l] = t[l] + b.ln_shade[face];
        }
        HitLanes {
            l: l_out,
            key: [b.key_base + face as u16; LANES],
            id: [b.id; LANES],
            z: *s,
            u,
            v,
            footprint: fp,
        }
    }

    /// Texture coordinates, footprint and log intensity of the surface `loc` found by
    /// [`FrameGeom::locate`] on the ray `(x, y)`.
    #[inline(always)]
    pub fn shade(&self, scene: &Scene, x: f32, y: f32, loc: &Located) -> Hit {
        let p = self.texture_point(x, y, loc);
        let l = if p.tex == usize::MAX {
            0.0
        } else {
            scene.textures[p.tex].sample(p.u, p.v, p.footprint) + p.ln_shade
        };
        p.hit(loc, l)
    }

    /// [`FrameGeom::shade`] of `LANES` located rays: lanes on one texture are sampled
    /// together ([`crate::texture::Texture::sample_lanes`], the same values), the others one
    /// by one.
    #[inline(always)]
    pub fn shade_lanes(
        &self,
        scene: &Scene,
        x: &[f32; LANES],
        y: &[f32; LANES],
        locs: &[Located; LANES],
    ) -> [Hit; LANES] {
        // Plain loops: `array::from_fn` closures were left out of line.
        let mut pts = [TexturePoint::NONE; LANES];
        for l in 0..LANES {
            pts[l] = self.texture_point(x[l], y[l], &locs[l]);
        }
        let mut l_out = [0.0f32; LANES];
        // Lanes not yet shaded (bit per lane); `Nothing` lanes keep 0.
        let mut todo: u32 = 0;
        for (l, p) in pts.iter().enumerate() {
            todo |= u32::from(p.tex != usize::MAX) << l;
        }
        while todo != 0 {
            let first = todo.trailing_zeros() as usize;
            let tex = pts[first].tex;
            let mut group = 0u32;
            for (l, p) in pts.iter().enumerate() {
                group |= u32::from(p.tex == tex) << l;
            }
            group &= todo;
            todo &= !group;
            let t = &scene.textures[tex];
            if group.count_ones() >= MIN_GROUP {
                // Lanes outside the group repeat the first member's point (results unused).
                let (mut u, mut v, mut fp) = ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
                for l in 0..LANES {
                    let p = &pts[if group >> l & 1 == 1 { l } else { first }];
                    (u[l], v[l], fp[l]) = (p.u, p.v, p.footprint);
                }
                let s = t.sample_lanes(&u, &v, &fp);
                for l in 0..LANES {
                    if group >> l & 1 == 1 {
                        l_out[l] = s[l] + pts[l].ln_shade;
                    }
                }
            } else {
                for l in 0..LANES {
                    if group >> l & 1 == 1 {
                        let p = &pts[l];
                        l_out[l] = t.sample(p.u, p.v, p.footprint) + p.ln_shade;
                    }
                }
            }
        }
        let mut hits = [Hit::NONE; LANES];
        for l in 0..LANES {
            hits[l] = pts[l].hit(&locs[l], l_out[l]);
        }
        hits
    }

    /// Texture, texture coordinates, footprint and log shading of the surface `loc` on the
    /// ray `(x, y)` (texture `usize::MAX` for no surface).
    #[inline(always)]
    fn texture_point(&self, x: f32, y: f32, loc: &Located) -> TexturePoint {
        let dn = (x * x + y * y + 1.0).sqrt();
        let s = loc.z;
        match loc.surface {
            Surface::Box { index, face, db } => {
                let b = &self.boxes[index];
                let axis = face / 2;
                let hp = [b.o_b[0] + s * db[0], b.o_b[1] + s * db[1], b.o_b[2] + s * db[2]];
                let (j, k) = ((axis + 1) % 3, (axis + 2) % 3);
                let cos = (db[axis].abs() / dn).max(MIN_COS);
                let footprint = s * self.inv_f / cos;
                let off = FACE_OFFSET[face];
                TexturePoint {
                    tex: b.tex,
                    u: hp[j] + off[0],
                    v: hp[k] + off[1],
                    footprint,
                    ln_shade: b.ln_shade[face],
                }
            }
            Surface::Nothing => TexturePoint::NONE,
            Surface::Plane(index) => {
                let p = &self.planes[index];
                let u = s * dot3(&p.e1, x, y) + p.off1;
                let v = s * dot3(&p.e2, x, y) + p.off2;
                let cos = (dot3(&p.n, x, y).abs() / dn).max(MIN_COS);
                let footprint = s * self.inv_f / cos;
                TexturePoint {
                    tex: p.tex,
                    u,
                    v,
                    footprint,
                    ln_shade: p.ln_shade,
                }
            }
        }
    }

    /// Log intensity of pixel `(px, py)` from 2x2 sub-samples averaged in linear intensity;
    /// `(x, y)` is the pixel centre's normalized ray and `du`, `dv` its change per pixel.
    #[allow(clippy::too_many_arguments)]
    pub fn supersample(
        &self,
        scene: &Scene,
        x: f32,
        y: f32,
        du: [f32; 2],
        dv: [f32; 2],
        px: i32,
        py: i32,
    ) -> f32 {
        let mut acc = 0.0f32;
        for (sx, sy) in sub_sample_rays(x, y, du, dv) {
            acc += self.cast(scene, sx, sy, px, py, None).l.exp();
        }
        (0.25 * acc).ln()
    }

    /// True when all four edge sub-samples of pixel `(px, py)` (offsets +-1/4 of `du` and `dv`
    /// around the centre ray `(x, y)`) certainly see the surface `key` the centre sees, from
    /// the geometry alone (no sub-ray located). The surface seen is the same across a region
    /// that no projected edge crosses: for a plane, the margin of its inverse depth over every
    /// other plane's (and over 0) exceeds their largest change over the sub-samples (affine
    /// in the ray), and no silhouette edge of a box whose pixel box holds the pixel passes
    /// near them (the centre, on a plane, misses every such box, so they miss it too); for a
    /// box face, none of the face's four edges passes near them, and every other box whose
    /// pixel box holds the pixel lies wholly farther from the camera. Boxes must lie inside
    /// the room (every corner on the camera's side of every plane, up to `ROOM_TOLERANCE`:
    /// a ray meets a box before any plane, except where the box touches a plane, which lies
    /// along its edges) with every corner in front of the camera (else `false`). The margins
    /// (`EDGE_EPS`, `plane_eps`) are far above the f32 rounding of [`FrameGeom::locate`] (an
    /// edge in about 1e-6 of its place), so it agrees: a `true` here means locating the four
    /// sub-rays would return `key` four times (tested on random rays near edges).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    pub fn edge_free(&self, x: f32, y: f32, du: [f32; 2], dv: [f32; 2], px: i32, py: i32, key: u16) -> bool {
        let holds = |b: &BoxGeom| px >= b.bbox[0] && px <= b.bbox[2] && py >= b.bbox[1] && py <= b.bbox[3];
        if let Some(p) = self.planes.get(key as usize) {
            // Inverse depths a . (x, y, 1): the plane stays ahead of every other and of 0.
            let margin = |g: [f32; 3]| {
                let d = g[0] * x + g[1] * y + g[2];
                let (a, b) = (g[0] * du[0] + g[1] * du[1], g[0] * dv[0] + g[1] * dv[1]);
                d > 0.25 * (a.abs() + b.abs()) + self.plane_eps
            };
            let mut ok = margin(p.a);
            for q in &self.planes {
                if q.key != key {
                    ok &= margin([p.a[0] - q.a[0], p.a[1] - q.a[1], p.a[2] - q.a[2]]);
                }
            }
            if !ok {
                return false;
            }
            for b in self.boxes.iter().filter(|b| holds(b)) {
                match &b.outline {
                    Some(o) if clear_of(&o.silhouette, x, y, du, dv) => {}
                    _ => return false,
                }
            }
            return true;
        }
        let Some(b) = self
            .boxes
            .iter()
            .find(|b| (b.key_base..b.key_base + 6).contains(&key))
        else {
            return false;
        };
        let Some(o) = &b.outline else {
            return false;
        };
        if !clear_of(&o.face[(key - b.key_base) as usize], x, y, du, dv) {
            return false;
        }
        self.boxes
            .iter()
            .filter(|c| holds(c) && c.key_base != b.key_base)
            .all(|c| {
                c.outline
                    .as_ref()
                    .is_some_and(|oc| oc.dist.0 > o.dist.1 * (1.0 + 1e-4) + 1e-3)
            })
    }

    /// Log intensity of an edge pixel `(px, py)` whose centre ray `(x, y)` hit `centre` (log
    /// intensity, surface key): the 2x2 sub-samples of [`FrameGeom::supersample`] averaged in
    /// linear intensity, where sub-samples on the centre's surface take the centre's value (so
    /// the centre's value when all do). Sub-samples on one surface differ from the centre only
    /// by texture detail finer than the pixel (which the mip-mapped texture already averages),
    /// so only geometric edges inside the sub-sample square are anti-aliased; sub-rays are
    /// located first and only those on other surfaces are textured. The flag is true when the
    /// value mixes surfaces.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    pub fn edge_sample(
        &self,
        scene: &Scene,
        x: f32,
        y: f32,
        du: [f32; 2],
        dv: [f32; 2],
        px: i32,
        py: i32,
        centre: (f32, u16),
    ) -> EdgeValue {
        if self.edge_free(x, y, du, dv, px, py, centre.1) {
            // What locating the sub-rays would conclude (see `edge_mix`), without locating them.
            return EdgeValue::unmixed(centre.0);
        }
        self.edge_mix(scene, x, y, du, dv, px, py, centre)
    }

    /// [`FrameGeom::edge_sample`] without its [`FrameGeom::edge_free`] shortcut (for callers
    /// that tested it): the four sub-rays located, those on other surfaces than the centre's
    /// textured.
    #[allow(clippy::too_many_arguments)]
    #[inline(never)]
    pub fn edge_mix(
        &self,
        scene: &Scene,
        x: f32,
        y: f32,
        du: [f32; 2],
        dv: [f32; 2],
        px: i32,
        py: i32,
        centre: (f32, u16),
    ) -> EdgeValue {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            return unsafe { self.edge_mix_avx2(scene, x, y, du, dv, px, py, centre) };
        }
        self.edge_mix_with(scene, x, y, du, dv, px, py, centre)
    }

    /// [`FrameGeom::edge_mix`] compiled with AVX2 (the lane search inlined).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[allow(clippy::too_many_arguments)]
    fn edge_mix_avx2(
        &self,
        scene: &Scene,
        x: f32,
        y: f32,
        du: [f32; 2],
        dv: [f32; 2],
        px: i32,
        py: i32,
        centre: (f32, u16),
    ) -> EdgeValue {
        self.edge_mix_with(scene, x, y, du, dv, px, py, centre)
    }

    /// The body of [`FrameGeom::edge_mix`].
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn edge_mix_with(
        &self,
        scene: &Scene,
        x: f32,
        y: f32,
        du: [f32; 2],
        dv: [f32; 2],
        px: i32,
        py: i32,
        centre: (f32, u16),
    ) -> EdgeValue {
        let rays = sub_sample_rays(x, y, du, dv);
        // Searched in `LANES` lanes (the four sub-rays twice: the vector search, see
        // `search_lanes`, costs no more than four lanes).
        let (mut x8, mut y8) = ([0.0f32; LANES], [0.0f32; LANES]);
        for l in 0..LANES {
            (x8[l], y8[l]) = rays[l % 4];
        }
        let found = self.search_lanes(&x8, &y8, &[px; LANES], &[py; LANES]);
        let keys = [0, 1, 2, 3].map(|l| found.key(self, l));
        if keys.iter().all(|&k| k == centre.1) {
            return EdgeValue::unmixed(centre.0);
        }
        // Sub-rays on the centre's surface take its value (as above); the others are textured.
        let centre_lin = centre.0.exp();
        let mut acc = 0.0f32;
        let mut object: Option<Located> = None;
        for (l, (sx, sy)) in rays.iter().enumerate() {
            acc += if keys[l] == centre.1 {
                centre_lin
            } else {
                let hit = found.located_lane(self, l);
                if hit.id != 0 && object.is_none_or(|o| hit.z < o.z) {
                    object = Some(hit);
                }
                self.shade(scene, *sx, *sy, &hit).l.exp()
            };
        }
        EdgeValue {
            l: (0.25 * acc).ln(),
            mixed: true,
            object,
        }
    }

    /// True optical flow (px/s) at pixel `(px, py)` with normalized ray `(x, y)` of the surface of
    /// object `id` (background for 0); `None` when that surface is not on the ray.
    #[allow(clippy::too_many_arguments)]
    pub fn flow(
        &self,
        _scene: &Scene,
        cam: &CameraConfig,
        x: f32,
        y: f32,
        px: i32,
        py: i32,
        id: u16,
    ) -> Option<(f64, f64)> {
        let hit = self.locate(x, y, px, py, Some(id));
        self.flow_at(cam, x, y, hit.key, hit.z, id)
    }

    /// [`FrameGeom::flow`] of the surface `key` of object `id` found at depth `z` (m) on the
    /// ray `(x, y)` (as `locate` with `only` that id would find it; e.g. the surface a key
    /// frame located at the pixel, whose object it is: the nearest surface of all is the
    /// nearest of its object's, at the same depth).
    pub fn flow_at(
        &self,
        cam: &CameraConfig,
        x: f32,
        y: f32,
        key: u16,
        z: f32,
        id: u16,
    ) -> Option<(f64, f64)> {
        if !z.is_finite() || key == u16::MAX {
            return None;
        }
        let motion = if id == 0 {
            // Background boxes do not move, but use their motion for generality.
            match self
                .boxes
                .iter()
                .find(|b| b.id == 0 && (b.key_base..b.key_base + 6).contains(&key))
            {
                Some(b) => &self.motions[b.motion],
                None => &self.motions[0],
            }
        } else {
            let b = self.boxes.iter().find(|b| b.id == id)?;
            &self.motions[b.motion]
        };
        let z = z as f64;
        let p = [x as f64 * z, y as f64 * z, z];
        let (ux, uy) = motion.normalized_flow(p);
        Some(cam.pixel_flow(x as f64, y as f64, ux, uy))
    }
}

/// Pixel bounding box of a box's projection (edges sampled, so lens distortion is covered),
/// with a 2 px margin; the whole image when the box reaches behind the camera; `None` when the
/// box is entirely behind the camera or off-image.
fn box_bbox(cam: &CameraConfig, pose: &BoxPose, half: Vec3) -> Option<[i32; 4]> {
    let corners = pose.corners(half);
    if corners.iter().all(|c| c[2] <= 0.0) {
        return None;
    }
    let (w, h) = (cam.width as i32, cam.height as i32);
    if corners.iter().any(|c| c[2] <= 0.05) {
        return Some([0, 0, w - 1, h - 1]);
    }
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for a in 0..8 {
        for bit in [1usize, 2, 4] {
            let b = a | bit;
            if b == a {
                continue;
            }
            for s in 0..=8 {
                let f = s as f64 / 8.0;
                let p = math::add(math::scale(corners[a], 1.0 - f), math::scale(corners[b], f));
                if let Some((u, v)) = cam.project(p) {
                    u0 = u0.min(u);
                    v0 = v0.min(v);
                    u1 = u1.max(u);
                    v1 = v1.max(v);
                }
            }
        }
    }
    let bb = [
        (u0 - 2.0).floor() as i32,
        (v0 - 2.0).floor() as i32,
        (u1 + 2.0).ceil() as i32,
        (v1 + 2.0).ceil() as i32,
    ];
    if bb[2] < 0 || bb[3] < 0 || bb[0] >= w || bb[1] >= h {
        return None;
    }
    Some([bb[0].max(0), bb[1].max(0), bb[2].min(w - 1), bb[3].min(h - 1)])
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::Distortion;

    /// Preset `name` (seed 3), its scene and its camera's rays.
    fn preset_scene(name: &str) -> (crate::SceneConfig, Scene, crate::camera::Rays) {
        let cfg = crate::presets::preset(name, 3).unwrap();
        let scene = Scene::new(&cfg.scene, cfg.camera_trajectory.clone(), 3, 0.01);
        let rays = crate::camera::Rays::new(&cfg.camera);
        (cfg, scene, rays)
    }

    #[test]
    fn locating_and_casting_rays_in_lanes_matches_doing_it_one_by_one() {
        // Every pixel of two presets (moving boxes, furniture, a distorted lens) at a few
        // instants, in lanes of 8 along rows and of 4 sub-rays inside a pixel.
        for name in ["two-objects", "distorted-lens"] {
            let (cfg, scene, rays) = preset_scene(name);
            let w = rays.width;
            for t in [0.0, 0.37, 1.1] {
                let g = FrameGeom::new(&scene, &cfg.camera, t);
                for v in (0..rays.height).step_by(3) {
                    for u0 in (0..w).step_by(8) {
                        let i = v * w + u0;
                        let x: [f32; 8] = std::array::from_fn(|l| rays.x[i + l]);
                        let y: [f32; 8] = std::array::from_fn(|l| rays.y[i + l]);
                        let px = std::array::from_fn(|l| (u0 + l) as i32);
                        let lanes = g.locate_lanes(&x, &y, &px, &[v as i32; 8]);
                        let hits = g.cast_lanes(&scene, &x, &y, &px, &[v as i32; 8]);
                        for l in 0..8 {
                            let one = g.locate(x[l], y[l], px[l], v as i32, None);
                            assert_eq!(lanes[l], one, "{name} t {t} pixel {} {v}", u0 + l);
                            // Bit for bit (NaN-free), through the one-plane and mixed paths.
                            let hit = g.cast(&scene, x[l], y[l], px[l], v as i32, None);
                            assert_eq!(hits.get(l), hit, "{name} t {t} pixel {} {v}", u0 + l);
                            assert_eq!(hits.l[l].to_bits(), hit.l.to_bits());
                        }
                        let sub: [f32; 4] = std::array::from_fn(|k| x[0] + 0.3 * k as f32 * rays.d_du[i][0]);
                        let found = g.locate_lanes(&sub, &[y[0]; 4], &[u0 as i32; 4], &[v as i32; 4]);
                        for k in 0..4 {
                            assert_eq!(found[k], g.locate(sub[k], y[0], u0 as i32, v as i32, None));
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn flow_of_the_located_surface_equals_flow_locating_its_object() {
        // What stable pixels' event truth relies on: the nearest surface of all, with its
        // depth, is what `flow` locates among its object's surfaces.
        for name in ["two-objects", "distorted-lens"] {
            let (cfg, scene, rays) = preset_scene(name);
            let w = rays.width;
            for t in [0.0, 0.37, 1.1] {
                let g = FrameGeom::new(&scene, &cfg.camera, t);
                for i in (0..w * rays.height).step_by(7) {
                    let (x, y, u, v) = (rays.x[i], rays.y[i], (i % w) as i32, (i / w) as i32);
                    let hit = g.locate(x, y, u, v, None);
                    let at = g.flow_at(&cfg.camera, x, y, hit.key, hit.z, hit.id);
                    assert_eq!(
                        at,
                        g.flow(&scene, &cfg.camera, x, y, u, v, hit.id),
                        "{name} {t} {i}"
                    );
                }
            }
        }
    }

    #[test]
    fn edge_free_sub_samples_locate_to_the_centre_surface() {
        // Every pixel near an edge (centre key differs from a 4-neighbour's) of three presets
        // at several instants, with random sub-pixel shifts of the centre: whenever
        // `edge_free` holds, the four sub-rays locate to the centre's surface. It must also
        // hold for most sub-sample squares that confirm the centre.
        let mut rng = crate::rng::Rng::new(7, 2);
        for name in ["one-object", "two-objects", "distorted-lens"] {
            let (cfg, scene, rays) = preset_scene(name);
            let (w, h) = (rays.width, rays.height);
            let (mut free, mut confirmed) = (0usize, 0usize);
            for t in [0.0, 0.21, 0.37, 0.8, 1.1] {
                let g = FrameGeom::new(&scene, &cfg.camera, t);
                let keys: Vec<u16> = (0..w * h)
                    .map(|i| {
                        g.locate(rays.x[i], rays.y[i], (i % w) as i32, (i / w) as i32, None)
                            .key
                    })
                    .collect();
                for i in 0..w * h {
                    let (u, v) = (i % w, i / w);
                    let k = keys[i];
                    let near = [(1, 0), (-1, 0), (0, 1), (0, -1), (2, 0), (-2, 0), (0, 2), (0, -2)]
                        .iter()
                        .any(|&(dx, dy): &(i64, i64)| {
                            let (a, b) = (u as i64 + dx, v as i64 + dy);
                            a >= 0
                                && b >= 0
                                && a < w as i64
                                && b < h as i64
                                && keys[b as usize * w + a as usize] != k
                        });
                    if !near {
                        continue;
                    }
                    let (du, dv) = (rays.d_du[i], rays.d_dv[i]);
                    for _ in 0..4 {
                        let (su, sv) = (rng.range(-0.5, 0.5) as f32, rng.range(-0.5, 0.5) as f32);
                        let x = rays.x[i] + su * du[0] + sv * dv[0];
                        let y = rays.y[i] + su * du[1] + sv * dv[1];
                        let centre = g.locate(x, y, u as i32, v as i32, None).key;
                        let mut all = true;
                        for (sx, sy) in sub_sample_rays(x, y, du, dv) {
                            all &= g.locate(sx, sy, u as i32, v as i32, None).key == centre;
                        }
                        let f = g.edge_free(x, y, du, dv, u as i32, v as i32, centre);
                        assert!(!f || all, "{name} t {t} pixel {u} {v} key {centre}");
                        confirmed += usize::from(all);
                        free += usize::from(f);
                    }
                }
            }
            assert!(free * 2 > confirmed, "{name}: {free} of {confirmed}");
            eprintln!("{name}: edge_free {free} of {confirmed} confirming");
        }
    }

    #[test]
    fn pixel_flow_of_a_distorted_camera_matches_finite_differences() {
        let cam = CameraConfig {
            width: 640,
            height: 480,
            fx: 560.0,
            fy: 555.0,
            cx: 320.0,
            cy: 240.0,
            distortion: Distortion::RadTan {
                k1: -0.22,
                k2: 0.06,
                p1: 0.0006,
                p2: -0.0008,
                k3: 0.0,
            },
        };
        let m = RelativeMotion {
            linear: [0.3, -0.2, 0.4],
            angular: [0.2, -0.5, 0.3],
        };
        for p in [[0.8, -0.5, 2.0], [-1.1, 0.7, 3.0], [0.0, 0.0, 1.5]] {
            let (x, y) = (p[0] / p[2], p[1] / p[2]);
            let (ux, uy) = m.normalized_flow(p);
            let (fx, fy) = cam.pixel_flow(x, y, ux, uy);
            let h = 1e-5;
            let v = m.velocity(p);
            let a = cam.project(math::add(p, math::scale(v, -h))).unwrap();
            let b = cam.project(math::add(p, math::scale(v, h))).unwrap();
            let (dx, dy) = ((b.0 - a.0) / (2.0 * h), (b.1 - a.1) / (2.0 * h));
            assert!((dx - fx).abs() < 1e-3 * fx.abs().max(1.0), "{dx} vs {fx}");
            assert!((dy - fy).abs() < 1e-3 * fy.abs().max(1.0), "{dy} vs {fy}");
        }
    }
}
