//! The error type of every decoder: each variant names the file and, where it makes sense, the byte
//! offset (binary formats) or the line (text formats) of the fault.

use std::path::PathBuf;

/// Why a file could not be opened or decoded.
///
/// A decoder that meets a fault first delivers every complete event decoded before it (see
/// [`crate::EventDecoder::next_chunk`]), then returns one of these.
#[derive(Debug, thiserror::Error)]
pub enum DecodeError {
    /// The operating system refused to open or read the file.
    #[error("{}: read error at byte {offset}: {source}", .path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// Byte offset of the read that failed.
        offset: u64,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The file ends in the middle of a record (word, event, packet, header).
    #[error("{}: truncated at byte {offset}: {what}", .path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Byte offset of the start of the incomplete record.
        offset: u64,
        /// What was being read.
        what: String,
    },
    /// Bytes that the format does not allow (bad magic, impossible size, coordinate outside the
    /// sensor, undecodable compressed data, ...).
    #[error("{}: corrupt data at byte {offset}: {what}", .path.display())]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Byte offset of the faulty record.
        offset: u64,
        /// What is wrong.
        what: String,
    },
    /// A malformed line of a text file.
    #[error("{}:{line}: {what}", .path.display())]
    BadLine {
        /// The file.
        path: PathBuf,
        /// Line number, starting at 1.
        line: u64,
        /// What is wrong.
        what: String,
    },
    /// The file is not in a format (or a variant of a format) that this crate decodes, or the
    /// options given cannot apply to it.
    #[error("{}: {what}", .path.display())]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// What is missing or unsupported.
        what: String,
    },
}

impl DecodeError {
    /// The file the error is about.
    pub fn path(&self) -> &std::path::Path {
        match self {
            DecodeError::Io { path, .. }
            | DecodeError::Truncated { path, .. }
            | DecodeError::Corrupt { path, .. }
            | DecodeError::BadLine { path, .. }
            | DecodeError::Unsupported { path, .. } => path,
        }
    }

    /// The byte offset of the fault, for binary formats.
    pub fn offset(&self) -> Option<u64> {
        match self {
            DecodeError::Io { offset, .. }
            | DecodeError::Truncated { offset, .. }
            | DecodeError::Corrupt { offset, .. } => Some(*offset),
            DecodeError::BadLine { .. } | DecodeError::Unsupported { .. } => None,
        }
    }
}
