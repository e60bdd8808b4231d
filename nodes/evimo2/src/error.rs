//! The crate's error type. Every variant names the file (and the member inside an `.npz`, written
//! as `archive.npz[member.npy]`) so a user can find the bad input.

/// What went wrong reading or writing an EVIMO2 folder.
#[derive(Debug, thiserror::Error)]
pub enum Evimo2Error {
    /// The operating system refused a read, write, open or seek.
    #[error("{file}: {source}")]
    Io {
        /// The file (path as given).
        file: String,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A byte-level format problem at a known position (npy header, truncated data, pickle).
    #[error("{file}: byte {offset}: {message}")]
    Format {
        /// The file, or `archive.npz[member]`.
        file: String,
        /// Byte offset from the start of the file or member.
        offset: u64,
        /// What was wrong.
        message: String,
    },
    /// Well-formed bytes with the wrong content (dtype, shape, mismatched lengths, ...).
    #[error("{file}: {message}")]
    Invalid {
        /// The file(s) concerned.
        file: String,
        /// What was wrong.
        message: String,
    },
    /// The file is not a zip archive or a member could not be decompressed.
    #[error("{file}: zip archive error: {source}")]
    Zip {
        /// The `.npz` file (and member if known).
        file: String,
        /// The zip library's error.
        #[source]
        source: zip::result::ZipError,
    },
    /// An expected `.npy` member is absent from an `.npz`.
    #[error("{file}: no member '{member}' (members: {available})")]
    MissingMember {
        /// The `.npz` file.
        file: String,
        /// The member looked for.
        member: String,
        /// The members present, comma separated (first 20).
        available: String,
    },
    /// `meta` was read but a field is missing or has the wrong type.
    #[error("{file}: meta{path}: {message}")]
    Meta {
        /// `dataset_info.npz[meta.npy]`.
        file: String,
        /// Python-style path to the field, e.g. `['meta']['fx']`.
        path: String,
        /// What was wrong.
        message: String,
    },
    /// The requested IMU topic is not in the meta.
    #[error("{file}: IMU topic '{wanted}' not in meta['imu'] (available: {available})")]
    ImuTopic {
        /// `dataset_info.npz[meta.npy]`.
        file: String,
        /// The topic asked for.
        wanted: String,
        /// The topics present, comma separated.
        available: String,
    },
    /// Data handed to the writer is inconsistent.
    #[error("cannot write {file}: {message}")]
    BadInput {
        /// The file that would have been written.
        file: String,
        /// What was wrong.
        message: String,
    },
}

/// Result with [`Evimo2Error`].
pub type Result<T> = std::result::Result<T, Evimo2Error>;

impl Evimo2Error {
    pub(crate) fn io(file: impl std::fmt::Display, source: std::io::Error) -> Self {
        Evimo2Error::Io {
            file: file.to_string(),
            source,
        }
    }

    pub(crate) fn format(file: impl std::fmt::Display, offset: u64, message: impl Into<String>) -> Self {
        Evimo2Error::Format {
            file: file.to_string(),
            offset,
            message: message.into(),
        }
    }

    pub(crate) fn invalid(file: impl std::fmt::Display, message: impl Into<String>) -> Self {
        Evimo2Error::Invalid {
            file: file.to_string(),
            message: message.into(),
        }
    }
}
