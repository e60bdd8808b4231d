//! The tracker: one constant-velocity Kalman filter per object, Hungarian association per slice,
//! stable ids (paper section 3.5, last paragraph).

use std::collections::HashMap;

use evseg_schemas::{Segment, Segmentation, Track, Tracks};

use crate::association::{associate, associate_cascade, pair_cost};
use crate::error::TrackerError;
use crate::kalman::CvKalman;
use crate::params::{TentativeEvents, TrackerParams};

/// One live track.
#[derive(Debug, Clone)]
struct TrackState {
    /// Published id (>= 1, never reused).
    id: u32,
    /// Filter on the image centroid (pixels, pixels/s).
    kf: CvKalman,
    /// The last matched box relative to the last matched centroid, pixels
    /// (`bbox − [cx, cy, cx, cy]`); the predicted box is the predicted centroid plus these.
    box_offsets: [f64; 4],
    /// Value of [`Tracker::slices`] when the track was created.
    created_slice: u64,
    /// Slices in which the track was matched (creation counts as one).
    hits: u32,
    /// Centre time of the slice of the last match, seconds.
    last_match_t: f64,
    /// Consecutive slices, up to the last one tracked, in which the track's segments formed
    /// groups lying apart that were large enough to split off without splitting yet (see
    /// `TrackerParams::split_after_slices`).
    apart_slices: u32,
}

impl TrackState {
    fn predicted_bbox(&self) -> [f64; 4] {
        let [x, y] = self.kf.position();
        let o = self.box_offsets;
        [x + o[0], y + o[1], x + o[2], y + o[3]]
    }

    /// Corrects the track with segment `s` seen in the slice centred at `t` seconds: the filter
    /// update with the segment's centroid, its box, one more hit.
    fn take(&mut self, s: &Segment, t: f64, params: &TrackerParams) {
        self.kf
            .update(s.centroid, params.measurement_std(bbox_f64(s.bbox)));
        self.box_offsets = box_offsets(s);
        self.hits = self.hits.saturating_add(1);
        self.last_match_t = t;
    }
}

/// Maps a segment label to its index in `Segmentation::segments`.
enum LabelIndex {
    /// Table indexed by label (`usize::MAX` = no segment), for small labels.
    Dense(Vec<usize>),
    /// Hash map, for large label values.
    Sparse(HashMap<u32, usize>),
}

impl LabelIndex {
    /// Largest label value for which a dense table is used (a 64k-entry table is cheap).
    const DENSE_MAX: u32 = 1 << 16;

    fn new(segments: &[Segment]) -> Result<Self, TrackerError> {
        let max = segments.iter().map(|s| s.label).max().unwrap_or(0);
        let mut index = if max <= Self::DENSE_MAX {
            LabelIndex::Dense(vec![usize::MAX; max as usize + 1])
        } else {
            LabelIndex::Sparse(HashMap::with_capacity(segments.len()))
        };
        for (i, s) in segments.iter().enumerate() {
            let duplicate = match &mut index {
                LabelIndex::Dense(v) => std::mem::replace(&mut v[s.label as usize], i) != usize::MAX,
                LabelIndex::Sparse(m) => m.insert(s.label, i).is_some(),
            };
            if duplicate {
                return Err(TrackerError::DuplicateSegment { label: s.label });
            }
        }
        Ok(index)
    }

    fn get(&self, label: u32) -> Option<usize> {
        match self {
            LabelIndex::Dense(v) => v.get(label as usize).copied().filter(|&i| i != usize::MAX),
            LabelIndex::Sparse(m) => m.get(&label).copied(),
        }
    }
}

/// Checks a foreground segment's centroid and box.
fn check_segment(s: &Segment) -> Result<(), TrackerError> {
    if !(s.centroid[0].is_finite() && s.centroid[1].is_finite()) {
        return Err(TrackerError::NonFiniteCentroid {
            label: s.label,
            centroid: s.centroid,
        });
    }
    let b = s.bbox;
    if !b.iter().all(|v| v.is_finite()) || b[0] > b[2] || b[1] > b[3] {
        return Err(TrackerError::InvalidBbox {
            label: s.label,
            bbox: b,
        });
    }
    Ok(())
}

fn bbox_f64(b: [f32; 4]) -> [f64; 4] {
    b.map(f64::from)
}

/// Tracks the merged segments of successive slices and gives each a stable id.
///
/// Per slice ([`Tracker::update`]):
/// 1. every track's filter is predicted to the slice's centre time; tracks not matched for more
///    than `max_missing_s` are dropped;
/// 2. tracks are matched one-to-one to the segments with label != 0 that have events
///    ([`crate::association`]); a matched track's filter is corrected with the segment centroid;
/// 3. a segment still unmatched whose box lies mostly inside a live track's predicted box
///    (`absorb_overlap`) is a fragment of that object and takes its id (it corrects the track's
///    filter only if nothing else matched the track);
/// 4. a tentative track (fewer than `min_hits` matches) that was not matched is dropped;
/// 5. each unmatched segment with at least `min_events` events opens a track with a new id
///    (1, 2, 3, ...; ids are never reused);
/// 6. tracks that are pieces of one object merge (`merge_inside`, `merge_velocity_px_s`); a
///    track whose segments form groups lying apart hands a group touching another established
///    track's segment to that track (`split_yields_to_tracks`), keeps the largest other group,
///    and each other large enough group opens a track of its own (`split_gap_px`);
/// 7. every event of a segment takes the id of the segment's track; events of label 0 and of
///    small unmatched segments (no track) are background, 0.
///
/// Events of a tentative track (fewer than `min_hits` matches) are moving but carry no id:
/// [`Tracks::UNCONFIRMED`] until the track is confirmed (`tentative_events` can give them the
/// track's id, or background); only confirmed tracks are listed in `Tracks::tracks`.
#[derive(Debug, Clone)]
pub struct Tracker {
    params: TrackerParams,
    tracks: Vec<TrackState>,
    /// The id the next new track gets.
    next_id: u32,
    /// Centre time of the previous slice, seconds.
    last_t: Option<f64>,
    /// Slices processed so far.
    slices: u64,
}

impl Tracker {
    /// A tracker with no tracks; refuses parameters out of range.
    pub fn new(params: TrackerParams) -> Result<Self, TrackerError> {
        params.validate()?;
        Ok(Self {
            params,
            tracks: Vec::new(),
            next_id: 1,
            last_t: None,
            slices: 0,
        })
    }

    /// The parameters.
    pub fn params(&self) -> &TrackerParams {
        &self.params
    }

    /// Number of live tracks (tentative, matched or missing).
    pub fn live_tracks(&self) -> usize {
        self.tracks.len()
    }

    /// Tracks one slice: `span` is its time window `(t_start, t_end)` in seconds (from the
    /// envelope), `events` the number of events of the slice, `segmentation` its merged
    /// segments (per-event labels aligned with the slice's events).
    ///
    /// Returns per-event track ids (0 = background), the confirmed tracks matched in this slice
    /// (sorted by id) and the segmentation's egomotion. The segments' own `events` field is not
    /// used: event counts are taken from the per-event labels. Only foreground segments
    /// (label != 0) are checked for finite centroids and valid boxes. On error the tracker is
    /// unchanged.
    pub fn update(
        &mut self,
        span: (f64, f64),
        events: usize,
        segmentation: &Segmentation,
    ) -> Result<Tracks, TrackerError> {
        self.track_slice(span, events, None, segmentation)
    }

    /// As [`Tracker::update`], with the slice's event pixels `x`, `y` (aligned with the
    /// per-event labels): with `split_cell_px` > 0 a track's segments are grouped for the
    /// split by the cells their events occupy instead of by their boxes.
    pub fn update_with_pixels(
        &mut self,
        span: (f64, f64),
        x: &[u16],
        y: &[u16],
        segmentation: &Segmentation,
    ) -> Result<Tracks, TrackerError> {
        if x.len() != y.len() {
            return Err(TrackerError::PixelCount {
                x: x.len(),
                y: y.len(),
            });
        }
        self.track_slice(span, x.len(), Some((x, y)), segmentation)
    }

    fn track_slice(
        &mut self,
        span: (f64, f64),
        events: usize,
        pixels: Option<(&[u16], &[u16])>,
        segmentation: &Segmentation,
    ) -> Result<Tracks, TrackerError> {
        // ---- validation (no state change before this block succeeds) ----
        let (t_start, t_end) = span;
        if !(t_start.is_finite() && t_end.is_finite() && t_end >= t_start) {
            return Err(TrackerError::InvalidSpan { t_start, t_end });
        }
        let t = 0.5 * (t_start + t_end);
        if let Some(previous) = self.last_t
            && t <= previous
        {
            return Err(TrackerError::TimeNotIncreasing { previous, current: t });
        }
        if segmentation.label.len() != events {
            return Err(TrackerError::LabelCount {
                labels: segmentation.label.len(),
                events,
            });
        }
        let segments = &segmentation.segments;
        let index = LabelIndex::new(segments)?;
        for s in segments.iter().filter(|s| s.label != 0) {
            check_segment(s)?;
        }
        let mut counts = vec![0u32; segments.len()];
        for (i, &label) in segmentation.label.iter().enumerate() {
            if label == 0 {
                continue;
            }
            match index.get(label) {
                Some(k) => counts[k] += 1,
                None => return Err(TrackerError::UnknownLabel { index: i, label }),
            }
        }

        let candidates: Vec<usize> = (0..segments.len())
            .filter(|&k| segments[k].label != 0 && counts[k] > 0)
            .collect();
        if u64::from(self.next_id) + candidates.len() as u64 > u64::from(u32::MAX) {
            return Err(TrackerError::IdsExhausted {
                next: self.next_id,
                needed: candidates.len(),
            });
        }

        // ---- prediction and expiry ----
        if let Some(previous) = self.last_t {
            let dt = t - previous;
            for tr in &mut self.tracks {
                tr.kf.predict(dt, self.params.accel_std_px_s2);
            }
        }
        let max_missing = self.params.max_missing_s;
        self.tracks.retain(|tr| {
            let live = t - tr.last_match_t <= max_missing;
            if !live {
                tracing::debug!(t, id = tr.id, hits = tr.hits, "track expired");
            }
            live
        });

        // ---- association ----
        // Boxes as predicted before any correction of this slice (matching and fragments).
        let predicted: Vec<[f64; 4]> = self.tracks.iter().map(TrackState::predicted_bbox).collect();
        let costs: Vec<Vec<Option<f64>>> = self
            .tracks
            .iter()
            .zip(&predicted)
            .map(|(tr, &pb)| {
                candidates
                    .iter()
                    .map(|&k| {
                        let s = &segments[k];
                        pair_cost(&tr.kf, pb, s.centroid, bbox_f64(s.bbox), &self.params)
                    })
                    .collect()
            })
            .collect();
        let matches = if self.params.matching_cascade {
            let last: Vec<f64> = self.tracks.iter().map(|tr| tr.last_match_t).collect();
            associate_cascade(&costs, &last, self.params.bbox_weight)
        } else {
            associate(&costs, self.params.bbox_weight)
        };
        // The tracks as predicted, before this slice's corrections (a split may hand a track
        // to another of its groups, which then corrects it instead).
        let before: Vec<TrackState> = if self.params.split_gap_px > 0.0 {
            self.tracks.clone()
        } else {
            Vec::new()
        };

        // Track index per segment index, filled for matched and new tracks.
        let mut track_of_segment: Vec<Option<usize>> = vec![None; segments.len()];
        let mut matched_track = vec![false; self.tracks.len()];
        // The segment that corrected each track's filter in this slice.
        let mut primary: Vec<Option<usize>> = vec![None; self.tracks.len()];
        for (ti, m) in matches.iter().enumerate() {
            if let Some(ci) = *m {
                let k = candidates[ci];
                let s = &segments[k];
                self.tracks[ti].take(s, t, &self.params);
                matched_track[ti] = true;
                primary[ti] = Some(k);
                track_of_segment[k] = Some(ti);
            }
        }

        // ---- fragments: unmatched segments inside a live track's predicted box ----
        let mut absorbed = vec![false; segments.len()];
        if self.params.absorb_overlap > 0.0 {
            for &k in &candidates {
                if track_of_segment[k].is_some() {
                    continue;
                }
                let sb = bbox_f64(segments[k].bbox);
                let best = predicted
                    .iter()
                    .enumerate()
                    .map(|(ti, &pb)| (ti, inside_fraction(sb, pb)))
                    .filter(|&(_, f)| f >= self.params.absorb_overlap)
                    .max_by(|a, b| a.1.total_cmp(&b.1));
                if let Some((ti, _)) = best {
                    let s = &segments[k];
                    tracing::debug!(
                        t,
                        id = self.tracks[ti].id,
                        events = counts[k],
                        bbox = ?segments[k].bbox,
                        "fragment absorbed"
                    );
                    if !matched_track[ti] {
                        self.tracks[ti].take(s, t, &self.params);
                        matched_track[ti] = true;
                        primary[ti] = Some(k);
                    } else {
                        absorbed[k] = true;
                    }
                    track_of_segment[k] = Some(ti);
                }
            }
        }

        // ---- new tracks (enough ids were checked above) ----
        let new_segments: Vec<usize> = candidates
            .iter()
            .copied()
            .filter(|&k| track_of_segment[k].is_none() && counts[k] >= self.params.min_events)
            .collect();
        for &k in &new_segments {
            self.open_track(&segments[k], t);
            matched_track.push(true);
            primary.push(Some(k));
            track_of_segment[k] = Some(self.tracks.len() - 1);
        }

        // ---- pieces of one object: tracks whose segments touch and move alike ----
        let mut ended = vec![false; self.tracks.len()];
        if self.params.merge_velocity_px_s > 0.0 {
            self.merge_pieces(
                segments,
                &counts,
                &mut track_of_segment,
                &mut absorbed,
                &mut ended,
            );
        }
        // ---- groups far from a track's matched segment: another object ----
        if self.params.split_gap_px > 0.0 {
            let cells = match pixels {
                Some((x, y)) if self.params.split_cell_px > 0 => Some(SegmentCells::new(
                    &segmentation.label,
                    &index,
                    x,
                    y,
                    segments.len(),
                    self.params.split_cell_px,
                )),
                _ => None,
            };
            let opened = self.split_apart(
                segments,
                cells.as_ref(),
                &counts,
                &primary,
                &before,
                &mut track_of_segment,
                &mut absorbed,
                t,
            );
            matched_track.extend(std::iter::repeat_n(true, opened));
            ended.extend(std::iter::repeat_n(false, opened));
        }
        // A track's box is that of all its pieces in this slice, so that the pieces fall inside
        // its predicted box next time (and are absorbed there).
        let union = union_boxes(segments, &track_of_segment, self.tracks.len());
        for (tr, u) in self.tracks.iter_mut().zip(&union) {
            if let Some(u) = u {
                let [cx, cy] = tr.kf.position();
                tr.box_offsets = [u[0] - cx, u[1] - cy, u[2] - cx, u[3] - cy];
            }
        }

        // ---- outputs ----
        let id_of_segment: Vec<u32> = track_of_segment
            .iter()
            .map(|m| {
                m.map_or(0, |ti| {
                    let tr = &self.tracks[ti];
                    if tr.hits >= self.params.min_hits {
                        return tr.id;
                    }
                    match self.params.tentative_events {
                        TentativeEvents::Unconfirmed => Tracks::UNCONFIRMED,
                        TentativeEvents::Id => tr.id,
                        TentativeEvents::Background => 0,
                    }
                })
            })
            .collect();
        let label: Vec<u32> = segmentation
            .label
            .iter()
            .map(|&l| {
                if l == 0 {
                    0
                } else {
                    index.get(l).map_or(0, |k| id_of_segment[k])
                }
            })
            .collect();
        // Events of absorbed fragments count with their track's main segment.
        let mut fragment_events = vec![0u32; self.tracks.len()];
        for (k, m) in track_of_segment.iter().enumerate() {
            if let Some(ti) = *m
                && absorbed[k]
            {
                fragment_events[ti] = fragment_events[ti].saturating_add(counts[k]);
            }
        }
        let mut tracks: Vec<Track> = track_of_segment
            .iter()
            .enumerate()
            .filter(|&(k, _)| !absorbed[k])
            .filter_map(|(k, m)| m.map(|ti| (k, ti, &self.tracks[ti])))
            .filter(|(_, _, tr)| tr.hits >= self.params.min_hits)
            .map(|(k, ti, tr)| Track {
                id: tr.id,
                centroid: tr.kf.position(),
                velocity: tr.kf.velocity(),
                bbox: segments[k].bbox,
                translation: segments[k].translation,
                age: u32::try_from(self.slices - tr.created_slice).unwrap_or(u32::MAX),
                events: counts[k].saturating_add(fragment_events[ti]),
            })
            .collect();
        tracks.sort_by_key(|tr| tr.id);
        if tracing::enabled!(tracing::Level::DEBUG) {
            let ids: Vec<(u32, u32, [f32; 4], [i32; 2])> = tracks
                .iter()
                .map(|tr| {
                    let v = tr.velocity.map(|v| v.round() as i32);
                    (tr.id, tr.events, tr.bbox, v)
                })
                .collect();
            tracing::debug!(t, tracks = ?ids, "slice tracked (id, events, bbox px, velocity px/s)");
        }

        // Tentative tracks missed in this slice are dropped at once; tracks merged into another
        // end.
        let min_hits = self.params.min_hits;
        let mut keep = matched_track.into_iter().zip(ended);
        self.tracks.retain(|tr| {
            let (matched, ended) = keep.next().unwrap_or((true, false));
            !ended && (matched || tr.hits >= min_hits)
        });

        self.last_t = Some(t);
        self.slices += 1;
        Ok(Tracks {
            label,
            tracks,
            egomotion: segmentation.egomotion,
        })
    }
}

impl Tracker {
    /// Opens a track (a new id) on segment `s` of the slice centred at `t` seconds.
    fn open_track(&mut self, s: &Segment, t: f64) {
        let id = self.next_id;
        self.next_id += 1;
        tracing::debug!(t, id, centroid = ?s.centroid, bbox = ?s.bbox, "track opened");
        let [sx, sy] = self.params.measurement_std(bbox_f64(s.bbox));
        self.tracks.push(TrackState {
            id,
            kf: CvKalman::new(s.centroid, sx.max(sy), self.params.initial_velocity_std_px_s),
            box_offsets: box_offsets(s),
            created_slice: self.slices,
            hits: 1,
            last_match_t: t,
            apart_slices: 0,
        });
    }

    /// Splits a track whose segments form groups lying apart (see
    /// `TrackerParams::split_gap_px`): groups touching another established track's segments
    /// are handed to that track as fragments (`TrackerParams::split_yields_to_tracks`, when a
    /// group of the size to keep is left); of the rest, the group with the most events keeps
    /// the track (if that is not the group of the segment that corrected it, the track is
    /// restored from `before`, its state as predicted, and corrected with that group's largest
    /// segment instead); every other group with at least `split_min_events` events opens a new
    /// track on its largest segment, its other segments becoming that track's fragments.
    /// Returns the number of tracks opened (appended to `self.tracks`).
    #[allow(clippy::too_many_arguments)]
    fn split_apart(
        &mut self,
        segments: &[Segment],
        cells: Option<&SegmentCells>,
        counts: &[u32],
        primary: &[Option<usize>],
        before: &[TrackState],
        track_of_segment: &mut [Option<usize>],
        absorbed: &mut [bool],
        t: f64,
    ) -> usize {
        let p = &self.params;
        let (gap, min_events, min_share) = (p.split_gap_px, p.split_min_events, p.split_min_share);
        let split_after = p.split_after_slices;
        let (yield_to_tracks, yield_min_share) = (p.split_yields_to_tracks, p.split_yield_min_share);
        let mut opened = 0;
        for (ti, first) in primary.iter().enumerate() {
            let Some(first) = *first else { continue };
            if track_of_segment[first] != Some(ti) {
                continue; // merged into another track
            }
            let members: Vec<usize> = (0..segments.len())
                .filter(|&k| track_of_segment[k] == Some(ti))
                .collect();
            if members.len() < 2 {
                continue;
            }
            let groups = match cells {
                Some(c) => c.groups(&members, gap),
                None => box_groups(segments, &members, gap),
            };
            let events: Vec<u32> = groups
                .iter()
                .map(|g| g.iter().map(|&k| counts[k]).sum())
                .collect();
            if groups.len() > 1 {
                tracing::debug!(
                    t,
                    id = self.tracks[ti].id,
                    ?events,
                    "track's segments in groups apart"
                );
            }
            let largest = |g: &[usize]| g.iter().copied().max_by_key(|&k| counts[k]);
            let first_group = groups.iter().position(|g| g.contains(&first)).unwrap_or(0);
            // Groups touching another established track's segments of this slice belong to
            // that track (`split_yields_to_tracks`), if a group of the split-off size is left (one
            // group alone has nothing to keep instead).
            let owner: Vec<Option<usize>> = if yield_to_tracks && groups.len() > 1 {
                groups
                    .iter()
                    .map(|g| self.touching_track(segments, track_of_segment, ti, g))
                    .collect()
            } else {
                vec![None; groups.len()]
            };
            let most = events.iter().copied().max().unwrap_or(0);
            let free = |g: usize| {
                owner[g].is_none()
                    && events[g] >= min_events
                    && f64::from(events[g]) >= yield_min_share * f64::from(most)
            };
            let yields = (0..groups.len()).any(|g| owner[g].is_some()) && (0..groups.len()).any(free);
            let mut keep = if yields {
                (0..groups.len()).find(|&g| free(g)).unwrap_or(first_group)
            } else {
                first_group
            };
            for (g, &e) in events.iter().enumerate() {
                if e > events[keep] && (!yields || free(g)) {
                    keep = g;
                }
            }
            if keep != first_group
                && let Some(prior) = before.get(ti)
                && let Some(main) = largest(&groups[keep])
            {
                self.tracks[ti] = prior.clone();
                self.tracks[ti].take(&segments[main], t, &self.params);
                absorbed[main] = false;
                absorbed[first] = true;
            }
            if yields {
                for (g, group) in groups.iter().enumerate() {
                    let Some(tj) = owner[g] else { continue };
                    tracing::debug!(
                        t,
                        from = self.tracks[ti].id,
                        to = self.tracks[tj].id,
                        events = events[g],
                        "group handed to the track it touches"
                    );
                    for &k in group {
                        track_of_segment[k] = Some(tj);
                        absorbed[k] = true;
                    }
                }
            }
            let splits = |g: usize| {
                let share = f64::from(events[g]) / f64::from(events[keep].max(1));
                g != keep && owner[g].is_none() && events[g] >= min_events && share >= min_share
            };
            if !(0..groups.len()).any(splits) {
                self.tracks[ti].apart_slices = 0;
                continue;
            }
            self.tracks[ti].apart_slices = self.tracks[ti].apart_slices.saturating_add(1);
            if self.tracks[ti].apart_slices < split_after {
                continue;
            }
            self.tracks[ti].apart_slices = 0;
            for (g, group) in groups.iter().enumerate() {
                if !splits(g) {
                    continue;
                }
                let Some(main) = largest(group) else {
                    continue;
                };
                tracing::debug!(
                    t,
                    from = self.tracks[ti].id,
                    events = events[g],
                    "group split off"
                );
                self.open_track(&segments[main], t);
                let nt = self.tracks.len() - 1;
                for &k in group {
                    track_of_segment[k] = Some(nt);
                    absorbed[k] = k != main;
                }
                opened += 1;
            }
        }
        opened
    }

    /// The established track (confirmed, opened before this slice and matched in at least as
    /// many slices as track `ti`, other than `ti`) one of whose segments in this slice has a
    /// box touching or overlapping the box of a segment of `group` (indices into `segments`);
    /// of several, the one with the most such segments.
    fn touching_track(
        &self,
        segments: &[Segment],
        track_of_segment: &[Option<usize>],
        ti: usize,
        group: &[usize],
    ) -> Option<usize> {
        let min_hits = self.tracks[ti].hits.max(self.params.min_hits);
        let established = |tr: &TrackState| tr.created_slice < self.slices && tr.hits >= min_hits;
        let mut touches: HashMap<usize, usize> = HashMap::new();
        for (k, m) in track_of_segment.iter().enumerate() {
            let Some(tj) = *m else { continue };
            if tj == ti || !self.tracks.get(tj).is_some_and(established) {
                continue;
            }
            let b = bbox_f64(segments[k].bbox);
            if group
                .iter()
                .any(|&g| box_gap(bbox_f64(segments[g].bbox), b) <= 0.0)
            {
                *touches.entry(tj).or_default() += 1;
            }
        }
        touches
            .into_iter()
            .max_by_key(|&(tj, n)| (n, std::cmp::Reverse(tj)))
            .map(|(tj, _)| tj)
    }

    /// Merges tracks that are pieces of one object (see `TrackerParams::merge_velocity_px_s`
    /// and `TrackerParams::merge_inside`): repeatedly takes the pair of tracks matched in this
    /// slice whose segments' boxes lie one inside the other (a young piece), else the
    /// closest-moving pair whose boxes touch; the younger one's segments become fragments of
    /// the older one (`absorbed`) and the younger one is marked `ended` (the caller grows the
    /// older one's box over all its pieces).
    fn merge_pieces(
        &mut self,
        segments: &[Segment],
        counts: &[u32],
        track_of_segment: &mut [Option<usize>],
        absorbed: &mut [bool],
        ended: &mut [bool],
    ) {
        let p = &self.params;
        loop {
            let boxes = union_boxes(segments, track_of_segment, self.tracks.len());
            let mut best: Option<(usize, usize, f64)> = None;
            for a in 0..self.tracks.len() {
                for b in a + 1..self.tracks.len() {
                    let (Some(ba), Some(bb)) = (boxes[a], boxes[b]) else {
                        continue;
                    };
                    if ended[a] || ended[b] {
                        continue;
                    }
                    // Containment: one piece's box mostly inside the other's (any velocity).
                    // Otherwise touching boxes and alike velocities of trusted filters.
                    let (ta, tb) = (&self.tracks[a], &self.tracks[b]);
                    let contained = p.merge_inside > 0.0
                        && ta.hits.min(tb.hits) <= p.merge_inside_max_hits
                        && inside_fraction(ba, bb).max(inside_fraction(bb, ba)) >= p.merge_inside;
                    let dv = if contained {
                        0.0
                    } else {
                        if ta.hits < p.min_hits_to_merge
                            || tb.hits < p.min_hits_to_merge
                            || (p.merge_velocity_max_hits > 0
                                && ta.hits.min(tb.hits) > p.merge_velocity_max_hits)
                            || box_gap(ba, bb) > p.merge_gap_px
                        {
                            continue;
                        }
                        let (va, vb) = (ta.kf.velocity(), tb.kf.velocity());
                        (va[0] - vb[0]).hypot(va[1] - vb[1])
                    };
                    if dv <= p.merge_velocity_px_s && best.is_none_or(|(_, _, d)| dv < d) {
                        best = Some((a, b, dv));
                    }
                }
            }
            let Some((a, b, _)) = best else {
                return;
            };
            // The track with more events in this slice keeps its id
            // (`merge_keeps_most_events`), else the one matched more often
            // (`merge_keeps_most_hits`), else (and on a tie) the older one (smaller id).
            let events_of = |ti: usize| -> u64 {
                track_of_segment
                    .iter()
                    .zip(counts)
                    .filter(|(m, _)| **m == Some(ti))
                    .map(|(_, &c)| u64::from(c))
                    .sum()
            };
            let established = self.tracks[a].hits.min(self.tracks[b].hits) > p.merge_inside_max_hits;
            let (ea, eb) = if p.merge_keeps_most_events && established {
                (events_of(a), events_of(b))
            } else {
                (0, 0)
            };
            let (ta, tb) = (&self.tracks[a], &self.tracks[b]);
            let a_keeps = if ea != eb {
                ea > eb
            } else if p.merge_keeps_most_hits && ta.hits != tb.hits {
                ta.hits > tb.hits
            } else {
                ta.id < tb.id
            };
            let (keep, end) = if a_keeps { (a, b) } else { (b, a) };
            tracing::debug!(
                id = self.tracks[keep].id,
                hits = self.tracks[keep].hits,
                ended = self.tracks[end].id,
                ended_hits = self.tracks[end].hits,
                "tracks merged"
            );
            for (k, m) in track_of_segment.iter_mut().enumerate() {
                if *m == Some(end) {
                    *m = Some(keep);
                    absorbed[k] = true;
                }
            }
            ended[end] = true;
        }
    }
}

/// Per track (index below `tracks`), the smallest box holding the boxes of its segments in this
/// slice (`track_of_segment[k]`: the track of `segments[k]`), pixels; `None` for a track without
/// a segment.
fn union_boxes(
    segments: &[Segment],
    track_of_segment: &[Option<usize>],
    tracks: usize,
) -> Vec<Option<[f64; 4]>> {
    let mut boxes: Vec<Option<[f64; 4]>> = vec![None; tracks];
    for (s, m) in segments.iter().zip(track_of_segment) {
        if let Some(ti) = *m {
            let b = bbox_f64(s.bbox);
            boxes[ti] = Some(boxes[ti].map_or(b, |u| box_union(u, b)));
        }
    }
    boxes
}

/// The grid cells each segment's events occupy, for grouping a track's segments by where
/// their events lie (`TrackerParams::split_cell_px`).
struct SegmentCells {
    /// Cell side, pixels.
    cell_px: u16,
    /// Grid columns.
    cols: u32,
    /// Per segment index: the row-major indices of the cells holding any of its events,
    /// sorted, without repeats.
    cells: Vec<Vec<u32>>,
}

impl SegmentCells {
    /// The cells of `segment_count` segments from the per-event `labels` (segment index through
    /// `index`; label 0 and unknown labels skipped) at pixels `x`, `y`.
    fn new(
        labels: &[u32],
        index: &LabelIndex,
        x: &[u16],
        y: &[u16],
        segment_count: usize,
        cell_px: u16,
    ) -> Self {
        let c = u32::from(cell_px.max(1));
        let cols = x.iter().map(|&v| u32::from(v) / c).max().unwrap_or(0) + 1;
        let mut keys: Vec<u64> = labels
            .iter()
            .zip(x.iter().zip(y))
            .filter(|&(&l, _)| l != 0)
            .filter_map(|(&l, (&px, &py))| {
                let k = index.get(l)?;
                let cell = (u32::from(py) / c) * cols + u32::from(px) / c;
                Some(((k as u64) << 32) | u64::from(cell))
            })
            .collect();
        keys.sort_unstable();
        keys.dedup();
        let mut cells = vec![Vec::new(); segment_count];
        for key in keys {
            if let Some(v) = cells.get_mut((key >> 32) as usize) {
                v.push(key as u32);
            }
        }
        Self {
            cell_px: cell_px.max(1),
            cols,
            cells,
        }
    }

    /// `members` (segment indices) in groups, transitively joining two segments with occupied
    /// cells at most `gap_px` apart (rounded up to whole cells; cells sharing a side or a
    /// corner are 0 apart). Groups in the order of their first member, members sorted; a
    /// segment without cells is a group of its own.
    fn groups(&self, members: &[usize], gap_px: f64) -> Vec<Vec<usize>> {
        // (Saturating: `as` saturates a huge ratio, the + 1 must not wrap.)
        let reach = ((gap_px / f64::from(self.cell_px)).ceil() as i64).saturating_add(1);
        let mut parent: Vec<usize> = (0..members.len()).collect();
        fn root(parent: &mut [usize], mut a: usize) -> usize {
            while parent[a] != a {
                parent[a] = parent[parent[a]];
                a = parent[a];
            }
            a
        }
        let mut owner: HashMap<u32, usize> = HashMap::new();
        let cols = i64::from(self.cols);
        for (local, &k) in members.iter().enumerate() {
            let Some(cells) = self.cells.get(k) else { continue };
            for &cell in cells {
                let (cx, cy) = (i64::from(cell) % cols, i64::from(cell) / cols);
                for dy in -reach..=reach {
                    for dx in -reach..=reach {
                        let (nx, ny) = (cx + dx, cy + dy);
                        if nx < 0 || ny < 0 || nx >= cols {
                            continue;
                        }
                        if let Some(&other) = u32::try_from(ny * cols + nx).ok().and_then(|n| owner.get(&n)) {
                            let (ra, rb) = (root(&mut parent, local), root(&mut parent, other));
                            if ra != rb {
                                parent[ra.max(rb)] = ra.min(rb);
                            }
                        }
                    }
                }
            }
            for &cell in cells {
                owner.entry(cell).or_insert(local);
            }
        }
        let mut groups: Vec<Vec<usize>> = Vec::new();
        let mut group_of_root: HashMap<usize, usize> = HashMap::new();
        for (local, &k) in members.iter().enumerate() {
            let r = root(&mut parent, local);
            let g = *group_of_root.entry(r).or_insert_with(|| {
                groups.push(Vec::new());
                groups.len() - 1
            });
            groups[g].push(k);
        }
        for g in &mut groups {
            g.sort_unstable();
        }
        groups
    }
}

/// Groups of `members` (indices into `segments`) whose boxes lie at most `gap` pixels apart,
/// transitively: each group's segment indices, in `members`' order.
fn box_groups(segments: &[Segment], members: &[usize], gap: f64) -> Vec<Vec<usize>> {
    let boxes: Vec<[f64; 4]> = members.iter().map(|&k| bbox_f64(segments[k].bbox)).collect();
    let mut placed = vec![false; members.len()];
    let mut groups = Vec::new();
    for start in 0..members.len() {
        if placed[start] {
            continue;
        }
        placed[start] = true;
        let mut group = Vec::new();
        let mut stack = vec![start];
        while let Some(a) = stack.pop() {
            group.push(a);
            for b in 0..members.len() {
                if !placed[b] && box_gap(boxes[a], boxes[b]) <= gap {
                    placed[b] = true;
                    stack.push(b);
                }
            }
        }
        group.sort_unstable();
        groups.push(group.into_iter().map(|i| members[i]).collect());
    }
    groups
}

/// The smallest box holding boxes `a` and `b`.
fn box_union(a: [f64; 4], b: [f64; 4]) -> [f64; 4] {
    [a[0].min(b[0]), a[1].min(b[1]), a[2].max(b[2]), a[3].max(b[3])]
}

/// Gap between two boxes (inclusive pixel extents), pixels: 0 when they touch or overlap.
fn box_gap(a: [f64; 4], b: [f64; 4]) -> f64 {
    let gx = (a[0].max(b[0]) - a[2].min(b[2]) - 1.0).max(0.0);
    let gy = (a[1].max(b[1]) - a[3].min(b[3]) - 1.0).max(0.0);
    gx.max(gy)
}

/// The fraction of box `inner`'s area (inclusive pixel extents) that lies inside box `outer`,
/// in [0, 1].
fn inside_fraction(inner: [f64; 4], outer: [f64; 4]) -> f64 {
    let area = (inner[2] - inner[0] + 1.0).max(0.0) * (inner[3] - inner[1] + 1.0).max(0.0);
    let iw = (inner[2].min(outer[2]) + 1.0 - inner[0].max(outer[0])).max(0.0);
    let ih = (inner[3].min(outer[3]) + 1.0 - inner[1].max(outer[1])).max(0.0);
    if area > 0.0 { iw * ih / area } else { 0.0 }
}

/// A segment's box relative to its centroid, pixels.
fn box_offsets(s: &Segment) -> [f64; 4] {
    let [cx, cy] = s.centroid;
    let b = bbox_f64(s.bbox);
    [b[0] - cx, b[1] - cy, b[2] - cx, b[3] - cy]
}
