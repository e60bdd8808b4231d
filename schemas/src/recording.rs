//! Limits of the MCAP writer's settings, shared by the graph checker (graph.yaml's `record:`
//! section, errors with line and column) and the recorder node (its own parameters).

use std::ops::RangeInclusive;

/// Allowed target sizes of an uncompressed MCAP chunk, bytes: 1 KiB to 1 GiB. A chunk is held
/// in memory until it is full, so the upper end bounds the recorder's buffer; a recording cut
/// off (recorder killed) loses at most its last chunk.
pub const CHUNK_BYTES_RANGE: RangeInclusive<u64> = 1024..=1 << 30;

/// Allowed zstd compression levels of the chunks: 0 (zstd's default, level 3) to 22. Levels
/// 20 and above ("ultra") need tens to hundreds of MiB per compression and are slow; a recorder
/// that compresses slower than the graph publishes falls behind (live mode drops, lock-step
/// waits).
pub const ZSTD_LEVEL_RANGE: RangeInclusive<u32> = 0..=22;
