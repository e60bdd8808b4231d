//! Errors of the tracker: malformed input messages and invalid parameters.

/// Why a slice could not be tracked, or why parameters were refused.
///
/// An error leaves the tracker's state as it was before the call.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackerError {
    /// A parameter is outside its valid range.
    #[error("parameter {name} = {} is invalid: {reason}", evseg_schemas::params::short_number(*.value))]
    InvalidParam {
        /// Parameter name (as in [`crate::TrackerParams`] and the node config).
        name: &'static str,
        /// The value given.
        value: f64,
        /// What it must be.
        reason: &'static str,
    },
    /// A parameter that names one of a few choices names none of them.
    #[error("parameter {name} = `{value}` is invalid: expected one of {expected:?}")]
    InvalidChoice {
        /// Parameter name (as in [`crate::TrackerParams`] and the node config).
        name: &'static str,
        /// The value given.
        value: String,
        /// The valid values.
        expected: &'static [&'static str],
    },
    /// The per-event label vector does not have one entry per event of the slice.
    #[error("segmentation has {labels} per-event labels but the slice has {events} events")]
    LabelCount {
        /// Length of `Segmentation::label`.
        labels: usize,
        /// Number of events in the slice.
        events: usize,
    },
    /// The slice's event columns differ in length.
    #[error("the slice has {x} event x coordinates but {y} y coordinates")]
    PixelCount {
        /// Length of the x column.
        x: usize,
        /// Length of the y column.
        y: usize,
    },
    /// An event carries a label that no segment describes.
    #[error("event {index} has label {label}, which is not among the segments")]
    UnknownLabel {
        /// Index of the event in the slice.
        index: usize,
        /// Its label.
        label: u32,
    },
    /// Two segments share one label.
    #[error("segment label {label} appears more than once in the segment list")]
    DuplicateSegment {
        /// The repeated label.
        label: u32,
    },
    /// A foreground segment's centroid is NaN or infinite.
    #[error("segment {label} has a non-finite centroid {centroid:?} (pixels)")]
    NonFiniteCentroid {
        /// Segment label.
        label: u32,
        /// The centroid, pixels.
        centroid: [f64; 2],
    },
    /// A foreground segment's bounding box is non-finite or has `min > max`.
    #[error("segment {label} has an invalid bounding box {bbox:?} (pixels, [x_min, y_min, x_max, y_max])")]
    InvalidBbox {
        /// Segment label.
        label: u32,
        /// The box, pixels.
        bbox: [f32; 4],
    },
    /// The slice's time window is non-finite or ends before it starts.
    #[error("slice time window [{t_start}, {t_end}) s is invalid")]
    InvalidSpan {
        /// Window start, seconds.
        t_start: f64,
        /// Window end, seconds.
        t_end: f64,
    },
    /// The slice's centre time is not after the previous slice's.
    #[error("slice centre time {current} s is not after the previous slice's {previous} s")]
    TimeNotIncreasing {
        /// Previous slice centre, seconds.
        previous: f64,
        /// This slice centre, seconds.
        current: f64,
    },
    /// Track ids (u32) would run out: ids are never reused.
    #[error("track ids exhausted: next id {next}, up to {needed} new tracks needed")]
    IdsExhausted {
        /// The next free id.
        next: u32,
        /// Foreground segments that could open tracks.
        needed: usize,
    },
}
