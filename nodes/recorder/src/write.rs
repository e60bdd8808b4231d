//! Writing a recording: one MCAP channel per recorded node output, each message the exact
//! frame (envelope and body) that travelled on the wire.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use evseg_schemas::Envelope;

use crate::error::RecordError;
use crate::{MESSAGE_ENCODING, SCHEMA_ENCODING};

/// One recorded output: an MCAP channel.
#[derive(Debug, Clone, PartialEq)]
pub struct ChannelSpec {
    /// Topic: `node/output`.
    pub topic: String,
    /// Schema name of its messages (`evseg.Slice`, ...).
    pub schema: String,
    /// Schema version written in the channel metadata (`schema_version`); 0 when unknown.
    pub version: u16,
    /// Extra channel metadata (the Zenoh key, the producer), written as given.
    pub metadata: BTreeMap<String, String>,
}

/// Settings of the MCAP writer.
#[derive(Debug, Clone, PartialEq)]
pub struct WriterSettings {
    /// Target uncompressed chunk size, bytes. Default 1 MiB, the mcap crate's own default: small
    /// enough that a cut-off recording loses little, large enough to compress well. A message
    /// larger than this gets a chunk of its own.
    pub chunk_bytes: u64,
    /// zstd compression level (0 = zstd's default, level 3).
    pub zstd_level: u32,
}

impl Default for WriterSettings {
    fn default() -> Self {
        Self {
            chunk_bytes: mcap::WriteOptions::DEFAULT_CHUNK_SIZE,
            zstd_level: 0,
        }
    }
}

impl WriterSettings {
    /// Checks both settings against [`evseg_schemas::recording::CHUNK_BYTES_RANGE`] and
    /// [`evseg_schemas::recording::ZSTD_LEVEL_RANGE`]; on error, the setting's name and why.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        let chunk = evseg_schemas::recording::CHUNK_BYTES_RANGE;
        if !chunk.contains(&self.chunk_bytes) {
            return Err((
                "chunk_bytes",
                format!(
                    "{} bytes is outside {}..={} (1 KiB to 1 GiB)",
                    self.chunk_bytes,
                    chunk.start(),
                    chunk.end()
                ),
            ));
        }
        let zstd = evseg_schemas::recording::ZSTD_LEVEL_RANGE;
        if !zstd.contains(&self.zstd_level) {
            return Err((
                "zstd_level",
                format!("{} is outside {}..={}", self.zstd_level, zstd.start(), zstd.end()),
            ));
        }
        Ok(())
    }
}

/// An MCAP file being written.
pub struct McapRecorder {
    path: PathBuf,
    writer: mcap::Writer<BufWriter<File>>,
    channels: Vec<u16>,
    counts: Vec<u64>,
}

/// The text stored as each schema's data: how to decode the messages of that schema.
pub fn schema_text(name: &str, version: u16) -> String {
    format!(
        "{name} v{version}: each message is an evseg frame, an evseg.Envelope then the body, both \
         bincode 2 via serde (standard configuration: little endian, variable-length integers); \
         Rust definitions in crate evseg-schemas (schemas/src/messages.rs, schemas/src/codec.rs), \
         decode with evseg_schemas::codec::decode::<T>."
    )
}

impl McapRecorder {
    /// Creates `path` (parent folders too) with one channel per entry of `channels` (in order;
    /// port `i` of [`Self::write_frame`] is `channels[i]`), zstd-compressed chunks; refuses `settings` outside their ranges ([`WriterSettings::check`]).
    pub fn create(
        path: &Path,
        channels: &[ChannelSpec],
        settings: &WriterSettings,
    ) -> Result<Self, RecordError> {
        let io = |e: std::io::Error| RecordError::Io {
            file: path.to_path_buf(),
            source: e,
        };
        let mc = |e: mcap::McapError| RecordError::Mcap {
            file: path.to_path_buf(),
            source: e,
        };
        settings.check().map_err(|(name, reason)| RecordError::Param {
            name: name.into(),
            reason,
        })?;
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let file = File::create(path).map_err(io)?;
        let mut writer = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(settings.zstd_level)
            // One compression thread: the machine is shared with the graph's own nodes.
            .compression_threads(0)
            .chunk_size(Some(settings.chunk_bytes))
            .profile("evseg")
            .create(BufWriter::new(file))
            .map_err(mc)?;
        let mut schema_ids: BTreeMap<(String, u16), u16> = BTreeMap::new();
        let mut ids = Vec::new();
        for c in channels {
            let key = (c.schema.clone(), c.version);
            let schema_id = match schema_ids.get(&key) {
                Some(id) => *id,
                None => {
                    let id = writer
                        .add_schema(
                            &c.schema,
                            SCHEMA_ENCODING,
                            schema_text(&c.schema, c.version).as_bytes(),
                        )
                        .map_err(mc)?;
                    schema_ids.insert(key, id);
                    id
                }
            };
            let mut metadata = c.metadata.clone();
            metadata.insert("schema_version".into(), c.version.to_string());
            let id = writer
                .add_channel(schema_id, &c.topic, MESSAGE_ENCODING, &metadata)
                .map_err(mc)?;
            ids.push(id);
        }
        Ok(Self {
            path: path.to_path_buf(),
            writer,
            counts: vec![0; ids.len()],
            channels: ids,
        })
    }

    fn mcap_err(&self, e: mcap::McapError) -> RecordError {
        RecordError::Mcap {
            file: self.path.clone(),
            source: e,
        }
    }

    /// Writes a metadata record `name` with string entries.
    pub fn metadata(&mut self, name: &str, entries: BTreeMap<String, String>) -> Result<(), RecordError> {
        self.writer
            .write_metadata(&mcap::records::Metadata {
                name: name.to_string(),
                metadata: entries,
            })
            .map_err(|e| self.mcap_err(e))
    }

    /// Writes an attachment (a file stored in the recording), `time_ns` = wall clock, ns since
    /// the Unix epoch.
    pub fn attach(
        &mut self,
        name: &str,
        media_type: &str,
        data: &[u8],
        time_ns: u64,
    ) -> Result<(), RecordError> {
        self.writer
            .attach(&mcap::Attachment {
                log_time: time_ns,
                create_time: time_ns,
                name: name.to_string(),
                media_type: media_type.to_string(),
                data: std::borrow::Cow::Borrowed(data),
            })
            .map_err(|e| self.mcap_err(e))
    }

    /// Writes one frame received on channel `port`: the frame bytes unchanged as message data,
    /// log and publish time = the envelope's publish time (ns since the Unix epoch), MCAP
    /// sequence = the envelope's sequence number (saturated to u32).
    pub fn write_frame(&mut self, port: usize, envelope: &Envelope, frame: &[u8]) -> Result<(), RecordError> {
        let Some(&channel_id) = self.channels.get(port) else {
            return Err(RecordError::NoChannel {
                file: self.path.clone(),
                port,
            });
        };
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: u32::try_from(envelope.seq).unwrap_or(u32::MAX),
            log_time: envelope.publish_ns,
            publish_time: envelope.publish_ns,
        };
        self.writer
            .write_to_known_channel(&header, frame)
            .map_err(|e| self.mcap_err(e))?;
        self.counts[port] += 1;
        Ok(())
    }

    /// Messages written per channel, in channel order.
    pub fn counts(&self) -> &[u64] {
        &self.counts
    }

    /// Writes the summary and footer and flushes the file.
    pub fn finish(mut self) -> Result<(), RecordError> {
        self.writer.finish().map_err(|e| self.mcap_err(e))?;
        let path = self.path.clone();
        let mut inner = self.writer.into_inner();
        std::io::Write::flush(&mut inner).map_err(|e| RecordError::Io {
            file: path,
            source: e,
        })
    }
}
