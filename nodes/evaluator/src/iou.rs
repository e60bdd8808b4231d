//! Intersection over union of moving-object events, against per-event ids or against a mask.
//!
//! An event is *predicted moving* when its label is not 0 (any track or segment) and *truly
//! moving* when its ground-truth object id is not 0. IoU = |both| / |either|, over events.

use evseg_schemas::{Events, Mask};
use serde::Serialize;

use crate::error::EvalError;

/// Event counts behind an IoU.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct IouCounts {
    /// Events predicted moving and truly moving.
    pub intersection: u64,
    /// Events predicted moving or truly moving.
    pub union: u64,
    /// Events predicted moving.
    pub predicted: u64,
    /// Events truly moving.
    pub truth: u64,
}

impl IouCounts {
    /// Counts over pairs `(predicted moving, truly moving)`.
    pub fn from_pairs(pairs: impl Iterator<Item = (bool, bool)>) -> Self {
        let mut c = IouCounts::default();
        for (p, t) in pairs {
            c.predicted += p as u64;
            c.truth += t as u64;
            c.intersection += (p && t) as u64;
            c.union += (p || t) as u64;
        }
        c
    }

    /// |intersection| / |union|, in [0, 1]; `None` when the union is empty.
    pub fn iou(&self) -> Option<f64> {
        (self.union > 0).then(|| self.intersection as f64 / self.union as f64)
    }
}

/// IoU counts of predicted labels against per-event ground-truth object ids (same length).
pub fn event_iou(seq: u64, labels: &[u32], ids: &[u16]) -> Result<IouCounts, EvalError> {
    if labels.len() != ids.len() {
        return Err(EvalError::TruthLength {
            seq,
            ids: ids.len(),
            events: labels.len(),
        });
    }
    Ok(IouCounts::from_pairs(
        labels.iter().zip(ids).map(|(&l, &i)| (l != 0, i != 0)),
    ))
}

/// The mask whose time is nearest to `t` (seconds), if any.
pub fn nearest_mask(masks: &[Mask], t: f64) -> Option<&Mask> {
    masks
        .iter()
        .min_by(|a, b| (a.t - t).abs().total_cmp(&(b.t - t).abs()))
}

/// The events of a slice that the mask protocol evaluates and their ground-truth ids.
#[derive(Debug, Clone, PartialEq)]
pub struct MaskLookup {
    /// Time of the mask, seconds.
    pub mask_t: f64,
    /// Indices (into the slice's events) of the events within half a mask period of `mask_t`.
    pub events: Vec<usize>,
    /// Object id of the mask at each evaluated event's pixel (0 = background).
    pub ids: Vec<u16>,
}

/// Looks up the events within `period_s / 2` seconds of the mask's time at their pixel in the
/// mask (the EVIMO2 protocol: the only ground truth it has). An event outside the mask's size is
/// an error.
pub fn mask_lookup(seq: u64, events: &Events, mask: &Mask, period_s: f64) -> Result<MaskLookup, EvalError> {
    let half = period_s / 2.0;
    let (w, h) = (mask.width as usize, mask.height as usize);
    let mut out = MaskLookup {
        mask_t: mask.t,
        events: Vec::new(),
        ids: Vec::new(),
    };
    for (i, &t) in events.t.iter().enumerate() {
        if (t - mask.t).abs() > half {
            continue;
        }
        let (x, y) = (events.x[i], events.y[i]);
        let id = mask
            .ids
            .get(y as usize * w + x as usize)
            .filter(|_| (x as usize) < w && (y as usize) < h)
            .ok_or(EvalError::EventOutsideMask {
                seq,
                event: i,
                x,
                y,
                width: mask.width,
                height: mask.height,
            })?;
        out.events.push(i);
        out.ids.push(*id);
    }
    Ok(out)
}

/// IoU counts of the labels of the looked-up events against the mask ids.
pub fn mask_iou(labels: &[u32], lookup: &MaskLookup) -> IouCounts {
    IouCounts::from_pairs(
        lookup
            .events
            .iter()
            .zip(&lookup.ids)
            .map(|(&i, &id)| (labels.get(i).is_some_and(|&l| l != 0), id != 0)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ground_truth_labels_give_one_and_background_gives_zero() {
        let ids = [0u16, 3, 3, 0, 5];
        let perfect: Vec<u32> = ids.iter().map(|&i| i as u32 * 10).collect();
        let c = event_iou(0, &perfect, &ids).unwrap();
        assert_eq!(c.iou(), Some(1.0));
        assert_eq!((c.intersection, c.union), (3, 3));
        let none = event_iou(0, &[0; 5], &ids).unwrap();
        assert_eq!(none.iou(), Some(0.0));
        assert_eq!(none.truth, 3);
    }

    #[test]
    fn partial_overlap_known_value() {
        // predicted {1,2,4}, truth {1,2,3}: 2 / 4.
        let c = event_iou(0, &[0, 1, 1, 0, 7], &[0, 2, 2, 2, 0]).unwrap();
        assert_eq!(c.iou(), Some(0.5));
    }

    #[test]
    fn no_union_has_no_iou_and_length_mismatch_is_an_error() {
        assert_eq!(event_iou(0, &[0, 0], &[0, 0]).unwrap().iou(), None);
        assert_eq!(
            event_iou(9, &[0, 0, 1], &[0, 0]),
            Err(EvalError::TruthLength {
                seq: 9,
                ids: 2,
                events: 3
            })
        );
    }

    fn mask_4x3() -> Mask {
        // Object 2 covers columns 1..=2 of rows 0..=1.
        #[rustfmt::skip]
        let ids = vec![
            0, 2, 2, 0,
            0, 2, 2, 0,
            0, 0, 0, 0,
        ];
        Mask {
            t: 0.1,
            width: 4,
            height: 3,
            ids,
        }
    }

    #[test]
    fn mask_protocol_looks_up_only_events_near_the_mask_time() {
        let mut ev = Events::default();
        ev.push(0.090, 1, 0, 1); // too early (half period 1/120 s = 8.3 ms)
        ev.push(0.095, 1, 0, 1); // on object
        ev.push(0.100, 2, 1, 0); // on object
        ev.push(0.101, 3, 2, 1); // background
        ev.push(0.105, 0, 0, 1); // background
        ev.push(0.109, 2, 0, 1); // too late
        let lookup = mask_lookup(0, &ev, &mask_4x3(), 1.0 / 60.0).unwrap();
        assert_eq!(lookup.events, vec![1, 2, 3, 4]);
        assert_eq!(lookup.ids, vec![2, 2, 0, 0]);
        // Predicted: events 0 (not evaluated), 1 and 3 moving -> intersection {1}, union {1,2,3}.
        let labels = [4, 4, 0, 4, 0, 4];
        let c = mask_iou(&labels, &lookup);
        assert_eq!((c.intersection, c.union, c.predicted, c.truth), (1, 3, 2, 2));
        assert!((c.iou().unwrap() - 1.0 / 3.0).abs() < 1e-15);
        let perfect = [0, 1, 1, 0, 0, 0];
        assert_eq!(mask_iou(&perfect, &lookup).iou(), Some(1.0));
    }

    #[test]
    fn event_outside_the_mask_is_an_error() {
        let mut ev = Events::default();
        ev.push(0.1, 4, 0, 1);
        let err = mask_lookup(3, &ev, &mask_4x3(), 1.0 / 60.0).unwrap_err();
        assert!(matches!(
            err,
            EvalError::EventOutsideMask {
                seq: 3,
                event: 0,
                x: 4,
                ..
            }
        ));
    }

    #[test]
    fn nearest_mask_by_time() {
        let mut a = mask_4x3();
        let mut b = mask_4x3();
        a.t = 0.0;
        b.t = 1.0;
        let masks = [a, b];
        assert_eq!(nearest_mask(&masks, 0.6).map(|m| m.t), Some(1.0));
        assert_eq!(nearest_mask(&masks, 0.4).map(|m| m.t), Some(0.0));
        assert!(nearest_mask(&[], 0.4).is_none());
    }
}
