//! Checking, before anything starts, that a recording holds every channel a replay publishes,
//! with the schema, version and encoding the graph expects.

use std::collections::BTreeMap;
use std::path::Path;

use evseg_recorder::MESSAGE_ENCODING;
use evseg_recorder::read::{ChannelInfo, Recording};

use crate::error::ReplayError;

/// One output the replay must publish.
#[derive(Debug, Clone, PartialEq)]
pub struct Wanted {
    /// Topic in the recording, `node/output`.
    pub topic: String,
    /// Schema name the graph's consumers expect (`evseg.Slice`, ...).
    pub schema: String,
    /// Consumers in the replayed graph, for messages (`node.port`, comma separated).
    pub needed_by: String,
}

/// Checks the channels of an already read `recording` against `wanted`: each topic present,
/// with the expected schema name, the schema's current version (when the schema is one of the
/// pipeline's) and the evseg message encoding. Errors name the file and the channel.
pub fn check_channels(recording: &Recording, wanted: &[Wanted]) -> Result<(), ReplayError> {
    check_channels_with(recording, wanted, false)
}

/// [`check_channels`], letting channels with gaps pass when `allow_gaps` (a replay that keeps
/// only the slices every channel holds, [`crate::keep`]).
pub fn check_channels_with(
    recording: &Recording,
    wanted: &[Wanted],
    allow_gaps: bool,
) -> Result<(), ReplayError> {
    let by_topic: BTreeMap<&str, &ChannelInfo> = recording
        .channels
        .values()
        .map(|c| (c.topic.as_str(), c))
        .collect();
    for w in wanted {
        let Some(c) = by_topic.get(w.topic.as_str()) else {
            return Err(ReplayError::MissingChannel {
                file: recording.file.clone(),
                topic: w.topic.clone(),
                schema: w.schema.clone(),
                needed_by: w.needed_by.clone(),
                available: by_topic.keys().map(|t| t.to_string()).collect(),
            });
        };
        let version = evseg_schemas::schema_version(&w.schema);
        let version_ok = match (version, c.version) {
            (Some(v), Some(found)) => v == found,
            (Some(_), None) => false,
            (None, _) => true,
        };
        if let (false, missing @ 1.., Some(first_missing)) =
            (allow_gaps, c.gaps.missing, c.gaps.first_missing)
        {
            return Err(ReplayError::Gap {
                file: recording.file.clone(),
                topic: w.topic.clone(),
                missing,
                first_missing,
            });
        }
        if c.schema != w.schema || !version_ok || c.message_encoding != MESSAGE_ENCODING {
            let v = |v: Option<u16>| v.map(|v| format!(" v{v}")).unwrap_or_default();
            return Err(ReplayError::WrongSchema {
                file: recording.file.clone(),
                topic: w.topic.clone(),
                expected: format!("{}{} ({MESSAGE_ENCODING})", w.schema, v(version)),
                found: format!("{}{} ({})", c.schema, v(c.version), c.message_encoding),
            });
        }
    }
    Ok(())
}

/// Reads the recording at `path` (without keeping its messages; a cut-off file is read up to
/// its last complete chunk) and checks it holds `wanted`. Returns what was read, so the caller
/// can say how complete the file is ([`Recording::completeness`]) and how many messages each
/// channel has.
pub fn check_recording(path: &Path, wanted: &[Wanted]) -> Result<Recording, ReplayError> {
    check_recording_with(path, wanted, false)
}

/// [`check_recording`], letting channels with gaps pass when `allow_gaps` (see
/// [`check_channels_with`]).
pub fn check_recording_with(
    path: &Path,
    wanted: &[Wanted],
    allow_gaps: bool,
) -> Result<Recording, ReplayError> {
    let recording = evseg_recorder::read::read(path, |_| Ok(()))?;
    check_channels_with(&recording, wanted, allow_gaps)?;
    Ok(recording)
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_recorder::read::Recording;

    fn recording(channels: &[(&str, &str, Option<u16>)]) -> Recording {
        Recording {
            file: "run.mcap".into(),
            size: 1,
            channels: channels
                .iter()
                .enumerate()
                .map(|(i, (topic, schema, version))| {
                    let c = ChannelInfo {
                        id: i as u16,
                        topic: topic.to_string(),
                        schema: schema.to_string(),
                        version: *version,
                        message_encoding: MESSAGE_ENCODING.into(),
                        metadata: Default::default(),
                        messages: 0,
                        bytes: 0,
                        time_ns: None,
                        gaps: Default::default(),
                    };
                    (i as u16, c)
                })
                .collect(),
            metadata: vec![],
            attachments: vec![],
            chunks: 0,
            messages: 0,
            orphan_messages: 0,
            truncated: None,
        }
    }

    fn wanted(topic: &str, schema: &str) -> Wanted {
        Wanted {
            topic: topic.into(),
            schema: schema.into(),
            needed_by: "evaluator.truth".into(),
        }
    }

    #[test]
    fn missing_or_mistyped_channels_are_named_with_the_file() {
        let v = |s| evseg_schemas::schema_version(s);
        let rec = recording(&[
            ("slicer/slices", "evseg.Slice", v("evseg.Slice")),
            ("slicer/truth", "evseg.Tracks", v("evseg.Tracks")),
            ("old/slices", "evseg.Slice", Some(999)),
        ]);
        assert!(check_channels(&rec, &[wanted("slicer/slices", "evseg.Slice")]).is_ok());
        let err = check_channels(&rec, &[wanted("flow/flow", "evseg.NormalFlow")]).unwrap_err();
        let text = err.to_string();
        assert!(matches!(err, ReplayError::MissingChannel { .. }));
        assert!(
            text.contains("run.mcap") && text.contains("flow/flow") && text.contains("evaluator.truth"),
            "{text}"
        );
        let err = check_channels(&rec, &[wanted("slicer/truth", "evseg.Truth")]).unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("run.mcap") && text.contains("slicer/truth") && text.contains("evseg.Tracks"),
            "{text}"
        );
        let err = check_channels(&rec, &[wanted("old/slices", "evseg.Slice")]).unwrap_err();
        assert!(err.to_string().contains("v999"), "{err}");
    }

    #[test]
    fn a_channel_that_skips_sequence_numbers_is_refused_naming_the_first() {
        let v = |s| evseg_schemas::schema_version(s);
        let mut rec = recording(&[("slicer/slices", "evseg.Slice", v("evseg.Slice"))]);
        let gaps = &mut rec.channels.get_mut(&0).unwrap().gaps;
        // 0, 1, 2, 4, 4 (published again), 7: sequences 3, 5 and 6 are missing.
        for seq in [0, 1, 2, 4, 4, 7] {
            gaps.add(seq);
        }
        assert_eq!((gaps.missing, gaps.first_missing), (3, Some(3)));
        let err = check_channels(&rec, &[wanted("slicer/slices", "evseg.Slice")]).unwrap_err();
        assert!(
            matches!(
                err,
                ReplayError::Gap {
                    missing: 3,
                    first_missing: 3,
                    ..
                }
            ),
            "{err}"
        );
        assert!(
            err.to_string()
                .contains("run.mcap: channel `slicer/slices` lacks 3"),
            "{err}"
        );
    }

    #[test]
    fn a_file_that_is_not_mcap_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("notes.txt");
        std::fs::write(&path, b"not a recording").unwrap();
        let err = check_recording(&path, &[]).unwrap_err().to_string();
        assert!(err.contains("notes.txt"), "{err}");
        let err = check_recording(&dir.path().join("missing.mcap"), &[])
            .unwrap_err()
            .to_string();
        assert!(err.contains("missing.mcap"), "{err}");
    }
}
