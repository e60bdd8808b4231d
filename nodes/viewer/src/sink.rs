//! Where the visualisation goes: an .rrd file or a running Rerun viewer.

use std::path::PathBuf;

use rerun::{RecordingStream, RecordingStreamBuilder};

use crate::error::ViewError;

/// Rerun application id of every evseg recording (the viewer groups recordings by it).
pub const APPLICATION_ID: &str = "evseg";

/// Destination of a recording stream.
#[derive(Debug, Clone, PartialEq)]
pub enum Sink {
    /// An .rrd file (parent folders are created), opened later with `rerun FILE.rrd`.
    File(PathBuf),
    /// A running viewer's gRPC proxy URL, e.g. `rerun+http://127.0.0.1:9876/proxy` (what
    /// `rerun` listens on by default).
    Grpc(String),
}

impl std::fmt::Display for Sink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::File(p) => write!(f, "{}", p.display()),
            Self::Grpc(u) => write!(f, "{u}"),
        }
    }
}

/// Opens a recording stream named `recording_name` (shown in the viewer) to `sink`.
pub fn open(sink: &Sink, recording_name: &str) -> Result<RecordingStream, ViewError> {
    let builder = RecordingStreamBuilder::new(APPLICATION_ID).recording_name(recording_name);
    let opened = match sink {
        Sink::File(path) => {
            if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                std::fs::create_dir_all(dir).map_err(|source| ViewError::Io {
                    file: dir.to_path_buf(),
                    source,
                })?;
            }
            builder.save(path)
        }
        Sink::Grpc(url) => builder.connect_grpc_opts(url.clone()),
    };
    opened.map_err(|source| ViewError::Open {
        sink: sink.to_string(),
        source,
    })
}
