//! `report.md`: the scoreboard table in the paper's form and the notes needed to read it.

use std::fmt::Write;

use crate::sequence::{SequenceSummary, VELOCITY_SCALING_NOTE};

fn pct(v: Option<f64>) -> String {
    v.map_or("n/a".into(), |v| format!("{:.2}", 100.0 * v))
}

fn num(v: Option<f64>, decimals: usize) -> String {
    v.map_or("n/a".into(), |v| format!("{v:.decimals$}"))
}

/// The scoreboard: one row per sequence with IoU % (paper's mask protocol, and per-event ids),
/// per-object IoU %, per-axis velocity RMSE (m/s, direction scaled by true speed), median
/// direction error (degrees) and the windows each figure is over.
pub fn scoreboard_table(rows: &[SequenceSummary]) -> String {
    let mut s = String::new();
    s.push_str(
        "| Sequence | IoU (%) mask | IoU (%) events | IoU (%) per object | Vx RMSE (m/s) | Vy RMSE (m/s) \
         | Vz RMSE (m/s) | Median dir. err (deg) | Windows IoU mask / events / ego |\n",
    );
    s.push_str("|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in rows {
        let rmse = r.egomotion.rmse_mps;
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} / {} / {} |",
            r.sequence,
            pct(r.iou_mask.mean),
            pct(r.iou_events.mean),
            pct(r.iou_per_object_mean),
            num(rmse.map(|v| v[0]), 3),
            num(rmse.map(|v| v[1]), 3),
            num(rmse.map(|v| v[2]), 3),
            num(r.egomotion.direction_error.median_deg, 1),
            r.iou_mask.windows,
            r.iou_events.windows,
            r.egomotion.windows,
        );
    }
    s
}

fn skips(map: &std::collections::BTreeMap<String, u64>) -> String {
    if map.is_empty() {
        return "none".into();
    }
    map.iter()
        .map(|(k, v)| format!("{k} {v}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The whole `report.md` for one sequence; `images` are the PNG file names to show.
pub fn report_markdown(s: &SequenceSummary, images: &[&str]) -> String {
    let mut m = String::new();
    let _ = writeln!(m, "# Evaluation: {}\n", s.sequence);
    m.push_str(&scoreboard_table(std::slice::from_ref(s)));
    let _ = writeln!(
        m,
        "\n{} slices evaluated, {} with a moving object in the ground truth.\n",
        s.windows, s.windows_with_moving_object
    );
    let st = &s.static_share_labelled_moving;
    if st.windows > 0 {
        let _ = writeln!(
            m,
            "**False alarms.** In the {} windows whose ground truth has no moving object, {} % of the events were labelled moving (mean over the windows).\n",
            st.windows,
            num(st.mean.map(|v| 100.0 * v), 2)
        );
    }
    let _ = writeln!(m, "**Velocity scaling.** {VELOCITY_SCALING_NOTE}\n");
    m.push_str("**IoU.** *mask*: the paper's protocol (ground-truth mask nearest to the window's middle; events within half a mask period of it, looked up at their pixel). *events*: against per-event object ids (simulator only). Both count only windows whose ground truth has a moving-object event. Per-object IoU uses Hungarian matching of labels to objects.\n\n");
    let _ = writeln!(m, "## Skipped windows\n");
    let _ = writeln!(m, "- IoU mask: {}", skips(&s.iou_mask.skipped));
    let _ = writeln!(m, "- IoU events: {}", skips(&s.iou_events.skipped));
    let _ = writeln!(m, "- egomotion: {}", skips(&s.egomotion.skipped));
    let _ = writeln!(m, "- direction error: {}", skips(&s.egomotion.direction_skipped));
    let _ = writeln!(m, "- object motion: {}\n", skips(&s.object_motion.skipped));
    let e = &s.egomotion;
    let _ = writeln!(
        m,
        "## Egomotion\n\nDirection error: median {} deg, mean {} deg over {} slices; mean true speed {} m/s.\n",
        num(e.direction_error.median_deg, 2),
        num(e.direction_error.mean_deg, 2),
        e.direction_error.count,
        num(e.mean_true_speed_mps, 3)
    );
    if !s.iou_per_object.is_empty() {
        m.push_str(
            "## Per-object IoU\n\nWhere each object's events went (shares of its events over its windows): under the label \
             matched to it, labelled background (missed), under other labels (pieces, joined to another \
             object, or moving without an id yet). Id switches count the matches above IoU `switch_min_iou` (MOTS); \
             in brackets, every match.\n\n| Object | IoU (%) | Windows | Matched | Id switches | In match (%) | Background (%) | Other labels (%) |\n\
             |---:|---:|---:|---:|---:|---:|---:|---:|\n",
        );
        for o in &s.iou_per_object {
            let _ = writeln!(
                m,
                "| {} | {:.2} | {} | {} | {} ({}) | {:.1} | {:.1} | {:.1} |",
                o.object,
                100.0 * o.mean_iou,
                o.windows,
                o.matched_windows,
                o.id_switches,
                o.id_switches_any_overlap,
                100.0 * o.share_in_match,
                100.0 * o.share_as_background,
                100.0 * o.share_in_other_labels
            );
        }
        m.push('\n');
    }
    let o = &s.object_motion;
    let _ = writeln!(
        m,
        "## Object image-plane motion\n\n{} (slice, object) samples with ground-truth motion, {} with a matched track. \
         RMSE of translational image motion (normalized units/s) x {}, y {}; of image velocity (px/s) x {}, y {}.\n",
        o.samples,
        o.with_prediction,
        num(o.rmse_translational_flow.map(|v| v[0]), 4),
        num(o.rmse_translational_flow.map(|v| v[1]), 4),
        num(o.rmse_image_velocity_px.map(|v| v[0]), 2),
        num(o.rmse_image_velocity_px.map(|v| v[1]), 2),
    );
    if !images.is_empty() {
        m.push_str("## Plots\n\n");
        for i in images {
            let _ = writeln!(m, "![{i}]({i})\n");
        }
    }
    m
}
