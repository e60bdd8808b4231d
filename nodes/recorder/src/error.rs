//! Errors of recording, reading and exporting.

use std::path::PathBuf;

/// What can go wrong with a recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// A file could not be read or written.
    #[error("{}: {source}", file.display())]
    Io {
        /// The file.
        file: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// The MCAP writer failed.
    #[error("{}: mcap: {source}", file.display())]
    Mcap {
        /// The file.
        file: PathBuf,
        /// The mcap crate's error.
        source: mcap::McapError,
    },
    /// The file does not start with the MCAP magic bytes.
    #[error("{}: not an MCAP file (byte 0: expected the MCAP magic \\x89MCAP0\\r\\n)", file.display())]
    NotMcap {
        /// The file.
        file: PathBuf,
    },
    /// A frame was written to a port the recording has no channel for (a bug of the caller).
    #[error("{}: no channel for input port {port}", file.display())]
    NoChannel {
        /// The file.
        file: PathBuf,
        /// The port index.
        port: usize,
    },
    /// A recorder parameter is missing or wrong.
    #[error("recorder parameter `{name}`: {reason}")]
    Param {
        /// Parameter name.
        name: String,
        /// What is wrong.
        reason: String,
    },
}
