//! Local bounds of the image speed over one key-frame interval, so that unstable pixels can be
//! rendered at their own pace.
//!
//! Render steps are short enough for the fastest scene point anywhere in the image (see
//! `Engine::plan`). Most unstable pixels lie on seams of the static room, whose image motion
//! comes from the camera alone and is often several times slower. Each unstable pixel is
//! therefore rendered every `stride` steps, the largest power of two for which its local speed
//! bound times the longest `stride`-step window of the interval stays within
//! `max_px_per_step`: the ESIM sampling rule holds for every pixel, with fewer renders.
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

/// Render strides: for each power of two `stride` (1, 2, 4, ...), the longest time (s)
/// between renders `stride` steps apart (aligned at multiples of `stride`, the last window
/// ending at the key frame) of the interval with render times `times`.
pub fn stride_windows(times: &[f64]) -> Vec<(usize, f64)> {
    let k = times.len() - 1;
    let mut out = Vec::new();
    let mut stride = 1;
    loop {
        let longest = (0..k)
            .step_by(stride)
            .map(|s| times[(s + stride).min(k)] - times[s])
            .fold(0.0, f64::max);
        out.push((stride, longest));
        if stride >= k {
            break;
        }
        stride *= 2;
    }
    out
}

/// The largest stride of `windows` whose longest window keeps a pixel with speed bound `speed`
/// (px/s) within `max_px` pixels of motion between renders (1 when none does).
#[inline]
pub fn stride_for(windows: &[(usize, f64)], speed: f32, max_px: f64) -> usize {
    windows
        .iter()
        .rev()
        .find(|(_, w)| speed as f64 * w <= max_px)
        .map_or(1, |(s, _)| *s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strides_keep_every_window_within_the_step_budget() {
        let times: Vec<f64> = (0..=16)
            .map(|i| i as f64 * 0.001 + (i as f64).powi(2) * 1e-5)
            .collect();
        let w = stride_windows(&times);
        assert_eq!(w.iter().map(|x| x.0).collect::<Vec<_>>(), vec![1, 2, 4, 8, 16]);
        // The longest single step is the last one.
        assert!((w[0].1 - (times[16] - times[15])).abs() < 1e-12);
        assert!((w[4].1 - times[16]).abs() < 1e-12);
        // A pixel as fast as the global bound (0.5 px in the longest step) gets stride 1;
        // one 4x slower gets at most 4, and 0 px/s renders only at the key frame.
        let global = 0.5 / w[0].1;
        assert_eq!(stride_for(&w, global as f32, 0.5), 1);
        let s = stride_for(&w, (global / 4.0) as f32, 0.5);
        assert!((2..=4).contains(&s), "{s}");
        assert!((global / 4.0) * w.iter().find(|x| x.0 == s).unwrap().1 <= 0.5);
        assert_eq!(stride_for(&w, 0.0, 0.5), 16);
        // Uneven step counts: the last window is cut at the key frame.
        let w = stride_windows(&times[..7]);
        assert_eq!(w.iter().map(|x| x.0).collect::<Vec<_>>(), vec![1, 2, 4, 8]);
        assert!((w[3].1 - times[6]).abs() < 1e-12);
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
