//! Matching predicted segments (labels) to ground-truth objects, and per-object IoU.
//!
//! Matching is **Hungarian** (optimal one-to-one assignment maximising the summed IoU over all
//! pairs, [`evseg_geometry::assignment::assign_max`]); a pair with IoU 0 is not a match. Each
//! ground-truth object's IoU is then the IoU of its events with the events of the matched label
//! (0 when unmatched). Events labelled [`Tracks::UNCONFIRMED`] (moving, but their track is not
//! confirmed) are moving for the IoU per event and per mask, but name no object, so they are
//! never matched.

use std::collections::BTreeMap;

use evseg_geometry::assignment::assign_max;
use evseg_schemas::Tracks;
use serde::Serialize;

/// One ground-truth object of a slice and the predicted label matched to it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ObjectMatch {
    /// Ground-truth object id.
    pub object: u16,
    /// Matched predicted label (track id), `None` when no label overlaps it in the assignment.
    pub label: Option<u32>,
    /// IoU of the object's events with the matched label's events (0 when unmatched).
    pub iou: f64,
    /// Events of the object.
    pub truth_events: u64,
    /// Events of the matched label (0 when unmatched).
    pub predicted_events: u64,
    /// Events in both.
    pub intersection: u64,
    /// Events of the object labelled background (0): what the segmentation missed.
    pub as_background: u64,
    /// Events of the object under other non-zero labels than the matched one: the object
    /// split into pieces, joined to a label matched to another object (or to none), or
    /// [`Tracks::UNCONFIRMED`].
    pub in_other_labels: u64,
}

/// Matches labels to objects over `(predicted label, ground-truth id)` pairs, one per event.
/// Label 0 and id 0 are background and never matched, nor is label [`Tracks::UNCONFIRMED`].
/// Objects come out in id order.
pub fn match_objects(pairs: impl Iterator<Item = (u32, u16)>) -> Vec<ObjectMatch> {
    let mut joint: BTreeMap<(u16, u32), u64> = BTreeMap::new();
    let mut per_object: BTreeMap<u16, u64> = BTreeMap::new();
    let mut per_label: BTreeMap<u32, u64> = BTreeMap::new();
    let mut background: BTreeMap<u16, u64> = BTreeMap::new();
    for (label, id) in pairs {
        if id != 0 {
            *per_object.entry(id).or_default() += 1;
            if label == 0 {
                *background.entry(id).or_default() += 1;
            }
        }
        if label == Tracks::UNCONFIRMED {
            continue;
        }
        if label != 0 {
            *per_label.entry(label).or_default() += 1;
        }
        if id != 0 && label != 0 {
            *joint.entry((id, label)).or_default() += 1;
        }
    }
    let objects: Vec<(u16, u64)> = per_object.into_iter().collect();
    let labels: Vec<(u32, u64)> = per_label.into_iter().collect();
    let iou = |oi: usize, li: usize| -> (f64, u64) {
        let n = joint.get(&(objects[oi].0, labels[li].0)).copied().unwrap_or(0);
        let union = objects[oi].1 + labels[li].1 - n;
        (if union == 0 { 0.0 } else { n as f64 / union as f64 }, n)
    };
    let weights: Vec<Vec<f64>> = (0..objects.len())
        .map(|oi| (0..labels.len()).map(|li| iou(oi, li).0).collect())
        .collect();
    let assignment = assign_max(&weights);
    objects
        .iter()
        .enumerate()
        .map(|(oi, &(object, truth_events))| {
            let matched = assignment[oi].filter(|&li| weights[oi][li] > 0.0);
            let as_background = background.get(&object).copied().unwrap_or(0);
            let labelled = truth_events - as_background;
            match matched {
                Some(li) => {
                    let (v, n) = iou(oi, li);
                    ObjectMatch {
                        object,
                        label: Some(labels[li].0),
                        iou: v,
                        truth_events,
                        predicted_events: labels[li].1,
                        intersection: n,
                        as_background,
                        in_other_labels: labelled - n,
                    }
                }
                None => ObjectMatch {
                    object,
                    label: None,
                    iou: 0.0,
                    truth_events,
                    predicted_events: 0,
                    intersection: 0,
                    as_background,
                    in_other_labels: labelled,
                },
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_object_iou_after_matching() {
        // Object 1: events 0..4; object 2: events 4..6; background: 6..8.
        let ids = [1u16, 1, 1, 1, 2, 2, 0, 0];
        // Label 7 covers object 1 plus one background event; label 9 covers half of object 2.
        let labels = [7u32, 7, 7, 7, 9, 0, 7, 0];
        let m = match_objects(labels.iter().copied().zip(ids.iter().copied()));
        assert_eq!(m.len(), 2);
        assert_eq!((m[0].object, m[0].label), (1, Some(7)));
        assert!((m[0].iou - 4.0 / 5.0).abs() < 1e-12);
        assert_eq!((m[1].object, m[1].label), (2, Some(9)));
        assert!((m[1].iou - 0.5).abs() < 1e-12);
        assert_eq!((m[0].as_background, m[0].in_other_labels), (0, 0));
        assert_eq!((m[1].as_background, m[1].in_other_labels), (1, 0));
        // Swapped label values give the same matching quality: label ids are arbitrary.
        let all_bg = match_objects([0u32; 8].iter().copied().zip(ids.iter().copied()));
        assert!(all_bg.iter().all(|o| o.label.is_none() && o.iou == 0.0));
    }

    #[test]
    fn one_label_covering_two_objects_matches_only_one() {
        let ids = [1u16, 1, 1, 2];
        let labels = [5u32, 5, 5, 5];
        let m = match_objects(labels.iter().copied().zip(ids.iter().copied()));
        assert_eq!(m[0].label, Some(5));
        assert!((m[0].iou - 0.75).abs() < 1e-12);
        assert_eq!(m[1].label, None);
        assert_eq!(m[1].iou, 0.0);
        // Object 2 was not missed: its event went to the label matched to object 1.
        assert_eq!((m[1].as_background, m[1].in_other_labels), (0, 1));
    }

    #[test]
    fn an_object_split_into_pieces_counts_the_pieces_outside_its_match() {
        let ids = [1u16, 1, 1, 1, 1, 0];
        let labels = [4u32, 4, 4, 6, 0, 0];
        let m = match_objects(labels.iter().copied().zip(ids.iter().copied()));
        assert_eq!(m[0].label, Some(4));
        assert_eq!(
            (m[0].intersection, m[0].in_other_labels, m[0].as_background),
            (3, 1, 1)
        );
    }

    #[test]
    fn unconfirmed_events_are_never_matched_but_count_outside_the_match() {
        let u = Tracks::UNCONFIRMED;
        // Object 1 wholly unconfirmed: unmatched, its events neither background nor matched.
        let m = match_objects([u, u, u].into_iter().zip([1u16, 1, 1]));
        assert_eq!((m[0].label, m[0].iou), (None, 0.0));
        assert_eq!((m[0].as_background, m[0].in_other_labels), (0, 3));
        // Partly unconfirmed: the unconfirmed events do not enter the matched label's union.
        let ids = [1u16, 1, 1, 1, 0];
        let labels = [3u32, 3, u, u, u];
        let m = match_objects(labels.into_iter().zip(ids));
        assert_eq!(m[0].label, Some(3));
        assert!((m[0].iou - 0.5).abs() < 1e-12);
        assert_eq!((m[0].intersection, m[0].in_other_labels), (2, 2));
    }
}
