//! Errors of replaying a recording.

use std::path::PathBuf;

/// What can go wrong replaying a recording.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The recording could not be read at all (missing file, not MCAP, I/O error).
    #[error(transparent)]
    Read(#[from] evseg_recorder::RecordError),
    /// The recording has no channel for an output the replay must publish.
    #[error(
        "{}: no channel `{topic}` ({schema}), needed to replay it to {needed_by}; the recording has {available:?} (record the original run with all outputs: `evseg run --record`)",
        file.display()
    )]
    MissingChannel {
        /// The recording.
        file: PathBuf,
        /// Topic `node/output`.
        topic: String,
        /// Schema the graph expects on it.
        schema: String,
        /// Who consumes it in the replayed graph (`node.port`, ...).
        needed_by: String,
        /// Topics the recording has.
        available: Vec<String>,
    },
    /// A channel carries another schema (or schema version, or encoding) than the graph expects.
    #[error("{}: channel `{topic}` holds {found}, but the graph expects {expected}", file.display())]
    WrongSchema {
        /// The recording.
        file: PathBuf,
        /// Topic `node/output`.
        topic: String,
        /// What the graph expects (`evseg.Slice v2`, encoding).
        expected: String,
        /// What the channel holds.
        found: String,
    },
    /// A channel skips sequence numbers: the replayed stages, in lock-step, would wait for them.
    #[error(
        "{}: channel `{topic}` lacks {missing} message(s), from sequence {first_missing} on (a message lost before the recorder, a live-mode drop, or one cut out of the file); a lock-step replay would wait for them. `evseg replay --skip-gaps` replays the slices every replayed channel holds, renumbered",
        file.display()
    )]
    Gap {
        /// The recording.
        file: PathBuf,
        /// Topic `node/output`.
        topic: String,
        /// Sequence numbers missing.
        missing: u64,
        /// The first one.
        first_missing: u32,
    },
    /// A recorded message is not a data frame of its channel's schema.
    #[error("{}: channel `{topic}`, message {index}: {reason}", file.display())]
    BadFrame {
        /// The recording.
        file: PathBuf,
        /// Topic `node/output`.
        topic: String,
        /// Index of the message on its channel, from 0.
        index: u64,
        /// What is wrong.
        reason: String,
    },
    /// A replay parameter is missing or wrong.
    #[error("replay parameter `{name}`: {reason}")]
    Param {
        /// Parameter name.
        name: String,
        /// What is wrong.
        reason: String,
    },
}
