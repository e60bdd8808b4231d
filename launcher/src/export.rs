//! `evseg export run.mcap --out DIR`: NumPy files for analysis in Python.

use std::path::Path;

use evseg_recorder::export::export as export_recording;

/// Exports `path` into `out`; returns the text to print (files written, what was skipped).
pub fn export(path: &Path, out: &Path) -> anyhow::Result<String> {
    let summary = export_recording(path, out)?;
    let mut s = format!("{}\n", summary.recording.completeness());
    for f in &summary.files {
        s.push_str(&format!(
            "  {} ({} rows x {} columns, {} from {})\n",
            out.join(&f.file).display(),
            f.shape[0],
            f.shape[1],
            f.schema,
            f.topic
        ));
    }
    for (topic, n) in &summary.not_exported {
        s.push_str(&format!(
            "  not exported from {topic}: {} of a schema without export, {} of an unknown schema or \
             version, {} undecodable{}\n",
            n.other_schema,
            n.unknown_schema,
            n.undecodable,
            n.first_problem
                .as_ref()
                .map(|p| format!(" (first: {p})"))
                .unwrap_or_default()
        ));
    }
    s.push_str(&format!(
        "columns and units: {}",
        out.join("README.txt").display()
    ));
    Ok(s)
}
