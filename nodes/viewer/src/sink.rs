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
        Sink::Grpc(url) => {
            probe(url)?;
            builder.connect_grpc_opts(url.clone())
        }
    };
    opened.map_err(|source| ViewError::Open {
        sink: sink.to_string(),
        source,
    })
}

/// How long [`probe`] waits for a viewer's port to accept a connection.
const PROBE_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(3);

/// Checks that something accepts TCP connections at the host and port of viewer URL `url`
/// (`rerun+http://HOST:PORT/proxy`). Rerun's stream connects lazily and buffers while it
/// cannot, so without this a run to a viewer that is not there would stall its lock-step graph
/// with no word of the URL.
fn probe(url: &str) -> Result<(), ViewError> {
    use std::net::{TcpStream, ToSocketAddrs};
    let bad = |reason: String| ViewError::Param {
        name: "connect".into(),
        reason,
    };
    let rest = url.split_once("://").map_or(url, |(_, rest)| rest);
    let authority = rest.split('/').next().unwrap_or_default();
    if authority.is_empty() {
        return Err(bad(format!("{url} names no host and port")));
    }
    // A URL without a port is Rerun's to refuse (it has its own defaults).
    let Ok(addrs) = authority.to_socket_addrs() else {
        return Ok(());
    };
    let mut last = None;
    for addr in addrs {
        match TcpStream::connect_timeout(&addr, PROBE_TIMEOUT) {
            Ok(_) => return Ok(()),
            Err(e) => last = Some(format!("{addr}: {e}")),
        }
    }
    Err(bad(format!(
        "cannot reach {url} ({}); start a Rerun viewer there first (`rerun` serves rerun+http://127.0.0.1:9876/proxy)",
        last.unwrap_or_else(|| format!("{authority} resolves to no address"))
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_viewer_url_nobody_listens_on_is_refused_naming_it() {
        // A port that was free a moment ago: nobody listens there.
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .map(|a| a.port())
            .unwrap();
        let url = format!("rerun+http://127.0.0.1:{port}/proxy");
        let e = probe(&url).unwrap_err().to_string();
        assert!(
            e.contains("connect") && e.contains(&url) && e.contains("cannot reach"),
            "{e}"
        );
        // One that listens passes.
        let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
        let port = listener.local_addr().unwrap().port();
        probe(&format!("rerun+http://127.0.0.1:{port}/proxy")).unwrap();
        assert!(probe("rerun+http:///proxy").is_err());
    }
}
