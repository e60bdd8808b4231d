//! The report's figures built from slice reports (data -> panels).

use std::collections::BTreeMap;

use super::plots::{PALETTE, Panel, Series, Style, chart};
use super::raster::Canvas;
use crate::slice_eval::SliceReport;

/// Figure width, pixels.
const WIDTH: usize = 960;
/// Height of one panel, pixels.
const PANEL: usize = 250;

fn mid(r: &SliceReport) -> f64 {
    0.5 * (r.t_start + r.t_end)
}

/// IoU per slice over time (both forms); skipped slices leave gaps.
pub fn iou_figure(reports: &[SliceReport]) -> Canvas {
    let ev = reports
        .iter()
        .map(|r| (mid(r), r.iou_events.scored().map_or(f64::NAN, |s| s.iou)))
        .collect();
    let mask = reports
        .iter()
        .map(|r| (mid(r), r.iou_mask.scored().map_or(f64::NAN, |s| s.iou)))
        .collect();
    let panel = Panel {
        title: "IoU per slice (windows with a moving object)".into(),
        y_label: "IoU".into(),
        series: vec![
            Series {
                name: "vs per-event ids".into(),
                color: PALETTE[0],
                points: ev,
                style: Style::LineMarkers,
            },
            Series {
                name: "vs nearest mask (paper)".into(),
                color: PALETTE[1],
                points: mask,
                style: Style::LineMarkers,
            },
        ],
        // A little headroom so that IoU 1 is not drawn on the frame.
        y_range: Some((0.0, 1.04)),
    };
    chart(&[panel], "time (s)", WIDTH, PANEL + 40)
}

/// True camera velocity and the estimate (predicted direction x true speed) per axis.
pub fn velocity_figure(reports: &[SliceReport]) -> Canvas {
    let panels: Vec<Panel> = ["x", "y", "z"]
        .iter()
        .enumerate()
        .map(|(k, axis)| {
            let truth = reports
                .iter()
                .map(|r| {
                    (
                        mid(r),
                        r.camera_truth.scored().map_or(f64::NAN, |v| v.velocity_mps[k]),
                    )
                })
                .collect();
            let est: Vec<(f64, f64)> = reports
                .iter()
                .map(|r| {
                    (
                        mid(r),
                        r.egomotion
                            .scored()
                            .map_or(f64::NAN, |e| e.scaled_velocity_mps[k]),
                    )
                })
                .collect();
            let est_name = if est.iter().any(|p| p.1.is_finite()) {
                "estimate: direction x true speed"
            } else {
                "estimate: not available (valid=false)"
            };
            Panel {
                title: format!("camera velocity V{axis} (camera frame)"),
                y_label: format!("V{axis} (m/s)"),
                series: vec![
                    Series {
                        name: "ground truth".into(),
                        color: [20, 20, 20],
                        points: truth,
                        style: Style::Line,
                    },
                    Series {
                        name: est_name.into(),
                        color: PALETTE[3],
                        points: est,
                        style: Style::LineMarkers,
                    },
                ],
                y_range: None,
            }
        })
        .collect();
    chart(&panels, "time (s)", WIDTH, PANEL)
}

/// True vs predicted translational image motion of each object (x and y panels), normalized
/// image units per second. `None` when no object has ground-truth motion.
pub fn object_motion_figure(reports: &[SliceReport]) -> Option<Canvas> {
    // object id -> (time, true flow, predicted flow)
    type Sample = (f64, [f64; 2], [f64; 2]);
    let mut per_obj: BTreeMap<u32, Vec<Sample>> = BTreeMap::new();
    for r in reports {
        for o in r.object_motion.iter().filter_map(|o| o.scored()) {
            per_obj.entry(o.object).or_default().push((
                mid(r),
                o.true_translational_flow,
                o.predicted_translational_flow,
            ));
        }
    }
    if per_obj.is_empty() {
        return None;
    }
    let panels = ["X", "Y"]
        .iter()
        .enumerate()
        .map(|(k, axis)| {
            let mut series = Vec::new();
            for (i, (id, samples)) in per_obj.iter().take(4).enumerate() {
                // First object: black truth, red track; further objects: dark and bright palette.
                let (dim, color) = if i == 0 {
                    ([20, 20, 20], PALETTE[3])
                } else {
                    let c = PALETTE[(2 * i) % PALETTE.len()];
                    (c.map(|v| v / 2), c)
                };
                series.push(Series {
                    name: format!("obj {id} truth"),
                    color: dim,
                    points: samples.iter().map(|s| (s.0, s.1[k])).collect(),
                    style: Style::Line,
                });
                series.push(Series {
                    name: format!("obj {id} track"),
                    color,
                    points: samples.iter().map(|s| (s.0, s.2[k])).collect(),
                    style: Style::Markers,
                });
            }
            Panel {
                title: format!("object translational image motion, delta {axis}"),
                y_label: format!("d{} (1/s, f = 1)", axis.to_lowercase()),
                series,
                y_range: None,
            }
        })
        .collect::<Vec<_>>();
    Some(chart(&panels, "time (s)", WIDTH, PANEL))
}
