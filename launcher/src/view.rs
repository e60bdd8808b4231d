//! `evseg view run.mcap [--out run.rrd | --connect URL]`: a recording turned into a Rerun
//! recording (events coloured by segment, flow direction and truth; tracks; egomotion and
//! metrics as time series), through the same library as the live `evseg-viewer` node.

use std::path::{Path, PathBuf};

use evseg_viewer::{Sink, ViewSummary, ViewerParams, view_recording};

/// Where `evseg view` writes: `--connect` URL, else `--out`, else the recording's path with
/// the extension `.rrd`.
pub fn sink(recording: &Path, out: Option<PathBuf>, connect: Option<String>) -> Sink {
    match (connect, out) {
        (Some(url), _) => Sink::Grpc(url),
        (None, Some(p)) => Sink::File(p),
        (None, None) => Sink::File(recording.with_extension("rrd")),
    }
}

/// Converts `recording` to `sink`; returns the text to print.
pub fn view(recording: &Path, sink: &Sink, max_points_per_slice: Option<usize>) -> anyhow::Result<String> {
    let mut params = ViewerParams::default();
    if let Some(n) = max_points_per_slice {
        params.max_points_per_slice = n;
    }
    let summary = view_recording(recording, sink, &params)?;
    Ok(describe(&summary, sink))
}

/// The text `evseg view` prints.
pub fn describe(s: &ViewSummary, sink: &Sink) -> String {
    let st = &s.stats;
    let mut text = format!("{}\n", s.recording.completeness());
    match &s.slices_from {
        Some(p) => text.push_str(&format!(
            "{} slices of `{p}` ({} events, {} drawn per layer), {} per-event layers, {} boxes, {} scalar \
             samples\n",
            st.slices, st.events, st.points_per_layer, st.layers, st.boxes, st.scalars
        )),
        None => text.push_str("no evseg.Slice channel: no events drawn\n"),
    }
    let skipped = [
        (st.unmatched, "per-event messages without their slice"),
        (
            st.misaligned,
            "per-event messages of another length than their slice",
        ),
        (
            st.unaligned_truth,
            "truth messages of a node other than the slices' (not aligned)",
        ),
        (st.other_slices, "slices of a second slice stream"),
        (
            st.not_drawn - st.undecodable,
            "messages of a schema that is not drawn",
        ),
        (st.undecodable, "undecodable messages"),
    ];
    for (n, what) in skipped {
        if n > 0 {
            text.push_str(&format!("  skipped: {n} {what}\n"));
        }
    }
    if let Some(p) = &st.first_problem {
        text.push_str(&format!("  first problem: {p}\n"));
    }
    match sink {
        Sink::File(p) => {
            let size = std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
            text.push_str(&format!(
                "wrote {} ({size} bytes); open it with `rerun {}`",
                p.display(),
                p.display()
            ));
        }
        Sink::Grpc(url) => text.push_str(&format!("streamed to {url}")),
    }
    text
}
