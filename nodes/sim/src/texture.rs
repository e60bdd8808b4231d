//! Procedural textures, baked once into a mip-mapped log-intensity image per surface.
//!
//! Anti-aliasing of the texture itself is done by analytic filtering: every sample looks up a
//! trilinear (mip-mapped) value at the level whose texel size matches the pixel footprint on the
//! surface, so texture detail finer than a pixel is averaged rather than aliased into flicker
//! (and spurious events). Hard pattern edges are baked with a one-texel linear ramp. Geometric
//! edges (silhouettes, creases) are anti-aliased by the renderer (see `render`).
//!
//! Textures are periodic (they tile), so they can cover planes of any size; the period is
//! `size * texel_m` metres.

use serde::{Deserialize, Serialize};

use crate::SimError;
use crate::math::{fmax, fmin};
use crate::rng::Rng;

#[cfg(target_arch = "x86_64")]
mod lanes;

/// The pattern of a texture, before the value-noise layer is mixed in.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum Pattern {
    /// Multi-octave value noise only.
    Noise,
    /// A checkerboard with the given square size (m, rounded so the texture tiles).
    Checker {
        /// Square side, m.
        square_m: f64,
    },
    /// Random discs and rectangles of random grey levels on a mid-grey ground ("clutter",
    /// posters, objects on a wall).
    Blobs {
        /// Number of shapes per square metre.
        per_m2: f64,
        /// Typical shape radius / half-size, m (actual sizes vary from 0.3x to 1.5x).
        radius_m: f64,
    },
    /// Parallel stripes along the texture's v axis.
    Stripes {
        /// Stripe period, m (rounded so the texture tiles).
        period_m: f64,
    },
}

/// How one surface looks. The log intensity is `ln(eps + albedo)` with
/// `albedo = mean_albedo * exp(contrast * z)`, `z` in [-1, 1] the pattern value.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TextureConfig {
    /// Pattern.
    pub pattern: Pattern,
    /// Texels per side (power of two, 16..=4096).
    pub size: u32,
    /// Texel size, m.
    pub texel_m: f64,
    /// Mean albedo in (0, 1].
    pub mean_albedo: f64,
    /// Log-intensity amplitude of the pattern (natural-log units; 1 = factor e either way).
    pub contrast: f64,
    /// Weight of the value-noise layer mixed into the pattern, 0..=1.
    pub noise_weight: f64,
    /// Wavelength of the coarsest noise octave, m (finer octaves halve it down to 8 texels).
    pub noise_feature_m: f64,
    /// Texture seed (mixed with the scene seed).
    pub seed: u64,
}

impl TextureConfig {
    /// Checks the values; `what` names the surface in errors.
    pub fn validate(&self, what: &str) -> Result<(), SimError> {
        let bad = |m: String| Err(SimError::Config(format!("{what}.texture: {m}")));
        if !self.size.is_power_of_two() || !(16..=4096).contains(&self.size) {
            return bad(format!("size {} must be a power of two in 16..=4096", self.size));
        }
        if !(self.texel_m.is_finite() && self.texel_m > 0.0) {
            return bad(format!("texel_m {} must be > 0", self.texel_m));
        }
        if !(self.mean_albedo > 0.0 && self.mean_albedo <= 1.0) {
            return bad(format!("mean_albedo {} must be in (0, 1]", self.mean_albedo));
        }
        if !(self.contrast.is_finite() && (0.0..=5.0).contains(&self.contrast)) {
            return bad(format!("contrast {} must be in [0, 5]", self.contrast));
        }
        if !(0.0..=1.0).contains(&self.noise_weight) {
            return bad(format!("noise_weight {} must be in [0, 1]", self.noise_weight));
        }
        if !(self.noise_feature_m.is_finite() && self.noise_feature_m > 0.0) {
            return bad(format!("noise_feature_m {} must be > 0", self.noise_feature_m));
        }
        let positive = |v: f64| v.is_finite() && v > 0.0;
        let ok = match self.pattern {
            Pattern::Noise => true,
            Pattern::Checker { square_m } => positive(square_m),
            Pattern::Blobs { per_m2, radius_m } => positive(per_m2) && per_m2 < 1e4 && positive(radius_m),
            Pattern::Stripes { period_m } => positive(period_m),
        };
        if !ok {
            return bad(format!("pattern {:?} needs positive finite sizes", self.pattern));
        }
        Ok(())
    }
}

/// A baked, mip-mapped texture of log intensities.
#[derive(Debug, Clone)]
pub struct Texture {
    /// Mip levels, finest first.
    mips: Vec<MipLevel>,
    /// Texels of every level, finest first, one after the other (levels index into it).
    texels: Vec<f32>,
    /// For every texel of `texels`, the four taps of a bilinear sample whose floor it is:
    /// itself, its right neighbour, the one below and the one below right (wrapping within its
    /// level), so that 8-lane samples load each lane's taps with one 16-byte load (hardware
    /// gathers of single texels took twice as long; see `lanes`).
    quads: Vec<[f32; 4]>,
    /// Per level (the last repeated up to 8): texels per metre, side and first texel, the
    /// tables [`Texture::sample_lanes`] looks levels up in.
    lane_scale: [f32; LANES],
    lane_size: [i32; LANES],
    lane_start: [i32; LANES],
    inv_texel: f32,
    max_level: f32,
    /// Per level k: min and max of the level-0 texels in each aligned 2^k x 2^k cell.
    range_min: Vec<Vec<f32>>,
    range_max: Vec<Vec<f32>>,
    /// Per level k: largest texel-to-texel difference of level 0 (log units per texel) along
    /// either axis in each aligned 2^k x 2^k cell (cells include the differences to their
    /// right and lower neighbours, wrapping).
    grad_max: Vec<Vec<f32>>,
}

/// One mip level: a square, periodic image of log intensities.
#[derive(Debug, Clone)]
struct MipLevel {
    /// Index of the level's first texel in [`Texture::texels`] (row-major).
    start: usize,
    /// Texels per side (a power of two).
    size: u32,
    /// Texels per metre.
    scale: f32,
}

/// Lanes of [`Texture::sample_lanes`].
pub const LANES: usize = 8;

/// `floor(x)` as an integer and `x - floor(x)` (valid for |x| < 2^31; the same values as
/// `floor_fast`, with one float-to-integer conversion).
#[inline(always)]
fn floor_split(x: f32) -> (i32, f32) {
    let t = x as i32;
    let i = t - i32::from((t as f32) > x);
    (i, x - i as f32)
}

/// Bounds of a texture along a straight path of surface coordinates (see
/// [`Texture::path_bounds`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathBounds {
    /// Smallest value any sample near the path can take, log units.
    pub lo: f32,
    /// Largest value any sample near the path can take, log units.
    pub hi: f32,
    /// Lipschitz bound of samples at one footprint near the path, log units per metre of
    /// surface: `|sample(p, fp) - sample(q, fp)| <= grad_per_m * |p - q|`.
    pub grad_per_m: f32,
}

/// `floor` without a libm call (valid for |x| < 2^31).
#[inline]
fn floor_fast(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x { t - 1.0 } else { t }
}

/// Approximate log2 of a positive number: exact at powers of two, linear in between
/// (continuous and monotone, which is what level selection needs).
#[inline]
pub fn fast_log2(x: f32) -> f32 {
    let bits = x.to_bits();
    let e = ((bits >> 23) & 255) as i32 - 127;
    let m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    e as f32 + (m - 1.0)
}

fn smooth5(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

/// A periodic square wave of amplitude 1 and the given period (texels), with edges ramped
/// linearly over one texel.
fn square_wave(x: f64, period: f64) -> f64 {
    let f = x.rem_euclid(period);
    let half = period / 2.0;
    let e = f.min((f - half).abs()).min(period - f);
    let sign = if f < half { 1.0 } else { -1.0 };
    sign * (e / 0.5).min(1.0)
}

impl Texture {
    /// Bakes `cfg` with scene seed `seed`; `eps` is the log offset of `ln(eps + albedo)`.
    pub fn bake(cfg: &TextureConfig, seed: u64, eps: f64) -> Self {
        let n = cfg.size as usize;
        let mut rng = Rng::new(seed ^ cfg.seed.wrapping_mul(0x9E37_79B9), 0x7e57);
        let extent = n as f64 * cfg.texel_m;
        let pattern = Self::pattern(cfg, n, extent, &mut rng);
        let noise = Self::value_noise(cfg, n, extent, &mut rng);
        let w = cfg.noise_weight;
        let level0: Vec<f32> = pattern
            .iter()
            .zip(&noise)
            .map(|(p, q)| {
                let z = ((1.0 - w) * p + w * q).clamp(-1.0, 1.0);
                let albedo = (cfg.mean_albedo * (cfg.contrast * z).exp()).clamp(1e-3, 1.0);
                (eps + albedo).ln() as f32
            })
            .collect();
        let mut levels = vec![level0];
        let mut sizes = vec![cfg.size];
        while *sizes.last().unwrap_or(&1) > 8 && levels.len() < 8 {
            let (prev, m) = (&levels[levels.len() - 1], sizes[sizes.len() - 1] as usize);
            let h = m / 2;
            let mut next = vec![0.0f32; h * h];
            for y in 0..h {
                for x in 0..h {
                    let a = prev[2 * y * m + 2 * x] + prev[2 * y * m + 2 * x + 1];
                    let b = prev[(2 * y + 1) * m + 2 * x] + prev[(2 * y + 1) * m + 2 * x + 1];
                    next[y * h + x] = 0.25 * (a + b);
                }
            }
            levels.push(next);
            sizes.push(h as u32);
        }
        let max_level = (levels.len() - 1) as f32;
        let inv_texel = (1.0 / cfg.texel_m) as f32;
        let mut range_min = vec![levels[0].clone()];
        let mut range_max = vec![levels[0].clone()];
        let mut m = cfg.size as usize;
        while m > 1 {
            let h = m / 2;
            let (pmin, pmax) = (&range_min[range_min.len() - 1], &range_max[range_max.len() - 1]);
            let mut nmin = vec![0.0f32; h * h];
            let mut nmax = vec![0.0f32; h * h];
            for y in 0..h {
                for x in 0..h {
                    let idx = [
                        2 * y * m + 2 * x,
                        2 * y * m + 2 * x + 1,
                        (2 * y + 1) * m + 2 * x,
                        (2 * y + 1) * m + 2 * x + 1,
                    ];
                    nmin[y * h + x] = idx.iter().map(|&i| pmin[i]).fold(f32::INFINITY, f32::min);
                    nmax[y * h + x] = idx.iter().map(|&i| pmax[i]).fold(f32::NEG_INFINITY, f32::max);
                }
            }
            range_min.push(nmin);
            range_max.push(nmax);
            m = h;
        }
        let grad_max = Self::gradient_pyramid(&levels[0], cfg.size as usize);
        // At most 8 levels (see the loop above), so the lane tables hold them all.
        let mut texels = Vec::with_capacity(levels.iter().map(Vec::len).sum());
        let mut mips = Vec::with_capacity(levels.len());
        for (k, (data, size)) in levels.into_iter().zip(sizes).enumerate() {
            mips.push(MipLevel {
                start: texels.len(),
                size,
                scale: inv_texel / (1u32 << k) as f32,
            });
            texels.extend_from_slice(&data);
        }
        let quads = Self::bilinear_quads(&texels, &mips);
        let table = |k: usize| &mips[k.min(mips.len() - 1)];
        let lane_scale = std::array::from_fn(|k| table(k).scale);
        let lane_size = std::array::from_fn(|k| table(k).size as i32);
        // Sizes up to 4096 texels: under 2^25 texels in all, so starts fit an i32.
        let lane_start = std::array::from_fn(|k| table(k).start as i32);
        Self {
            mips,
            texels,
            quads,
            lane_scale,
            lane_size,
            lane_start,
            inv_texel,
            max_level,
            range_min,
            range_max,
            grad_max,
        }
    }

    /// The bilinear taps of every texel of `texels` (see `quads`).
    fn bilinear_quads(texels: &[f32], mips: &[MipLevel]) -> Vec<[f32; 4]> {
        let mut quads = vec![[0.0f32; 4]; texels.len()];
        for m in mips {
            let (n, mask) = (m.size as usize, m.size as usize - 1);
            let d = &texels[m.start..m.start + n * n];
            for y in 0..n {
                let y1 = (y + 1) & mask;
                for x in 0..n {
                    let x1 = (x + 1) & mask;
                    quads[m.start + y * n + x] = [d[y * n + x], d[y * n + x1], d[y1 * n + x], d[y1 * n + x1]];
                }
            }
        }
        quads
    }

    /// Pyramid of the largest level-0 neighbour difference per aligned cell (see `grad_max`).
    fn gradient_pyramid(d: &[f32], n: usize) -> Vec<Vec<f32>> {
        let mut g0 = vec![0.0f32; n * n];
        for y in 0..n {
            let y1 = (y + 1) % n;
            for x in 0..n {
                let x1 = (x + 1) % n;
                let c = d[y * n + x];
                g0[y * n + x] = (d[y * n + x1] - c).abs().max((d[y1 * n + x] - c).abs());
            }
        }
        let mut out = vec![g0];
        let mut m = n;
        while m > 1 {
            let h = m / 2;
            let prev = &out[out.len() - 1];
            let mut next = vec![0.0f32; h * h];
            for y in 0..h {
                for x in 0..h {
                    let a = prev[2 * y * m + 2 * x].max(prev[2 * y * m + 2 * x + 1]);
                    let b = prev[(2 * y + 1) * m + 2 * x].max(prev[(2 * y + 1) * m + 2 * x + 1]);
                    next[y * h + x] = a.max(b);
                }
            }
            out.push(next);
            m = h;
        }
        out
    }

    fn pattern(cfg: &TextureConfig, n: usize, extent: f64, rng: &mut Rng) -> Vec<f64> {
        let tiled = |p: f64| extent / (extent / p).round().max(1.0) / cfg.texel_m;
        match cfg.pattern {
            Pattern::Noise => vec![0.0; n * n],
            Pattern::Checker { square_m } => {
                let period = tiled(2.0 * square_m);
                let mut out = vec![0.0; n * n];
                for y in 0..n {
                    let sy = square_wave(y as f64 + 0.5, period);
                    for x in 0..n {
                        out[y * n + x] = square_wave(x as f64 + 0.5, period) * sy;
                    }
                }
                out
            }
            Pattern::Stripes { period_m } => {
                let period = tiled(period_m);
                let row: Vec<f64> = (0..n).map(|x| square_wave(x as f64 + 0.5, period)).collect();
                (0..n * n).map(|i| row[i % n]).collect()
            }
            Pattern::Blobs { per_m2, radius_m } => {
                let mut out = vec![0.0; n * n];
                let count = (per_m2 * extent * extent).round() as usize;
                for _ in 0..count {
                    let level = rng.range(-1.0, 1.0);
                    let cx = rng.range(0.0, n as f64);
                    let cy = rng.range(0.0, n as f64);
                    let r = radius_m * rng.range(0.3, 1.5) / cfg.texel_m;
                    let aspect = rng.range(0.5, 2.0);
                    let (rx, ry) = (r * aspect.sqrt(), r / aspect.sqrt());
                    let disc = rng.uniform() < 0.5;
                    let (ex, ey) = (rx.ceil() as i64 + 2, ry.ceil() as i64 + 2);
                    for dy in -ey..=ey {
                        for dx in -ex..=ex {
                            let px = (cx.floor() as i64 + dx).rem_euclid(n as i64) as usize;
                            let py = (cy.floor() as i64 + dy).rem_euclid(n as i64) as usize;
                            let ox = cx.floor() + dx as f64 + 0.5 - cx;
                            let oy = cy.floor() + dy as f64 + 0.5 - cy;
                            // Signed distance to the shape's outline, texels (negative inside).
                            let sd = if disc {
                                let q = ((ox / rx).powi(2) + (oy / ry).powi(2)).sqrt();
                                (q - 1.0) * rx.min(ry)
                            } else {
                                (ox.abs() - rx).max(oy.abs() - ry)
                            };
                            let a = (0.5 - sd).clamp(0.0, 1.0);
                            let v = &mut out[py * n + px];
                            *v = *v * (1.0 - a) + level * a;
                        }
                    }
                }
                out
            }
        }
    }

    fn value_noise(cfg: &TextureConfig, n: usize, extent: f64, rng: &mut Rng) -> Vec<f64> {
        let mut out = vec![0.0; n * n];
        if cfg.noise_weight <= 0.0 {
            return out;
        }
        let mut cells = ((extent / cfg.noise_feature_m).round().max(1.0) as usize)
            .next_power_of_two()
            .min(n);
        let mut amp = 1.0;
        let mut total = 0.0;
        while cells <= n / 8 {
            let lattice: Vec<f64> = (0..cells * cells).map(|_| rng.range(-1.0, 1.0)).collect();
            let per = n as f64 / cells as f64;
            for y in 0..n {
                let fy = (y as f64 + 0.5) / per;
                let iy = fy.floor() as usize;
                let ty = smooth5(fy - iy as f64);
                let (y0, y1) = (iy % cells, (iy + 1) % cells);
                for x in 0..n {
                    let fx = (x as f64 + 0.5) / per;
                    let ix = fx.floor() as usize;
                    let tx = smooth5(fx - ix as f64);
                    let (x0, x1) = (ix % cells, (ix + 1) % cells);
                    let a = lattice[y0 * cells + x0] * (1.0 - tx) + lattice[y0 * cells + x1] * tx;
                    let b = lattice[y1 * cells + x0] * (1.0 - tx) + lattice[y1 * cells + x1] * tx;
                    out[y * n + x] += amp * (a * (1.0 - ty) + b * ty);
                }
            }
            total += amp;
            amp *= 0.5;
            cells *= 2;
        }
        if total > 0.0 {
            // Value noise rarely reaches its bounds; stretch so that it spans about [-1, 1].
            for v in &mut out {
                *v = (*v / total * 1.8).clamp(-1.0, 1.0);
            }
        }
        out
    }

    /// The texels of mip level `m`.
    #[inline(always)]
    fn level(&self, m: &MipLevel) -> &[f32] {
        &self.texels[m.start..m.start + (m.size * m.size) as usize]
    }

    #[inline(always)]
    fn bilinear(&self, level: usize, u: f32, v: f32) -> f32 {
        let m = &self.mips[level];
        let (size, mask) = (m.size, m.size - 1);
        let (iu, a) = floor_split(u * m.scale - 0.5);
        let (iv, b) = floor_split(v * m.scale - 0.5);
        let x0 = (iu as u32) & mask;
        let y0 = (iv as u32) & mask;
        // The four taps (wrapping) in one quad (see `quads`), the memory the lane samples use.
        let [d00, d01, d10, d11] = self.quads[m.start + (y0 * size + x0) as usize];
        let top = d00 + a * (d01 - d00);
        let bot = d10 + a * (d11 - d10);
        top + b * (bot - top)
    }

    /// Log intensity at surface coordinates `(u, v)` (m) for a pixel footprint of
    /// `footprint_m` metres on the surface (trilinear mip-mapping).
    #[inline(always)]
    pub fn sample(&self, u: f32, v: f32, footprint_m: f32) -> f32 {
        let lod = fast_log2((footprint_m * self.inv_texel).max(1e-6)).clamp(0.0, self.max_level);
        if lod <= 0.0 {
            return self.bilinear(0, u, v);
        }
        let l0 = floor_fast(lod);
        let f = lod - l0;
        let a = self.bilinear(l0 as usize, u, v);
        if f <= 0.0 || l0 >= self.max_level {
            return a;
        }
        let b = self.bilinear(l0 as usize + 1, u, v);
        a + f * (b - a)
    }

    /// [`Texture::sample`] of [`LANES`] points at once: the same arithmetic lane by lane, so
    /// the same values. With AVX2 (detected at run time) the lanes run in SIMD registers (see
    /// `lanes`); otherwise the points are sampled one by one.
    #[inline(always)]
    pub fn sample_lanes(&self, u: &[f32; LANES], v: &[f32; LANES], fp: &[f32; LANES]) -> [f32; LANES] {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            return unsafe { self.sample_lanes_avx2(u, v, fp) };
        }
        std::array::from_fn(|l| self.sample(u[l], v[l], fp[l]))
    }

    /// Samples at `j / m` for `j = 1..m` (exclusive) of the straight path from `start` to
    /// `start + delta`, replacing `out`, and their smallest and largest value (infinite for
    /// none). Both hold `[u (m), v (m), footprint (m), offset (log units)]`; each sample is
    /// `sample(u, v, footprint) + offset` at the interpolated values. With AVX2 (detected at
    /// run time) 8 at a time (see `lanes`): the same values.
    #[inline(always)]
    pub fn sample_path(&self, start: [f32; 4], delta: [f32; 4], m: usize, out: &mut Vec<f32>) -> (f32, f32) {
        let n = m.saturating_sub(1);
        out.clear();
        out.resize(n, 0.0);
        if n == 0 {
            return (f32::INFINITY, f32::NEG_INFINITY);
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            return unsafe { self.sample_path_avx2(start, delta, m, out) };
        }
        let mf = m as f32;
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for (j, o) in out.iter_mut().enumerate() {
            let f = (j + 1) as f32 / mf;
            let s = self.sample(
                start[0] + f * delta[0],
                start[1] + f * delta[1],
                start[2] + f * delta[2],
            );
            *o = s + start[3] + f * delta[3];
            lo = fmin(lo, *o);
            hi = fmax(hi, *o);
        }
        (lo, hi)
    }

    /// Bounds `(min, max)` of every value [`Texture::sample`] returns on the straight path
    /// from `(u0, v0)` to `(u1, v1)` (m) with footprints between `fp_min` and `fp_max` (m),
    /// when the bilinear taps of every level those footprints blend span at most `max_texels`
    /// texels per axis (else `None`): the extremes of those texels. A bilinear sample is a
    /// convex blend of its four texels and a trilinear one of two bilinear samples, so this
    /// holds up to f32 rounding (callers add an allowance).
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub fn path_range(
        &self,
        u0: f32,
        v0: f32,
        u1: f32,
        v1: f32,
        fp_min: f32,
        fp_max: f32,
        max_texels: u32,
    ) -> Option<(f32, f32)> {
        let (lod_lo, lod_hi) = (self.lod(fp_min), self.lod(fp_max));
        if !(lod_lo.is_finite() && lod_hi.is_finite()) {
            return None;
        }
        let first = lod_lo as usize;
        let last = if lod_hi <= 0.0 {
            0
        } else {
            (lod_hi as usize + 1).min(self.mips.len() - 1)
        };
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for m in &self.mips[first..=last] {
            let (fu0, fu1) = (u0 * m.scale - 0.5, u1 * m.scale - 0.5);
            let (fv0, fv1) = (v0 * m.scale - 0.5, v1 * m.scale - 0.5);
            let (x0, _) = floor_split(fu0.min(fu1));
            let (x1, _) = floor_split(fu0.max(fu1));
            let (y0, _) = floor_split(fv0.min(fv1));
            let (y1, _) = floor_split(fv0.max(fv1));
            // Taps reach one texel past the floor on either axis.
            let (nx, ny) = ((x1 - x0 + 2) as u32, (y1 - y0 + 2) as u32);
            if nx > max_texels || ny > max_texels {
                return None;
            }
            let (a, b) = self.texel_range(m, (x0 as u32, y0 as u32), (nx, ny));
            lo = fmin(lo, a);
            hi = fmax(hi, b);
        }
        Some((lo, hi))
    }

    /// The extremes of the `nx` x `ny` texels (both at least 2) of level `m` from texel `x0`,
    /// `y0` on (wrapping): read as the bilinear quads (see `quads`, each 2 x 2 texels) at
    /// every other texel, the last row and column of quads moved back to end at the
    /// region's edge (quads may overlap; extremes do not mind).
    #[inline]
    fn texel_range(&self, m: &MipLevel, (x0, y0): (u32, u32), (nx, ny): (u32, u32)) -> (f32, f32) {
        let mask = m.size - 1;
        let quads = &self.quads[m.start..m.start + (m.size * m.size) as usize];
        let at = |k: u32, n: u32| (2 * k).min(n - 2);
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            // SSE (part of every x86_64): 4 texels per load.
            let (mut a, mut b) = ([0.0f32; 4], [0.0f32; 4]);
            // SAFETY: SSE is available on every x86_64; unaligned loads of the 4 floats of one
            // quad and stores of 4 floats into arrays of 4.
            unsafe {
                let (mut lo, mut hi) = (_mm_set1_ps(f32::INFINITY), _mm_set1_ps(f32::NEG_INFINITY));
                for ky in 0..ny.div_ceil(2) {
                    let row = ((y0.wrapping_add(at(ky, ny)) & mask) * m.size) as usize;
                    for kx in 0..nx.div_ceil(2) {
                        let q = &quads[row + (x0.wrapping_add(at(kx, nx)) & mask) as usize];
                        let t = _mm_loadu_ps(q.as_ptr());
                        lo = _mm_min_ps(lo, t);
                        hi = _mm_max_ps(hi, t);
                    }
                }
                _mm_storeu_ps(a.as_mut_ptr(), lo);
                _mm_storeu_ps(b.as_mut_ptr(), hi);
            }
            (
                fmin(fmin(a[0], a[1]), fmin(a[2], a[3])),
                fmax(fmax(b[0], b[1]), fmax(b[2], b[3])),
            )
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            for ky in 0..ny.div_ceil(2) {
                let row = ((y0.wrapping_add(at(ky, ny)) & mask) * m.size) as usize;
                for kx in 0..nx.div_ceil(2) {
                    for &t in &quads[row + (x0.wrapping_add(at(kx, nx)) & mask) as usize] {
                        lo = fmin(lo, t);
                        hi = fmax(hi, t);
                    }
                }
            }
            (lo, hi)
        }
    }

    /// Bounds `(min, max)` of every value [`Texture::sample`] can return at points of the
    /// rectangle spanned by `(u0, v0)` and `(u1, v1)` (m) with footprints up to `footprint_m`.
    #[inline]
    pub fn range(&self, u0: f32, v0: f32, u1: f32, v1: f32, footprint_m: f32) -> (f32, f32) {
        let b = self.path_bounds(u0, v0, u1, v1, footprint_m);
        (b.lo, b.hi)
    }

    /// Mip level (fractional, clamped to the baked levels) [`Texture::sample`] uses for a
    /// footprint of `footprint_m` metres.
    #[inline]
    pub fn lod(&self, footprint_m: f32) -> f32 {
        fast_log2((footprint_m * self.inv_texel).max(1e-6)).clamp(0.0, self.max_level)
    }

    /// Value range and Lipschitz bound of [`Texture::sample`] over the rectangle spanned by
    /// `(u0, v0)` and `(u1, v1)` (m) with footprints up to `footprint_m`.
    ///
    /// The gradient of a bilinear interpolant is bounded per axis by the largest neighbour
    /// difference of the texels it blends; texels of coarser levels are means of level-0
    /// blocks, so their differences per level-0 texel are bounded by level-0 differences in
    /// the blocks; trilinear blending at a fixed footprint keeps the bound. Hence
    /// `sqrt(2) * max difference` per texel over the region the filters reach.
    #[inline]
    pub fn path_bounds(&self, u0: f32, v0: f32, u1: f32, v1: f32, footprint_m: f32) -> PathBounds {
        // The bilinear filter of level L blends texels of level L within 1.5 of its texels
        // (1.5 * 2^L level-0 texels) of the point; `sample` uses levels floor(lod) and
        // floor(lod) + 1, or level 0 alone at lod 0. Half a texel more covers rounding.
        let lod = self.lod(footprint_m);
        let top = if lod <= 0.0 {
            0
        } else {
            (lod as u32 + 1).min(self.max_level as u32)
        };
        let pad = 1.5 * (1u32 << top) as f32 + 0.5;
        let s = self.inv_texel;
        let (a0, a1) = ((u0.min(u1) * s - pad), (u0.max(u1) * s + pad));
        let (b0, b1) = ((v0.min(v1) * s - pad), (v0.max(v1) * s + pad));
        let extent = (a1 - a0).max(b1 - b0).max(1.0);
        // Cells of 2^k texels with 2 * 2^k >= extent: the rectangle touches at most 3 x 3.
        let k = ((fast_log2(extent).ceil() as usize).saturating_sub(1)).min(self.range_min.len() - 1);
        let n = (self.mips[0].size >> k).max(1);
        let grad = |g: f32| g * s * std::f32::consts::SQRT_2;
        if n <= 3 {
            let last = self.range_min.len() - 1;
            return PathBounds {
                lo: self.range_min[last][0],
                hi: self.range_max[last][0],
                grad_per_m: grad(self.grad_max[last][0]),
            };
        }
        let cell = (1u32 << k) as f32;
        let mask = n - 1;
        let (cx0, cy0) = (floor_fast(a0 / cell) as i32, floor_fast(b0 / cell) as i32);
        let (cx1, cy1) = (floor_fast(a1 / cell) as i32, floor_fast(b1 / cell) as i32);
        let (mn, mx, gm) = (&self.range_min[k], &self.range_max[k], &self.grad_max[k]);
        let (mut lo, mut hi, mut g) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f32);
        for cy in cy0..=cy1 {
            let row = ((cy as u32) & mask) * n;
            for cx in cx0..=cx1 {
                let c = (row + ((cx as u32) & mask)) as usize;
                lo = lo.min(mn[c]);
                hi = hi.max(mx[c]);
                g = g.max(gm[c]);
            }
        }
        PathBounds {
            lo,
            hi,
            grad_per_m: grad(g),
        }
    }

    /// The coarsest level's mean, i.e. the texture's average log intensity.
    pub fn mean(&self) -> f32 {
        let last = self.level(&self.mips[self.mips.len() - 1]);
        last.iter().sum::<f32>() / last.len() as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cfg(pattern: Pattern) -> TextureConfig {
        TextureConfig {
            pattern,
            size: 64,
            texel_m: 0.01,
            mean_albedo: 0.4,
            contrast: 1.0,
            noise_weight: 0.3,
            noise_feature_m: 0.16,
            seed: 3,
        }
    }

    #[test]
    fn fast_log2_is_exact_at_powers_and_monotone() {
        assert_eq!(fast_log2(8.0), 3.0);
        assert_eq!(fast_log2(0.25), -2.0);
        let mut prev = fast_log2(0.1);
        for i in 1..1000 {
            let v = fast_log2(0.1 + i as f32 * 0.01);
            assert!(v >= prev);
            prev = v;
        }
    }

    #[test]
    fn textures_tile_and_filter_towards_the_mean() {
        for p in [
            Pattern::Noise,
            Pattern::Checker { square_m: 0.08 },
            Pattern::Blobs {
                per_m2: 30.0,
                radius_m: 0.05,
            },
            Pattern::Stripes { period_m: 0.1 },
        ] {
            let c = cfg(p);
            c.validate("t").unwrap();
            let t = Texture::bake(&c, 1, 0.01);
            let period = 0.64f32;
            let a = t.sample(0.123, 0.456, 0.001);
            let b = t.sample(0.123 + period, 0.456 - period, 0.001);
            assert!((a - b).abs() < 1e-4, "{p:?}: {a} vs {b}");
            // A huge footprint returns the coarsest level, close to the mean everywhere.
            let m = t.mean();
            assert!((t.sample(0.3, 0.1, 10.0) - m).abs() < 0.5, "{p:?}");
            // Contrast: level 0 spans a real range.
            let lo = t.level(&t.mips[0]).iter().cloned().fold(f32::MAX, f32::min);
            let hi = t.level(&t.mips[0]).iter().cloned().fold(f32::MIN, f32::max);
            assert!(hi - lo > 0.3, "{p:?}: range {lo}..{hi}");
        }
        // Range bounds hold every sample inside the rectangle.
        let t = Texture::bake(
            &cfg(Pattern::Blobs {
                per_m2: 30.0,
                radius_m: 0.05,
            }),
            2,
            0.01,
        );
        for (u0, v0, u1, v1, fp) in [
            (0.1f32, 0.2f32, 0.13f32, 0.21f32, 0.005f32),
            (-0.3, 0.6, -0.2, 0.5, 0.03),
            (0.5, 0.5, 0.5, 0.5, 0.001),
        ] {
            let (lo, hi) = t.range(u0, v0, u1, v1, fp);
            assert!(hi >= lo);
            for i in 0..=20 {
                let f = i as f32 / 20.0;
                for ff in [fp * 0.5, fp] {
                    let s = t.sample(u0 + f * (u1 - u0), v0 + f * (v1 - v0), ff);
                    assert!(s >= lo - 1e-6 && s <= hi + 1e-6, "{s} outside {lo}..{hi}");
                }
            }
        }
        let mut bad = cfg(Pattern::Noise);
        bad.size = 100;
        assert!(
            bad.validate("wall")
                .unwrap_err()
                .to_string()
                .contains("wall.texture")
        );
    }

    #[test]
    fn path_bounds_hold_every_sample_and_every_slope_along_the_path() {
        // Hard-edged patterns have the steepest slopes; check value and Lipschitz bounds on
        // densely sampled paths at several footprints (mip levels 0..2).
        for p in [
            Pattern::Checker { square_m: 0.16 },
            Pattern::Blobs {
                per_m2: 10.0,
                radius_m: 0.08,
            },
        ] {
            let t = Texture::bake(&cfg(p), 4, 0.01);
            let mut rng = Rng::new(11, 1);
            let (mut tight, mut steep) = (0usize, 0.0f32);
            for _ in 0..400 {
                let (u0, v0) = (rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32);
                let len = rng.range(0.0, 0.05) as f32;
                let ang = rng.range(0.0, std::f64::consts::TAU) as f32;
                let (u1, v1) = (u0 + len * ang.cos(), v0 + len * ang.sin());
                let fp = [0.002f32, 0.012, 0.03][rng.below(3) as usize];
                let b = t.path_bounds(u0, v0, u1, v1, fp);
                let n = 200;
                let mut prev = t.sample(u0, v0, fp);
                for k in 1..=n {
                    let f = k as f32 / n as f32;
                    let s = t.sample(u0 + f * (u1 - u0), v0 + f * (v1 - v0), fp);
                    assert!(
                        s >= b.lo - 1e-5 && s <= b.hi + 1e-5,
                        "{s} outside {}..{}",
                        b.lo,
                        b.hi
                    );
                    let slope = (s - prev).abs() / (len / n as f32).max(1e-9);
                    steep = steep.max(slope / b.grad_per_m.max(1e-9));
                    assert!(
                        (s - prev).abs() <= b.grad_per_m * len / n as f32 + 1e-5,
                        "slope {slope} > {}",
                        b.grad_per_m
                    );
                    prev = s;
                }
                tight += usize::from(
                    b.hi - b.lo < 0.5 * (t.range_max.last().unwrap()[0] - t.range_min.last().unwrap()[0]),
                );
            }
            eprintln!("{p:?}: largest slope / bound {steep:.3}, local ranges {tight} of 400");
            // The bounds are local: most short paths see much less than the texture's range.
            assert!(tight > 40, "{p:?}: only {tight} tight ranges");
        }
    }

    #[test]
    fn path_range_holds_every_sample_along_the_path() {
        // Paths across levels 0..3, with footprints changing along the path.
        let t = Texture::bake(
            &cfg(Pattern::Blobs {
                per_m2: 30.0,
                radius_m: 0.05,
            }),
            5,
            0.01,
        );
        let mut rng = Rng::new(7, 2);
        let (mut bounded, mut tight) = (0usize, 0usize);
        for _ in 0..2000 {
            let (u0, v0) = (rng.range(-1.0, 1.0) as f32, rng.range(-1.0, 1.0) as f32);
            let (du, dv) = (rng.range(-0.03, 0.03) as f32, rng.range(-0.03, 0.03) as f32);
            let fp0 = [0.002f32, 0.008, 0.015, 0.05][rng.below(4) as usize];
            let fp1 = fp0 * rng.range(0.8, 1.25) as f32;
            let Some((lo, hi)) = t.path_range(u0, v0, u0 + du, v0 + dv, fp0.min(fp1), fp0.max(fp1), 4) else {
                continue;
            };
            bounded += 1;
            let mut out = Vec::new();
            t.sample_path([u0, v0, fp0, 0.0], [du, dv, fp1 - fp0, 0.0], 40, &mut out);
            out.push(t.sample(u0, v0, fp0));
            out.push(t.sample(u0 + du, v0 + dv, fp1));
            for s in out {
                assert!(s >= lo - 1e-5 && s <= hi + 1e-5, "{s} outside {lo}..{hi}");
            }
            tight += usize::from(hi - lo < 0.3);
        }
        // Most short paths are bounded, and the bounds are local.
        assert!(
            bounded > 1000 && tight > bounded / 4,
            "{bounded} bounded, {tight} tight"
        );
    }

    #[test]
    fn lane_samples_equal_samples_one_by_one() {
        // Every level and blend, fractional and integral levels of detail, negative and
        // wrapping coordinates; bit-identical values.
        let t = Texture::bake(
            &cfg(Pattern::Blobs {
                per_m2: 30.0,
                radius_m: 0.05,
            }),
            5,
            0.01,
        );
        let mut rng = Rng::new(9, 3);
        for round in 0..4000 {
            let u: [f32; LANES] = std::array::from_fn(|_| rng.range(-3.0, 3.0) as f32);
            let v: [f32; LANES] = std::array::from_fn(|_| rng.range(-3.0, 3.0) as f32);
            let fp: [f32; LANES] = std::array::from_fn(|l| match (round + l) % 4 {
                0 => 0.01 * (1u32 << ((round / 4) % 9)) as f32,
                1 => 1e-9,
                _ => (10.0f64).powf(rng.range(-4.0, 1.0)) as f32,
            });
            let lanes = t.sample_lanes(&u, &v, &fp);
            for l in 0..LANES {
                let one = t.sample(u[l], v[l], fp[l]);
                assert_eq!(lanes[l].to_bits(), one.to_bits(), "{} {} {}", u[l], v[l], fp[l]);
            }
        }
    }

    #[test]
    fn path_samples_equal_samples_one_by_one() {
        // Paths on the finest level only (the shortcut), across levels and blends, short and
        // long, with a shading ramp: bit-identical to `sample` at the interpolated points,
        // and their extremes.
        let t = Texture::bake(&cfg(Pattern::Checker { square_m: 0.05 }), 4, 0.01);
        let mut rng = Rng::new(11, 5);
        let mut out = Vec::new();
        for round in 0..3000 {
            let fp0 = [0.002f32, 0.006, 0.0099, 0.03, 0.2][round % 5];
            let start = [
                rng.range(-2.0, 2.0) as f32,
                rng.range(-2.0, 2.0) as f32,
                fp0,
                rng.range(-1.0, 0.0) as f32,
            ];
            let delta = [
                rng.range(-0.05, 0.05) as f32,
                rng.range(-0.05, 0.05) as f32,
                fp0 * rng.range(-0.2, 0.2) as f32,
                rng.range(-0.01, 0.01) as f32,
            ];
            let m = 1 + rng.below(40) as usize;
            let (lo, hi) = t.sample_path(start, delta, m, &mut out);
            assert_eq!(out.len(), m - 1);
            let (mut lo1, mut hi1) = (f32::INFINITY, f32::NEG_INFINITY);
            for (j, &s) in out.iter().enumerate() {
                let f = (j + 1) as f32 / m as f32;
                let one = t.sample(
                    start[0] + f * delta[0],
                    start[1] + f * delta[1],
                    start[2] + f * delta[2],
                ) + start[3]
                    + f * delta[3];
                assert_eq!(s.to_bits(), one.to_bits(), "round {round} sample {j}");
                (lo1, hi1) = (lo1.min(one), hi1.max(one));
            }
            assert_eq!((lo.to_bits(), hi.to_bits()), (lo1.to_bits(), hi1.to_bits()));
        }
    }

    #[test]
    fn invalid_sizes_are_rejected() {
        let mut bad = cfg(Pattern::Noise);
        bad.size = 100;
        assert!(
            bad.validate("wall")
                .unwrap_err()
                .to_string()
                .contains("wall.texture")
        );
    }
}
