//! The one wire codec: an [`Envelope`] followed by the message body, both bincode 2 (serde,
//! standard configuration: little endian, variable-length integers).
//!
//! Change the wire format here and nowhere else; the golden-bytes tests pin it.

use serde::{Deserialize, Serialize, de::DeserializeOwned};

/// A message type that can travel between nodes.
pub trait Message: Serialize + DeserializeOwned {
    /// Schema name, `evseg.<Type>`.
    const SCHEMA: &'static str;
    /// Schema version; bump it on any change of the type's fields.
    const VERSION: u16;
}

/// Whether a frame carries data or marks the end of a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameKind {
    /// A message body follows the envelope.
    Data,
    /// End of stream: no body; `seq` is the number of data frames sent before it.
    End,
}

/// The header of every frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Envelope {
    /// Schema name of the body (see [`Message::SCHEMA`]).
    pub schema: String,
    /// Schema version of the body.
    pub version: u16,
    /// Data or end of stream.
    pub kind: FrameKind,
    /// Sequence number: the slice number (or, for a source's batches, the batch number),
    /// counted from 0 on each output.
    pub seq: u64,
    /// Start of the sensor time span covered, seconds on the sequence clock.
    pub t_start: f64,
    /// End of the sensor time span covered (exclusive), seconds on the sequence clock.
    pub t_end: f64,
    /// Wall-clock publish time, ns since the Unix epoch (for latency figures only).
    pub publish_ns: u64,
}

/// A decoded frame: its envelope and, for data frames, its body.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame<T> {
    /// The header.
    pub envelope: Envelope,
    /// The body; `None` for an end-of-stream frame.
    pub body: Option<T>,
}

/// What can go wrong decoding a frame.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    /// The bytes are not a valid envelope.
    #[error("malformed frame header: {0}")]
    Header(String),
    /// The envelope names another schema or version than the receiver expects.
    #[error("schema mismatch: expected {expected} v{expected_version}, got {got} v{got_version}")]
    Mismatch {
        /// Schema the receiver expects.
        expected: &'static str,
        /// Version the receiver expects.
        expected_version: u16,
        /// Schema found in the frame.
        got: String,
        /// Version found in the frame.
        got_version: u16,
    },
    /// The body does not decode as the declared schema.
    #[error("malformed {schema} body: {reason}")]
    Body {
        /// Schema of the body.
        schema: &'static str,
        /// Decoder's message.
        reason: String,
    },
    /// Bytes left after the body.
    #[error("{extra} trailing bytes after the {schema} body")]
    Trailing {
        /// Schema of the body.
        schema: &'static str,
        /// Number of extra bytes.
        extra: usize,
    },
    /// Encoding failed (should not happen for the pipeline's types).
    #[error("cannot encode {schema}: {reason}")]
    Encode {
        /// Schema being encoded.
        schema: &'static str,
        /// Encoder's message.
        reason: String,
    },
}

fn config() -> bincode::config::Configuration {
    bincode::config::standard()
}

/// Upper bound on a decoded frame's allocations, bytes (guards against corrupt length fields).
pub const MAX_FRAME_BYTES: usize = 1 << 31;

fn now_ns() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos() as u64)
        .unwrap_or(0)
}

/// The envelope of a data frame of schema `T` with sequence number `seq` and time span
/// `[t_start, t_end)` seconds, stamped with the current wall-clock time.
pub fn data_envelope<T: Message>(seq: u64, t_start: f64, t_end: f64) -> Envelope {
    Envelope {
        schema: T::SCHEMA.to_string(),
        version: T::VERSION,
        kind: FrameKind::Data,
        seq,
        t_start,
        t_end,
        publish_ns: now_ns(),
    }
}

/// Encodes a data frame for `body` with sequence number `seq` and time span
/// `[t_start, t_end)` seconds.
pub fn encode<T: Message>(seq: u64, t_start: f64, t_end: f64, body: &T) -> Result<Vec<u8>, CodecError> {
    encode_with(&data_envelope::<T>(seq, t_start, t_end), Some(body))
}

/// Encodes an end-of-stream frame for schema `T` after `count` data frames.
pub fn encode_end<T: Message>(count: u64, t_end: f64) -> Result<Vec<u8>, CodecError> {
    let envelope = Envelope {
        schema: T::SCHEMA.to_string(),
        version: T::VERSION,
        kind: FrameKind::End,
        seq: count,
        t_start: t_end,
        t_end,
        publish_ns: now_ns(),
    };
    encode_with::<T>(&envelope, None)
}

/// Encodes an end-of-stream frame for a schema known only by name (the runtime ends ports whose
/// Rust type it does not know); the version is the schema's current one, 0 if unknown.
pub fn encode_end_named(schema: &str, count: u64, t_end: f64) -> Result<Vec<u8>, CodecError> {
    let envelope = Envelope {
        schema: schema.to_string(),
        version: crate::messages::schema_version(schema).unwrap_or(0),
        kind: FrameKind::End,
        seq: count,
        t_start: t_end,
        t_end,
        publish_ns: now_ns(),
    };
    bincode::serde::encode_to_vec(&envelope, config()).map_err(|e| CodecError::Encode {
        schema: "evseg.End",
        reason: e.to_string(),
    })
}

/// Encodes a frame from an explicit envelope (used by replay, which keeps recorded envelopes).
///
/// The frame's length is counted first and the buffer allocated once: a slice of 100k events
/// is 1.3 MB, and growing the buffer by doubling (then appending the body to the header) copied
/// it three more times on every hop.
pub fn encode_with<T: Message>(envelope: &Envelope, body: Option<&T>) -> Result<Vec<u8>, CodecError> {
    let len = encoded_len(envelope, body)?;
    let mut out = Vec::with_capacity(len);
    write_frame(envelope, body, &mut out)?;
    Ok(out)
}

/// Length in bytes of the frame [`encode_with`] would produce (counted, nothing is allocated).
pub fn encoded_len<T: Message>(envelope: &Envelope, body: Option<&T>) -> Result<usize, CodecError> {
    let err = |e: bincode::error::EncodeError| CodecError::Encode {
        schema: T::SCHEMA,
        reason: e.to_string(),
    };
    let mut size = bincode::enc::write::SizeWriter::default();
    bincode::serde::encode_into_writer(envelope, &mut size, config()).map_err(err)?;
    if let Some(body) = body {
        bincode::serde::encode_into_writer(body, &mut size, config()).map_err(err)?;
    }
    Ok(size.bytes_written)
}

/// Writes the frame of [`encode_with`] into `dst`, which must hold exactly
/// [`encoded_len`] bytes (a shared-memory buffer, for example); returns the bytes written.
pub fn encode_into_slice<T: Message>(
    envelope: &Envelope,
    body: Option<&T>,
    dst: &mut [u8],
) -> Result<usize, CodecError> {
    let err = |e: bincode::error::EncodeError| CodecError::Encode {
        schema: T::SCHEMA,
        reason: e.to_string(),
    };
    let head = bincode::serde::encode_into_slice(envelope, &mut *dst, config()).map_err(err)?;
    let mut used = head;
    if let Some(body) = body {
        let rest = dst.get_mut(head..).unwrap_or_default();
        used += bincode::serde::encode_into_slice(body, rest, config()).map_err(err)?;
    }
    Ok(used)
}

fn write_frame<T: Message>(
    envelope: &Envelope,
    body: Option<&T>,
    out: &mut Vec<u8>,
) -> Result<(), CodecError> {
    let err = |e: bincode::error::EncodeError| CodecError::Encode {
        schema: T::SCHEMA,
        reason: e.to_string(),
    };
    bincode::serde::encode_into_std_write(envelope, out, config()).map_err(err)?;
    if let Some(body) = body {
        bincode::serde::encode_into_std_write(body, out, config()).map_err(err)?;
    }
    Ok(())
}

/// Decodes only the envelope; returns it and the number of header bytes.
pub fn decode_header(bytes: &[u8]) -> Result<(Envelope, usize), CodecError> {
    let cfg = config().with_limit::<MAX_FRAME_BYTES>();
    bincode::serde::decode_from_slice::<Envelope, _>(bytes, cfg)
        .map_err(|e| CodecError::Header(e.to_string()))
}

/// The frame `bytes` with its envelope's sequence number set to `seq` and the body unchanged
/// (byte for byte): what a replay that renumbers recorded slices publishes.
pub fn with_seq(bytes: &[u8], seq: u64) -> Result<Vec<u8>, CodecError> {
    let (mut envelope, head) = decode_header(bytes)?;
    envelope.seq = seq;
    let body = bytes.get(head..).unwrap_or_default();
    let mut out =
        bincode::serde::encode_to_vec(&envelope, config()).map_err(|e| CodecError::Header(e.to_string()))?;
    out.extend_from_slice(body);
    Ok(out)
}

/// Decodes a frame that must carry schema `T` (name and version checked).
pub fn decode<T: Message>(bytes: &[u8]) -> Result<Frame<T>, CodecError> {
    let (envelope, used) = decode_header(bytes)?;
    if envelope.schema != T::SCHEMA || envelope.version != T::VERSION {
        return Err(CodecError::Mismatch {
            expected: T::SCHEMA,
            expected_version: T::VERSION,
            got: envelope.schema,
            got_version: envelope.version,
        });
    }
    if envelope.kind == FrameKind::End {
        return Ok(Frame { envelope, body: None });
    }
    let cfg = config().with_limit::<MAX_FRAME_BYTES>();
    let (body, n) =
        bincode::serde::decode_from_slice::<T, _>(&bytes[used..], cfg).map_err(|e| CodecError::Body {
            schema: T::SCHEMA,
            reason: e.to_string(),
        })?;
    let extra = bytes.len() - used - n;
    if extra != 0 {
        return Err(CodecError::Trailing {
            schema: T::SCHEMA,
            extra,
        });
    }
    Ok(Frame {
        envelope,
        body: Some(body),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::messages::*;

    fn packet() -> EventPacket {
        let mut events = Events::default();
        events.push(0.5, 3, 4, 1);
        events.push(0.75, 300, 2, 0);
        EventPacket {
            camera: CameraInfo {
                width: 640,
                height: 480,
                fx: 320.0,
                fy: 320.0,
                cx: 319.5,
                cy: 239.5,
                distortion: Distortion::RadTan {
                    k1: -0.1,
                    k2: 0.01,
                    p1: 0.0,
                    p2: 0.0,
                    k3: 0.0,
                },
                imu_to_camera: CameraInfo::IDENTITY,
                imu_time_offset_s: 0.0,
                time_origin_us: 1_000_000,
                sensor: "test".into(),
            },
            events,
            imu: vec![ImuSample {
                t: 0.5,
                gyro: [0.0, 0.1, 0.0],
                accel: [0.0, 9.81, 0.0],
            }],
        }
    }

    #[test]
    fn a_frame_renumbered_keeps_its_envelope_and_body() {
        let p = packet();
        // Across the varint size steps of the sequence number (1, 3, 5 and 9 bytes).
        for (from, to) in [(7u64, 300_000u64), (300_000, 3), (250, 1 << 40), (1 << 40, 0)] {
            let bytes = encode(from, 0.5, 0.8, &p).unwrap();
            let again = with_seq(&bytes, to).unwrap();
            let (a, b) = (
                decode::<EventPacket>(&bytes).unwrap(),
                decode::<EventPacket>(&again).unwrap(),
            );
            assert_eq!(
                b.envelope,
                Envelope {
                    seq: to,
                    ..a.envelope
                }
            );
            assert_eq!(b.body, a.body);
        }
        assert!(with_seq(b"not a frame", 1).is_err());
    }

    #[test]
    fn round_trip_data_and_end() {
        let p = packet();
        let bytes = encode(7, 0.5, 0.8, &p).unwrap();
        let frame = decode::<EventPacket>(&bytes).unwrap();
        assert_eq!(frame.envelope.seq, 7);
        assert_eq!(frame.envelope.kind, FrameKind::Data);
        assert_eq!(frame.body.unwrap(), p);
        let end = encode_end::<EventPacket>(8, 3.0).unwrap();
        let frame = decode::<EventPacket>(&end).unwrap();
        assert_eq!(frame.envelope.kind, FrameKind::End);
        assert_eq!(frame.envelope.seq, 8);
        assert!(frame.body.is_none());
    }

    #[test]
    fn counted_length_and_in_place_encoding_match_the_heap_encoding() {
        let p = packet();
        let env = data_envelope::<EventPacket>(4, 0.25, 0.5);
        let heap = encode_with(&env, Some(&p)).unwrap();
        assert_eq!(encoded_len(&env, Some(&p)).unwrap(), heap.len());
        assert_eq!(
            heap.capacity(),
            heap.len(),
            "allocated once, to the counted length"
        );
        let mut dst = vec![0xaa; heap.len()];
        assert_eq!(encode_into_slice(&env, Some(&p), &mut dst).unwrap(), heap.len());
        assert_eq!(dst, heap);
        // A buffer one byte short is an error, not a panic or a cut frame.
        let mut short = vec![0; heap.len() - 1];
        assert!(encode_into_slice(&env, Some(&p), &mut short).is_err());
    }

    #[test]
    fn wrong_schema_names_both() {
        let bytes = encode(0, 0.0, 1.0, &packet()).unwrap();
        let err = decode::<Slice>(&bytes).unwrap_err().to_string();
        assert!(err.contains("evseg.Slice v1"), "{err}");
        assert!(err.contains("evseg.EventPacket v1"), "{err}");
    }

    #[test]
    fn wrong_version_is_refused() {
        let env = Envelope {
            schema: EventPacket::SCHEMA.into(),
            version: 99,
            kind: FrameKind::Data,
            seq: 0,
            t_start: 0.0,
            t_end: 0.0,
            publish_ns: 0,
        };
        let bytes = encode_with(&env, Some(&packet())).unwrap();
        let err = decode::<EventPacket>(&bytes).unwrap_err().to_string();
        assert!(err.contains("v99"), "{err}");
    }

    #[test]
    fn garbage_and_truncation_are_errors_not_panics() {
        assert!(decode::<EventPacket>(&[]).is_err());
        assert!(decode::<EventPacket>(&[0xff; 64]).is_err());
        let bytes = encode(1, 0.0, 1.0, &packet()).unwrap();
        for cut in 0..bytes.len() {
            assert!(decode::<EventPacket>(&bytes[..cut]).is_err(), "cut at {cut}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(matches!(
            decode::<EventPacket>(&longer),
            Err(CodecError::Trailing { .. })
        ));
    }

    #[test]
    fn a_column_of_the_wrong_length_is_an_error() {
        let mut events = Events::default();
        events.push(0.5, 3, 4, 1);
        let mut p = packet();
        p.events = events;
        let mut bytes = encode(0, 0.0, 1.0, &p).unwrap();
        // The x column is "02 03 00"; claim 3 bytes instead of 2 by patching its length byte.
        let pos = bytes.windows(3).rposition(|w| w == [2, 3, 0]).unwrap();
        bytes[pos] = 3;
        bytes.insert(pos + 3, 0);
        let err = decode::<EventPacket>(&bytes).unwrap_err().to_string();
        assert!(err.contains("not a multiple of 2"), "{err}");
    }

    /// Pins the wire format: a change here is a change of every recording and every peer.
    #[test]
    fn golden_bytes() {
        let env = Envelope {
            schema: "evseg.EventPacket".into(),
            version: 1,
            kind: FrameKind::Data,
            seq: 3,
            t_start: 0.5,
            t_end: 1.0,
            publish_ns: 0,
        };
        let mut events = Events::default();
        events.push(0.5, 3, 260, 1);
        let body = EventPacket {
            camera: CameraInfo {
                width: 2,
                height: 1,
                fx: 1.0,
                fy: 1.0,
                cx: 0.0,
                cy: 0.0,
                distortion: Distortion::None,
                imu_to_camera: CameraInfo::IDENTITY,
                imu_time_offset_s: 0.0,
                time_origin_us: -1,
                sensor: "s".into(),
            },
            events,
            imu: vec![],
        };
        let bytes = encode_with(&env, Some(&body)).unwrap();
        let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(
            hex, GOLDEN_EVENT_PACKET,
            "wire format changed; bump versions and update the golden bytes"
        );
    }

    const GOLDEN_EVENT_PACKET: &str = "1165767365672e4576656e745061636b6574010003000000000000e03f000000000000f03f000201000000000000f03f000000000000f03f0000000000000000000000000000000000000000000000f03f000000000000000000000000000000000000000000000000000000000000f03f000000000000000000000000000000000000000000000000000000000000f03f000000000000000001017308000000000000e03f020300020401010100";
}
