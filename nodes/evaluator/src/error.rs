//! Errors of the evaluator library.

/// Malformed input or parameters. Every variant names the slice (`seq`) it came from.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EvalError {
    /// A parameter is out of range.
    #[error("parameter {name}: {reason}")]
    Param {
        /// Parameter name.
        name: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// The slice's event columns have different lengths.
    #[error("slice {seq}: event columns have different lengths")]
    EventColumns {
        /// Slice number.
        seq: u64,
    },
    /// The window is empty, reversed or not finite.
    #[error("slice {seq}: bad window [{t_start}, {t_end}) s")]
    Window {
        /// Slice number.
        seq: u64,
        /// Window start, s.
        t_start: f64,
        /// Window end, s.
        t_end: f64,
    },
    /// A slice starts before the previous one ended (slices must come in time order).
    #[error("slice {seq}: window starts at {t_start} s, before the previous slice's end {prev_end} s")]
    OutOfOrder {
        /// Slice number.
        seq: u64,
        /// Window start, s.
        t_start: f64,
        /// End of the previous slice, s.
        prev_end: f64,
    },
    /// The result's per-event labels do not match the slice's events.
    #[error("slice {seq}: result has {labels} labels for {events} events")]
    LabelLength {
        /// Slice number.
        seq: u64,
        /// Labels in the result.
        labels: usize,
        /// Events in the slice.
        events: usize,
    },
    /// The truth's per-event object ids do not match the slice's events.
    #[error("slice {seq}: truth has {ids} per-event object ids for {events} events")]
    TruthLength {
        /// Slice number.
        seq: u64,
        /// Ids in the truth.
        ids: usize,
        /// Events in the slice.
        events: usize,
    },
    /// A mask's pixel array does not match its size.
    #[error("slice {seq}: mask {index} (t = {t} s) has {len} pixels for {width} x {height}")]
    MaskSize {
        /// Slice number.
        seq: u64,
        /// Index of the mask in the slice's truth.
        index: usize,
        /// Mask time, s.
        t: f64,
        /// Pixels present.
        len: usize,
        /// Mask width, pixels.
        width: u16,
        /// Mask height, pixels.
        height: u16,
    },
    /// An event lies outside the mask it is looked up in.
    #[error("slice {seq}: event {event} at pixel ({x}, {y}) is outside the {width} x {height} mask")]
    EventOutsideMask {
        /// Slice number.
        seq: u64,
        /// Event index in the slice.
        event: usize,
        /// Column, pixels.
        x: u16,
        /// Row, pixels.
        y: u16,
        /// Mask width, pixels.
        width: u16,
        /// Mask height, pixels.
        height: u16,
    },
    /// A ground-truth sample has a non-finite time or position or a zero/non-finite quaternion.
    #[error("slice {seq}: {what} sample {index} is invalid: {reason}")]
    BadSample {
        /// Slice number.
        seq: u64,
        /// `camera motion`, `object pose` or `mask`.
        what: &'static str,
        /// Index in the slice's truth.
        index: usize,
        /// What is wrong.
        reason: String,
    },
    /// A valid egomotion whose direction is zero or not finite.
    #[error(
        "slice {seq}: egomotion marked valid but its direction {direction:?} is not a non-zero finite vector"
    )]
    BadDirection {
        /// Slice number.
        seq: u64,
        /// The direction given.
        direction: [f64; 3],
    },
}
