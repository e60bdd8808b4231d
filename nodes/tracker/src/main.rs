//! `evseg-tracker`: Kalman-filter tracks with stable ids for the merged segments of each slice
//! (paper section 3.5, last paragraph).

use std::process::ExitCode;

use evseg_runtime::describe::Describe;
use evseg_runtime::{BoxError, Inputs, NodeConfig, Outputs, Stage, run_stage};
use evseg_schemas::describe::NodeDescription;
use evseg_schemas::{Segmentation, Slice, Tracks};
use evseg_tracker::{Tracker, TrackerParams};

struct Node(Tracker);

impl Stage for Node {
    fn process(&mut self, input: &Inputs, out: &mut Outputs) -> Result<(), BoxError> {
        let slice: Slice = input.get("slices")?;
        let segmentation: Segmentation = input.get("segments")?;
        let span = input.span();
        let tracks = self
            .0
            .update_with_pixels(span, &slice.events.x, &slice.events.y, &segmentation)
            .map_err(|e| format!("slice {}: {e}", input.seq()))?;
        tracing::debug!(
            slice = input.seq(),
            published = tracks.tracks.len(),
            live = self.0.live_tracks(),
            "tracked"
        );
        out.send("tracks", input.seq(), span.0, span.1, &tracks)?;
        Ok(())
    }
}

fn description() -> NodeDescription {
    let d = TrackerParams::default();
    Describe::new(
        "evseg-tracker",
        "Kalman-filter (constant velocity, image centroid) tracker with Hungarian association: \
         stable track ids per event, 0 = background (paper section 3.5)",
    )
    .input::<Slice>(
        "slices",
        "event slices (event count; the window comes from the envelope)",
    )
    .input::<Segmentation>(
        "segments",
        "merged segmentation of the same slices: per-event labels, segments, egomotion",
    )
    .output::<Tracks>(
        "tracks",
        "per-event track id (0 = background), confirmed tracks matched in the slice, egomotion",
    )
    .param(
        "accel_std_px_s2",
        d.accel_std_px_s2,
        "process noise: white acceleration standard deviation, pixels/s^2",
    )
    .param(
        "measurement_std_px",
        d.measurement_std_px,
        "least segment centroid measurement noise standard deviation, pixels",
    )
    .param(
        "measurement_std_box_fraction",
        d.measurement_std_box_fraction,
        "centroid noise standard deviation as a fraction of the segment's box size, per axis",
    )
    .param(
        "initial_velocity_std_px_s",
        d.initial_velocity_std_px_s,
        "velocity standard deviation of a new track, pixels/s",
    )
    .param(
        "gate_chi2",
        d.gate_chi2,
        "gate on the squared Mahalanobis distance (13.82 = chi2(2) 99.9 %)",
    )
    .param(
        "max_distance_px",
        d.max_distance_px,
        "gate on the centroid distance, pixels",
    )
    .param(
        "bbox_weight",
        d.bbox_weight,
        "weight of (1 - box IoU) in the matching cost",
    )
    .param(
        "min_events",
        d.min_events,
        "least events for an unmatched segment to open a track (smaller ones become background)",
    )
    .param(
        "max_missing_s",
        d.max_missing_s,
        "a track unmatched for longer than this (seconds) is dropped; ids are never reused",
    )
    .param(
        "min_hits",
        d.min_hits,
        "matches before a track is confirmed: listed in `tracks` and its events labelled with its id (SORT's 3)",
    )
    .param(
        "tentative_events",
        d.tentative_events.name(),
        "label of the events of a track with fewer than min_hits matches: unconfirmed (moving, no id yet: Tracks::UNCONFIRMED), id (the track's id), background",
    )
    .param(
        "absorb_overlap",
        d.absorb_overlap,
        "an unmatched segment this much inside a track's predicted box (fraction of its box) takes the track's id (0 = off)",
    )
    .param(
        "merge_velocity_px_s",
        d.merge_velocity_px_s,
        "two tracks whose segments touch and whose image velocities differ by at most this (px/s) are one object (0 = off)",
    )
    .param(
        "merge_gap_px",
        d.merge_gap_px,
        "largest gap between the boxes of two tracks merged as one object, pixels",
    )
    .param(
        "min_hits_to_merge",
        d.min_hits_to_merge,
        "matches each track needs before it can be merged with another",
    )
    .param(
        "merge_velocity_max_hits",
        d.merge_velocity_max_hits,
        "the velocity merge only joins a track matched at most this many times to another (0 = no limit)",
    )
    .param(
        "merge_inside",
        d.merge_inside,
        "two tracks where one's box lies at least this fraction inside the other's are one object (0 = off)",
    )

    .param(
        "merge_inside_max_hits",
        d.merge_inside_max_hits,
        "most matches of the younger track for the containment merge (a fresh piece, not a tracked object)",
    )
    .param(
        "split_gap_px",
        d.split_gap_px,
        "a group of a track's segments whose boxes lie more than this (pixels) from the matched segment's group opens a track of its own (0 = off)",
    )
    .param(
        "split_min_events",
        d.split_min_events,
        "fewest events of a group split off a track",
    )
    .param(
        "split_min_share",
        d.split_min_share,
        "fewest events of a group split off a track, as a fraction of the events of the group that keeps it (0 = any)",
    )
    .param(
        "split_cell_px",
        d.split_cell_px,
        "group a track's segments for the split by the cells of this side (pixels) their events occupy (0 = by their boxes)",
    )
    .param(
        "split_after_slices",
        d.split_after_slices,
        "slices in a row in which a track's segments must lie apart before a group splits off",
    )
    .param(
        "matching_cascade",
        d.matching_cascade,
        "match the tracks matched most recently first (a track missed for a while cannot take another's segment)",
    )
    .param(
        "merge_keeps_most_hits",
        d.merge_keeps_most_hits,
        "of two merged tracks, the one matched in more slices keeps its id (off: the older one)",
    )
    .param(
        "merge_keeps_most_events",
        d.merge_keeps_most_events,
        "of two merged tracks both matched more than merge_inside_max_hits times, the one with more events in the slice keeps its id (else merge_keeps_most_hits decides)",
    )
    .param(
        "split_yields_to_tracks",
        d.split_yields_to_tracks,
        "a group of a track's segments apart from the rest that touches another track's segment goes to that track",
    )
    .param(
        "split_yield_min_share",
        d.split_yield_min_share,
        "fewest events of the group a track keeps when it hands another over, as a fraction of its largest group's",
    )

    .build()
}

fn main() -> ExitCode {
    run_stage(description(), |cfg: &NodeConfig| {
        let params = TrackerParams {
            accel_std_px_s2: cfg.param("accel_std_px_s2")?,
            measurement_std_px: cfg.param("measurement_std_px")?,
            measurement_std_box_fraction: cfg.param("measurement_std_box_fraction")?,
            initial_velocity_std_px_s: cfg.param("initial_velocity_std_px_s")?,
            gate_chi2: cfg.param("gate_chi2")?,
            max_distance_px: cfg.param("max_distance_px")?,
            bbox_weight: cfg.param("bbox_weight")?,
            min_events: cfg.param("min_events")?,
            max_missing_s: cfg.param("max_missing_s")?,
            min_hits: cfg.param("min_hits")?,
            tentative_events: cfg.param::<String>("tentative_events")?.parse()?,
            absorb_overlap: cfg.param("absorb_overlap")?,
            merge_velocity_px_s: cfg.param("merge_velocity_px_s")?,
            merge_gap_px: cfg.param("merge_gap_px")?,
            min_hits_to_merge: cfg.param("min_hits_to_merge")?,
            merge_velocity_max_hits: cfg.param("merge_velocity_max_hits")?,
            merge_inside: cfg.param("merge_inside")?,
            merge_inside_max_hits: cfg.param("merge_inside_max_hits")?,
            split_gap_px: cfg.param("split_gap_px")?,
            split_min_events: cfg.param("split_min_events")?,
            split_min_share: cfg.param("split_min_share")?,
            split_cell_px: cfg.param("split_cell_px")?,
            split_after_slices: cfg.param("split_after_slices")?,
            matching_cascade: cfg.param("matching_cascade")?,
            merge_keeps_most_hits: cfg.param("merge_keeps_most_hits")?,
            merge_keeps_most_events: cfg.param("merge_keeps_most_events")?,
            split_yields_to_tracks: cfg.param("split_yields_to_tracks")?,
            split_yield_min_share: cfg.param("split_yield_min_share")?,
        };
        Ok(Node(Tracker::new(params)?))
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::Message;

    #[test]
    fn description_names_the_ports_and_every_parameter() {
        let d = description();
        assert_eq!(d.input("slices").map(|p| p.schema.as_str()), Some(Slice::SCHEMA));
        assert_eq!(
            d.input("segments").map(|p| p.schema.as_str()),
            Some(Segmentation::SCHEMA)
        );
        assert_eq!(
            d.output("tracks").map(|p| p.schema.as_str()),
            Some(Tracks::SCHEMA)
        );
        let names: Vec<&str> = d.params.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "accel_std_px_s2",
                "measurement_std_px",
                "measurement_std_box_fraction",
                "initial_velocity_std_px_s",
                "gate_chi2",
                "max_distance_px",
                "bbox_weight",
                "min_events",
                "max_missing_s",
                "min_hits",
                "tentative_events",
                "absorb_overlap",
                "merge_velocity_px_s",
                "merge_gap_px",
                "min_hits_to_merge",
                "merge_velocity_max_hits",
                "merge_inside",
                "merge_inside_max_hits",
                "split_gap_px",
                "split_min_events",
                "split_min_share",
                "split_cell_px",
                "split_after_slices",
                "matching_cascade",
                "merge_keeps_most_hits",
                "merge_keeps_most_events",
                "split_yields_to_tracks",
                "split_yield_min_share",
            ]
        );
        let default_of = |n: &str| d.params.iter().find(|p| p.name == n).map(|p| p.default.clone());
        assert_eq!(default_of("gate_chi2"), Some(13.82.into()));
        assert_eq!(default_of("min_hits"), Some(3.into()));
        assert_eq!(default_of("tentative_events"), Some("unconfirmed".into()));
    }
}
