//! The Rerun logging of a run: one [`RunLogger`] takes decoded pipeline messages (in any
//! order across streams) and logs them on the timelines `slice` (sequence number) and
//! `sensor_time` (start of the slice window, seconds on the sequence clock).
//!
//! Entity layout (`P` = the producing node's id, e.g. `tracker`):
//! - `events/polarity`: the slice's events as 2-D points (pixel centres, x right, y down; a
//!   pixel `(x, y)` is drawn at `(x + 0.5, y + 0.5)` so it lands inside the image pixel),
//!   coloured ON / OFF; `events/frame`: the sensor outline (static);
//! - `segments/P/events`: the same points coloured by P's per-event label (tracks or segments;
//!   stable colour per id, grey = background, dark half-transparent grey = moving without a
//!   confirmed track, `Tracks::UNCONFIRMED`); `segments/P/boxes`: P's confirmed track boxes
//!   labelled `id N` (or segment boxes labelled `segment N`);
//! - `flow/P/events`: the same points coloured by P's normal-flow direction (hue) and magnitude
//!   (brightness);
//! - `truth/events`: coloured by the ground-truth object id (only truth from the node that made
//!   the slices, whose per-event ids are aligned with them);
//! - `egomotion/P/direction` (unit translation direction x, y, z, camera frame) and
//!   `egomotion/P/omega` (rotation rate x, y, z, rad/s, camera frame) as time series, with
//!   `egomotion/truth/...` from the true camera motion of the slice;
//! - `metrics/P/<name>`: every per-slice figure of P (IoU, direction error, ...), time series.
//!
//! Per-event messages are joined with their slice by sequence number: a message that comes
//! before its slice waits (at most [`ViewerParams::cache_slices`] slices), and the decimated
//! positions of the newest slices are kept for messages that come after.

use std::collections::{BTreeMap, BTreeSet};

use evseg_schemas::{Metrics, NormalFlow, Segmentation, Slice, Tracks, Truth};
use rerun::RecordingStream;

use crate::colour::{flow_colour, label_colour, polarity_colour};
use crate::decimate::decimate;
use crate::error::ViewError;
use crate::params::ViewerParams;

/// Name of the sequence timeline (slice number).
pub const SLICE_TIMELINE: &str = "slice";
/// Name of the duration timeline (start of the slice window, seconds on the sequence clock).
pub const TIME_TIMELINE: &str = "sensor_time";

/// Where a message sits in the run: its producer and its envelope's slice number and window.
#[derive(Debug, Clone, PartialEq)]
pub struct Origin<'a> {
    /// Id of the node that produced it (`tracker`, `flow`, ...); names the entities.
    pub producer: &'a str,
    /// Slice (sequence) number.
    pub seq: u64,
    /// Start of the window, seconds on the sequence clock.
    pub t_start: f64,
    /// End of the window, seconds on the sequence clock.
    pub t_end: f64,
}

/// What was logged and what was skipped, for the user.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LogStats {
    /// Slices logged.
    pub slices: u64,
    /// Events in those slices.
    pub events: u64,
    /// Events drawn (after decimation, per layer).
    pub points_per_layer: u64,
    /// Per-event layers logged (labels, flow, truth), joined with their slice.
    pub layers: u64,
    /// Tracks / segment boxes logged.
    pub boxes: u64,
    /// Scalar samples logged (egomotion components, metrics).
    pub scalars: u64,
    /// Per-event messages whose slice never came or was too old (see `cache_slices`).
    pub unmatched: u64,
    /// Per-event messages whose length differs from their slice's event count.
    pub misaligned: u64,
    /// Slices of a second slice stream (only the first producer's slices are drawn).
    pub other_slices: u64,
    /// Truth messages of a node other than the slices' producer (not aligned with the slices).
    pub unaligned_truth: u64,
    /// Messages not drawn: of a schema the viewer does not draw (event packets, residuals),
    /// or undecodable.
    pub not_drawn: u64,
    /// Of those, messages that did not decode (unknown schema or version, corrupt bytes).
    pub undecodable: u64,
    /// First problem seen, for the report.
    pub first_problem: Option<String>,
}

impl LogStats {
    fn problem(&mut self, text: String) {
        tracing::warn!("{text}");
        self.first_problem.get_or_insert(text);
    }
}

/// The drawn subset of one slice.
#[derive(Debug, Clone)]
struct CachedSlice {
    /// Events in the slice.
    events: usize,
    /// Indices of the drawn events.
    indices: Vec<usize>,
    /// Their positions, pixels (pixel centre convention, see the module docs).
    positions: Vec<[f32; 2]>,
}

/// A per-event message waiting for its slice, or being drawn.
#[derive(Debug, Clone)]
enum PerEvent {
    /// Labels (track ids or segment labels) of `producer`.
    Labels { producer: String, label: Vec<u32> },
    /// Normal flow of `producer`.
    Flow { producer: String, flow: NormalFlow },
    /// Ground-truth object ids.
    TruthIds(Vec<u16>),
}

impl PerEvent {
    fn len(&self) -> usize {
        match self {
            Self::Labels { label, .. } => label.len(),
            Self::Flow { flow, .. } => flow.nx.len().min(flow.ny.len()).min(flow.confidence.len()),
            Self::TruthIds(ids) => ids.len(),
        }
    }

    fn entity(&self) -> String {
        match self {
            Self::Labels { producer, .. } => format!("segments/{producer}/events"),
            Self::Flow { producer, .. } => format!("flow/{producer}/events"),
            Self::TruthIds(_) => "truth/events".into(),
        }
    }
}

/// Logs a run's messages to one Rerun recording stream.
pub struct RunLogger {
    rec: RecordingStream,
    params: ViewerParams,
    /// Producer of the slice stream (the first one seen).
    slice_producer: Option<String>,
    /// Decimated slices by sequence number (the newest `cache_slices`).
    cache: BTreeMap<u64, CachedSlice>,
    /// Per-event messages waiting for their slice, by sequence number.
    pending: BTreeMap<u64, Vec<(f64, PerEvent)>>,
    /// 2-D roots whose sensor outline was logged.
    framed: BTreeSet<String>,
    /// Time-series entities whose series names were logged.
    named_series: BTreeSet<String>,
    /// Sensor size from the first slice, pixels.
    sensor: Option<(u16, u16)>,
    stats: LogStats,
}

impl RunLogger {
    /// A logger writing to `rec` (a file, a gRPC connection or memory; see [`crate::sink`]).
    pub fn new(rec: RecordingStream, params: ViewerParams) -> Result<Self, ViewError> {
        params.validate()?;
        Ok(Self {
            rec,
            params,
            slice_producer: None,
            cache: BTreeMap::new(),
            pending: BTreeMap::new(),
            framed: BTreeSet::new(),
            named_series: BTreeSet::new(),
            sensor: None,
            stats: LogStats::default(),
        })
    }

    /// Declares the node whose slices are drawn (before any message comes): truth of any other
    /// node is then known to be unaligned from the start. Without it, the first slice's producer
    /// is taken.
    pub fn expect_slices_from(&mut self, producer: &str) {
        self.slice_producer = Some(producer.to_string());
    }

    /// Counts a message that is not drawn (a schema without a drawing, or one that does not
    /// decode); `problem` describes it when it is an error.
    pub fn skipped(&mut self, problem: Option<String>) {
        self.stats.not_drawn += 1;
        if let Some(p) = problem {
            self.stats.undecodable += 1;
            self.stats.problem(p);
        }
    }

    /// What was logged so far.
    pub fn stats(&self) -> &LogStats {
        &self.stats
    }

    /// The recording stream.
    pub fn stream(&self) -> &RecordingStream {
        &self.rec
    }

    fn at(&self, seq: u64, t_start: f64) {
        self.rec.set_time_sequence(SLICE_TIMELINE, seq as i64);
        if t_start.is_finite() {
            self.rec.set_duration_secs(TIME_TIMELINE, t_start);
        }
    }

    fn log(&self, entity: &str, what: &impl rerun::AsComponents) -> Result<(), ViewError> {
        self.rec.log(entity, what).map_err(|source| ViewError::Log {
            entity: entity.to_string(),
            source,
        })
    }

    fn log_static(&self, entity: &str, what: &impl rerun::AsComponents) -> Result<(), ViewError> {
        self.rec
            .log_static(entity, what)
            .map_err(|source| ViewError::Log {
                entity: entity.to_string(),
                source,
            })
    }

    /// Logs the sensor outline under `root` once (static), when the sensor size is known.
    fn frame(&mut self, root: &str) -> Result<(), ViewError> {
        let Some((w, h)) = self.sensor else { return Ok(()) };
        if !self.framed.insert(root.to_string()) {
            return Ok(());
        }
        let outline = rerun::Boxes2D::from_mins_and_sizes([(0.0, 0.0)], [(f32::from(w), f32::from(h))])
            .with_colors([rerun::Color::from_unmultiplied_rgba(200, 200, 200, 255)]);
        self.log_static(&format!("{root}/frame"), &outline)
    }

    fn points(&self, positions: &[[f32; 2]], colours: impl Iterator<Item = [u8; 4]>) -> rerun::Points2D {
        rerun::Points2D::new(positions.iter().map(|p| (p[0], p[1])))
            .with_colors(colours.map(|[r, g, b, a]| rerun::Color::from_unmultiplied_rgba(r, g, b, a)))
            .with_radii([rerun::Radius::new_ui_points(self.params.point_radius_ui)])
    }

    /// Logs a slice of `origin.producer`: its events coloured by polarity, and every per-event
    /// message that was waiting for it. Only the first slice producer's slices are drawn; the
    /// slices of any other producer are counted in [`LogStats::other_slices`].
    pub fn slice(&mut self, origin: &Origin<'_>, slice: &Slice) -> Result<(), ViewError> {
        match &self.slice_producer {
            None => self.slice_producer = Some(origin.producer.to_string()),
            Some(p) if p != origin.producer => {
                self.stats.other_slices += 1;
                return Ok(());
            }
            Some(_) => {}
        }
        let e = &slice.events;
        if !e.is_consistent() {
            self.stats.problem(format!(
                "{} slice {}: event columns of different lengths (t {}, x {}, y {}, p {}); not drawn",
                origin.producer,
                origin.seq,
                e.t.len(),
                e.x.len(),
                e.y.len(),
                e.p.len()
            ));
            return Ok(());
        }
        if self.sensor.is_none() {
            self.sensor = Some((slice.camera.width, slice.camera.height));
        }
        let indices = decimate(e.len(), self.params.max_points_per_slice);
        let positions: Vec<[f32; 2]> = indices
            .iter()
            .map(|&i| [f32::from(e.x[i]) + 0.5, f32::from(e.y[i]) + 0.5])
            .collect();
        self.frame("events")?;
        self.at(origin.seq, origin.t_start);
        let points = self.points(&positions, indices.iter().map(|&i| polarity_colour(e.p[i])));
        self.log("events/polarity", &points)?;
        self.stats.slices += 1;
        self.stats.events += e.len() as u64;
        self.stats.points_per_layer += indices.len() as u64;
        self.cache.insert(
            origin.seq,
            CachedSlice {
                events: e.len(),
                indices,
                positions,
            },
        );
        while self.cache.len() > self.params.cache_slices {
            self.cache.pop_first();
        }
        if let Some(waiting) = self.pending.remove(&origin.seq) {
            for (t_start, m) in waiting {
                self.draw(origin.seq, t_start, &m)?;
            }
        }
        Ok(())
    }

    /// Draws `m` on its slice's points now, or keeps it until the slice comes.
    fn per_event(&mut self, seq: u64, t_start: f64, m: PerEvent) -> Result<(), ViewError> {
        if self.cache.contains_key(&seq) {
            return self.draw(seq, t_start, &m);
        }
        let too_old = self.cache.len() >= self.params.cache_slices
            && self
                .cache
                .first_key_value()
                .is_some_and(|(&oldest, _)| seq < oldest);
        if too_old {
            self.stats.unmatched += 1;
            return Ok(());
        }
        self.pending.entry(seq).or_default().push((t_start, m));
        while self.pending.len() > self.params.cache_slices {
            if let Some((_, dropped)) = self.pending.pop_first() {
                self.stats.unmatched += dropped.len() as u64;
            }
        }
        Ok(())
    }

    fn draw(&mut self, seq: u64, t_start: f64, m: &PerEvent) -> Result<(), ViewError> {
        let Some(slice) = self.cache.get(&seq) else {
            self.stats.unmatched += 1;
            return Ok(());
        };
        let entity = m.entity();
        if m.len() != slice.events {
            self.stats.misaligned += 1;
            let text = format!(
                "{entity} slice {seq}: {} per-event values for {} events; not drawn",
                m.len(),
                slice.events
            );
            self.stats.problem(text);
            return Ok(());
        }
        let idx = &slice.indices;
        let points = match m {
            PerEvent::Labels { label, .. } => {
                self.points(&slice.positions, idx.iter().map(|&i| label_colour(label[i])))
            }
            PerEvent::TruthIds(ids) => self.points(
                &slice.positions,
                idx.iter().map(|&i| label_colour(u32::from(ids[i]))),
            ),
            PerEvent::Flow { flow, .. } => {
                let full = self.params.flow_full_scale;
                self.points(
                    &slice.positions,
                    idx.iter()
                        .map(|&i| flow_colour(flow.nx[i], flow.ny[i], flow.confidence[i], full)),
                )
            }
        };
        let root = entity.trim_end_matches("/events").to_string();
        self.frame(&root)?;
        self.at(seq, t_start);
        self.log(&entity, &points)?;
        self.stats.layers += 1;
        Ok(())
    }

    /// Logs a 3-vector as one time series entity with components named x, y, z.
    fn vector(&mut self, entity: &str, v: [f64; 3]) -> Result<(), ViewError> {
        if !v.iter().all(|x| x.is_finite()) {
            return Ok(());
        }
        if self.named_series.insert(entity.to_string()) {
            self.log_static(entity, &rerun::SeriesLines::new().with_names(["x", "y", "z"]))?;
        }
        self.log(entity, &rerun::Scalars::new(v))?;
        self.stats.scalars += 3;
        Ok(())
    }

    fn egomotion(&mut self, producer: &str, e: &evseg_schemas::Egomotion) -> Result<(), ViewError> {
        if !e.valid {
            return Ok(());
        }
        self.vector(&format!("egomotion/{producer}/direction"), e.direction)?;
        self.vector(&format!("egomotion/{producer}/omega"), e.omega)
    }

    fn boxes(&mut self, entity: &str, boxes: &[([f32; 4], u32, String)]) -> Result<(), ViewError> {
        let mins = boxes.iter().map(|(b, _, _)| (b[0], b[1]));
        let sizes = boxes
            .iter()
            .map(|(b, _, _)| ((b[2] - b[0]).max(0.0), (b[3] - b[1]).max(0.0)));
        let colours = boxes.iter().map(|(_, id, _)| {
            let [r, g, b, a] = label_colour(*id);
            rerun::Color::from_unmultiplied_rgba(r, g, b, a)
        });
        let labels = boxes.iter().map(|(_, _, l)| l.clone());
        let archetype = rerun::Boxes2D::from_mins_and_sizes(mins, sizes)
            .with_colors(colours)
            .with_labels(labels);
        self.log(entity, &archetype)?;
        self.stats.boxes += boxes.len() as u64;
        Ok(())
    }

    /// Logs a tracker's (or segmenter's) result: per-event track ids on the slice's points,
    /// the track boxes labelled `id N` (pixels), and the egomotion time series.
    pub fn tracks(&mut self, origin: &Origin<'_>, tracks: &Tracks) -> Result<(), ViewError> {
        self.at(origin.seq, origin.t_start);
        let root = format!("segments/{}", origin.producer);
        self.frame(&root)?;
        let boxes: Vec<([f32; 4], u32, String)> = tracks
            .tracks
            .iter()
            .map(|t| (t.bbox, t.id, format!("id {}", t.id)))
            .collect();
        self.boxes(&format!("{root}/boxes"), &boxes)?;
        self.egomotion(origin.producer, &tracks.egomotion)?;
        self.per_event(
            origin.seq,
            origin.t_start,
            PerEvent::Labels {
                producer: origin.producer.to_string(),
                label: tracks.label.clone(),
            },
        )
    }

    /// Logs a segmentation: per-event labels on the slice's points, segment boxes labelled
    /// `segment N` (pixels), and the egomotion time series.
    pub fn segmentation(&mut self, origin: &Origin<'_>, s: &Segmentation) -> Result<(), ViewError> {
        self.at(origin.seq, origin.t_start);
        let root = format!("segments/{}", origin.producer);
        self.frame(&root)?;
        let boxes: Vec<([f32; 4], u32, String)> = s
            .segments
            .iter()
            .filter(|g| g.label != 0)
            .map(|g| (g.bbox, g.label, format!("segment {}", g.label)))
            .collect();
        self.boxes(&format!("{root}/boxes"), &boxes)?;
        self.egomotion(origin.producer, &s.egomotion)?;
        self.per_event(
            origin.seq,
            origin.t_start,
            PerEvent::Labels {
                producer: origin.producer.to_string(),
                label: s.label.clone(),
            },
        )
    }

    /// Logs per-event labels of `origin.producer` that come without boxes (over-segmentation
    /// clusters, the background merger's groups) on the slice's points, as
    /// `segments/<producer>/events`. 0 is drawn as background, `u32::MAX` as unlabelled.
    pub fn labels(&mut self, origin: &Origin<'_>, label: Vec<u32>) -> Result<(), ViewError> {
        self.per_event(
            origin.seq,
            origin.t_start,
            PerEvent::Labels {
                producer: origin.producer.to_string(),
                label,
            },
        )
    }

    /// Logs per-event normal flow on the slice's points (colour = direction and magnitude).
    pub fn flow(&mut self, origin: &Origin<'_>, flow: &NormalFlow) -> Result<(), ViewError> {
        self.per_event(
            origin.seq,
            origin.t_start,
            PerEvent::Flow {
                producer: origin.producer.to_string(),
                flow: flow.clone(),
            },
        )
    }

    /// Logs ground truth: per-event object ids on the slice's points and the true camera
    /// motion of the window (mean linear velocity direction, mean angular velocity) as
    /// `egomotion/truth/...`. Only truth of the slices' producer is aligned with them; truth of
    /// another node is counted in [`LogStats::unaligned_truth`] and skipped. Truth that comes
    /// before any slice is taken to be the slices' producer's if it has the same producer as the
    /// first slice that comes later.
    pub fn truth(&mut self, origin: &Origin<'_>, truth: &Truth) -> Result<(), ViewError> {
        if self
            .slice_producer
            .as_deref()
            .is_some_and(|p| p != origin.producer)
        {
            self.stats.unaligned_truth += 1;
            return Ok(());
        }
        self.at(origin.seq, origin.t_start);
        let mut v = [0.0; 3];
        let mut w = [0.0; 3];
        let (mut nv, mut nw) = (0.0, 0.0);
        for c in &truth.camera {
            if let Some(l) = c.linear_velocity {
                (0..3).for_each(|k| v[k] += l[k]);
                nv += 1.0;
            }
            if let Some(a) = c.angular_velocity {
                (0..3).for_each(|k| w[k] += a[k]);
                nw += 1.0;
            }
        }
        let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
        if nv > 0.0 && norm > 0.0 {
            self.vector("egomotion/truth/direction", v.map(|x| x / norm))?;
        }
        if nw > 0.0 {
            self.vector("egomotion/truth/omega", w.map(|x| x / nw))?;
        }
        if truth.event_object.is_empty() {
            return Ok(());
        }
        self.per_event(
            origin.seq,
            origin.t_start,
            PerEvent::TruthIds(truth.event_object.clone()),
        )
    }

    /// Logs every figure of a metrics message as the time series `metrics/<producer>/<name>`
    /// (NaN values, "not defined for this slice", are left out).
    pub fn metrics(&mut self, origin: &Origin<'_>, m: &Metrics) -> Result<(), ViewError> {
        self.at(origin.seq, origin.t_start);
        for v in &m.values {
            if !v.value.is_finite() {
                continue;
            }
            let entity = format!("metrics/{}/{}", origin.producer, sanitize(&v.name));
            self.log(&entity, &rerun::Scalars::single(v.value))?;
            self.stats.scalars += 1;
        }
        Ok(())
    }

    /// Ends the run: per-event messages still waiting for a slice are counted as unmatched,
    /// and everything logged is flushed to the sink (the file is complete when this returns).
    pub fn finish(mut self) -> Result<LogStats, ViewError> {
        let waiting: u64 = self.pending.values().map(|v| v.len() as u64).sum();
        self.stats.unmatched += waiting;
        self.pending.clear();
        self.rec.flush_blocking().map_err(|e| ViewError::Flush {
            sink: "recording stream".into(),
            reason: e.to_string(),
        })?;
        Ok(self.stats)
    }
}

/// An entity-path-safe version of a metric name (`/` and spaces become `_`).
fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| if c == '/' || c.is_whitespace() { '_' } else { c })
        .collect()
}
