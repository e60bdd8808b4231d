//! Matching predicted tracks to the foreground segments of a slice.
//!
//! Cost of a pair (unitless), for pairs inside both gates:
//! `d²/gate_chi2 + bbox_weight · (1 − IoU)`, with `d²` the squared Mahalanobis distance of the
//! segment centroid under the track's predicted centroid distribution and IoU that of the
//! track's predicted box and the segment's box. Pairs with `d² > gate_chi2` or a centroid
//! distance above `max_distance_px` are never matched. The assignment minimising the summed
//! cost among those with the most matches is found with the Hungarian algorithm
//! ([`evseg_geometry::assignment::assign_max`]).

use evseg_geometry::assignment::assign_max;

use crate::kalman::CvKalman;
use crate::params::TrackerParams;

/// Intersection over union of two boxes `[x_min, y_min, x_max, y_max]` in pixels, where the
/// extents are inclusive pixel coordinates (a box covers `[x_min, x_max + 1) × [y_min, y_max + 1)`,
/// so a one-pixel box has area 1). In [0, 1].
pub fn bbox_iou(a: [f64; 4], b: [f64; 4]) -> f64 {
    let area = |r: [f64; 4]| (r[2] - r[0] + 1.0).max(0.0) * (r[3] - r[1] + 1.0).max(0.0);
    let iw = (a[2].min(b[2]) + 1.0 - a[0].max(b[0])).max(0.0);
    let ih = (a[3].min(b[3]) + 1.0 - a[1].max(b[1])).max(0.0);
    let inter = iw * ih;
    let union = area(a) + area(b) - inter;
    if union > 0.0 { inter / union } else { 0.0 }
}

/// The matching cost of a track (its filter already predicted to this slice, and its box moved
/// with it, pixels) and a segment (centroid and box, pixels); `None` outside the gates.
pub fn pair_cost(
    predicted: &CvKalman,
    predicted_bbox: [f64; 4],
    centroid: [f64; 2],
    bbox: [f64; 4],
    params: &TrackerParams,
) -> Option<f64> {
    let innovation = predicted.innovation(centroid, params.measurement_std(bbox));
    if innovation.residual.norm() > params.max_distance_px {
        return None;
    }
    let d2 = innovation.mahalanobis2();
    if d2.is_nan() || d2 > params.gate_chi2 {
        return None;
    }
    Some(d2 / params.gate_chi2 + params.bbox_weight * (1.0 - bbox_iou(predicted_bbox, bbox)))
}

/// Optimal matching from a cost table (`costs[track][segment]`, `None` = outside the gate).
/// Returns the matched segment of each track. Among all gated matchings, the one with the most
/// pairs wins, then the one with the lowest summed cost.
pub fn associate(costs: &[Vec<Option<f64>>], bbox_weight: f64) -> Vec<Option<usize>> {
    // Every gated cost lies in [0, 1 + bbox_weight]; weight = (2 + bbox_weight) − cost is then
    // >= 1 for a gated pair and 0 marks a pair that must not be matched.
    let top = 2.0 + bbox_weight;
    let weights: Vec<Vec<f64>> = costs
        .iter()
        .map(|row| row.iter().map(|c| c.map_or(0.0, |c| top - c)).collect())
        .collect();
    assign_max(&weights)
        .into_iter()
        .enumerate()
        .map(|(t, s)| s.filter(|&s| costs[t][s].is_some()))
        .collect()
}

/// Matching in order of recency (the "matching cascade" of DeepSORT, Wojke et al., ICIP 2017):
/// the tracks matched most recently (`last_match_t`, seconds, one per row of `costs`) are
/// matched first, by [`associate`], to all segments; the tracks last matched before them are
/// matched next to the segments left; and so on. A track missed for a while has a grown
/// uncertainty, so its Mahalanobis cost to a segment can be lower than that of the track that
/// has followed the object all along; the cascade does not let it take the segment. Returns the
/// matched segment of each track.
pub fn associate_cascade(
    costs: &[Vec<Option<f64>>],
    last_match_t: &[f64],
    bbox_weight: f64,
) -> Vec<Option<usize>> {
    let mut matches = vec![None; costs.len()];
    let segments = costs.first().map_or(0, Vec::len);
    let mut taken = vec![false; segments];
    let mut levels: Vec<f64> = last_match_t.to_vec();
    levels.sort_by(|a, b| b.total_cmp(a));
    levels.dedup();
    for level in levels {
        let rows: Vec<usize> = (0..costs.len()).filter(|&t| last_match_t[t] == level).collect();
        let table: Vec<Vec<Option<f64>>> = rows
            .iter()
            .map(|&t| {
                costs[t]
                    .iter()
                    .zip(&taken)
                    .map(|(c, &used)| if used { None } else { *c })
                    .collect()
            })
            .collect();
        for (&t, m) in rows.iter().zip(associate(&table, bbox_weight)) {
            if let Some(s) = m {
                taken[s] = true;
                matches[t] = Some(s);
            }
        }
    }
    matches
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn iou_of_known_boxes() {
        // 10x10 boxes (inclusive 0..=9) overlapping by 5 columns: 50 / 150.
        let a = [0.0, 0.0, 9.0, 9.0];
        let b = [5.0, 0.0, 14.0, 9.0];
        assert!((bbox_iou(a, b) - 50.0 / 150.0).abs() < 1e-12);
        assert_eq!(bbox_iou(a, a), 1.0);
        assert_eq!(bbox_iou(a, [20.0, 20.0, 25.0, 25.0]), 0.0);
        // A one-pixel box inside a 2x2 box: 1 / 4.
        assert!((bbox_iou([3.0, 3.0, 3.0, 3.0], [3.0, 3.0, 4.0, 4.0]) - 0.25).abs() < 1e-12);
    }

    #[test]
    fn gates_refuse_far_pairs() {
        let params = TrackerParams::default();
        let kf = CvKalman::new([100.0, 100.0], 4.0, 1.0);
        let b = [95.0, 95.0, 105.0, 105.0];
        // Box 11 px wide: measurement std max(4, 0.1 · 11) = 4 px.
        // S = (16 + 16) I = 32 I; d = 10 px → d² = 100/32 = 3.125, IoU 1 → cost 3.125/13.82.
        let c = pair_cost(&kf, b, [110.0, 100.0], b, &params).unwrap_or(f64::NAN);
        assert!((c - 3.125 / 13.82).abs() < 1e-12, "{c}");
        // d = 30 px → d² = 28.1 > 13.82: outside the Mahalanobis gate.
        assert_eq!(pair_cost(&kf, b, [130.0, 100.0], b, &params), None);
        // A very uncertain track passes the Mahalanobis gate but not the distance gate.
        let wide = CvKalman::new([100.0, 100.0], 1000.0, 1.0);
        assert!(pair_cost(&wide, b, [190.0, 100.0], b, &params).is_some());
        assert_eq!(pair_cost(&wide, b, [210.0, 100.0], b, &params), None);
        // A 201 px wide segment box: measurement std 20.1 px in x, so d = 30 px in x is inside
        // the gate: d² = 900 / (16 + 404.01) = 2.14.
        let big = [0.0, 95.0, 200.0, 105.0];
        let c = pair_cost(&kf, big, [130.0, 100.0], big, &params).unwrap_or(f64::NAN);
        assert!((c - 900.0 / 420.01 / 13.82).abs() < 1e-9, "{c}");
    }

    #[test]
    fn cascade_gives_the_recently_matched_track_first_pick() {
        // Track 1 (missed for a while) is cheaper for segment 0 than track 0, which was matched
        // in the last slice; track 1 could also take segment 1. Plain association takes the
        // cheaper sum (1 -> 0, 0 -> 1); the cascade lets track 0 choose first.
        let costs = vec![vec![Some(0.5), Some(0.9)], vec![Some(0.1), Some(0.8)]];
        assert_eq!(associate(&costs, 1.0), vec![Some(1), Some(0)]);
        let last = [0.30, 0.15];
        assert_eq!(associate_cascade(&costs, &last, 1.0), vec![Some(0), Some(1)]);
        // A stale track still takes what the recent ones leave.
        let costs = vec![vec![Some(0.5), None], vec![Some(0.1), Some(0.8)]];
        assert_eq!(associate_cascade(&costs, &last, 1.0), vec![Some(0), Some(1)]);
        // Equal recency: the same as plain association.
        let costs = vec![vec![Some(0.5), Some(0.9)], vec![Some(0.1), Some(0.8)]];
        assert_eq!(
            associate_cascade(&costs, &[0.3, 0.3], 1.0),
            associate(&costs, 1.0)
        );
        // No tracks, no segments.
        assert!(associate_cascade(&[], &[], 1.0).is_empty());
    }

    #[test]
    fn association_is_optimal_and_respects_the_gate() {
        // Greedy would give track 0 segment 0 (cost 0.1) and leave track 1 with the gated-out
        // segment... optimal takes (0,1) and (1,0).
        let costs = vec![vec![Some(0.1), Some(0.2)], vec![Some(0.3), None]];
        assert_eq!(associate(&costs, 1.0), vec![Some(1), Some(0)]);
        // Only gated-out pairs: nothing matches.
        let costs = vec![vec![None, None], vec![None, None]];
        assert_eq!(associate(&costs, 1.0), vec![None, None]);
        // More tracks than segments.
        let costs = vec![vec![Some(0.9)], vec![Some(0.2)], vec![None]];
        assert_eq!(associate(&costs, 1.0), vec![None, Some(0), None]);
        // No segments at all.
        let costs: Vec<Vec<Option<f64>>> = vec![vec![], vec![]];
        assert_eq!(associate(&costs, 1.0), vec![None, None]);
    }
}
