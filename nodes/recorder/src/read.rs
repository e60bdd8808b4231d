//! Reading a recording record by record, so that a file cut off mid-write (its writer killed)
//! is read up to its last complete chunk, and the reader says where and why it stopped.
//!
//! The file is walked from the start (the summary section at the end is not needed): top-level
//! records are checked for a complete length before they are parsed, and a chunk's messages are
//! only handed out once the whole chunk has been decompressed and parsed.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mcap::records::Record;

use crate::error::RecordError;

/// A schema of the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct SchemaInfo {
    /// Schema name (`evseg.Slice`, ...).
    pub name: String,
    /// Schema encoding.
    pub encoding: String,
}

/// A channel of the recording and what was read of it.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelInfo {
    /// MCAP channel id.
    pub id: u16,
    /// Topic (`node/output`).
    pub topic: String,
    /// Schema name ("" when the channel has none).
    pub schema: String,
    /// Schema version from the channel metadata (`schema_version`), if present and a number.
    pub version: Option<u16>,
    /// Message encoding.
    pub message_encoding: String,
    /// Channel metadata.
    pub metadata: BTreeMap<String, String>,
    /// Messages read.
    pub messages: u64,
    /// Bytes of message data read.
    pub bytes: u64,
    /// Earliest and latest log time, ns since the Unix epoch (`None` when no message).
    pub time_ns: Option<(u64, u64)>,
    /// Sequence numbers skipped between consecutive messages of the channel (in file order: a
    /// message lost on its way to the recorder, a live-mode drop, or one cut out of the file),
    /// with the first one skipped. A replay in lock-step would wait for them.
    pub gaps: SequenceGaps,
}

/// Sequence numbers missing from a channel (see [`ChannelInfo::gaps`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SequenceGaps {
    /// Highest sequence number read so far.
    pub last: Option<u32>,
    /// Sequence numbers skipped.
    pub missing: u64,
    /// The first one skipped.
    pub first_missing: Option<u32>,
}

impl SequenceGaps {
    /// Takes the next message's sequence number (a repeated or older one, as a message
    /// published again, skips nothing).
    pub fn add(&mut self, seq: u32) {
        if let Some(last) = self.last {
            if seq > last.saturating_add(1) {
                self.missing += u64::from(seq - last - 1);
                self.first_missing.get_or_insert(last + 1);
            }
            if seq <= last {
                return;
            }
        }
        self.last = Some(seq);
    }
}

/// An attachment of the recording.
#[derive(Debug, Clone, PartialEq)]
pub struct AttachmentInfo {
    /// File name.
    pub name: String,
    /// Media type.
    pub media_type: String,
    /// Contents.
    pub data: Vec<u8>,
}

/// Where and why reading stopped before the footer.
#[derive(Debug, Clone, PartialEq)]
pub struct Truncation {
    /// Byte offset of the first record that could not be read.
    pub offset: u64,
    /// What was wrong with it.
    pub reason: String,
}

/// Everything read from a recording except the messages themselves.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The file.
    pub file: PathBuf,
    /// File size, bytes.
    pub size: u64,
    /// Channels by id.
    pub channels: BTreeMap<u16, ChannelInfo>,
    /// Metadata records in file order: name and entries.
    pub metadata: Vec<(String, BTreeMap<String, String>)>,
    /// Attachments in file order.
    pub attachments: Vec<AttachmentInfo>,
    /// Complete chunks read.
    pub chunks: u64,
    /// Messages read (all channels).
    pub messages: u64,
    /// Messages on a channel id that was never declared (not handed out).
    pub orphan_messages: u64,
    /// `None` when the file ended with its footer; otherwise where reading stopped.
    pub truncated: Option<Truncation>,
}

impl Recording {
    /// One line on how complete the file is, e.g. for `evseg info`.
    pub fn completeness(&self) -> String {
        match &self.truncated {
            None => format!(
                "{}: complete ({} messages in {} chunks)",
                self.file.display(),
                self.messages,
                self.chunks
            ),
            Some(t) => format!(
                "{}: TRUNCATED at byte {} of {} ({}); recovered {} messages in {} complete chunks",
                self.file.display(),
                t.offset,
                self.size,
                t.reason,
                self.messages,
                self.chunks
            ),
        }
    }

    /// Earliest and latest log time over all channels, ns since the Unix epoch.
    pub fn time_span_ns(&self) -> Option<(u64, u64)> {
        self.channels
            .values()
            .filter_map(|c| c.time_ns)
            .reduce(|a, b| (a.0.min(b.0), a.1.max(b.1)))
    }

    /// The metadata record called `name`, if any (the last one).
    pub fn metadata_named(&self, name: &str) -> Option<&BTreeMap<String, String>> {
        self.metadata
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, m)| m)
    }
}

/// One message handed to the visitor of [`read`].
pub struct MessageRef<'a> {
    /// Its channel.
    pub channel: &'a ChannelInfo,
    /// MCAP sequence number.
    pub sequence: u32,
    /// Log time, ns since the Unix epoch.
    pub log_time: u64,
    /// Message data (for evseg recordings: the frame as it was on the wire).
    pub data: &'a [u8],
}

fn record_name(op: u8) -> &'static str {
    use mcap::records::op;
    match op {
        op::HEADER => "header",
        op::FOOTER => "footer",
        op::SCHEMA => "schema",
        op::CHANNEL => "channel",
        op::MESSAGE => "message",
        op::CHUNK => "chunk",
        op::MESSAGE_INDEX => "message index",
        op::CHUNK_INDEX => "chunk index",
        op::ATTACHMENT => "attachment",
        op::ATTACHMENT_INDEX => "attachment index",
        op::STATISTICS => "statistics",
        op::METADATA => "metadata",
        op::METADATA_INDEX => "metadata index",
        op::SUMMARY_OFFSET => "summary offset",
        op::DATA_END => "data end",
        _ => "unknown",
    }
}

struct Walk<'v, V> {
    rec: Recording,
    schemas: BTreeMap<u16, SchemaInfo>,
    visit: &'v mut V,
}

impl<V: FnMut(MessageRef<'_>) -> Result<(), RecordError>> Walk<'_, V> {
    /// Takes one record (top level or from a chunk).
    fn take(&mut self, record: Record<'_>) -> Result<(), RecordError> {
        match record {
            Record::Schema { header, .. } => {
                self.schemas.insert(
                    header.id,
                    SchemaInfo {
                        name: header.name,
                        encoding: header.encoding,
                    },
                );
            }
            Record::Channel(c) if !self.rec.channels.contains_key(&c.id) => {
                let schema = self
                    .schemas
                    .get(&c.schema_id)
                    .map(|s| s.name.clone())
                    .unwrap_or_default();
                let version = c.metadata.get("schema_version").and_then(|v| v.parse().ok());
                self.rec.channels.insert(
                    c.id,
                    ChannelInfo {
                        id: c.id,
                        topic: c.topic,
                        schema,
                        version,
                        message_encoding: c.message_encoding,
                        metadata: c.metadata,
                        messages: 0,
                        bytes: 0,
                        time_ns: None,
                        gaps: SequenceGaps::default(),
                    },
                );
            }
            Record::Message { header, data } => {
                let Some(channel) = self.rec.channels.get_mut(&header.channel_id) else {
                    self.rec.orphan_messages += 1;
                    return Ok(());
                };
                channel.messages += 1;
                channel.bytes += data.len() as u64;
                channel.gaps.add(header.sequence);
                channel.time_ns = Some(match channel.time_ns {
                    None => (header.log_time, header.log_time),
                    Some((a, b)) => (a.min(header.log_time), b.max(header.log_time)),
                });
                self.rec.messages += 1;
                (self.visit)(MessageRef {
                    channel,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    data: &data,
                })?;
            }
            Record::Metadata(m) => self.rec.metadata.push((m.name, m.metadata)),
            Record::Attachment { header, data, .. } => self.rec.attachments.push(AttachmentInfo {
                name: header.name,
                media_type: header.media_type,
                data: data.into_owned(),
            }),
            _ => {}
        }
        Ok(())
    }
}

/// Reads the recording at `path`, handing every message to `visit` in file order, and returns
/// what was found. A file cut off mid-write is not an error: reading stops at the first
/// incomplete or unreadable record, and [`Recording::truncated`] says at which byte and why.
/// The file is streamed one top-level record (at most one chunk) at a time, so memory does not
/// grow with the file. Errors: the file cannot be read, is not MCAP, or `visit` failed.
pub fn read(
    path: &Path,
    mut visit: impl FnMut(MessageRef<'_>) -> Result<(), RecordError>,
) -> Result<Recording, RecordError> {
    let io = |e: std::io::Error| RecordError::Io {
        file: path.to_path_buf(),
        source: e,
    };
    let file = std::fs::File::open(path).map_err(io)?;
    let size = file.metadata().map_err(io)?.len();
    walk_records(path, std::io::BufReader::new(file), size, &mut visit)
}

/// [`read`] on bytes already in memory (`path` only names them in messages).
pub fn read_bytes(
    path: &Path,
    bytes: &[u8],
    visit: &mut impl FnMut(MessageRef<'_>) -> Result<(), RecordError>,
) -> Result<Recording, RecordError> {
    walk_records(path, bytes, bytes.len() as u64, visit)
}

/// Walks the top-level records of `size` bytes read from `src`.
fn walk_records(
    path: &Path,
    mut src: impl std::io::Read,
    size: u64,
    visit: &mut impl FnMut(MessageRef<'_>) -> Result<(), RecordError>,
) -> Result<Recording, RecordError> {
    let io = |e: std::io::Error| RecordError::Io {
        file: path.to_path_buf(),
        source: e,
    };
    let magic_len = mcap::MAGIC.len() as u64;
    let mut magic = [0u8; 8];
    if size < magic_len || src.read_exact(&mut magic).is_err() || magic[..] != *mcap::MAGIC {
        return Err(RecordError::NotMcap {
            file: path.to_path_buf(),
        });
    }
    let mut walk = Walk {
        rec: Recording {
            file: path.to_path_buf(),
            size,
            channels: BTreeMap::new(),
            metadata: Vec::new(),
            attachments: Vec::new(),
            chunks: 0,
            messages: 0,
            orphan_messages: 0,
            truncated: None,
        },
        schemas: BTreeMap::new(),
        visit,
    };
    let mut pos = magic_len;
    let stop = |offset: u64, reason: String| Some(Truncation { offset, reason });
    let mut body = Vec::new();
    let truncated = loop {
        let left = size - pos;
        if left == 0 {
            break stop(pos, "the file ends without a footer".into());
        }
        if left < 9 {
            break stop(pos, format!("incomplete record header ({left} of 9 bytes)"));
        }
        let mut head = [0u8; 9];
        src.read_exact(&mut head).map_err(io)?;
        let op = head[0];
        let mut len_bytes = [0u8; 8];
        len_bytes.copy_from_slice(&head[1..9]);
        let len = u64::from_le_bytes(len_bytes);
        let name = record_name(op);
        if len == u64::MAX {
            break stop(
                pos,
                format!(
                    "incomplete {name} record: its length was never written (the writer stopped inside it)"
                ),
            );
        }
        if len > left - 9 {
            break stop(
                pos,
                format!("incomplete {name} record: needs {len} bytes, {} left", left - 9),
            );
        }
        // The length is bounded by the file size, so this allocation is too.
        body.resize(len as usize, 0);
        src.read_exact(&mut body).map_err(io)?;
        let record = match mcap::parse_record(op, &body) {
            Ok(r) => r,
            Err(e) => break stop(pos, format!("unreadable {name} record: {e}")),
        };
        match record {
            Record::Footer(_) => {
                let end = pos + 9 + len;
                let mut tail = [0u8; 8];
                if size - end == magic_len && src.read_exact(&mut tail).is_ok() && tail[..] == *mcap::MAGIC {
                    break None;
                }
                break stop(
                    end,
                    "the footer is not followed by the closing magic bytes".into(),
                );
            }
            Record::Chunk { header, data } => {
                let inner: Result<Vec<Record<'_>>, mcap::McapError> =
                    mcap::read::ChunkReader::new(header, &data).and_then(|r| r.collect());
                match inner {
                    Ok(records) => {
                        for r in records {
                            walk.take(r)?;
                        }
                        walk.rec.chunks += 1;
                    }
                    Err(e) => break stop(pos, format!("unreadable chunk: {e}")),
                }
            }
            other => walk.take(other)?,
        }
        pos += 9 + len;
    };
    walk.rec.truncated = truncated;
    Ok(walk.rec)
}
