//! `evseg info run.mcap`: what a recording holds, and whether it is complete.

use std::path::Path;

use evseg_recorder::read::{Recording, read};

/// Reads `path` (a cut-off file up to its last complete chunk) and describes it.
pub fn info(path: &Path) -> anyhow::Result<String> {
    let rec = read(path, |_| Ok(()))?;
    Ok(describe(&rec))
}

fn seconds(ns: u64) -> f64 {
    ns as f64 * 1e-9
}

/// The text `evseg info` prints for `rec`.
pub fn describe(rec: &Recording) -> String {
    let mut s = format!("{}\nsize {} bytes\n", rec.completeness(), rec.size);
    if let Some((a, b)) = rec.time_span_ns() {
        s.push_str(&format!(
            "time span {:.3} s (publish times {:.3} .. {:.3} s since the Unix epoch)\n",
            seconds(b.saturating_sub(a)),
            seconds(a),
            seconds(b)
        ));
    }
    s.push_str(&format!(
        "\n{:<4} {:<28} {:<22} {:>7} {:>9} {:>12}\n",
        "id", "topic", "schema", "version", "messages", "bytes"
    ));
    for c in rec.channels.values() {
        let version = c.version.map_or_else(|| "?".to_string(), |v| v.to_string());
        s.push_str(&format!(
            "{:<4} {:<28} {:<22} {:>7} {:>9} {:>12}\n",
            c.id, c.topic, c.schema, version, c.messages, c.bytes
        ));
    }
    for c in rec.channels.values() {
        if let Some(first) = c.gaps.first_missing {
            s.push_str(&format!(
                "channel {} lacks {} message(s), from sequence {first} on (lost before the \
                 recorder, dropped in live mode, or cut out of the file): a replay in lock-step \
                 cannot use it\n",
                c.topic, c.gaps.missing
            ));
        }
    }
    if rec.orphan_messages > 0 {
        s.push_str(&format!(
            "{} messages on undeclared channels (skipped)\n",
            rec.orphan_messages
        ));
    }
    for (name, entries) in &rec.metadata {
        s.push_str(&format!("\nmetadata {name}:\n"));
        for (k, v) in entries {
            s.push_str(&format!("  {k}: {v}\n"));
        }
    }
    for a in &rec.attachments {
        s.push_str(&format!(
            "\nattachment {} ({}, {} bytes)\n",
            a.name,
            a.media_type,
            a.data.len()
        ));
    }
    s
}
