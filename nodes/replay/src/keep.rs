//! Replaying a recording with gaps: the slices complete on every replayed channel, renumbered.
//!
//! A recording made in live mode (or by a recorder that could not keep up) can lack messages.
//! A lock-step replay waits for every slice number in turn, so by default such a recording is
//! refused ([`crate::ReplayError::Gap`]). With `evseg replay --skip-gaps` the replay keeps the
//! slices that every replayed channel holds and numbers them 0, 1, 2, ... in order
//! ([`KeptSlices::rank`]); envelopes keep their sensor times, so the stages see a stream with a
//! few longer steps between slices, as in live mode. The channels must count the same slices:
//! a slice kept must carry the same sensor time span on every channel (else they are numbered
//! differently, e.g. a source's batches beside the slicer's slices, and the replay is refused).

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use evseg_schemas::{FrameKind, codec};

use crate::ReplayError;

/// The recorded slice numbers kept, as sorted disjoint ranges `[start, end)`.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct KeptSlices {
    ranges: Vec<(u64, u64)>,
}

impl KeptSlices {
    /// From sorted, distinct slice numbers.
    pub fn from_sorted(seqs: impl IntoIterator<Item = u64>) -> Self {
        let mut ranges: Vec<(u64, u64)> = Vec::new();
        for s in seqs {
            match ranges.last_mut() {
                Some((_, end)) if *end == s => *end += 1,
                _ => ranges.push((s, s + 1)),
            }
        }
        Self { ranges }
    }

    /// Checks the ranges are sorted, disjoint and not empty (a `keep` parameter from a file).
    pub fn validate(&self) -> Result<(), String> {
        let mut last_end = None;
        for &(a, b) in &self.ranges {
            if a >= b || last_end.is_some_and(|e| a < e) {
                return Err(format!(
                    "range [{a}, {b}) is empty, unsorted or overlaps the one before"
                ));
            }
            last_end = Some(b);
        }
        Ok(())
    }

    /// Slices kept.
    pub fn len(&self) -> u64 {
        self.ranges.iter().map(|(a, b)| b - a).sum()
    }

    /// True when no slice is kept.
    pub fn is_empty(&self) -> bool {
        self.ranges.is_empty()
    }

    /// The new number of recorded slice `seq` (its rank among those kept), or `None` when it
    /// is left out.
    pub fn rank(&self, seq: u64) -> Option<u64> {
        let i = self.ranges.partition_point(|&(_, end)| end <= seq);
        let &(start, _) = self.ranges.get(i)?;
        if seq < start {
            return None;
        }
        Some(self.ranges[..i].iter().map(|(a, b)| b - a).sum::<u64>() + (seq - start))
    }
}

/// What [`kept_slices`] found.
#[derive(Debug, Clone, PartialEq)]
pub struct GapReport {
    /// The slices every channel holds.
    pub kept: KeptSlices,
    /// Per channel: its messages and how many of them are left out (held by it but missing
    /// on another channel).
    pub channels: BTreeMap<String, (u64, u64)>,
    /// Slice numbers from 0 to the largest one seen, held by no channel at all.
    pub missing_everywhere: u64,
}

/// Reads the data frames of `topics` in the recording at `path` and keeps the slice numbers
/// every one of them holds (see the module docs). A frame whose header does not decode is an
/// error naming it; so is a kept slice whose sensor time span differs between two channels.
pub fn kept_slices(path: &Path, topics: &[String]) -> Result<GapReport, ReplayError> {
    let mut spans: BTreeMap<&str, BTreeMap<u64, (u64, u64)>> =
        topics.iter().map(|t| (t.as_str(), BTreeMap::new())).collect();
    let mut bad: Option<ReplayError> = None;
    let mut index: BTreeMap<String, u64> = BTreeMap::new();
    evseg_recorder::read::read(path, |m| {
        let Some(seqs) = spans.get_mut(m.channel.topic.as_str()) else {
            return Ok(());
        };
        let i = index.entry(m.channel.topic.clone()).or_default();
        match codec::decode_header(m.data) {
            Ok((e, _)) if e.kind == FrameKind::Data => {
                seqs.insert(e.seq, (e.t_start.to_bits(), e.t_end.to_bits()));
            }
            Ok(_) => {}
            Err(e) => {
                bad.get_or_insert(ReplayError::BadFrame {
                    file: path.to_path_buf(),
                    topic: m.channel.topic.clone(),
                    index: *i,
                    reason: e.to_string(),
                });
            }
        }
        *i += 1;
        Ok(())
    })?;
    if let Some(e) = bad {
        return Err(e);
    }
    let mut common: Option<BTreeSet<u64>> = None;
    for seqs in spans.values() {
        let here: BTreeSet<u64> = seqs.keys().copied().collect();
        common = Some(match common {
            None => here,
            Some(c) => c.intersection(&here).copied().collect(),
        });
    }
    let common = common.unwrap_or_default();
    // The same slice on every channel: the same sensor time span.
    if let Some((first_topic, first)) = spans.iter().next() {
        for (topic, seqs) in &spans {
            if let Some(&seq) = common.iter().find(|s| seqs.get(s) != first.get(s)) {
                return Err(ReplayError::Param {
                    name: "skip-gaps".into(),
                    reason: format!(
                        "{}: slice {seq} of `{topic}` and of `{first_topic}` cover different sensor \
                         times, so the channels are numbered differently and cannot be matched; \
                         replay from a node whose outputs all count slices",
                        path.display()
                    ),
                });
            }
        }
    }
    let seen: BTreeSet<u64> = spans.values().flat_map(|s| s.keys().copied()).collect();
    let top = seen.iter().next_back().map_or(0, |s| s + 1);
    let channels = spans
        .iter()
        .map(|(t, s)| {
            let out = s.keys().filter(|k| !common.contains(k)).count() as u64;
            (t.to_string(), (s.len() as u64, out))
        })
        .collect();
    Ok(GapReport {
        kept: KeptSlices::from_sorted(common),
        channels,
        missing_everywhere: top - seen.len() as u64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_recorder::write::{ChannelSpec, McapRecorder, WriterSettings};
    use evseg_schemas::messages::Metrics;

    /// Per message of a test channel: (seq, t_end) of a frame, or `None` for bytes that are not
    /// a frame.
    type TestFrames = Vec<Option<(u64, f64)>>;

    /// A recording of `Metrics` channels with the given messages.
    fn recording(path: &Path, channels: &[(&str, TestFrames)]) {
        let specs: Vec<ChannelSpec> = channels
            .iter()
            .map(|(t, _)| ChannelSpec {
                topic: t.to_string(),
                schema: "evseg.Metrics".into(),
                version: 1,
                metadata: BTreeMap::new(),
            })
            .collect();
        let mut w = McapRecorder::create(path, &specs, &WriterSettings::default()).unwrap();
        for (port, (_, frames)) in channels.iter().enumerate() {
            for f in frames {
                let (seq, t_end) = f.unwrap_or((0, 0.0));
                let envelope = codec::data_envelope::<Metrics>(seq, t_end - 0.03, t_end);
                let bytes = match f {
                    Some(_) => codec::encode(seq, t_end - 0.03, t_end, &Metrics::default()).unwrap(),
                    None => b"\xff\xff not a frame".to_vec(),
                };
                w.write_frame(port, &envelope, &bytes).unwrap();
            }
        }
        w.finish().unwrap();
    }

    #[test]
    fn slices_held_by_every_channel_are_kept_and_bad_input_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let t = |s: u64| Some((s, 0.03 * (s + 1) as f64));
        let topics = ["a/x".to_string(), "a/y".to_string()];
        let path = dir.path().join("gaps.mcap");
        recording(
            &path,
            &[
                ("a/x", vec![t(0), t(1), t(3), t(4)]),
                ("a/y", vec![t(0), t(2), t(3), t(4)]),
            ],
        );
        let r = kept_slices(&path, &topics).unwrap();
        assert_eq!(r.kept, KeptSlices::from_sorted([0, 3, 4]));
        assert_eq!(r.channels["a/x"], (4, 1));
        assert_eq!(r.missing_everywhere, 0);
        // A message that is not a frame: named by channel and index.
        let path = dir.path().join("bad.mcap");
        recording(&path, &[("a/x", vec![t(0), None]), ("a/y", vec![t(0)])]);
        let e = kept_slices(&path, &topics).unwrap_err().to_string();
        assert!(e.contains("channel `a/x`, message 1"), "{e}");
        // Channels numbered differently (the same number, other sensor times): refused.
        let path = dir.path().join("other.mcap");
        let late = |s: u64| Some((s, 0.01 * (s + 1) as f64));
        recording(
            &path,
            &[("a/x", vec![t(0), t(1)]), ("a/y", vec![late(0), late(1)])],
        );
        let e = kept_slices(&path, &topics).unwrap_err().to_string();
        assert!(e.contains("cover different sensor times"), "{e}");
        // Not a recording at all.
        std::fs::write(dir.path().join("text.mcap"), "hello").unwrap();
        assert!(kept_slices(&dir.path().join("text.mcap"), &topics).is_err());
    }

    #[test]
    fn kept_slices_are_renumbered_in_order() {
        let k = KeptSlices::from_sorted([0, 1, 2, 5, 6, 9]);
        assert_eq!(k.len(), 6);
        let ranks: Vec<Option<u64>> = (0..11).map(|s| k.rank(s)).collect();
        assert_eq!(
            ranks,
            [
                Some(0),
                Some(1),
                Some(2),
                None,
                None,
                Some(3),
                Some(4),
                None,
                None,
                Some(5),
                None
            ]
        );
        assert!(k.validate().is_ok());
        let json = serde_json::to_string(&k).unwrap();
        assert_eq!(json, r#"{"ranges":[[0,3],[5,7],[9,10]]}"#);
        let bad: KeptSlices = serde_json::from_str(r#"{"ranges":[[3,5],[4,6]]}"#).unwrap();
        assert!(bad.validate().is_err());
        assert_eq!(KeptSlices::default().rank(0), None);
    }
}
