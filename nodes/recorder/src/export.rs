//! Exporting a recording as NumPy `.npy` files, for users who analyse in Python.
//!
//! Per recorded output (file prefix = topic with `/` replaced by `.`, e.g. `segmenter.tracks`):
//! - `evseg.Slice`: `<prefix>.events.npy`, float64 (N, 5): slice, t (s), x (px), y (px), polarity;
//! - `evseg.Tracks`: `<prefix>.labels.npy`, int64 (N, 2): slice, label (0 = background, -1 =
//!   moving but its track not yet confirmed, `Tracks::UNCONFIRMED`), per event in slice order; `<prefix>.egomotion.npy`, float64 (S, 10): slice, t_start, t_end (s),
//!   direction x y z (unit, camera frame), omega x y z (rad/s, camera frame), valid (0/1);
//!   `<prefix>.tracks.npy`, float64 (T, 15): slice, id, centroid x y (px), velocity x y (px/s),
//!   bbox x_min y_min x_max y_max (px), translation x y z (1/s at depth 1, camera frame), age (slices),
//!   events;
//! - `evseg.Segmentation` (a segmenter's output before tracking): `<prefix>.labels.npy` and
//!   `<prefix>.egomotion.npy` as for `evseg.Tracks`; `<prefix>.segments.npy`, float64 (G, 12):
//!   slice, label, translation x y z (1/s at depth 1, camera frame), centroid x y (px), bbox
//!   x_min y_min x_max y_max (px), events;
//! - `evseg.CoarseSegmentation`: `<prefix>.groups.npy`, float64 (N, 3): slice, group (0 = merged
//!   background, g >= 1 = cluster g - 1, -1 = unassigned), residual (normalized coordinates per
//!   second, NaN without flow); `<prefix>.egomotion.npy` as for `evseg.Tracks`;
//! - `evseg.Clusters`: `<prefix>.clusters.npy`, int64 (N, 2): slice, cluster (-1 = unassigned);
//! - `evseg.Residuals`: `<prefix>.residuals.npy`, float64 (N, 3): slice, residual (normalized
//!   coordinates per second, NaN without flow), background (0/1);
//! - `evseg.Truth` with per-event ground truth: `<prefix>.objects.npy`, int64 (N, 2): slice,
//!   object id (0 = background); `<prefix>.flow.npy`, float64 (N, 3): slice, true flow x y (px/s),
//!   when the source gives it;
//! - `evseg.NormalFlow`: `<prefix>.flow.npy`, float64 (N, 4): slice, nx, ny (normalized image coordinates per second), confidence (0..1);
//! - `evseg.Metrics`: `<prefix>.metrics.npy`, float64 (S, 1 + M): slice, then one column per
//!   metric name (NaN where a slice lacks it).
//!
//! `columns.json` and `README.txt` in the output folder list every file's columns and units.
//! Messages of another schema are counted (not exported); messages of an unknown schema or
//! version, or that do not decode, are counted and reported, never a panic.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use evseg_evimo2::npy;
use evseg_schemas::{
    Clusters, CoarseSegmentation, CodecError, Egomotion, Message, Metrics, NormalFlow, Residuals,
    Segmentation, Slice, Tracks, Truth, codec,
};
use serde::Serialize;

use crate::error::RecordError;
use crate::read::{MessageRef, Recording, read};

/// One column of an exported array.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Column {
    /// Column name.
    pub name: String,
    /// Unit ("" when none).
    pub unit: String,
}

fn cols(spec: &[(&str, &str)]) -> Vec<Column> {
    spec.iter()
        .map(|(n, u)| Column {
            name: n.to_string(),
            unit: u.to_string(),
        })
        .collect()
}

/// One written file.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ExportedFile {
    /// File name in the output folder.
    pub file: String,
    /// Topic it came from.
    pub topic: String,
    /// Schema of that topic.
    pub schema: String,
    /// NumPy dtype (`<f8`, `<i8`).
    pub dtype: String,
    /// Shape (rows, columns).
    pub shape: [usize; 2],
    /// Columns in order.
    pub columns: Vec<Column>,
}

/// Messages that were not exported, per topic.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct NotExported {
    /// Messages of a known schema that has no export (e.g. `evseg.EventPacket`: the slices hold the same events).
    pub other_schema: u64,
    /// Messages of a schema name or version this build does not know.
    pub unknown_schema: u64,
    /// Messages that did not decode (the first reason is kept).
    pub undecodable: u64,
    /// First problem seen, for the report.
    pub first_problem: Option<String>,
}

/// What [`export`] did.
#[derive(Debug, Clone, PartialEq)]
pub struct ExportSummary {
    /// The recording as read (completeness, channels, counts).
    pub recording: Recording,
    /// Files written, in name order.
    pub files: Vec<ExportedFile>,
    /// Topics with messages that were not exported.
    pub not_exported: BTreeMap<String, NotExported>,
}

#[derive(Default)]
struct Table {
    schema: String,
    columns: Vec<Column>,
    f64_rows: Vec<f64>,
    i64_rows: Vec<i64>,
    integer: bool,
}

#[derive(Default)]
struct MetricsTable {
    names: Vec<String>,
    rows: Vec<(u64, Vec<(usize, f64)>)>,
}

#[derive(Default)]
struct Collector {
    /// (topic, kind) -> table.
    tables: BTreeMap<(String, &'static str), Table>,
    metrics: BTreeMap<String, MetricsTable>,
    not_exported: BTreeMap<String, NotExported>,
}

impl Collector {
    fn table(
        &mut self,
        topic: &str,
        kind: &'static str,
        schema: &str,
        spec: &[(&str, &str)],
        integer: bool,
    ) -> &mut Table {
        self.tables
            .entry((topic.to_string(), kind))
            .or_insert_with(|| Table {
                schema: schema.to_string(),
                columns: cols(spec),
                integer,
                ..Table::default()
            })
    }

    fn problem(&mut self, topic: &str, unknown: bool, text: String) {
        let n = self.not_exported.entry(topic.to_string()).or_default();
        if unknown {
            n.unknown_schema += 1;
        } else {
            n.undecodable += 1;
        }
        n.first_problem.get_or_insert(text);
    }

    fn decode<T: Message>(&mut self, m: &MessageRef<'_>) -> Option<(u64, f64, f64, T)> {
        match codec::decode::<T>(m.data) {
            Ok(frame) => {
                let e = frame.envelope;
                frame.body.map(|b| (e.seq, e.t_start, e.t_end, b))
            }
            Err(err @ CodecError::Mismatch { .. }) => {
                self.problem(&m.channel.topic, true, err.to_string());
                None
            }
            Err(err) => {
                self.problem(
                    &m.channel.topic,
                    false,
                    format!("message {} (sequence {}): {err}", m.channel.topic, m.sequence),
                );
                None
            }
        }
    }

    /// One row of `<topic>.egomotion.npy`: `(seq, t_start, t_end)` and `g`.
    fn egomotion(&mut self, topic: &str, schema: &str, (seq, t0, t1): (u64, f64, f64), g: &Egomotion) {
        let ego = self.table(topic, "egomotion", schema, EGOMOTION, false);
        ego.f64_rows.extend([seq as f64, t0, t1]);
        ego.f64_rows.extend(g.direction);
        ego.f64_rows.extend(g.omega);
        ego.f64_rows.push(if g.valid { 1.0 } else { 0.0 });
    }

    fn take(&mut self, m: MessageRef<'_>) {
        let topic = m.channel.topic.clone();
        let schema = match codec::decode_header(m.data) {
            Ok((env, _)) => env.schema,
            Err(err) => {
                self.problem(&topic, false, format!("sequence {}: {err}", m.sequence));
                return;
            }
        };
        match schema.as_str() {
            Slice::SCHEMA => {
                let Some((seq, _, _, s)) = self.decode::<Slice>(&m) else {
                    return;
                };
                let t = self.table(&topic, "events", Slice::SCHEMA, EVENTS, false);
                let e = &s.events;
                for i in 0..e.len() {
                    t.f64_rows.extend([
                        seq as f64,
                        e.t[i],
                        f64::from(e.x[i]),
                        f64::from(e.y[i]),
                        f64::from(e.p[i]),
                    ]);
                }
            }
            Tracks::SCHEMA => {
                let Some((seq, t0, t1, tr)) = self.decode::<Tracks>(&m) else {
                    return;
                };
                let labels = self.table(&topic, "labels", Tracks::SCHEMA, TRACK_LABELS, true);
                for &l in &tr.label {
                    let l = if l == Tracks::UNCONFIRMED {
                        -1
                    } else {
                        i64::from(l)
                    };
                    labels.i64_rows.extend([seq as i64, l]);
                }
                self.egomotion(&topic, Tracks::SCHEMA, (seq, t0, t1), &tr.egomotion);
                let tracks = self.table(&topic, "tracks", Tracks::SCHEMA, TRACKS, false);
                for k in &tr.tracks {
                    tracks.f64_rows.extend([seq as f64, f64::from(k.id)]);
                    tracks.f64_rows.extend(k.centroid);
                    tracks.f64_rows.extend(k.velocity);
                    tracks.f64_rows.extend(k.bbox.map(f64::from));
                    tracks.f64_rows.extend(k.translation);
                    tracks.f64_rows.extend([f64::from(k.age), f64::from(k.events)]);
                }
            }
            Segmentation::SCHEMA => {
                let Some((seq, t0, t1, sg)) = self.decode::<Segmentation>(&m) else {
                    return;
                };
                let labels = self.table(&topic, "labels", Segmentation::SCHEMA, LABELS, true);
                for &l in &sg.label {
                    labels.i64_rows.extend([seq as i64, i64::from(l)]);
                }
                self.egomotion(&topic, Segmentation::SCHEMA, (seq, t0, t1), &sg.egomotion);
                let segments = self.table(&topic, "segments", Segmentation::SCHEMA, SEGMENTS, false);
                for g in &sg.segments {
                    segments.f64_rows.extend([seq as f64, f64::from(g.label)]);
                    segments.f64_rows.extend(g.translation);
                    segments.f64_rows.extend(g.centroid);
                    segments.f64_rows.extend(g.bbox.map(f64::from));
                    segments.f64_rows.push(f64::from(g.events));
                }
            }
            CoarseSegmentation::SCHEMA => {
                let Some((seq, t0, t1, c)) = self.decode::<CoarseSegmentation>(&m) else {
                    return;
                };
                let t = self.table(&topic, "groups", CoarseSegmentation::SCHEMA, GROUPS, false);
                for (i, &g) in c.group.iter().enumerate() {
                    let group = if g == CoarseSegmentation::UNASSIGNED {
                        -1.0
                    } else {
                        f64::from(g)
                    };
                    let r = c.residual.get(i).map_or(f64::NAN, |&r| f64::from(r));
                    t.f64_rows.extend([seq as f64, group, r]);
                }
                self.egomotion(&topic, CoarseSegmentation::SCHEMA, (seq, t0, t1), &c.egomotion);
            }
            Clusters::SCHEMA => {
                let Some((seq, _, _, c)) = self.decode::<Clusters>(&m) else {
                    return;
                };
                let t = self.table(&topic, "clusters", Clusters::SCHEMA, CLUSTERS, true);
                for &id in &c.id {
                    t.i64_rows
                        .extend([seq as i64, if id == u16::MAX { -1 } else { i64::from(id) }]);
                }
            }
            Residuals::SCHEMA => {
                let Some((seq, _, _, r)) = self.decode::<Residuals>(&m) else {
                    return;
                };
                let t = self.table(&topic, "residuals", Residuals::SCHEMA, RESIDUALS, false);
                for (i, &bg) in r.background.iter().enumerate() {
                    let v = r.residual.get(i).map_or(f64::NAN, |&v| f64::from(v));
                    t.f64_rows.extend([seq as f64, v, if bg { 1.0 } else { 0.0 }]);
                }
            }
            Truth::SCHEMA => {
                let Some((seq, _, _, tr)) = self.decode::<Truth>(&m) else {
                    return;
                };
                if !tr.event_object.is_empty() {
                    let t = self.table(&topic, "objects", Truth::SCHEMA, OBJECTS, true);
                    for &o in &tr.event_object {
                        t.i64_rows.extend([seq as i64, i64::from(o)]);
                    }
                }
                if !tr.flow_x.is_empty() && tr.flow_x.len() == tr.flow_y.len() {
                    let t = self.table(&topic, "flow", Truth::SCHEMA, TRUE_FLOW, false);
                    for (&fx, &fy) in tr.flow_x.iter().zip(&tr.flow_y) {
                        t.f64_rows.extend([seq as f64, f64::from(fx), f64::from(fy)]);
                    }
                }
            }
            NormalFlow::SCHEMA => {
                let Some((seq, _, _, f)) = self.decode::<NormalFlow>(&m) else {
                    return;
                };
                let t = self.table(&topic, "flow", NormalFlow::SCHEMA, FLOW, false);
                let n = f.nx.len().min(f.ny.len()).min(f.confidence.len());
                for i in 0..n {
                    t.f64_rows.extend([
                        seq as f64,
                        f64::from(f.nx[i]),
                        f64::from(f.ny[i]),
                        f64::from(f.confidence[i]),
                    ]);
                }
            }
            Metrics::SCHEMA => {
                let Some((seq, _, _, ms)) = self.decode::<Metrics>(&m) else {
                    return;
                };
                let table = self.metrics.entry(topic).or_default();
                let mut row = Vec::with_capacity(ms.values.len());
                for v in ms.values {
                    let idx = match table.names.iter().position(|n| *n == v.name) {
                        Some(i) => i,
                        None => {
                            table.names.push(v.name);
                            table.names.len() - 1
                        }
                    };
                    row.push((idx, v.value));
                }
                table.rows.push((seq, row));
            }
            other => {
                let version = codec::decode_header(m.data).map(|(e, _)| e.version).unwrap_or(0);
                if evseg_schemas::schema_version(other) == Some(version) {
                    self.not_exported.entry(topic).or_default().other_schema += 1;
                } else {
                    self.problem(&topic, true, format!("unknown schema {other} v{version}"));
                }
            }
        }
    }
}

const EVENTS: &[(&str, &str)] = &[
    ("slice", "index"),
    ("t", "s"),
    ("x", "px"),
    ("y", "px"),
    ("polarity", "0/1"),
];
const LABELS: &[(&str, &str)] = &[("slice", "index"), ("label", "segment id, 0 = background")];
const TRACK_LABELS: &[(&str, &str)] = &[
    ("slice", "index"),
    (
        "label",
        "track id, 0 = background, -1 = moving, track not yet confirmed",
    ),
];
const EGOMOTION: &[(&str, &str)] = &[
    ("slice", "index"),
    ("t_start", "s"),
    ("t_end", "s"),
    ("direction_x", "unit vector, camera frame"),
    ("direction_y", "unit vector, camera frame"),
    ("direction_z", "unit vector, camera frame"),
    ("omega_x", "rad/s, camera frame"),
    ("omega_y", "rad/s, camera frame"),
    ("omega_z", "rad/s, camera frame"),
    ("valid", "0/1"),
];
const TRACKS: &[(&str, &str)] = &[
    ("slice", "index"),
    ("id", "track id"),
    ("centroid_x", "px"),
    ("centroid_y", "px"),
    ("velocity_x", "px/s"),
    ("velocity_y", "px/s"),
    ("bbox_x_min", "px"),
    ("bbox_y_min", "px"),
    ("bbox_x_max", "px"),
    ("bbox_y_max", "px"),
    ("translation_x", "1/s at depth 1, camera frame"),
    ("translation_y", "1/s at depth 1, camera frame"),
    ("translation_z", "1/s at depth 1, camera frame"),
    ("age", "slices"),
    ("events", "count"),
];
const SEGMENTS: &[(&str, &str)] = &[
    ("slice", "index"),
    ("label", "segment id, 0 = background"),
    ("translation_x", "1/s at depth 1, camera frame"),
    ("translation_y", "1/s at depth 1, camera frame"),
    ("translation_z", "1/s at depth 1, camera frame"),
    ("centroid_x", "px"),
    ("centroid_y", "px"),
    ("bbox_x_min", "px"),
    ("bbox_y_min", "px"),
    ("bbox_x_max", "px"),
    ("bbox_y_max", "px"),
    ("events", "count"),
];
const GROUPS: &[(&str, &str)] = &[
    ("slice", "index"),
    (
        "group",
        "0 = merged background, g >= 1 = cluster g - 1, -1 = unassigned",
    ),
    ("residual", "normalized coordinates/s, NaN without flow"),
];
const CLUSTERS: &[(&str, &str)] = &[("slice", "index"), ("cluster", "cluster id, -1 = unassigned")];
const RESIDUALS: &[(&str, &str)] = &[
    ("slice", "index"),
    ("residual", "normalized coordinates/s, NaN without flow"),
    ("background", "0/1"),
];
const OBJECTS: &[(&str, &str)] = &[("slice", "index"), ("object", "object id, 0 = background")];
const TRUE_FLOW: &[(&str, &str)] = &[("slice", "index"), ("flow_x", "px/s"), ("flow_y", "px/s")];
const FLOW: &[(&str, &str)] = &[
    ("slice", "index"),
    ("nx", "normalized coordinates/s"),
    ("ny", "normalized coordinates/s"),
    ("confidence", "0..1"),
];

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> Result<(), RecordError> {
    let path = dir.join(name);
    std::fs::write(&path, bytes).map_err(|e| RecordError::Io {
        file: path,
        source: e,
    })
}

fn f64_bytes(v: &[f64]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Reads the recording at `path` (a cut-off one up to its last complete chunk) and writes the
/// `.npy` files described in the module documentation, `columns.json` and `README.txt` into
/// `out` (created if needed).
pub fn export(path: &Path, out: &Path) -> Result<ExportSummary, RecordError> {
    let mut c = Collector::default();
    let recording = read(path, |m| {
        c.take(m);
        Ok(())
    })?;
    std::fs::create_dir_all(out).map_err(|e| RecordError::Io {
        file: out.to_path_buf(),
        source: e,
    })?;
    let mut files = Vec::new();
    for ((topic, kind), t) in &c.tables {
        let name = format!("{}.{kind}.npy", topic.replace('/', "."));
        let width = t.columns.len();
        let (dtype, rows, bytes) = if t.integer {
            let b: Vec<u8> = t.i64_rows.iter().flat_map(|x| x.to_le_bytes()).collect();
            ("<i8", t.i64_rows.len() / width, b)
        } else {
            ("<f8", t.f64_rows.len() / width, f64_bytes(&t.f64_rows))
        };
        write_file(out, &name, &npy::encode_array(dtype, &[rows, width], &bytes))?;
        files.push(ExportedFile {
            file: name,
            topic: topic.clone(),
            schema: t.schema.clone(),
            dtype: dtype.into(),
            shape: [rows, width],
            columns: t.columns.clone(),
        });
    }
    for (topic, m) in &c.metrics {
        let name = format!("{}.metrics.npy", topic.replace('/', "."));
        let width = 1 + m.names.len();
        let mut data = vec![f64::NAN; m.rows.len() * width];
        for (r, (seq, values)) in m.rows.iter().enumerate() {
            data[r * width] = *seq as f64;
            for &(i, v) in values {
                data[r * width + 1 + i] = v;
            }
        }
        write_file(
            out,
            &name,
            &npy::encode_array("<f8", &[m.rows.len(), width], &f64_bytes(&data)),
        )?;
        let mut columns = cols(&[("slice", "index")]);
        columns.extend(m.names.iter().map(|n| Column {
            name: n.clone(),
            unit: "as named".into(),
        }));
        files.push(ExportedFile {
            file: name,
            topic: topic.clone(),
            schema: Metrics::SCHEMA.into(),
            dtype: "<f8".into(),
            shape: [m.rows.len(), width],
            columns,
        });
    }
    files.sort_by(|a, b| a.file.cmp(&b.file));
    let summary = ExportSummary {
        recording,
        files,
        not_exported: c.not_exported,
    };
    write_descriptions(out, &summary)?;
    Ok(summary)
}

fn write_descriptions(out: &Path, s: &ExportSummary) -> Result<(), RecordError> {
    let json = serde_json::json!({
        "recording": s.recording.file.display().to_string(),
        "complete": s.recording.truncated.is_none(),
        "truncated_at_byte": s.recording.truncated.as_ref().map(|t| t.offset),
        "messages_read": s.recording.messages,
        "files": s.files,
        "not_exported": s.not_exported,
    });
    let text = serde_json::to_string_pretty(&json).map_err(|e| RecordError::Param {
        name: "columns.json".into(),
        reason: e.to_string(),
    })?;
    write_file(out, "columns.json", text.as_bytes())?;
    let mut readme = format!(
        "Exported by `evseg export` from {}\n{}\n\nEvery file is a 2-D NumPy array (numpy.load(name)); \
         rows are concatenated over slices in recording order, and the first column is the slice \
         index (the message's sequence number). Times are seconds on the sequence clock; pixel \
         coordinates are raw sensor pixels; 3-D vectors are in the camera frame.\n",
        s.recording.file.display(),
        s.recording.completeness()
    );
    for f in &s.files {
        readme.push_str(&format!(
            "\n{} ({} from topic {}, dtype {}, shape {:?}):\n",
            f.file, f.schema, f.topic, f.dtype, f.shape
        ));
        for (i, c) in f.columns.iter().enumerate() {
            readme.push_str(&format!("  [{i}] {} ({})\n", c.name, c.unit));
        }
    }
    for (topic, n) in &s.not_exported {
        readme.push_str(&format!(
            "\nnot exported from {topic}: {} of a schema without export, {} of an unknown schema or \
             version, {} undecodable{}\n",
            n.other_schema,
            n.unknown_schema,
            n.undecodable,
            n.first_problem
                .as_ref()
                .map(|p| format!(" (first: {p})"))
                .unwrap_or_default()
        ));
    }
    write_file(out, "README.txt", readme.as_bytes())
}

/// Path of the file `evseg export` writes for `topic` and `kind` (`labels`, `flow`, ...).
pub fn file_for(out: &Path, topic: &str, kind: &str) -> PathBuf {
    out.join(format!("{}.{kind}.npy", topic.replace('/', ".")))
}
