//! Unstable pixels (near silhouettes, creases and seams) of one key-frame interval, stepped
//! together in a compact list.
//!
//! These pixels are ray cast at every render step. They are a few percent of the image,
//! scattered along edges, so their per-pixel state (rays, thresholds, reference levels, the
//! previous step's intensity) is gathered into dense arrays at the start of the interval and
//! the reference levels are scattered back at its end: every step then reads contiguous memory
//! instead of a dozen image-sized arrays at scattered indices. Each pixel is rendered at the
//! render slots its local speed bound needs (see `local_speed::render_slots`).

use crate::camera::Rays;
use crate::engine::KeyFrame;
use crate::firing::Seen;
use crate::render::FrameGeom;
use crate::scene::Scene;

/// Pixel centres located and shaded together.
const LANES: usize = crate::texture::LANES;

/// Marks "no unstable neighbour" in [`UnstableList::neighbours`].
pub const NONE: u32 = u32::MAX;

/// Marks "no moving object at an edge sub-sample" in [`UnstableList::edge_object`].
const NO_EDGE_OBJECT: Seen = Seen {
    id: 0,
    key: u16::MAX,
    z: f32::INFINITY,
};

/// Per-pixel state of the unstable pixels of one interval (structure of arrays, in pixel
/// order).
#[derive(Debug, Clone, Default)]
pub struct UnstableList {
    /// Row-major pixel index.
    pub pixel: Vec<u32>,
    /// Undistorted normalized ray of the pixel centre.
    pub x: Vec<f32>,
    /// Undistorted normalized ray of the pixel centre.
    pub y: Vec<f32>,
    /// Change of the normalized ray per pixel along the row and down the column.
    pub d_du: Vec<[f32; 2]>,
    /// Change of the normalized ray per pixel along the row and down the column.
    pub d_dv: Vec<[f32; 2]>,
    /// List indices of the right, left, lower and upper neighbours when they are unstable too
    /// ([`NONE`] otherwise or outside the image).
    pub neighbours: Vec<[u32; 4]>,
    /// ESIM reference level, log units.
    pub reference: Vec<f32>,
    /// Time of the last emitted event, s.
    pub last_event: Vec<f64>,
    /// ON threshold, log units.
    pub c_on: Vec<f32>,
    /// OFF threshold, log units.
    pub c_off: Vec<f32>,
    /// Log intensity at the previous render step.
    pub l_prev: Vec<f32>,
    /// What the pixel centre saw at the previous render step.
    pub(crate) seen_prev: Vec<Seen>,
    /// Log intensity of the current render step.
    pub l: Vec<f32>,
    /// Surface key of the current render step.
    pub key: Vec<u16>,
    /// Object id of the current render step.
    pub id: Vec<u16>,
    /// Depth of the current render step's centre surface, m.
    pub z: Vec<f32>,
    /// The moving object an edge sub-sample met at the current render step where the centre
    /// sees the background (id 0: none; see [`seen_at`]).
    pub(crate) edge_object: Vec<Seen>,
    /// Render schedule: index into `local_speed::Schedules::lists`.
    pub schedule: Vec<u32>,
    /// Position of the pixel's next render in its schedule.
    pub next: Vec<u32>,
    /// Render slot of the pixel's previous render (0: the opening key frame; see
    /// `local_speed::SUBSTEPS`).
    pub s_prev: Vec<u32>,
    /// List indices of the pixels rendered at the current slot.
    pub active: Vec<u32>,
    /// `active` grouped by the surface key of the pixels' previous renders (scratch of
    /// [`UnstableList::render`]).
    by_key: Vec<u32>,
    /// Counts and offsets of the key groups of `by_key`.
    key_counts: Vec<u32>,
}

/// What list pixel `j` saw at its latest render for the truth (from the list's `edge_object`,
/// `id`, `key` and `z` columns): its centre's surface, or the moving object that covers part
/// of it where the centre sees the background.
#[inline(always)]
pub(crate) fn seen_at(edge_object: &[Seen], id: &[u16], key: &[u16], z: &[f32], j: usize) -> Seen {
    if edge_object[j].id != 0 {
        return edge_object[j];
    }
    Seen {
        id: id[j],
        key: key[j],
        z: z[j],
    }
}

/// The per-pixel image arrays an [`UnstableList`] is gathered from.
pub struct PixelState<'a> {
    /// Rays of every pixel.
    pub rays: &'a Rays,
    /// Reference levels, log units.
    pub reference: &'a [f32],
    /// Times of the last events, s.
    pub last_event: &'a [f64],
    /// ON thresholds, log units.
    pub c_on: &'a [f32],
    /// OFF thresholds, log units.
    pub c_off: &'a [f32],
    /// The interval's first key frame.
    pub kf0: &'a KeyFrame,
}

impl UnstableList {
    /// Number of pixels in the list.
    pub fn len(&self) -> usize {
        self.pixel.len()
    }

    /// True when the list is empty.
    pub fn is_empty(&self) -> bool {
        self.pixel.is_empty()
    }

    /// Gathers the pixels whose `class` equals `unstable`, in pixel order, with their state
    /// from `src` at the start of the interval.
    pub fn gather(&mut self, class: &[u8], unstable: u8, src: &PixelState) {
        let (w, n) = (src.rays.width, class.len());
        self.pixel.clear();
        // Unstable pixels are a few percent, along edges: blocks of 64 without one are
        // skipped whole (a vectorised test), the others scanned pixel by pixel.
        for (b, block) in class.chunks(64).enumerate() {
            let has = block.iter().fold(false, |a, &c| a | (c == unstable));
            if has {
                let base = (b * 64) as u32;
                self.pixel.extend(
                    (0..block.len() as u32)
                        .filter(|&k| block[k as usize] == unstable)
                        .map(|k| base + k),
                );
            }
        }
        let pix = &self.pixel;
        let r = src.rays;
        let g = |out: &mut Vec<f32>, a: &[f32]| {
            out.clear();
            out.extend(pix.iter().map(|&p| a[p as usize]));
        };
        g(&mut self.x, &r.x);
        g(&mut self.y, &r.y);
        g(&mut self.reference, src.reference);
        g(&mut self.c_on, src.c_on);
        g(&mut self.c_off, src.c_off);
        g(&mut self.l_prev, &src.kf0.l);
        self.d_du.clear();
        self.d_du.extend(pix.iter().map(|&p| r.d_du[p as usize]));
        self.d_dv.clear();
        self.d_dv.extend(pix.iter().map(|&p| r.d_dv[p as usize]));
        self.last_event.clear();
        self.last_event
            .extend(pix.iter().map(|&p| src.last_event[p as usize]));
        self.seen_prev.clear();
        self.seen_prev
            .extend(pix.iter().map(|&p| src.kf0.seen(p as usize)));
        let m = pix.len();
        self.l.clear();
        self.l.resize(m, 0.0);
        self.key.clear();
        self.key.extend(pix.iter().map(|&p| src.kf0.key[p as usize]));
        self.schedule.clear();
        self.schedule.resize(m, 0);
        self.next.clear();
        self.next.resize(m, 0);
        self.s_prev.clear();
        self.s_prev.resize(m, 0);
        self.id.clear();
        self.id.resize(m, 0);
        self.z.clear();
        self.z.resize(m, 0.0);
        self.edge_object.clear();
        self.edge_object.resize(m, NO_EDGE_OBJECT);
        // Neighbours by walking the list (in pixel order): the left and right ones are the
        // adjacent entries, the lower and upper ones found by two cursors that only move on.
        self.neighbours.clear();
        let (mut down, mut up) = (0usize, 0usize);
        let find = |cursor: &mut usize, target: u32| {
            while *cursor < m && pix[*cursor] < target {
                *cursor += 1;
            }
            if *cursor < m && pix[*cursor] == target {
                *cursor as u32
            } else {
                NONE
            }
        };
        for (j, &p) in pix.iter().enumerate() {
            let i = p as usize;
            let (x, y) = (i % w, i / w);
            let right = if x + 1 < w && j + 1 < m && pix[j + 1] == p + 1 {
                (j + 1) as u32
            } else {
                NONE
            };
            let left = if x > 0 && j > 0 && pix[j - 1] == p - 1 {
                (j - 1) as u32
            } else {
                NONE
            };
            let below = if i + w < n {
                find(&mut down, p + w as u32)
            } else {
                NONE
            };
            let above = if y > 0 { find(&mut up, p - w as u32) } else { NONE };
            self.neighbours.push([right, left, below, above]);
        }
    }

    /// Ray casts the `active` pixels at `geom` into `l`, `key` and `id`; with `supersample`,
    /// those whose surface differs from a listed 4-neighbour's (as of the neighbour's latest
    /// render) are edge sampled. Returns the number of edge-sampled pixels.
    pub fn render(&mut self, scene: &Scene, geom: &FrameGeom, w: usize, supersample: bool) -> u64 {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is available (checked just above).
            return unsafe { self.render_avx2(scene, geom, w, supersample) };
        }
        self.render_with(scene, geom, w, supersample)
    }

    /// [`UnstableList::render`] compiled with AVX2 (the same arithmetic, so the same values).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn render_avx2(&mut self, scene: &Scene, geom: &FrameGeom, w: usize, supersample: bool) -> u64 {
        self.render_with(scene, geom, w, supersample)
    }

    /// The body of [`UnstableList::render`].
    #[inline(always)]
    fn render_with(&mut self, scene: &Scene, geom: &FrameGeom, w: usize, supersample: bool) -> u64 {
        self.group_by_key(scene.key_texture.len());
        // Centres cast `LANES` at a time (see `FrameGeom::cast_lanes`), grouped by the surface
        // of their previous render: it rarely changes between renders, so most groups hit one
        // plane or box face and are shaded in vector form. Each pixel's value is its own, so
        // the order does not matter.
        // The columns as slices of the list's length: one index test per pixel.
        let n = self.pixel.len();
        let (pixel, xs, ys) = (&self.pixel[..n], &self.x[..n], &self.y[..n]);
        let (ls, keys, ids, zs) = (
            &mut self.l[..n],
            &mut self.key[..n],
            &mut self.id[..n],
            &mut self.z[..n],
        );
        let mut groups = self.by_key.chunks_exact(LANES);
        for g in &mut groups {
            // Plain loops: `array::from_fn` and `array::map` closures were left out of line.
            let mut js = [0usize; LANES];
            let (mut px, mut py) = ([0i32; LANES], [0i32; LANES]);
            let (mut x, mut y) = ([0.0f32; LANES], [0.0f32; LANES]);
            for l in 0..LANES {
                let j = g[l] as usize;
                let p = pixel[j] as usize;
                (js[l], px[l], py[l], x[l], y[l]) = (j, (p % w) as i32, (p / w) as i32, xs[j], ys[j]);
            }
            let hits = geom.cast_lanes(scene, &x, &y, &px, &py);
            for (l, &j) in js.iter().enumerate() {
                if j < n {
                    (ls[j], keys[j], ids[j], zs[j]) = (hits.l[l], hits.key[l], hits.id[l], hits.z[l]);
                }
            }
        }
        for &a in groups.remainder() {
            let j = a as usize;
            let i = pixel[j] as usize;
            let hit = geom.cast(scene, xs[j], ys[j], (i % w) as i32, (i / w) as i32, None);
            (ls[j], keys[j], ids[j], zs[j]) = (hit.l, hit.key, hit.id, hit.z);
        }
        if !supersample {
            return 0;
        }
        let mut count = 0;
        let (neighbours, d_du, d_dv) = (&self.neighbours[..n], &self.d_du[..n], &self.d_dv[..n]);
        let edge_object = &mut self.edge_object[..n];
        for &a in &self.active {
            let j = a as usize;
            edge_object[j] = NO_EDGE_OBJECT;
            let k = keys[j];
            // Without early exits (`NONE` is past the list's end: no key).
            let edge = neighbours[j].iter().fold(false, |e, &nb| {
                e | keys.get(nb as usize).is_some_and(|&kn| kn != k)
            });
            if edge {
                let i = pixel[j] as usize;
                let (px, py) = ((i % w) as i32, (i / w) as i32);
                count += 1;
                // `edge_sample` in two parts: its shortcut inlined here (AVX2; the centre's
                // value stands when the sub-samples certainly see its surface), the rest out
                // of line.
                if geom.edge_free(xs[j], ys[j], d_du[j], d_dv[j], px, py, k) {
                    continue;
                }
                let value = geom.edge_mix(scene, xs[j], ys[j], d_du[j], d_dv[j], px, py, (ls[j], k));
                ls[j] = value.l;
                if let Some(o) = value.truth_object(ids[j]) {
                    edge_object[j] = Seen::from(o);
                }
            }
        }
        count
    }

    /// `active` into `by_key`, grouped by the surface keys of the pixels' previous renders
    /// (`keys` surface keys; "nothing" last), in their order within a group (counting sort).
    fn group_by_key(&mut self, keys: usize) {
        let slot = |k: u16| (k as usize).min(keys);
        self.key_counts.clear();
        self.key_counts.resize(keys + 2, 0);
        for &a in &self.active {
            self.key_counts[slot(self.key[a as usize]) + 1] += 1;
        }
        for k in 1..self.key_counts.len() {
            self.key_counts[k] += self.key_counts[k - 1];
        }
        self.by_key.clear();
        self.by_key.resize(self.active.len(), 0);
        for &a in &self.active {
            let c = &mut self.key_counts[slot(self.key[a as usize])];
            self.by_key[*c as usize] = a;
            *c += 1;
        }
    }

    /// Writes the reference levels and last-event times back to the image arrays.
    pub fn scatter(&self, reference: &mut [f32], last_event: &mut [f64]) {
        for (j, &p) in self.pixel.iter().enumerate() {
            reference[p as usize] = self.reference[j];
            last_event[p as usize] = self.last_event[j];
        }
    }
}
