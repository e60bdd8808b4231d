//! Feeding encoded evseg frames (as they travel on the wire and are stored in recordings) to a
//! [`RunLogger`]: the one entry point of both the live node and `evseg view`.

use evseg_schemas::{
    Clusters, CoarseSegmentation, Message, Metrics, NormalFlow, Segmentation, Slice, Tracks, Truth, codec,
};

use crate::error::ViewError;
use crate::logger::{Origin, RunLogger};

/// Decodes `frame` (envelope and body) produced by node `producer` and logs it. Frames of a
/// schema the viewer does not draw, end-of-stream frames and frames that do not decode are
/// counted in the logger's statistics, never an error; errors are Rerun's only.
pub fn log_frame(logger: &mut RunLogger, producer: &str, frame: &[u8]) -> Result<(), ViewError> {
    let envelope = match codec::decode_header(frame) {
        Ok((e, _)) => e,
        Err(e) => {
            logger.skipped(Some(format!("{producer}: frame header: {e}")));
            return Ok(());
        }
    };
    let origin = Origin {
        producer,
        seq: envelope.seq,
        t_start: envelope.t_start,
        t_end: envelope.t_end,
    };
    macro_rules! body {
        ($t:ty) => {
            match codec::decode::<$t>(frame) {
                Ok(f) => match f.body {
                    Some(b) => b,
                    // End of stream.
                    None => return Ok(()),
                },
                Err(e) => {
                    logger.skipped(Some(format!("{producer} message {}: {e}", envelope.seq)));
                    return Ok(());
                }
            }
        };
    }
    match envelope.schema.as_str() {
        Slice::SCHEMA => logger.slice(&origin, &body!(Slice)),
        Tracks::SCHEMA => logger.tracks(&origin, &body!(Tracks)),
        Segmentation::SCHEMA => logger.segmentation(&origin, &body!(Segmentation)),
        NormalFlow::SCHEMA => logger.flow(&origin, &body!(NormalFlow)),
        Truth::SCHEMA => logger.truth(&origin, &body!(Truth)),
        Metrics::SCHEMA => logger.metrics(&origin, &body!(Metrics)),
        Clusters::SCHEMA => {
            let c = body!(Clusters);
            let label =
                c.id.iter()
                    .map(|&i| if i == u16::MAX { u32::MAX } else { u32::from(i) + 1 })
                    .collect();
            logger.labels(&origin, label)
        }
        CoarseSegmentation::SCHEMA => logger.labels(&origin, body!(CoarseSegmentation).group),
        other => {
            let known = evseg_schemas::schema_version(other) == Some(envelope.version);
            logger.skipped((!known).then(|| {
                format!(
                    "{producer} message {}: unknown schema {other} v{}",
                    envelope.seq, envelope.version
                )
            }));
            Ok(())
        }
    }
}
