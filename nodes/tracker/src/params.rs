//! Tracker parameters. The paper gives none of these values (section 3.5 only says "a Kalman
//! Filter-based tracker"); each default says where it came from.

use crate::error::TrackerError;

/// Largest length parameter of the tracker, pixels (ten times a 1 kpx sensor's width).
const MAX_PIXELS: f64 = 1e4;
/// Largest velocity standard deviation, px/s.
const MAX_SPEED_PX_S: f64 = 1e6;
/// Largest acceleration standard deviation, px/s^2.
const MAX_ACCEL_PX_S2: f64 = 1e8;
/// Largest `split_gap_px / split_cell_px`: the split grouping visits (2 r + 3)^2 cells around
/// each occupied cell.
const MAX_SPLIT_REACH_CELLS: f64 = 32.0;

/// How a tracker labels the events of a tentative track (one not yet matched `min_hits` times).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TentativeEvents {
    /// [`evseg_schemas::Tracks::UNCONFIRMED`]: moving, no identity claimed yet (the default).
    Unconfirmed,
    /// The track's id from its first slice (the id does not change on confirmation), so a
    /// piece that opens a track for a slice or two shows, and is scored, as an object of its
    /// own.
    Id,
    /// Background until the track is confirmed: the usual suppression of short-lived
    /// detections, at the cost of the objects' first slices. Measured on `evseg bench`
    /// (evseg-bench-v3, 2026-11-28; IoU mask / events / per object %, worst object's id
    /// switches over any overlap, false alarms in static windows % for enter-leave 104,
    /// camera-only 105, enter-leave 204, camera-only 205): `id` with min_hits 1 72.56 / 81.95 /
    /// 76.98, 4.3, 7.3 / 6.3 / 13.5 / 9.2; background, min_hits 2 72.01 / 80.99 / 75.81, 2.6,
    /// 2.0 / 2.2 / 2.4 / 7.5; background, min_hits 3 70.99 / 79.68 / 74.54, 1.8, 0.8-6.3. For
    /// a robot that must not react to phantoms.
    Background,
}

impl TentativeEvents {
    /// Every value.
    const ALL: [Self; 3] = [Self::Unconfirmed, Self::Id, Self::Background];

    /// The parameter's values, as written in a graph.
    pub const NAMES: [&'static str; 3] = [Self::ALL[0].name(), Self::ALL[1].name(), Self::ALL[2].name()];

    /// The value's name, as written in a graph.
    pub const fn name(self) -> &'static str {
        match self {
            Self::Unconfirmed => "unconfirmed",
            Self::Id => "id",
            Self::Background => "background",
        }
    }
}

impl std::str::FromStr for TentativeEvents {
    type Err = TrackerError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| TrackerError::InvalidChoice {
                name: "tentative_events",
                value: s.to_string(),
                expected: &Self::NAMES,
            })
    }
}

/// Parameters of [`crate::Tracker`].
#[derive(Debug, Clone, PartialEq)]
pub struct TrackerParams {
    /// Standard deviation of the (piecewise constant, white) image-plane acceleration of an
    /// object, pixels/s², the process noise of the constant-velocity model. Default 1000 px/s²:
    /// hand-moved EVIMO2 objects reach a few hundred px/s and change speed within ~0.3 s; this
    /// moves the predicted position by at most ~0.5 px (1σ) over one 30 ms slice.
    pub accel_std_px_s2: f64,
    /// Least standard deviation of a segment centroid as a measurement of the object's
    /// position, pixels. Default 4 px: a segment's centroid moves by a few pixels between slices
    /// when its cluster boundaries change (over-segmentation cells are tens of pixels wide).
    pub measurement_std_px: f64,
    /// Standard deviation of a segment centroid as a fraction of the segment's box size, per
    /// axis; the measurement noise is `max(measurement_std_px, fraction · box extent)`. The
    /// centroid of a large object moves with the part of it that is visible or produces events
    /// (occlusion, edges parallel to the motion): hiding a quarter of a uniform box on one side
    /// moves its centroid by 1/8 of its width. Default 0.1 (that shift is then 1.25σ); found
    /// necessary on the simulator's `two-objects` preset, where one object occluding the other
    /// moved its centroid by 19 px (5σ with a fixed 4 px) in one slice.
    pub measurement_std_box_fraction: f64,
    /// Standard deviation of the velocity of a new track (its velocity starts at 0), px/s.
    /// Default 300 px/s: the typical image speed of EVIMO2 objects; with the 30 ms slices this
    /// lets the second measurement of a track lie ~30 px (3σ) from the first.
    pub initial_velocity_std_px_s: f64,
    /// Gate on the squared Mahalanobis distance between a track's predicted centroid and a
    /// segment centroid: pairs above it are never matched. Default 13.82, the 99.9 % quantile of
    /// χ² with 2 degrees of freedom (a correct match falls outside once in 1000 slices).
    pub gate_chi2: f64,
    /// Second gate, on the Euclidean distance between predicted and measured centroid, pixels:
    /// bounds the Mahalanobis gate of a track whose uncertainty grew while it was missing.
    /// Default 100 px: about 1/6 of the EVIMO2 image width (640 px); more than 3 slices of
    /// motion at 1000 px/s.
    pub max_distance_px: f64,
    /// Weight of the bounding-box term of the matching cost. Cost of a gated pair =
    /// `d²/gate_chi2 + bbox_weight · (1 − IoU)`, where IoU is that of the track's last box moved
    /// by the predicted displacement and the segment's box. Default 1: both terms count equally.
    pub bbox_weight: f64,
    /// Least number of events for an unmatched segment to open a new track; an unmatched
    /// smaller segment is labelled background (0). Default 30: below this a segment's centroid
    /// and box are not reliable (the over-segmenter's 30 clusters of a 30 ms slice hold several
    /// hundred events each).
    pub min_events: u32,
    /// A track not matched for longer than this, seconds (slice centre time since its last
    /// match), is dropped; its id is never reused. Default 0.5 s: an object that stops moving
    /// produces no events and vanishes from the segmentation; half a second (~17 slices of
    /// 30 ms) bridges short stops and occlusions without keeping stale tracks for long.
    pub max_missing_s: f64,
    /// Matches (slices) a track needs before it is confirmed and listed in `Tracks::tracks`;
    /// a tentative track missed in a slice is dropped at once, and its events are labelled as
    /// `tentative_events` says. Default 3, as SORT (Bewley et al., ICIP 2016): a piece of an
    /// object, or of the static scene, that the segmentation calls moving for a slice or two
    /// gets no identity. Measured on 2026-12-06 with the tentative events `unconfirmed` (mean
    /// of the worst object's id switches counted as MOTS, over any overlap in brackets, the
    /// largest; mean per-object IoU %): `evseg bench` (evseg-bench-v3) min_hits 1 0.8 (2.8),
    /// 4, 79.12; 2 0.4 (1.8), 1, 78.16; 3 0.2 (1.4), 1, 77.28. Seeds 301-307 and 401-407 (3 s):
    /// 1 0.58 (1.33), 5, 79.68; 2 0.58 (1.17), 5, 78.40; 3 0.33 (1.08), 2, 77.05. Seeds
    /// 501-507 and 601-607: 1 1.67 (3.50), 14, 77.93; 3 1.58 (2.33), 13, 75.77. The IoU mask
    /// and per event do not change (the tentative events stay moving); the per-object IoU loses
    /// each object's first two slices. Measured and not kept (2026-12-07, session 50): letting a
    /// tentative track survive one missed slice instead of ending it at its first miss (an
    /// object the segmentation finds in two slices of three never reaches three matches in a
    /// row): `evseg bench` (evseg-bench-v3) mean per-object IoU 79.23 -> 79.25 %, worst-object
    /// switches 0.2 (0.5) -> 0.2 (0.3), IoU mask and events unchanged; on multi-object
    /// sequences the bench has not seen (`evseg run graph.yaml`, three-objects and two-objects
    /// seeds 801-806, 3 s) per-object IoU 44.52 -> 44.58 % and 52.09 -> 51.87 %. The second and
    /// third objects' losses there are elsewhere (two-objects 801 and 803, three-objects 803):
    /// 35-41 % of their events labelled background and 28-45 % under other labels.
    pub min_hits: u32,
    /// How the events of a tentative track (fewer than `min_hits` matches) are labelled.
    /// Default [`TentativeEvents::Unconfirmed`]: they are moving (the paper scores every event's
    /// segmentation) but name no object until the track is confirmed.
    pub tentative_events: TentativeEvents,
    /// A segment left unmatched by the one-to-one association whose box lies at least this
    /// fraction (intersection over the segment box's area) inside a live track's predicted box
    /// is a fragment of that object and takes its id instead of opening a new track (the
    /// track's filter is corrected with it only when nothing else matched the track). 0 = off.
    /// The hierarchical merger does not always join an object's clusters, and each piece
    /// opening a track of its own was most of the id switches the evaluator counted on the
    /// simulator. Default 0.1 (was 0.3; a fragment need not lie mostly inside: the box is
    /// predicted from pieces that change from slice to slice). With the segmentation of
    /// 02cf208 (more of each object found, in more pieces), `evseg bench` (evseg-bench-v1; mean
    /// per-object IoU %, mean of the worst object's id switches): 0.3 47.43 / 32.3, 0.1 53.40 /
    /// 22.3, 0.05 53.37 / 23.3, 0 (off) 36.57 / 60.8; 0.1 raised every scene's per-object IoU
    /// (two-objects, whose objects cross, 39.5 -> 43.0 %). Earlier, chosen together with
    /// `merge_velocity_px_s` (fdbc78d): 0.5 and 30 px/s 29.15 / 59.3; 0.3 and 30 30.83 / 51.8;
    /// 0.2 and 30 31.01 / 49.8; 0.5 and 60 29.30 / 50.7; 0.3 and 60 31.89 / 36.8. Again on
    /// 2026-12-07 (session 50, 00116b7's defaults), 0.1 -> 0.3: on twelve multi-object
    /// sequences the bench has not seen (`evseg run graph.yaml`, three-objects and two-objects
    /// seeds 801-806, 3 s) mean per-object IoU 44.52 -> 46.34 % and 52.09 -> 52.15 %, the worst
    /// objects' switches summed 27 -> 25 and 18 -> 17 (a second object next to a first one's
    /// grown box is taken by it less often); but `evseg bench` (evseg-bench-v3) per object 79.23
    /// -> 77.66 %, worst-object switches 0.2 (0.5) -> 0.8 (1.8) (enter-leave 204 0 -> 6,
    /// two-objects 202 57.12 -> 50.52 %, low-contrast 206 73.18 -> 67.97 %: objects seen in
    /// pieces open tracks of their own again). Kept at 0.1. Also measured then, with a
    /// throw-away patch: 0.3 only for a segment with at least half the events of the segment
    /// that matched the track in that slice (a second object rather than a piece), 0.1 for
    /// smaller ones: unseen 46.32 % and 52.24 %, switches 26 and 16; bench 78.57 %, 0.2 (0.8)
    /// (low-contrast 206 67.75 %, one-object 101 85.91 -> 85.25 %). Neither is a clear gain.
    pub absorb_overlap: f64,
    /// Two tracks matched in the same slice, each matched at least `min_hits_to_merge` times,
    /// whose segments' boxes lie within `merge_gap_px` of each other and whose filtered image
    /// velocities differ by at most this (px/s), are one object seen in pieces: the younger
    /// track's segments take the older one's id, the older track's box grows to cover both, and
    /// the younger track ends. 0 = off. Default 120 px/s (was 60; 4 px per 30 ms slice; the
    /// objects of EVIMO2 and of the simulator move at hundreds of px/s relative to the
    /// background, and a fragment's filtered velocity is noisy because its centroid jumps with
    /// the pieces). With the segmentation of ad9c0c4, `evseg bench` (mean per-object IoU %,
    /// worst object's id switches) 30 / 60 / 120 / 200 / 400 px/s: 49.92 / 32.3, 53.40 / 22.3,
    /// 55.89 / 16.3, 57.21 / 13.8, 58.95 / 10.0; two-objects (crossing objects) 43.0 / 43.2 /
    /// 40.2 / 41.5 % at 60 / 120 / 200 / 400. Above 120 the test stops looking at velocity at
    /// all (it merges any two touching tracks), which only suits scenes of one object per
    /// neighbourhood, so the default stays at the smallest step that helped every scene. The
    /// risk is merging two objects that cross: on `graph.yaml`'s 1 s of two-objects, with
    /// `absorb_overlap` 0.3, per-object IoU 25.4 -> 24.2 % against 30 px/s (and, with the
    /// segmentation of 906957c, 29.6 -> 21.0 %); on `evseg bench` (see `absorb_overlap`) 0.3 and
    /// 60 px/s cut the worst object's id switches from 59.3 to 36.8 and raised per-object IoU
    /// from 29.15 to 31.89 %. Earlier (906957c's segmentation) 0 / 30 / 60 px/s gave 26.27 /
    /// 26.20 / 26.09 % and 48.7 / 39.5 / 35.8 switches.
    pub merge_velocity_px_s: f64,
    /// See `merge_velocity_px_s`: largest gap between the two boxes, pixels (default 4: touching
    /// or overlapping, as the hierarchical merger's `touch_px`).
    pub merge_gap_px: f64,
    /// See `merge_velocity_px_s`: the younger of the two tracks (fewer matches) must have been
    /// matched at most this many times (0 = no limit, the default), as `merge_inside_max_hits`
    /// for the containment rule. Two-objects 102's objects, tracked apart for 14 slices, were
    /// joined when the first one's (inflated) box came within 4 px of the second's while
    /// their velocities differed by 94 px/s. `evseg bench` (evseg-bench-v3, 49a6161's
    /// defaults; mean per-object IoU %, mean of the worst object's id switches): 0 79.32 /
    /// 2.1, 20 the same to the digit, 10 79.18 / 2.3 (102 61.79 -> 65.89 %, 6 -> 4 switches;
    /// low-contrast 206 69.37 -> 63.53 %, 8 -> 13: a faint object's pieces tracked apart
    /// for a while are its pieces all the same). Opt-in.
    pub merge_velocity_max_hits: u32,
    /// See `merge_velocity_px_s`: matches each track needs before its velocity is trusted
    /// (default 3: the filter has seen two displacements).
    pub min_hits_to_merge: u32,
    /// Two tracks matched in the same slice where the box of one's segments lies at least this
    /// fraction (intersection over its own area) inside the other's are one object seen in
    /// pieces, whatever their velocities and match counts: merged as under
    /// `merge_velocity_px_s` (the older id stays). 0 = off. A fragment's filtered velocity
    /// swings by hundreds of px/s as the pieces change, so the velocity rule kept an object's
    /// pieces apart, and the evaluator's best-matching label flipped between them slice after
    /// slice ("back" switches: 13 of one-object's 16 at f1cfeab). Default 0.5 (half inside:
    /// more than touching, which `merge_gap_px` covers). `evseg bench` (evseg-bench-v1, at
    /// 9a351d8's segmentation; mean per-object IoU %, mean of the worst object's id switches):
    /// off 55.89 / 16.3; 0.5 61.02 / 4.3 with the velocity rule's match count (3) applied to it
    /// too, 61.01 / 2.5 without; 0.3 61.02 / 4.0; 0.8 61.05 / 5.2 (with the match count); a
    /// velocity cap of 300 px/s on it 59.20 / 9.7; required in 3 / 6 slices in a row 60.14 /
    /// 6.7, 58.71 / 13.3 (and that did not keep crossing objects apart, see
    /// `merge_inside_max_hits`, which does); only when the two tracks' segment translations
    /// (hierarchical merger) point within 20 / 30 deg: 57.53 / 13.5, 58.72 / 12.7 (the pieces
    /// the hierarchical merger left apart disagree in translation too); only when the younger
    /// track has at most half the older one's matches: 57.46 / 12.0. The cost is on scenes
    /// whose objects are close: the younger object's pieces join the older one's track while
    /// both are young (two-objects 43.15 -> 39.35 %; `graph.yaml`'s 1 s of it 40.47 -> 31.35 %,
    /// its second object matched in 4 of 34 windows, no id switch on either).
    pub merge_inside: f64,
    /// See `merge_inside`: the younger of the two tracks must have been matched at most this
    /// many times (default 10, 0.3 s of 30 ms slices): a piece of an object opens a track of its
    /// own when the segmentation splits the object, so it is young when it lies inside the
    /// object's box; two objects that were tracked apart for longer and then overlap (cross)
    /// stay apart. `nodes/tracker/tests/sim_oracle.rs` (ground-truth segmentation of
    /// two-objects, whose objects cross) keeps one id per object at 10 and merges them at 20 and
    /// 30; `evseg bench` per-object IoU % / worst object's switches: 10 60.76 / 3.3, 30
    /// 61.03 / 2.7, unbounded 61.01 / 2.5. An object that overlaps another within 0.3 s of
    /// being first tracked is still merged into it. Measured and not kept (2026-12-07, session
    /// 50), 10 -> 4, so that a second object seen inside a young first track's box is merged
    /// only in its first slices: on twelve multi-object sequences the bench has not seen
    /// (three-objects and two-objects seeds 801-806, 3 s) mean per-object IoU 44.52 -> 44.65 %
    /// and 52.09 -> 53.65 %, but the worst objects' switches summed 27 -> 27 and 18 -> 29;
    /// `evseg bench` per object 79.23 -> 77.67 %, switches 0.2 (0.5) -> 1.5 (2.7) (low-contrast
    /// 206 73.18 -> 65.58 %: its pieces stay apart).
    pub merge_inside_max_hits: u32,
    /// A track's segments in one slice are grouped by their boxes (boxes at most this far
    /// apart, pixels, transitively, are one group); the group with the most events keeps the
    /// track (and corrects its filter), every other group with at least `split_min_events`
    /// events leaves it and opens a track of its own. 0 = off. Absorption (`absorb_overlap`)
    /// and the merges grow a track's box over all its pieces, and the grown box then absorbs
    /// whatever lies in it: once two objects had been joined (close or overlapping while both
    /// tracks were young) they stayed one track for the rest of the sequence, however far
    /// apart they moved (two-objects seed 202: its second object matched in 5 of 100 windows).
    /// Default 16 px (not in the paper): four times `merge_gap_px`, a clear gap rather than
    /// the seams between an object's pieces. `evseg bench` (evseg-bench-v2, at a2a91a9's
    /// segmentation; per-object IoU %, mean of the worst object's id switches): off 68.01 /
    /// 2.8, 16 px 70.02 / 4.2, 32 px 69.45 / 4.0, 16 px with `split_min_events` 300 69.88 /
    /// 3.8; two-objects 202 35.83 -> 58.06 % (its second object's own id once the two part).
    /// The cost is an object whose pieces lie apart (more switches on one-object and
    /// low-contrast). At first the group of the segment that had corrected the filter kept the
    /// track; when a piece split off was the larger one, the evaluator's best label switched
    /// to it and back ("1 -> 37 -> 1"). The larger group keeping it (the filter re-corrected
    /// from its prediction): at 74f59cd's segmentation, worst-object switches 5.0 -> 4.1
    /// (low-contrast 106 / 206: 16 -> 10, 17 -> 13), per-object 71.05 -> 70.77 %.
    pub split_gap_px: f64,
    /// See `split_gap_px`: group a track's segments by the cells of this side (pixels) that
    /// their events occupy, two segments being neighbours when occupied cells of the two lie
    /// at most `split_gap_px` apart (0 = by their boxes). Needs the slice's event pixels
    /// ([`crate::Tracker::update_with_pixels`], which the node uses); without them the boxes
    /// are used. Not in the paper. A box spans every event of its segment, so a few stray
    /// events stretched an object's pieces' boxes over the gap to another object: in
    /// two-objects 202 the second object's pieces lay 30-60 px from the first object's
    /// events but within 16 px of its boxes, and stayed in its track for 50 slices. Opt-in
    /// (default 0), since it splits crossing objects and objects seen in pieces sooner too.
    /// `evseg bench` (evseg-bench-v3, 49a6161's defaults; mean per-object IoU %, mean of the
    /// worst object's id switches): 0 79.32 / 2.1, 4 px 79.45 / 2.1, 8 px 79.68 / 2.1
    /// (two-objects 202 56.81 -> 63.40 %, its second object's own id from slice 32 instead of
    /// 51; 102 61.79 -> 58.94 %), 8 px with `split_gap_px` 24 / 32 79.26 / 2.1, 79.18 / 2.3.
    /// On sequences the bench has not seen (`evseg run graph.yaml`, seeds 11-13, 2 s,
    /// two-objects / one-object / low-contrast / enter-leave) 0 -> 8 px: 82.03 -> 82.33 %,
    /// worst-object switches 1.00 -> 1.42 (two-objects 13, whose objects cross, 1 -> 6).
    /// Also measured, not kept: the hierarchical merger publishing boxes without 2 / 5 % of a
    /// segment's events at each side (boxes by every grouping, absorption and merge rule
    /// here): 79.24 / 3.0 and 78.17 / 4.8. Again on 2026-12-07 (session 50, the defaults of
    /// 00116b7), 0 -> 8 px on twelve multi-object sequences the bench has not seen (`evseg run
    /// graph.yaml`, three-objects and two-objects seeds 801-806, 3 s): mean per-object IoU
    /// 44.52 -> 45.34 % and 52.09 -> 51.97 %, the worst objects' switches summed 27 -> 28 and
    /// 18 -> 18; still too small a gain to change the default.
    pub split_cell_px: u16,
    /// See `split_gap_px`: fewest events of a group split off a track as a fraction of the
    /// events of the group that keeps it. 0 = no such condition (default). A small object seen
    /// in pieces loses a piece to a track of its own, and that piece is at times the larger
    /// one. `evseg bench` (evseg-bench-v3, 2752ba6's defaults; mean of the worst object's id
    /// switches, mean per-object IoU %): 0 2.8 / 79.26, 0.25 2.8 / 78.90, 0.5 2.3 / 78.93
    /// (low-contrast 206 12 -> 8 switches, two-objects 202 5 -> 3 but its per-object IoU 66.97
    /// -> 57.90 %: its second object stays joined to the first for longer). A trade left to
    /// the user, as `label_tentative`.
    pub split_min_share: f64,
    /// See `split_gap_px`: slices in a row in which a track's segments must form groups lying
    /// apart (large enough to split off) before they split; 0 or 1 = at once. Default 3 (not in
    /// the paper): a small or faint object seen in pieces lost a piece to a track of its own
    /// for a slice or two, and that piece was at times its best match (low-contrast 206: 12
    /// switches). `evseg bench` (evseg-bench-v3, 74d9ea5's defaults with 1; mean per-object IoU
    /// %, mean of the worst object's id switches): 1 79.26 / 2.8, 2 79.51 / 2.8, 3 79.32 / 2.1,
    /// 4 79.38 / 2.1, 6 79.44 / 2.1 (at 3: low-contrast 106 5 -> 3, 206 12 -> 8, two-objects
    /// 202 5 -> 2 but its per-object IoU 66.97 -> 56.81 %: its two objects, joined while young,
    /// part for fewer slices in a row than that). On sequences the bench has not seen (`evseg
    /// run graph.yaml`, seeds 11-13, 2 s, two-objects / one-object / low-contrast /
    /// enter-leave) 1 -> 3: per-object IoU 81.80 -> 82.03 %, worst-object switches 1.83 -> 1.00
    /// (two-objects 13 10 -> 1, low-contrast 11 2 -> 0, two-objects 11 2 -> 3; two-objects'
    /// per-object IoU 57.2 -> 56.4 % on the mean of its three seeds).
    pub split_after_slices: u32,
    /// Match the tracks in order of recency (`crate::association::associate_cascade`): those
    /// matched in the previous slice choose their segments first, then those missed for one
    /// slice, and so on. Without it a track missed for several slices, whose predicted position
    /// has grown uncertain, can take an object's segment from the track that has followed the
    /// object (its Mahalanobis cost is lower), and the object's id changes. Default true (not
    /// in the paper; DeepSORT's matching cascade, Wojke et al., ICIP 2017). Found in
    /// high-contrast 207, where a track opened in the first slice on a piece of the static
    /// scene, missed for seven slices, took the object's segment from the object's own track.
    /// `evseg bench` (evseg-bench-v3, 1833d43's segmentation; mean of the worst object's id
    /// switches, mean per-object IoU %): neither 3.1 / 79.23, the cascade alone 2.9 / 79.26,
    /// `merge_keeps_most_hits` alone 3.2 / 79.23, both 2.8 / 79.26 (high-contrast 207 3 -> 1,
    /// two-objects 102 7 -> 6); IoU mask and events unchanged to the digit.
    pub matching_cascade: bool,
    /// When two tracks merge (`merge_inside`, `merge_velocity_px_s`), the one matched in more
    /// slices keeps its id (true) or the older one, the smaller id (false); on a tie the older
    /// one. Default true: a track opened on a stray segment earlier than the object's own track
    /// (the first slices of a sequence, before the egomotion has settled, segment pieces of the
    /// static scene) would otherwise take over the object's id when the two meet. Measured
    /// with `matching_cascade` (above). `merge_keeps_most_events` is asked first where both
    /// tracks are established.
    pub merge_keeps_most_hits: bool,
    /// When two tracks merge (`merge_inside`, `merge_velocity_px_s`) and both have been matched
    /// more than `merge_inside_max_hits` times, the one whose segments hold more events in this
    /// slice keeps its id; otherwise (and on a tie) `merge_keeps_most_hits` decides. Default
    /// true (not in the paper). An object seen in two pieces for a while is followed by two
    /// tracks, and the evaluator (MOTS counting: an identity needs an IoU above 0.5) takes the
    /// track of the piece that holds most of the object as its identity; when the pieces
    /// joined again, the track of the smaller piece, matched more often, kept the id and the
    /// identity changed back (low-contrast 206: track 1 followed a 500-event leading piece for
    /// 0.6 s while track 18 held the 4000-event bulk). A young track is not trusted with it:
    /// without the match count (any two tracks) one slice's events decided merges of fresh
    /// fragments too, and `evseg bench` (evseg-bench-v3, 8215a50's defaults; mean of the worst
    /// object's id switches, mean per-object IoU %) went 0.2 / 79.21 -> 0.6 / 78.68
    /// (low-contrast 206 2 -> 4, fast-rotation 103 and low-contrast 106 0 -> 1). With it:
    /// 0.2 / 79.23, 206 2 -> 1, every other sequence the same to the digit. Not fitted to the
    /// bench: on 24 sequences it has not seen (`evseg run graph.yaml`, seeds 301-307,
    /// 401-407, 501-507, 601-607 but camera-only, 3 s, enter-leave 5 s) every figure is the
    /// same; on 20 of two and three objects (seeds 701-710, 3 s) the mean worst-object
    /// switches 2.35 -> 2.30 (three-objects 705 3 -> 2) and per-object IoU 50.48 -> 50.59 %.
    pub merge_keeps_most_events: bool,
    /// See `split_gap_px`: fewest events of a group split off a track (default 100: a few
    /// over-segmentation clusters' worth, well above `min_events`, so that stray fragments
    /// stay with the track).
    pub split_min_events: u32,
    /// See `split_gap_px`: when a track's segments form groups lying apart and a group's boxes
    /// touch or overlap a segment of another track that is confirmed (`min_hits`), opened before
    /// this slice and matched in at least as many slices (an object followed for longer claims its
    /// neighbourhood), that group is a piece of the other track's object and is handed to it, and
    /// the track keeps the largest of the other groups, if one has at least `split_min_events`
    /// events (else nothing is handed over and the largest group keeps the track). Not in the
    /// paper. Found in two-objects 102: where two objects crossed, one segment joined them for a
    /// slice and the second object's track took it; in the next slices that track's larger group
    /// was the first object, beside the first object's own track, so the second track followed the
    /// first object and the second object got a new id (six switches). `evseg bench`
    /// (evseg-bench-v3, b27e6a5's segmentation): 102 6 -> 0 switches, per-object IoU 50.16 -> 53.71
    /// %, nothing else moved by more than 0.01 point (mean per-object 78.92 -> 79.21 %,
    /// worst-object switches 0.8 -> 0.2). Not fitted to the bench: on 24 sequences it has not seen
    /// (`evseg run graph.yaml`, seeds 301-307, 401-407, 501-507, 601-607, 3 s) the means are the
    /// same to the fourth digit; on 20 of two and three objects (seeds 701-710) the switches are
    /// the same in the mean (2.35; three-objects 702 4 -> 3, 708 3 -> 4) and the per-object IoU
    /// 50.69 -> 50.48 %; as EVIMO2 folders through `graphs/evimo2.yaml` (two-objects 102 / 202,
    /// three-objects 11-14; `evseg bench --sequences`) per object 46.14 -> 46.16 %, switches
    /// 1.3 -> 1.2. Without the `min_hits` condition a handover in the second slice of three-objects
    /// 13, between tracks of one or two matches, set it on another course (1 -> 4 switches).
    pub split_yields_to_tracks: bool,
    /// See `split_yields_to_tracks`: the group the track keeps when it hands another group
    /// over must hold at least this fraction of the events of the track's largest group, in
    /// [0, 1]; else nothing is handed over. Default 0.25 (not in the paper): in two-objects
    /// 602 (not a bench sequence) a large object's boxes overlapped the other object's track's
    /// box, and that track handed its own object (3125 events) over and kept a 103-event
    /// fringe; in 102 the group kept held 0.54 of the largest.
    pub split_yield_min_share: f64,
}

impl Default for TrackerParams {
    fn default() -> Self {
        Self {
            accel_std_px_s2: 1000.0,
            measurement_std_px: 4.0,
            measurement_std_box_fraction: 0.1,
            initial_velocity_std_px_s: 300.0,
            gate_chi2: 13.82,
            max_distance_px: 100.0,
            bbox_weight: 1.0,
            min_events: 30,
            max_missing_s: 0.5,
            min_hits: 3,
            tentative_events: TentativeEvents::Unconfirmed,
            absorb_overlap: 0.1,
            merge_velocity_px_s: 120.0,
            merge_gap_px: 4.0,
            min_hits_to_merge: 3,
            merge_velocity_max_hits: 0,
            merge_inside: 0.5,
            merge_inside_max_hits: 10,
            split_gap_px: 16.0,
            split_min_events: 100,
            split_min_share: 0.0,
            split_cell_px: 0,
            split_after_slices: 3,
            matching_cascade: true,
            merge_keeps_most_hits: true,
            merge_keeps_most_events: true,
            split_yields_to_tracks: true,
            split_yield_min_share: 0.25,
        }
    }
}

impl TrackerParams {
    /// Per-axis standard deviation (pixels) of the centroid of a segment with box `bbox`
    /// (`[x_min, y_min, x_max, y_max]`, inclusive pixel extents).
    pub fn measurement_std(&self, bbox: [f64; 4]) -> [f64; 2] {
        let f = self.measurement_std_box_fraction;
        [
            self.measurement_std_px.max(f * (bbox[2] - bbox[0] + 1.0)),
            self.measurement_std_px.max(f * (bbox[3] - bbox[1] + 1.0)),
        ]
    }

    /// Checks every parameter's range.
    pub fn validate(&self) -> Result<(), TrackerError> {
        let bad = |name: &'static str, value: f64, reason: &'static str| TrackerError::InvalidParam {
            name,
            value,
            reason,
        };
        let positive = [
            ("measurement_std_px", self.measurement_std_px),
            ("initial_velocity_std_px_s", self.initial_velocity_std_px_s),
            ("gate_chi2", self.gate_chi2),
            ("max_distance_px", self.max_distance_px),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(name, v, "must be a finite number > 0"));
            }
        }
        let non_negative = [
            ("accel_std_px_s2", self.accel_std_px_s2),
            ("bbox_weight", self.bbox_weight),
            ("measurement_std_box_fraction", self.measurement_std_box_fraction),
            ("max_missing_s", self.max_missing_s),
            ("absorb_overlap", self.absorb_overlap),
            ("merge_velocity_px_s", self.merge_velocity_px_s),
            ("merge_gap_px", self.merge_gap_px),
            ("split_gap_px", self.split_gap_px),
            ("split_min_share", self.split_min_share),
        ];
        for (name, v) in [
            ("merge_inside", self.merge_inside),
            ("split_yield_min_share", self.split_yield_min_share),
        ] {
            if !(0.0..=1.0).contains(&v) {
                return Err(bad(name, v, "must be in [0, 1]"));
            }
        }
        for (name, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return Err(bad(name, v, "must be a finite number >= 0"));
            }
        }
        if self.min_hits == 0 {
            return Err(bad("min_hits", 0.0, "must be at least 1"));
        }
        // Upper bounds that keep the filter's variances (squares of these) finite and the
        // cell search of `split_gap_px` small; each far beyond any sensor's use.
        let at_most = [
            (
                "measurement_std_px",
                self.measurement_std_px,
                MAX_PIXELS,
                "must be at most 1e4 px",
            ),
            (
                "initial_velocity_std_px_s",
                self.initial_velocity_std_px_s,
                MAX_SPEED_PX_S,
                "must be at most 1e6 px/s",
            ),
            (
                "accel_std_px_s2",
                self.accel_std_px_s2,
                MAX_ACCEL_PX_S2,
                "must be at most 1e8 px/s^2",
            ),
            (
                "measurement_std_box_fraction",
                self.measurement_std_box_fraction,
                10.0,
                "must be at most 10 (box sizes)",
            ),
            (
                "max_distance_px",
                self.max_distance_px,
                MAX_PIXELS,
                "must be at most 1e4 px",
            ),
            (
                "merge_gap_px",
                self.merge_gap_px,
                MAX_PIXELS,
                "must be at most 1e4 px",
            ),
            (
                "split_gap_px",
                self.split_gap_px,
                MAX_PIXELS,
                "must be at most 1e4 px",
            ),
        ];
        for (name, v, max, reason) in at_most {
            if v > max {
                return Err(bad(name, v, reason));
            }
        }
        if self.split_cell_px > 0 && self.split_gap_px / f64::from(self.split_cell_px) > MAX_SPLIT_REACH_CELLS
        {
            return Err(bad(
                "split_gap_px",
                self.split_gap_px,
                "must be at most 32 times split_cell_px (the cells searched around each occupied cell grow with the square of the ratio)",
            ));
        }
        Ok(())
    }
}
