//! Errors of the viewer library.

use std::path::PathBuf;

/// What can go wrong when visualising a run.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    /// The Rerun recording stream could not be created (file not writable, bad gRPC URL, ...).
    #[error("rerun sink {sink}: {source}")]
    Open {
        /// The sink as the user gave it (file path or URL).
        sink: String,
        /// Rerun's error.
        source: rerun::RecordingStreamError,
    },
    /// Logging to the Rerun stream failed.
    #[error("rerun: logging {entity}: {source}")]
    Log {
        /// Entity path being logged.
        entity: String,
        /// Rerun's error.
        source: rerun::RecordingStreamError,
    },
    /// Flushing the Rerun stream (writing the file, sending to the viewer) failed.
    #[error("rerun sink {sink}: flush: {reason}")]
    Flush {
        /// The sink.
        sink: String,
        /// What went wrong.
        reason: String,
    },
    /// A viewer parameter is out of range.
    #[error("viewer parameter `{name}`: {reason}")]
    Param {
        /// Parameter name.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// Reading the MCAP recording failed.
    #[error(transparent)]
    Recording(#[from] evseg_recorder::RecordError),
    /// The output file could not be prepared (its folder created).
    #[error("{}: {source}", file.display())]
    Io {
        /// The file or folder.
        file: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
}
