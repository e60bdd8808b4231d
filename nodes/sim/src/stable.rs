//! Quiet and stable pixels of one key-frame interval (see [`crate::engine`]): the work list
//! of the pixels that keep their surface (stable) or may cross at the closing key frame
//! (quiet), their run bounds, and their threshold crossings along interpolated texture paths.

use crate::engine::{KeyFrame, QUIET, RawEvent, STABLE};
use crate::esim::Thresholds;
use crate::firing::{FireCtx, fire, fire_path};
use crate::math::{fmax, fmin};
use crate::scene::Scene;

/// Rounding allowance, log units, of bounds of interpolated texture samples (f32 rounding of
/// the blends; not a modelling parameter).
const SAMPLE_EPS_LOG: f32 = 1e-4;
/// Most neighbouring stable pixels whose paths are bounded together (see `run_range`).
const RUN_PIXELS: usize = 8;
/// Largest texel span per axis of the union of a run's paths (see `run_range`).
const RUN_RANGE_TEXELS: u32 = 12;
/// Factor on a stable pixel's displacement from its texture Jacobian: covers the change of
/// the Jacobian along the path (perspective) and its finite-difference estimate.
const DISPLACEMENT_SAFETY: f32 = 1.1;

/// What the pass over an interval's listed pixels reads.
pub(crate) struct ListedPixels<'a> {
    /// The interval's opening and closing key frames.
    pub kf0: &'a KeyFrame,
    /// The closing key frame.
    pub kf1: &'a KeyFrame,
    /// The scene.
    pub scene: &'a Scene,
    /// Every pixel's class (`QUIET`, `STABLE` or `UNSTABLE`).
    pub class: &'a [u8],
    /// Per-pixel thresholds.
    pub thresholds: &'a Thresholds,
    /// Times of the key frames, s.
    pub span: (f64, f64),
    /// Largest image motion between two samples of a stable path, px.
    pub max_px: f32,
    /// Image width, px.
    pub width: usize,
}

/// Counts of one pass over the listed pixels.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct ListedCounts {
    /// Quiet pixels that fired at the closing key frame.
    pub violations: u64,
    /// Interpolated texture samples.
    pub samples: u64,
    /// Events of stable pixels.
    pub fired: u64,
}

impl ListedPixels<'_> {
    /// Threshold crossings of the pixels of `work` (pixel order) into `batch`: quiet pixels
    /// from key frame to key frame (a crossing is a violation; its events are kept), stable
    /// pixels along their interpolated texture paths, sampled every `max_px` of their own
    /// image motion (`stable_displacement`), unless the texel bound of their run (see
    /// `run_range`) keeps them strictly inside their thresholds: none of those can fire and
    /// their references stay. Run bounds and paths in one pass, so that each pixel's data is
    /// read from memory once. `reference` and `last_event` are every pixel's
    /// state, `path` scratch. With AVX2 (detected at run time) the loop is compiled for it,
    /// so that the texture samples inline: the same arithmetic, the same events.
    pub(crate) fn fire(
        &self,
        ctx: &FireCtx,
        work: &[u32],
        state: (&mut [f32], &mut [f64]),
        batch: &mut Vec<RawEvent>,
        path: &mut Vec<f32>,
    ) -> ListedCounts {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            return unsafe { self.fire_avx2(ctx, work, state, batch, path) };
        }
        self.fire_with(ctx, work, state, batch, path)
    }

    /// [`ListedPixels::fire`] compiled with AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn fire_avx2(
        &self,
        ctx: &FireCtx,
        work: &[u32],
        state: (&mut [f32], &mut [f64]),
        batch: &mut Vec<RawEvent>,
        path: &mut Vec<f32>,
    ) -> ListedCounts {
        self.fire_with(ctx, work, state, batch, path)
    }

    /// The body of [`ListedPixels::fire`].
    #[inline(always)]
    fn fire_with(
        &self,
        ctx: &FireCtx,
        work: &[u32],
        (reference, last_event): (&mut [f32], &mut [f64]),
        batch: &mut Vec<RawEvent>,
        path: &mut Vec<f32>,
    ) -> ListedCounts {
        let (kf0, kf1) = (self.kf0, self.kf1);
        let (t0, t1) = self.span;
        let mut counts = ListedCounts::default();
        let (on, off) = (&self.thresholds.on, &self.thresholds.off);
        let mut wi = 0;
        while wi < work.len() {
            let i = work[wi] as usize;
            match self.class[i] {
                QUIET => {
                    let before = batch.len();
                    fire(
                        ctx,
                        &mut reference[i],
                        &mut last_event[i],
                        i,
                        kf0.l[i],
                        kf1.l[i],
                        (t0, t1),
                        (&kf0.geom, &kf1.geom),
                        (kf0.seen(i), kf1.seen(i)),
                        (on[i], off[i]),
                        batch,
                    );
                    counts.violations += u64::from(batch.len() > before);
                    wi += 1;
                }
                STABLE => {
                    // The run's texel bound first (`run_range`); members it keeps strictly
                    // inside their thresholds cannot fire and keep their references. A
                    // member's test reads only its own reference, so processing the run's
                    // earlier members first decides the same.
                    let (end, bound) = run_range(kf0, kf1, self.scene, work, wi, self.class);
                    let (lo, hi) = bound.unwrap_or((f32::NEG_INFINITY, f32::INFINITY));
                    // The members' image displacements, for the whole run at once when one
                    // needs them (see `run_displacements`).
                    let mut disps: Option<[f32; RUN_PIXELS]> = None;
                    let first = work[wi] as usize;
                    for &p in &work[wi..end] {
                        let i = p as usize;
                        let r = reference[i];
                        if (hi < r + on[i]) & (lo > r - off[i]) {
                            continue;
                        }
                        let disp = match disps {
                            Some(d) => d[i - first],
                            None => match run_displacements(kf0, kf1, first, end - wi, self.width) {
                                Some(d) => {
                                    disps = Some(d);
                                    d[i - first]
                                }
                                None => {
                                    let (du, dv) = (kf1.u[i] - kf0.u[i], kf1.v[i] - kf0.v[i]);
                                    stable_displacement(kf0, kf1, i, self.width, du, dv)
                                }
                            },
                        };
                        let (n, f) = self.fire_stable(
                            ctx,
                            i,
                            disp,
                            (&mut reference[i], &mut last_event[i]),
                            batch,
                            path,
                        );
                        counts.samples += n;
                        counts.fired += f;
                    }
                    wi = end;
                }
                _ => wi += 1,
            }
        }
        counts
    }

    /// Threshold crossings of stable pixel `i` (state `reference`, `last_event`) along its
    /// texture path between the key frames (see [`ListedPixels::fire`]), sampled every
    /// `max_px` of its image displacement `disp` (px, [`stable_displacement`]): the numbers
    /// of interpolated samples and events.
    #[inline(always)]
    fn fire_stable(
        &self,
        ctx: &FireCtx,
        i: usize,
        disp: f32,
        state: (&mut f32, &mut f64),
        batch: &mut Vec<RawEvent>,
        path: &mut Vec<f32>,
    ) -> (u64, u64) {
        let (kf0, kf1) = (self.kf0, self.kf1);
        let (t0, t1) = self.span;
        let key = kf0.key[i] as usize;
        let tex = &self.scene.textures[self.scene.key_texture[key]];
        let m = ((disp / self.max_px).ceil() as usize).clamp(1, 4096);
        fire_path(
            ctx,
            tex,
            (&kf0.path_end(i, t0), &kf1.path_end(i, t1)),
            m,
            i,
            kf0.id[i],
            state,
            (self.thresholds.on[i], self.thresholds.off[i]),
            batch,
            path,
        )
    }
}

/// Texel bound (see [`Texture::path_range`]) of the union of the stable paths of a run of
/// neighbouring pixels that starts at `work[start]`: up to `RUN_PIXELS` consecutive pixels of
/// one row, all listed, stable and on the same surface. Returns the index in
/// `work` after the run and the bound (`None` for a run of one pixel, or when the union spans
/// more than `RUN_RANGE_TEXELS` texels). The union's texels include every member path's, so a
/// member whose thresholds hold the run's bound would hold its own: the same decisions as
/// bounding every path alone, with one setup and one texel scan per run.
#[inline(always)]
fn run_range(
    kf0: &KeyFrame,
    kf1: &KeyFrame,
    scene: &Scene,
    work: &[u32],
    start: usize,
    class: &[u8],
) -> (usize, Option<(f32, f32)>) {
    let first = work[start] as usize;
    let key = kf0.key[first];
    let mut end = start + 1;
    while end < work.len()
        && end - start < RUN_PIXELS
        && work[end] as usize == first + (end - start)
        && class[work[end] as usize] == STABLE
        && kf0.key[work[end] as usize] == key
    {
        end += 1;
    }
    if end - start < 2 {
        return (end, None);
    }
    let [u_lo, u_hi, v_lo, v_hi, fp_lo, fp_hi] = run_extent(kf0, kf1, first, end - start);
    let key = key as usize;
    let tex = &scene.textures[scene.key_texture[key]];
    let texels = tex.path_range(u_lo, v_lo, u_hi, v_hi, fp_lo, fp_hi, RUN_RANGE_TEXELS);
    (
        end,
        shaded_bounds(texels, kf0.geom.shade_by_key[key], kf1.geom.shade_by_key[key]),
    )
}

/// The extremes `[u_lo, u_hi, v_lo, v_hi, fp_lo, fp_hi]` of the texture coordinates and
/// footprints of pixels `first..first + len` (`len <= RUN_PIXELS`) at both key frames. Over a
/// window of `RUN_PIXELS` pixels with the ones past `len` masked (a fixed trip count the
/// compiler vectorises) when the window fits in the image, else one by one.
#[inline(always)]
fn run_extent(kf0: &KeyFrame, kf1: &KeyFrame, first: usize, len: usize) -> [f32; 6] {
    let (inf, ninf) = (f32::INFINITY, f32::NEG_INFINITY);
    let mut e = [inf, ninf, inf, ninf, inf, ninf];
    let n = kf0.u.len();
    if first + RUN_PIXELS > n {
        for i in first..first + len {
            e[0] = fmin(e[0], fmin(kf0.u[i], kf1.u[i]));
            e[1] = fmax(e[1], fmax(kf0.u[i], kf1.u[i]));
            e[2] = fmin(e[2], fmin(kf0.v[i], kf1.v[i]));
            e[3] = fmax(e[3], fmax(kf0.v[i], kf1.v[i]));
            e[4] = fmin(e[4], fmin(kf0.footprint[i], kf1.footprint[i]));
            e[5] = fmax(e[5], fmax(kf0.footprint[i], kf1.footprint[i]));
        }
        return e;
    }
    let w = first..first + RUN_PIXELS;
    let lanes = |a: &[f32]| -> [f32; RUN_PIXELS] { a[w.clone()].try_into().expect("run window") };
    let (u0, u1, v0, v1) = (lanes(&kf0.u), lanes(&kf1.u), lanes(&kf0.v), lanes(&kf1.v));
    let (f0, f1) = (lanes(&kf0.footprint), lanes(&kf1.footprint));
    let mut lo = [[inf; RUN_PIXELS]; 3];
    let mut hi = [[ninf; RUN_PIXELS]; 3];
    for l in 0..RUN_PIXELS {
        let on = l < len;
        for (k, (a, b)) in [(u0[l], u1[l]), (v0[l], v1[l]), (f0[l], f1[l])]
            .into_iter()
            .enumerate()
        {
            lo[k][l] = if on { fmin(a, b) } else { inf };
            hi[k][l] = if on { fmax(a, b) } else { ninf };
        }
    }
    for k in 0..3 {
        e[2 * k] = lo[k].iter().fold(inf, |a, &b| fmin(a, b));
        e[2 * k + 1] = hi[k].iter().fold(ninf, |a, &b| fmax(a, b));
    }
    e
}

/// Bounds of the log intensities along a stable path from the texel bound `texels` of its
/// surface (see [`Texture::path_range`]), with the surface's log shading `s0` and `s1` at the
/// key frames and the rounding allowance.
#[inline]
fn shaded_bounds(texels: Option<(f32, f32)>, s0: f32, s1: f32) -> Option<(f32, f32)> {
    texels.map(|(lo, hi)| (lo + s0.min(s1) - SAMPLE_EPS_LOG, hi + s0.max(s1) + SAMPLE_EPS_LOG))
}

/// Image displacement (px) of the texture point seen by stable pixel `i` from key frame
/// `kf0` to `kf1` (`du`, `dv`: its texture-coordinate change, m; `w`: image width): the change
/// mapped back through the pixel-to-texture Jacobian from central differences of the
/// neighbours' texture coordinates (when all four see the pixel's surface), the
/// larger of both key frames' with `DISPLACEMENT_SAFETY`, and never more than the change over
/// the smaller pixel size across the ray (the bound for any direction on a surface seen at
/// any angle). Image borders use that bound alone.
#[inline]
fn stable_displacement(kf0: &KeyFrame, kf1: &KeyFrame, i: usize, w: usize, du: f32, dv: f32) -> f32 {
    // The pixel's size on the surface across the ray at either key frame.
    let size = (kf0.z[i] * kf0.geom.inv_f())
        .min(kf1.z[i] * kf1.geom.inv_f())
        .max(1e-9);
    let any_direction = (du * du + dv * dv).sqrt() / size;
    let n = kf0.u.len();
    let (x, y) = (i % w, i / w);
    if x == 0 || x + 1 >= w || y == 0 || i + w >= n {
        return any_direction;
    }
    let (d0, d1) = (
        jacobian_displacement(kf0, i, w, du, dv),
        jacobian_displacement(kf1, i, w, du, dv),
    );
    (d0.max(d1) * DISPLACEMENT_SAFETY).min(any_direction)
}

/// [`stable_displacement`] of the `len` (`2..=RUN_PIXELS`) pixels from `first` on (one row)
/// in lanes: a window of `RUN_PIXELS` pixels whose every pixel and its 4-neighbours lie inside
/// the image (else `None`), lanes past `len` unused. The same operations in the same order as
/// one pixel at a time (no fused multiply-adds), so the same values; loops the compiler
/// vectorises in the AVX2 pass, where the window's neighbours are contiguous loads.
#[inline(always)]
fn run_displacements(
    kf0: &KeyFrame,
    kf1: &KeyFrame,
    first: usize,
    len: usize,
    w: usize,
) -> Option<[f32; RUN_PIXELS]> {
    let n = kf0.u.len();
    let (x, y) = (first % w, first / w);
    if len < 2 || x == 0 || x + RUN_PIXELS + 1 > w || y == 0 || first + RUN_PIXELS + w > n {
        return None;
    }
    let (u0, u1, v0, v1) = (
        win(&kf0.u, first),
        win(&kf1.u, first),
        win(&kf0.v, first),
        win(&kf1.v, first),
    );
    let (z0, z1) = (win(&kf0.z, first), win(&kf1.z, first));
    let (f0, f1) = (kf0.geom.inv_f(), kf1.geom.inv_f());
    let mut out = [0.0f32; RUN_PIXELS];
    let mut du = [0.0f32; RUN_PIXELS];
    let mut dv = [0.0f32; RUN_PIXELS];
    for l in 0..RUN_PIXELS {
        (du[l], dv[l]) = (u1[l] - u0[l], v1[l] - v0[l]);
        let size = (z0[l] * f0).min(z1[l] * f1).max(1e-9);
        out[l] = (du[l] * du[l] + dv[l] * dv[l]).sqrt() / size;
    }
    let (d0, d1) = (
        run_jacobian(kf0, first, w, &du, &dv),
        run_jacobian(kf1, first, w, &du, &dv),
    );
    for l in 0..RUN_PIXELS {
        out[l] = (d0[l].max(d1[l]) * DISPLACEMENT_SAFETY).min(out[l]);
    }
    Some(out)
}

/// The pixel-to-texture Jacobian displacements ([`jacobian_displacement`]) of the window of
/// `RUN_PIXELS` pixels from `first` on in key frame `kf` (texture-coordinate changes `du`,
/// `dv`), lane by lane; the window and its 4-neighbours lie inside the image (see
/// [`run_displacements`]).
#[inline(always)]
fn run_jacobian(
    kf: &KeyFrame,
    first: usize,
    w: usize,
    du: &[f32; RUN_PIXELS],
    dv: &[f32; RUN_PIXELS],
) -> [f32; RUN_PIXELS] {
    let (k, kr, kl, kd, ku) = (
        win(&kf.key, first),
        win(&kf.key, first + 1),
        win(&kf.key, first - 1),
        win(&kf.key, first + w),
        win(&kf.key, first - w),
    );
    let (ur, ul, ud, uu) = (
        win(&kf.u, first + 1),
        win(&kf.u, first - 1),
        win(&kf.u, first + w),
        win(&kf.u, first - w),
    );
    let (vr, vl, vd, vu) = (
        win(&kf.v, first + 1),
        win(&kf.v, first - 1),
        win(&kf.v, first + w),
        win(&kf.v, first - w),
    );
    let mut d = [0.0f32; RUN_PIXELS];
    for l in 0..RUN_PIXELS {
        let edge = (kr[l] != k[l]) | (kl[l] != k[l]) | (kd[l] != k[l]) | (ku[l] != k[l]);
        let (a, b) = (0.5 * (ur[l] - ul[l]), 0.5 * (ud[l] - uu[l]));
        let (c, e) = (0.5 * (vr[l] - vl[l]), 0.5 * (vd[l] - vu[l]));
        let det = a * e - b * c;
        let (px, py) = ((e * du[l] - b * dv[l]) / det, (a * dv[l] - c * du[l]) / det);
        let r = (px * px + py * py).sqrt();
        d[l] = if edge | det.is_nan() | (det.abs() <= 1e-12) {
            f32::INFINITY
        } else {
            r
        };
    }
    d
}

/// The `RUN_PIXELS` values of `a` from `at` on.
#[inline(always)]
fn win<T: Copy + Default>(a: &[T], at: usize) -> [T; RUN_PIXELS] {
    let mut o = [T::default(); RUN_PIXELS];
    o.copy_from_slice(&a[at..at + RUN_PIXELS]);
    o
}

/// The image displacement (px) of texture-coordinate change `(du, dv)` at pixel `i` of key
/// frame `kf` through its pixel-to-texture Jacobian from central differences (infinite when a
/// 4-neighbour sees another surface or the Jacobian is degenerate); see
/// [`stable_displacement`]. Inlined: it runs twice per stable pixel.
#[inline(always)]
fn jacobian_displacement(kf: &KeyFrame, i: usize, w: usize, du: f32, dv: f32) -> f32 {
    let k = kf.key[i];
    if kf.key[i + 1] != k || kf.key[i - 1] != k || kf.key[i + w] != k || kf.key[i - w] != k {
        // A neighbour on another surface (the pixel lies along an edge).
        return f32::INFINITY;
    }
    let (a, b) = (
        0.5 * (kf.u[i + 1] - kf.u[i - 1]),
        0.5 * (kf.u[i + w] - kf.u[i - w]),
    );
    let (c, d) = (
        0.5 * (kf.v[i + 1] - kf.v[i - 1]),
        0.5 * (kf.v[i + w] - kf.v[i - w]),
    );
    let det = a * d - b * c;
    if det.is_nan() || det.abs() <= 1e-12 {
        return f32::INFINITY;
    }
    let (px, py) = ((d * du - b * dv) / det, (a * dv - c * du) / det);
    (px * px + py * py).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::presets::preset;
    use crate::render::FrameGeom;

    /// Key frames of a 5 x 5 image whose texture coordinates are the affine map `(a, b, c, d)`
    /// of the pixel position (u = a x + b y, v = c x + d y), shifted by `shift`.
    fn affine(kf: &mut KeyFrame, w: usize, j: [f32; 4], shift: (f32, f32), px_size: f32) {
        let z = px_size / kf.geom.inv_f();
        for i in 0..w * w {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            kf.u[i] = j[0] * x + j[1] * y + shift.0;
            kf.v[i] = j[2] * x + j[3] * y + shift.1;
            kf.z[i] = z;
        }
    }

    #[test]
    fn run_displacements_equal_stable_displacements_bit_for_bit() {
        let cfg = preset("camera-only", 1).unwrap().with_resolution_scale(0.05);
        let scene = Scene::new(&cfg.scene, cfg.camera_trajectory.clone(), 1, 0.01);
        let geom = FrameGeom::new(&scene, &cfg.camera, 0.0);
        let (w, h) = (16, 6);
        let (mut kf0, mut kf1) = (KeyFrame::new(geom.clone(), w * h), KeyFrame::new(geom, w * h));
        let mut rng = crate::rng::Rng::new(9, 2);
        for trial in 0..200 {
            for kf in [&mut kf0, &mut kf1] {
                let j = [
                    0.004 * rng.uniform(),
                    0.002 * rng.uniform() - 0.001,
                    0.001 * rng.uniform(),
                    0.003,
                ];
                for i in 0..w * h {
                    let (x, y) = ((i % w) as f64, (i / w) as f64);
                    // Degenerate Jacobians now and then; noise on the coordinates.
                    let s = if trial % 7 == 0 { 0.0 } else { 1.0 };
                    kf.u[i] = (s * (j[0] * x + j[1] * y) + 1e-4 * rng.uniform()) as f32;
                    kf.v[i] = (s * (j[2] * x + j[3] * y) + 1e-4 * rng.uniform()) as f32;
                    kf.z[i] = (0.5 + 3.0 * rng.uniform()) as f32;
                    kf.key[i] = u16::from(rng.uniform() < 0.1);
                }
            }
            for first in [w + 1, w + 5, 2 * w + 3, 4 * w + 7] {
                let len = 2 + rng.below(7) as usize;
                let lanes = run_displacements(&kf0, &kf1, first, len, w).unwrap();
                for (l, lane) in lanes.iter().enumerate().take(len) {
                    let i = first + l;
                    let (du, dv) = (kf1.u[i] - kf0.u[i], kf1.v[i] - kf0.v[i]);
                    let one = stable_displacement(&kf0, &kf1, i, w, du, dv);
                    assert_eq!(lane.to_bits(), one.to_bits(), "trial {trial} pixel {i}");
                }
            }
            // Windows that reach the image border are left to the one-pixel path.
            assert!(run_displacements(&kf0, &kf1, w, 3, w).is_none());
            assert!(run_displacements(&kf0, &kf1, 2 * w - 8, 3, w).is_none());
            assert!(run_displacements(&kf0, &kf1, 1, 3, w).is_none());
            assert!(run_displacements(&kf0, &kf1, (h - 1) * w + 1, 3, w).is_none());
        }
    }

    #[test]
    fn stable_displacement_follows_the_texture_jacobian() {
        let cfg = preset("camera-only", 1).unwrap().with_resolution_scale(0.05);
        let scene = Scene::new(&cfg.scene, cfg.camera_trajectory.clone(), 1, 0.01);
        let geom = FrameGeom::new(&scene, &cfg.camera, 0.0);
        let (mut kf0, mut kf1) = (KeyFrame::new(geom.clone(), 25), KeyFrame::new(geom, 25));
        // A surface foreshortened 4x along x (4 mm per pixel) and 1 mm per pixel along y.
        let j = [0.004, 0.0, 0.0, 0.001];
        // The texture moves 3 px along x: 12 mm.
        // The pixel size across the ray (0.5 mm) bounds any direction by 2x too much or more.
        affine(&mut kf0, 5, j, (0.0, 0.0), 0.0005);
        affine(&mut kf1, 5, j, (0.012, 0.0), 0.0005);
        let d = stable_displacement(&kf0, &kf1, 12, 5, 0.012, 0.0);
        assert!((d - 3.0 * DISPLACEMENT_SAFETY).abs() < 1e-3, "{d}");
        // Along y, 3 px is 3 mm.
        let d = stable_displacement(&kf0, &kf1, 12, 5, 0.0, 0.003);
        assert!((d - 3.0 * DISPLACEMENT_SAFETY).abs() < 1e-3, "{d}");
        // Border pixels get the any-direction bound (12 mm over 0.5 mm pixels).
        let d = stable_displacement(&kf0, &kf1, 2, 5, 0.012, 0.0);
        assert!((d - 24.0).abs() < 1e-3, "{d}");
        // A degenerate Jacobian falls back to the any-direction bound.
        affine(&mut kf0, 5, [0.0; 4], (0.0, 0.0), 0.0005);
        let d = stable_displacement(&kf0, &kf1, 12, 5, 0.012, 0.0);
        assert!((d - 24.0).abs() < 1e-3, "{d}");
    }
}
