//! Local bounds of the image speed over one key-frame interval, so that unstable pixels can be
//! rendered at their own pace.
//!
//! Render steps are short enough for the fastest scene point anywhere in the image (see
//! `Engine::plan`). Most unstable pixels lie on seams of the static room, whose image motion
//! comes from the camera alone and is often several times slower. Each unstable pixel is
//! therefore rendered only at the steps it needs: as late as its local speed bound allows, so
//! that it moves at most `max_px_per_step` between renders (see [`render_steps`]): the ESIM
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

/// The render steps of a pixel with speed bound `speed` (px/s) in the interval with render
/// times `times` (steps `0..=k`, `k = times.len() - 1 <= 64`): bit `s` (`1 <= s < k`) is set
/// when the pixel is rendered at step `s`; it is always rendered at the closing key frame
/// (step `k`, no bit). Greedy: a pixel is rendered at step `s` when waiting for step `s + 1`
/// would take it more than `max_px` pixels of motion from its previous render (every step when
/// even one step does). Greedy covering renders least often among all schedules that keep
/// every pixel within `max_px` pixels between renders, in particular never more often than
/// the power-of-two strides it replaced (which wasted up to half the renders of a pixel
/// whose bound is just above half of the fastest one).
pub fn render_steps(times: &[f64], speed: f32, max_px: f64) -> u64 {
    let k = times.len() - 1;
    debug_assert!(k <= 64, "{k} steps");
    let budget = max_px / speed as f64;
    let mut steps = 0u64;
    let mut last = times[0];
    for s in 1..k {
        if times[s + 1] - last > budget {
            steps |= 1 << s;
            last = times[s];
        }
    }
    steps
}

/// Memo of [`render_steps`] over one interval: neighbouring unstable pixels share their speed
/// bound (one per block), so the schedule of the previous speed is kept.
#[derive(Debug, Clone)]
pub struct Schedules<'a> {
    times: &'a [f64],
    max_px: f64,
    last: Option<(f32, u64)>,
}

impl<'a> Schedules<'a> {
    /// Schedules of the interval with render times `times`, `max_px` pixels per render.
    pub fn new(times: &'a [f64], max_px: f64) -> Self {
        Self {
            times,
            max_px,
            last: None,
        }
    }

    /// [`render_steps`] of a pixel with speed bound `speed` (px/s).
    #[inline]
    pub fn steps(&mut self, speed: f32) -> u64 {
        match self.last {
            Some((v, steps)) if v.to_bits() == speed.to_bits() => steps,
            _ => {
                let steps = render_steps(self.times, speed, self.max_px);
                self.last = Some((speed, steps));
                steps
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Render times of each gap between renders of `steps` (0 and `k` included).
    fn gaps(times: &[f64], steps: u64) -> Vec<f64> {
        let k = times.len() - 1;
        let mut at: Vec<usize> = (1..k).filter(|s| steps >> s & 1 == 1).collect();
        at.insert(0, 0);
        at.push(k);
        at.windows(2).map(|w| times[w[1]] - times[w[0]]).collect()
    }

    #[test]
    fn render_steps_keep_every_gap_within_the_budget_and_beat_power_of_two_strides() {
        let times: Vec<f64> = (0..=20)
            .map(|i| i as f64 * 0.001 + (i as f64).powi(2) * 1e-5)
            .collect();
        let k = times.len() - 1;
        let longest_step = (0..k).map(|s| times[s + 1] - times[s]).fold(0.0, f64::max);
        let global = 0.5 / longest_step;
        let mut rng = crate::rng::Rng::new(5, 1);
        for j in 0..2000 {
            let speed = (global * if j == 0 { 1.0 } else { 1.2 * rng.uniform() }) as f32;
            let steps = render_steps(&times, speed, 0.5);
            assert_eq!(steps & 1, 0);
            assert_eq!(steps >> k, 0);
            // Every gap within 0.5 px (each single step is, for speeds up to the global bound).
            for g in gaps(&times, steps) {
                assert!(speed as f64 * g <= 0.5 || g <= longest_step, "{speed} {g}");
                if speed as f64 <= global {
                    assert!(speed as f64 * g <= 0.5 + 1e-12, "{speed} {g}");
                }
            }
            // Never more renders than the largest valid power-of-two stride.
            let mut stride_renders = k - 1;
            for stride in [2usize, 4, 8, 16, 32] {
                let ok = (0..k)
                    .step_by(stride)
                    .all(|s| speed as f64 * (times[(s + stride).min(k)] - times[s]) <= 0.5);
                if ok {
                    stride_renders = (1..k).filter(|s| s % stride == 0).count();
                }
            }
            assert!(steps.count_ones() as usize <= stride_renders, "{speed}");
        }
        // The fastest pixel renders at every step, a still one only at the key frame.
        assert_eq!(render_steps(&times, global as f32, 0.5), ((1u64 << k) - 1) & !1);
        assert_eq!(render_steps(&times, 0.0, 0.5), 0);
        // Just over half the global speed: about every other step instead of every step.
        let n = render_steps(&times, (0.55 * global) as f32, 0.5).count_ones();
        assert!((9..=12).contains(&n), "{n}");
        // The memo agrees.
        let mut memo = Schedules::new(&times, 0.5);
        for v in [100.0f32, 100.0, 250.0, 100.0] {
            assert_eq!(memo.steps(v), render_steps(&times, v, 0.5));
        }
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
