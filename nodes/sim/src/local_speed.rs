//! Local bounds of the image speed over one key-frame interval, so that unstable pixels can be
//! rendered at their own pace.
//!
//! Render steps are short enough for the fastest scene point anywhere in the image (see
//! `Engine::plan`). Most unstable pixels lie on seams of the static room, whose image motion
//! comes from the camera alone and is often several times slower. Each unstable pixel is
//! therefore rendered only at the steps it needs: as late as its local speed bound allows, so
//! that it moves at most `max_px_per_step` between renders, at quarter steps (see
//! [`render_slots`]): the ESIM
//! sampling rule holds for every pixel, with fewer renders.
//!
//! The local bound of a pixel is the largest background bound of the 3 x 3 blocks around its
//! block (each with the smallest background depth of its own 3 x 3 blocks at the last key
//! frame, so surfaces that move into the block during the interval are covered) over every
//! render time of the interval, and the bound of every moving object whose pixel bounding box
//! at any render time of the interval contains the pixel.

/// Bounds of the image speed (px/s, safety factors included) over one interval.
#[derive(Debug, Clone, Default)]
pub struct LocalSpeed {
    /// Blocks per row.
    pub blocks_x: usize,
    /// Block side, px.
    pub block: usize,
    /// Background bound per block (3 x 3 neighbourhood), px/s.
    pub background: Vec<f32>,
    /// Moving objects: pixel bounding box `[u0, v0, u1, v1]` (inclusive) covering the object at
    /// every render time of the interval, and its speed bound, px/s.
    pub objects: Vec<([i32; 4], f32)>,
}

impl LocalSpeed {
    /// Speed bound (px/s) at pixel `(x, y)`.
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> f32 {
        let mut s = self.background[(y / self.block) * self.blocks_x + x / self.block];
        let (xi, yi) = (x as i32, y as i32);
        for (b, v) in &self.objects {
            if xi >= b[0] && xi <= b[2] && yi >= b[1] && yi <= b[3] {
                s = s.max(*v);
            }
        }
        s
    }
}

/// Render slots per render step: unstable pixels may be rendered at `SUBSTEPS` evenly spaced
/// times inside each step (slot `q` is step `q / SUBSTEPS` plus `q % SUBSTEPS` quarters of the
/// step), so that a pixel whose bound is just over half the fastest one renders about every
/// 1.75 steps instead of every step.
pub const SUBSTEPS: usize = 4;

/// Time (s) of render slot `q` of the interval with render times `times` (slot
/// `SUBSTEPS * k` is the closing key frame).
#[inline]
pub fn slot_time(times: &[f64], q: usize) -> f64 {
    let (s, r) = (q / SUBSTEPS, q % SUBSTEPS);
    if r == 0 {
        times[s]
    } else {
        times[s] + (times[s + 1] - times[s]) * (r as f64 / SUBSTEPS as f64)
    }
}

/// The render slots (see [`SUBSTEPS`]) of a pixel with speed bound `speed` (px/s) in the
/// interval with render times `times`, ascending, ending with the closing key frame's
/// (`SUBSTEPS * k`). Greedy: a pixel is rendered at slot `q` when waiting for slot `q + 1`
/// would take it more than `max_px` pixels of motion from its previous render, unless both
/// lie in one step (the steps themselves keep every point within `max_px`). Both rules allow
/// every sub-gap of an allowed gap, so greedy covering renders least often among all schedules
/// on these slots that keep them; in particular never more often than at every step or than
/// power-of-two strides of whole steps (which wasted up to half the renders of a pixel whose
/// bound is just over half the fastest one).
pub fn render_slots(times: &[f64], speed: f32, max_px: f64) -> Vec<u32> {
    let last_slot = SUBSTEPS * (times.len() - 1);
    let budget = max_px / speed as f64;
    let mut out = Vec::new();
    let (mut last, mut last_q) = (times[0], 0);
    for q in 1..last_slot {
        // A gap inside one step is always short enough: the steps keep every scene point
        // within `max_px` (`Engine::plan`, from the bound at the step's own times, which the
        // local bound, the largest over the interval, may exceed).
        let one_step = last_q / SUBSTEPS == q / SUBSTEPS;
        if !one_step && slot_time(times, q + 1) - last > budget {
            out.push(q as u32);
            (last, last_q) = (slot_time(times, q), q);
        }
    }
    out.push(last_slot as u32);
    out
}

/// The render schedules of one interval's unstable pixels: one [`render_slots`] list per
/// distinct speed bound (neighbouring pixels share one per block).
#[derive(Debug, Clone)]
pub struct Schedules<'a> {
    times: &'a [f64],
    max_px: f64,
    by_speed: std::collections::HashMap<u32, u32>,
    /// The speed (bits) and schedule of the previous call: neighbouring pixels mostly share
    /// their block's bound, so most calls skip the hash lookup.
    last: Option<(u32, u32)>,
    /// Render slots of every schedule (see [`render_slots`]).
    pub lists: Vec<Vec<u32>>,
}

impl<'a> Schedules<'a> {
    /// No schedules yet for the interval with render times `times`, `max_px` pixels per render.
    pub fn new(times: &'a [f64], max_px: f64) -> Self {
        Self {
            times,
            max_px,
            by_speed: std::collections::HashMap::new(),
            last: None,
            lists: Vec::new(),
        }
    }

    /// Index in [`Schedules::lists`] of the schedule of a pixel with speed bound `speed`
    /// (px/s).
    pub fn of(&mut self, speed: f32) -> u32 {
        let bits = speed.to_bits();
        if let Some((b, s)) = self.last
            && b == bits
        {
            return s;
        }
        let (times, max_px, lists) = (self.times, self.max_px, &mut self.lists);
        let s = *self.by_speed.entry(bits).or_insert_with(|| {
            lists.push(render_slots(times, speed, max_px));
            (lists.len() - 1) as u32
        });
        self.last = Some((bits, s));
        s
    }

    /// The last slot: the closing key frame.
    pub fn key_slot(&self) -> usize {
        SUBSTEPS * (self.times.len() - 1)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_slots_keep_every_gap_within_the_budget_and_beat_whole_steps() {
        let times: Vec<f64> = (0..=20)
            .map(|i| i as f64 * 0.001 + (i as f64).powi(2) * 1e-5)
            .collect();
        let k = times.len() - 1;
        let key = SUBSTEPS * k;
        assert_eq!(slot_time(&times, key), times[k]);
        assert_eq!(slot_time(&times, 2 * SUBSTEPS), times[2]);
        assert!((slot_time(&times, 1) - 0.25 * times[1]).abs() < 1e-15);
        let longest_step = (0..k).map(|s| times[s + 1] - times[s]).fold(0.0, f64::max);
        let global = 0.5 / longest_step;
        let mut rng = crate::rng::Rng::new(5, 1);
        for j in 0..2000 {
            let speed = (global * if j == 0 { 1.0 } else { 1.2 * rng.uniform() }) as f32;
            let slots = render_slots(&times, speed, 0.5);
            assert_eq!(*slots.last().unwrap(), key as u32);
            assert!(slots.windows(2).all(|w| w[0] < w[1]) && slots[0] > 0);
            // Every gap within 0.5 px or inside one step.
            let mut prev = 0;
            for &q in &slots {
                let g = slot_time(&times, q as usize) - slot_time(&times, prev);
                let one_step = prev / SUBSTEPS == (q as usize - 1) / SUBSTEPS;
                assert!(one_step || speed as f64 * g <= 0.5, "{speed} {g}");
                prev = q as usize;
            }
            assert!(slots.len() <= k, "{speed}: {}", slots.len());
            // Never more renders than rendering at every step the speed needs (greedy over
            // whole steps; an upper bound of any power-of-two stride too).
            let mut whole = 1;
            let (mut last, mut last_s) = (times[0], 0);
            for s in 1..k {
                if s > last_s && speed as f64 * (times[s + 1] - last) > 0.5 {
                    last_s = s;
                    whole += 1;
                    last = times[s];
                }
            }
            assert!(slots.len() <= whole, "{speed}: {} > {whole}", slots.len());
        }
        // A pixel faster than the steps allow renders at every step; a still one only at the
        // key frame.
        let every: Vec<u32> = (1..=k).map(|s| (SUBSTEPS * s) as u32).collect();
        assert_eq!(render_slots(&times, (2.0 * global) as f32, 0.5), every);
        assert_eq!(render_slots(&times, 0.0, 0.5), vec![key as u32]);
        // Just over half the global speed: about every 1.75 steps instead of every step.
        let n = render_slots(&times, (0.55 * global) as f32, 0.5).len();
        assert!((11..=13).contains(&n), "{n}");
        // Schedules are shared per speed.
        let mut sch = Schedules::new(&times, 0.5);
        let (a, b, c) = (sch.of(100.0), sch.of(250.0), sch.of(100.0));
        assert!(a == c && a != b && sch.lists.len() == 2);
        assert_eq!(sch.lists[b as usize], render_slots(&times, 250.0, 0.5));
        assert_eq!(sch.key_slot(), key);
    }

    #[test]
    fn object_boxes_raise_the_bound_inside_only() {
        let ls = LocalSpeed {
            blocks_x: 2,
            block: 16,
            background: vec![100.0, 200.0, 300.0, 400.0],
            objects: vec![([10, 10, 20, 20], 1000.0)],
        };
        assert_eq!(ls.at(0, 0), 100.0);
        assert_eq!(ls.at(17, 0), 200.0);
        assert_eq!(ls.at(12, 12), 1000.0);
        assert_eq!(ls.at(21, 20), 400.0);
    }
}
