//! `evseg-baseline`: the honest floor of the scoreboard.
//!
//! It labels every event of a slice background (0), reports no tracks and no egomotion
//! (`valid: false`). It is not a segmentation method: it exists so that the evaluator and the
//! scoreboard have a reference row (IoU 0 on every window with a moving object, egomotion "not
//! available") until the paper's method runs end to end.

use std::process::ExitCode;

use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, Outputs, Stage, run_stage};
use evseg_schemas::describe::NodeDescription;
use evseg_schemas::{Egomotion, Slice, Tracks};

/// One line on what the node is, shown by `--describe` and the launcher.
const SUMMARY: &str = "Labels everything background; a floor for the scoreboard, not a method \
                       (no tracks, egomotion valid=false)";

/// The baseline's output for `slice`: one background label (0) per event, no tracks, and an
/// egomotion marked invalid (direction zero; `omega` is the slice's IMU rate in rad/s, camera
/// frame, or zero without IMU, and is only informative since `valid` is false).
fn baseline_tracks(slice: &Slice) -> Tracks {
    Tracks {
        label: vec![0; slice.events.len()],
        tracks: Vec::new(),
        egomotion: Egomotion {
            direction: [0.0; 3],
            omega: slice.omega.unwrap_or([0.0; 3]),
            valid: false,
        },
    }
}

/// The node's self-description (`--describe`).
fn description() -> NodeDescription {
    Describe::new("evseg-baseline", SUMMARY)
        .input::<Slice>("slices", "slices of events")
        .output::<Tracks>(
            "tracks",
            "every event labelled background (0), no tracks, egomotion valid=false",
        )
        .build()
}

struct BaselineNode;

impl Stage for BaselineNode {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        if !slice.events.is_consistent() {
            return Err(format!("slice {}: event columns have different lengths", input.seq()).into());
        }
        let (t0, t1) = input.span();
        out.send("tracks", input.seq(), t0, t1, &baseline_tracks(&slice))?;
        Ok(())
    }
}

fn main() -> ExitCode {
    run_stage(description(), |_cfg| Ok(BaselineNode))
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::{CameraInfo, Distortion, Events, Message};

    fn slice(n: usize) -> Slice {
        let mut events = Events::default();
        for i in 0..n {
            events.push(i as f64 * 1e-3, i as u16, 2, 1);
        }
        Slice {
            camera: CameraInfo {
                width: 10,
                height: 10,
                fx: 5.0,
                fy: 5.0,
                cx: 5.0,
                cy: 5.0,
                distortion: Distortion::None,
                imu_to_camera: CameraInfo::IDENTITY,
                imu_time_offset_s: 0.0,
                time_origin_us: 0,
                sensor: "test".into(),
            },
            events,
            imu: vec![],
            omega: Some([0.1, 0.2, 0.3]),
        }
    }

    #[test]
    fn labels_every_event_background_without_egomotion() {
        let t = baseline_tracks(&slice(7));
        assert_eq!(t.label, vec![0; 7]);
        assert!(t.tracks.is_empty());
        assert!(!t.egomotion.valid);
        assert_eq!(t.egomotion.omega, [0.1, 0.2, 0.3]);
        assert!(baseline_tracks(&slice(0)).label.is_empty());
    }

    #[test]
    fn description_round_trips_through_json_and_says_what_it_is() {
        let d = description();
        let json = serde_json::to_string_pretty(&d).unwrap();
        let back: NodeDescription = serde_json::from_str(&json).unwrap();
        assert_eq!(back, d);
        assert_eq!(back.binary, "evseg-baseline");
        assert!(back.summary.contains("not a method"));
        assert_eq!(
            back.input("slices").map(|p| p.schema.as_str()),
            Some(Slice::SCHEMA)
        );
        assert_eq!(
            back.output("tracks").map(|p| p.schema.as_str()),
            Some(Tracks::SCHEMA)
        );
    }
}
