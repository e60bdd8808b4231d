//! Frame snapshots for the report: events of a slice rasterised by predicted label and by
//! ground-truth id, kept for a few slices evenly spread over the sequence.

use crate::slice_eval::{TruthIds, UNKNOWN_ID};
use evseg_schemas::Tracks;

/// Pixel without any event in a snapshot's label raster. Not `u32::MAX`: that is
/// [`Tracks::UNCONFIRMED`], a label events carry (moving, track not confirmed yet), which the
/// frames must show; track ids count up from 1 and never reach this value.
pub const NO_EVENT_LABEL: u32 = u32::MAX - 1;
const _: () = assert!(NO_EVENT_LABEL != Tracks::UNCONFIRMED);
/// Pixel without any event in a snapshot's truth raster.
pub const NO_EVENT_ID: u16 = u16::MAX - 1;
/// Pixel whose last event has no ground truth (outside the mask's time) in a truth raster.
pub const UNKNOWN_TRUTH: u16 = UNKNOWN_ID;

/// One slice rasterised at sensor resolution (last event at a pixel wins).
#[derive(Debug, Clone, PartialEq)]
pub struct FrameSnapshot {
    /// Slice number.
    pub seq: u64,
    /// Window start, seconds.
    pub t_start: f64,
    /// Window end, seconds.
    pub t_end: f64,
    /// Width, pixels.
    pub width: u16,
    /// Height, pixels.
    pub height: u16,
    /// Predicted label per pixel, row-major ([`NO_EVENT_LABEL`] = no event).
    pub predicted: Vec<u32>,
    /// Ground-truth id per pixel, row-major ([`NO_EVENT_ID`], [`UNKNOWN_TRUTH`]).
    pub truth: Vec<u16>,
    /// IoU of the slice (per-event form if scored, else the mask form).
    pub iou: Option<f64>,
    /// `(predicted label, ground-truth object)` pairs matched in this slice.
    pub matches: Vec<(u32, u16)>,
}

impl FrameSnapshot {
    /// Rasterises events `(x, y)` with their labels and truth ids; events outside the sensor are
    /// left out.
    pub fn new(
        seq: u64,
        window: (f64, f64),
        size: (u16, u16),
        xy: (&[u16], &[u16]),
        labels: &[u32],
        truth: &TruthIds,
        iou: Option<f64>,
    ) -> Self {
        let (w, h) = (size.0 as usize, size.1 as usize);
        let mut predicted = vec![NO_EVENT_LABEL; w * h];
        let mut tr = vec![NO_EVENT_ID; w * h];
        for i in 0..xy.0.len().min(labels.len()).min(truth.len()) {
            let (x, y) = (xy.0[i] as usize, xy.1[i] as usize);
            if x < w && y < h {
                predicted[y * w + x] = labels[i];
                tr[y * w + x] = truth[i];
            }
        }
        Self {
            seq,
            t_start: window.0,
            t_end: window.1,
            width: size.0,
            height: size.1,
            predicted,
            truth: tr,
            iou,
            matches: Vec::new(),
        }
    }
}

/// Keeps about `2 n` evenly spaced candidates out of a stream of unknown length by thinning:
/// candidate `k` is kept when `k` is a multiple of the stride; when too many are kept, every
/// other one is dropped and the stride doubles.
#[derive(Debug)]
pub struct FrameReservoir {
    cap: usize,
    stride: u64,
    seen: u64,
    kept: Vec<FrameSnapshot>,
}

impl FrameReservoir {
    /// A reservoir for `wanted` frames in the end.
    pub fn new(wanted: usize) -> Self {
        Self {
            cap: (2 * wanted).max(2),
            stride: 1,
            seen: 0,
            kept: Vec::new(),
        }
    }

    /// True when the next candidate will be kept (so the caller may skip building it).
    pub fn wants_next(&self) -> bool {
        self.seen.is_multiple_of(self.stride)
    }

    /// Offers the next candidate (`None` when the caller skipped building it because
    /// [`Self::wants_next`] was false).
    pub fn offer(&mut self, snapshot: Option<FrameSnapshot>) {
        if self.wants_next()
            && let Some(s) = snapshot
        {
            self.kept.push(s);
        }
        self.seen += 1;
        while self.kept.len() > self.cap {
            let mut i = 0;
            self.kept.retain(|_| {
                i += 1;
                i % 2 == 1
            });
            self.stride *= 2;
        }
    }

    /// Up to `n` of the kept frames, evenly spaced, in time order.
    pub fn select(&self, n: usize) -> Vec<&FrameSnapshot> {
        let k = self.kept.len();
        if n == 0 || k == 0 {
            return Vec::new();
        }
        if k <= n {
            return self.kept.iter().collect();
        }
        (0..n)
            .map(|j| &self.kept[(j * (k - 1) + (n - 1) / 2) / (n - 1).max(1)])
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn snap(seq: u64) -> FrameSnapshot {
        FrameSnapshot::new(seq, (0.0, 1.0), (2, 1), (&[1], &[0]), &[7], &vec![3], Some(0.5))
    }

    #[test]
    fn rasterises_last_event_per_pixel() {
        let s = FrameSnapshot::new(
            0,
            (0.0, 1.0),
            (3, 2),
            (&[0, 2, 2, 9], &[0, 1, 1, 0]),
            &[1, 2, 3, 4],
            &vec![0, 5, 6, 7],
            None,
        );
        assert_eq!(
            s.predicted,
            vec![
                1,
                NO_EVENT_LABEL,
                NO_EVENT_LABEL,
                NO_EVENT_LABEL,
                NO_EVENT_LABEL,
                3
            ]
        );
        assert_eq!(s.truth[5], 6);
        assert_eq!(s.truth[1], NO_EVENT_ID);
        // An unconfirmed track's label is an event, not the raster's "no event".
        let u = FrameSnapshot::new(
            0,
            (0.0, 1.0),
            (1, 1),
            (&[0], &[0]),
            &[Tracks::UNCONFIRMED],
            &vec![1],
            None,
        );
        assert_eq!(u.predicted, vec![Tracks::UNCONFIRMED]);
    }

    #[test]
    fn reservoir_spreads_over_the_whole_stream() {
        let mut r = FrameReservoir::new(4);
        for k in 0..1000 {
            let s = r.wants_next().then(|| snap(k));
            r.offer(s);
        }
        let kept: Vec<u64> = r.kept.iter().map(|s| s.seq).collect();
        assert!(kept.len() <= 8 && kept.len() >= 4, "{kept:?}");
        assert_eq!(kept[0], 0);
        // Evenly spaced with the final stride, reaching the last half of the stream.
        let d = kept[1] - kept[0];
        assert!(kept.windows(2).all(|w| w[1] - w[0] == d));
        assert!(*kept.last().unwrap() >= 500);
        let sel: Vec<u64> = r.select(4).iter().map(|s| s.seq).collect();
        assert_eq!(sel.len(), 4);
        assert_eq!(sel[0], kept[0]);
        assert_eq!(*sel.last().unwrap(), *kept.last().unwrap());
    }
}
