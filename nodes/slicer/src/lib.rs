//! Fixed time windows over an event stream.
//!
//! Window `k` covers `[k * window, (k + 1) * window)` seconds on the sequence clock (0 = first
//! event). Every window is emitted, empty ones included, so slice numbers map to time one to
//! one. Each slice carries the IMU samples whose camera-clock time falls in it and the mean
//! camera rotation rate (IMU rate rotated into the camera frame).

#![warn(missing_docs)]

use evseg_schemas::{
    CameraInfo, CameraMotion, EventPacket, Events, ImuSample, Mask, ObjectPose, Slice, Truth,
};

/// Shortest window accepted, seconds (0.1 ms: 10 000 slices per second of sensor time; a
/// shorter one floods every stage with empty slices).
pub const MIN_WINDOW_S: f64 = 1e-4;
/// Longest window accepted, seconds (a minute: a slice would hold a whole recording's events).
pub const MAX_WINDOW_S: f64 = 60.0;

/// Slicer settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SlicerParams {
    /// Window length, seconds (default 0.03: the 30 ms slices of the paper's implementation
    /// notes in ARCHITECTURE.md).
    pub window_s: f64,
    /// Longest gap, seconds, over which the last IMU rate is carried into a window that has no
    /// IMU sample of its own (default 0.05 s: a few samples at the 200 Hz of EVIMO2's IMU).
    pub imu_hold_s: f64,
}

impl Default for SlicerParams {
    fn default() -> Self {
        Self {
            window_s: 0.03,
            imu_hold_s: 0.05,
        }
    }
}

/// Invalid slicer input.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SlicerError {
    /// Window length outside [`MIN_WINDOW_S`]..=[`MAX_WINDOW_S`] (or not a number).
    #[error("window must be within {MIN_WINDOW_S}..={MAX_WINDOW_S} s (window_ms 0.1..=60000), got {0} s")]
    Window(f64),
    /// IMU hold outside 0..=[`MAX_WINDOW_S`] (or not a number).
    #[error("imu_hold_ms must be within 0..=60000 ms, got {} ms", .0 * 1e3)]
    ImuHold(f64),
    /// The columns of an event packet have different lengths.
    #[error("event packet columns have different lengths")]
    Columns,
    /// Ground truth per-event arrays do not match the packet's events.
    #[error("truth has {truth} per-event labels for {events} events")]
    TruthLength {
        /// Labels in the truth message.
        truth: usize,
        /// Events in the packet.
        events: usize,
    },
}

/// One finished slice with its ground truth (when the stream has one).
#[derive(Debug, Clone, PartialEq)]
pub struct SliceOut {
    /// Slice number.
    pub seq: u64,
    /// Window start, seconds.
    pub t_start: f64,
    /// Window end (exclusive), seconds.
    pub t_end: f64,
    /// The slice.
    pub slice: Slice,
    /// Ground truth of the slice's events, aligned with them.
    pub truth: Option<Truth>,
}

/// Incremental slicer: feed packets in time order, collect finished slices.
#[derive(Debug)]
pub struct Slicer {
    params: SlicerParams,
    next: u64,
    camera: Option<CameraInfo>,
    events: Events,
    truth: Option<Truth>,
    imu: Vec<ImuSample>,
    last_rate: Option<(f64, [f64; 3])>,
    /// Events older than the current window (out of order input), dropped and counted.
    late: u64,
    /// Slices emitted without a camera rotation rate (no IMU sample in or shortly before them).
    without_rate: u64,
}

impl Slicer {
    /// A slicer with `params`.
    pub fn new(params: SlicerParams) -> Result<Self, SlicerError> {
        if !(MIN_WINDOW_S..=MAX_WINDOW_S).contains(&params.window_s) {
            return Err(SlicerError::Window(params.window_s));
        }
        if !(0.0..=MAX_WINDOW_S).contains(&params.imu_hold_s) {
            return Err(SlicerError::ImuHold(params.imu_hold_s));
        }
        Ok(Self {
            params,
            next: 0,
            camera: None,
            events: Events::default(),
            truth: None,
            imu: Vec::new(),
            last_rate: None,
            late: 0,
            without_rate: 0,
        })
    }

    /// Events that arrived after their window was emitted (dropped).
    pub fn late_events(&self) -> u64 {
        self.late
    }

    /// Slices emitted so far without a camera rotation rate (`Slice::omega` `None`: no IMU
    /// sample in the window nor within `imu_hold_s` before it); the stages then cannot remove
    /// the rotational flow.
    pub fn slices_without_rate(&self) -> u64 {
        self.without_rate
    }

    fn bounds(&self, k: u64) -> (f64, f64) {
        (
            k as f64 * self.params.window_s,
            (k + 1) as f64 * self.params.window_s,
        )
    }

    /// Adds a packet covering sensor time up to `t_end` (seconds) and returns every slice that
    /// is complete now.
    pub fn push(
        &mut self,
        packet: EventPacket,
        truth: Option<Truth>,
        t_end: f64,
    ) -> Result<Vec<SliceOut>, SlicerError> {
        if !packet.events.is_consistent() {
            return Err(SlicerError::Columns);
        }
        if let Some(t) = &truth
            && !t.event_object.is_empty()
            && t.event_object.len() != packet.events.len()
        {
            return Err(SlicerError::TruthLength {
                truth: t.event_object.len(),
                events: packet.events.len(),
            });
        }
        let (t0, _) = self.bounds(self.next);
        let keep = packet
            .events
            .t
            .iter()
            .position(|&t| t >= t0)
            .unwrap_or(packet.events.len());
        self.late += keep as u64;
        let n = packet.events.len();
        self.events.extend_from(&packet.events, keep..n);
        if let Some(t) = truth {
            let acc = self.truth.get_or_insert_with(Truth::default);
            append_truth(acc, &t, keep..n);
        }
        self.imu.extend(packet.imu);
        self.camera = Some(packet.camera);
        let mut out = Vec::new();
        let last_t = self
            .events
            .t
            .last()
            .copied()
            .unwrap_or(f64::NEG_INFINITY)
            .max(t_end);
        while self.bounds(self.next).1 <= last_t {
            out.push(self.emit());
        }
        Ok(out)
    }

    /// Emits the last, partial window (if it holds anything).
    pub fn finish(&mut self) -> Vec<SliceOut> {
        if self.events.is_empty() {
            Vec::new()
        } else {
            vec![self.emit()]
        }
    }

    fn emit(&mut self) -> SliceOut {
        let (t_start, t_end) = self.bounds(self.next);
        let seq = self.next;
        self.next += 1;
        let split = self.events.t.partition_point(|&t| t < t_end);
        let n = self.events.len();
        let mut events = Events::with_capacity(split);
        events.extend_from(&self.events, 0..split);
        let mut rest = Events::with_capacity(n - split);
        rest.extend_from(&self.events, split..n);
        self.events = rest;
        let truth = self.truth.as_mut().map(|acc| split_truth(acc, split, t_end));
        let camera = self.camera.clone().unwrap_or_else(default_camera);
        let offset = camera.imu_time_offset_s;
        let cut = self.imu.partition_point(|s| s.t + offset < t_end);
        let mut imu: Vec<ImuSample> = self.imu.drain(..cut).collect();
        imu.retain(|s| s.t + offset >= t_start);
        let omega = if imu.is_empty() {
            self.last_rate
                .filter(|(t, _)| t_start - t <= self.params.imu_hold_s)
                .map(|(_, w)| w)
        } else {
            let mut m = [0.0; 3];
            for s in &imu {
                for (a, g) in m.iter_mut().zip(s.gyro) {
                    *a += g;
                }
            }
            let k = imu.len() as f64;
            let w = camera.imu_vector_to_camera([m[0] / k, m[1] / k, m[2] / k]);
            self.last_rate = Some((t_end, w));
            Some(w)
        };
        if omega.is_none() {
            self.without_rate += 1;
        }
        SliceOut {
            seq,
            t_start,
            t_end,
            slice: Slice {
                camera,
                events,
                imu,
                omega,
            },
            truth,
        }
    }
}

/// Camera used only if a slice had to be emitted before any packet named one.
fn default_camera() -> CameraInfo {
    CameraInfo::pinhole(1, 1, 1.0, "unknown")
}

fn append_truth(acc: &mut Truth, t: &Truth, range: std::ops::Range<usize>) {
    if !t.event_object.is_empty() {
        acc.event_object.extend_from_slice(&t.event_object[range.clone()]);
    }
    if t.flow_x.len() >= range.end && t.flow_y.len() >= range.end {
        acc.flow_x.extend_from_slice(&t.flow_x[range.clone()]);
        acc.flow_y.extend_from_slice(&t.flow_y[range]);
    }
    acc.masks.extend(t.masks.iter().cloned());
    acc.camera.extend(t.camera.iter().copied());
    acc.objects.extend(t.objects.iter().copied());
}

/// Splits off the first `n` events' truth and the time-stamped items before `t_end`.
fn split_truth(acc: &mut Truth, n: usize, t_end: f64) -> Truth {
    fn take_vec<T: Clone>(v: &mut Vec<T>, n: usize) -> Vec<T> {
        let n = n.min(v.len());
        let rest = v.split_off(n);
        std::mem::replace(v, rest)
    }
    fn take_before<T>(v: &mut Vec<T>, t_end: f64, t: impl Fn(&T) -> f64) -> Vec<T> {
        let (before, after): (Vec<T>, Vec<T>) = v.drain(..).partition(|x| t(x) < t_end);
        *v = after;
        before
    }
    Truth {
        event_object: take_vec(&mut acc.event_object, n),
        flow_x: take_vec(&mut acc.flow_x, n),
        flow_y: take_vec(&mut acc.flow_y, n),
        masks: take_before(&mut acc.masks, t_end, |m: &Mask| m.t),
        camera: take_before(&mut acc.camera, t_end, |c: &CameraMotion| c.t),
        objects: take_before(&mut acc.objects, t_end, |o: &ObjectPose| o.t),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn packet(ts: &[f64], imu: &[(f64, [f64; 3])]) -> EventPacket {
        let mut events = Events::default();
        for (i, &t) in ts.iter().enumerate() {
            events.push(t, i as u16, 0, 1);
        }
        let mut camera = default_camera();
        // EVIMO2 convention: w_cam = (w_imu.y, -w_imu.x, w_imu.z).
        camera.imu_to_camera = [0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0];
        EventPacket {
            camera,
            events,
            imu: imu
                .iter()
                .map(|&(t, gyro)| ImuSample {
                    t,
                    gyro,
                    accel: [0.0; 3],
                })
                .collect(),
        }
    }

    #[test]
    fn windows_are_fixed_and_every_event_lands_once() {
        let mut s = Slicer::new(SlicerParams {
            window_s: 0.1,
            ..Default::default()
        })
        .unwrap();
        let mut out = s.push(packet(&[0.0, 0.05, 0.12], &[]), None, 0.15).unwrap();
        assert_eq!(out.len(), 1);
        out.extend(s.push(packet(&[0.35, 0.36], &[]), None, 0.4).unwrap());
        out.extend(s.finish());
        let seqs: Vec<u64> = out.iter().map(|o| o.seq).collect();
        // The second packet covers sensor time up to 0.4 s, so window 3 = [0.3, 0.4) is complete
        // and finish() has nothing left to flush.
        assert_eq!(seqs, vec![0, 1, 2, 3]);
        let counts: Vec<usize> = out.iter().map(|o| o.slice.events.len()).collect();
        assert_eq!(counts, [2, 1, 0, 2]);
        assert_eq!(out[2].t_start, 0.2);
    }

    #[test]
    fn imu_rate_is_rotated_into_the_camera_frame() {
        let mut s = Slicer::new(SlicerParams {
            window_s: 0.1,
            ..Default::default()
        })
        .unwrap();
        let out = s
            .push(
                packet(&[0.01], &[(0.02, [1.0, 2.0, 3.0]), (0.04, [3.0, 2.0, 1.0])]),
                None,
                0.1,
            )
            .unwrap();
        let w = out[0].slice.omega.unwrap();
        // mean imu rate (2, 2, 2) -> camera (2, -2, 2)
        assert_eq!(w, [2.0, -2.0, 2.0]);
        assert_eq!(out[0].slice.imu.len(), 2);
    }

    #[test]
    fn slices_without_imu_are_counted() {
        let mut s = Slicer::new(SlicerParams {
            window_s: 0.1,
            imu_hold_s: 0.05,
        })
        .unwrap();
        // Window 0 has IMU (its rate dates from its end, 0.1 s); window 1 starts within imu_hold_s
        // of it and holds the rate; windows 2 and 3 have none.
        let out = s
            .push(
                packet(&[0.01, 0.15, 0.25, 0.35], &[(0.05, [0.0, 0.0, 1.0])]),
                None,
                0.4,
            )
            .unwrap();
        let has_rate: Vec<bool> = out.iter().map(|o| o.slice.omega.is_some()).collect();
        assert_eq!(has_rate, [true, true, false, false]);
        assert_eq!(s.slices_without_rate(), 2);
    }

    #[test]
    fn truth_stays_aligned() {
        let mut s = Slicer::new(SlicerParams {
            window_s: 0.1,
            ..Default::default()
        })
        .unwrap();
        let truth = Truth {
            event_object: vec![0, 1, 2],
            flow_x: vec![0.0, 1.0, 2.0],
            flow_y: vec![0.0; 3],
            ..Default::default()
        };
        let mut out = s.push(packet(&[0.0, 0.05, 0.15], &[]), Some(truth), 0.2).unwrap();
        out.extend(s.finish());
        assert_eq!(out[0].truth.as_ref().unwrap().event_object, vec![0, 1]);
        assert_eq!(out[1].truth.as_ref().unwrap().event_object, vec![2]);
        assert_eq!(out[1].truth.as_ref().unwrap().flow_x, vec![2.0]);
    }

    #[test]
    fn events_older_than_the_open_window_are_counted() {
        let mut s = Slicer::new(SlicerParams {
            window_s: 0.1,
            ..Default::default()
        })
        .unwrap();
        s.push(packet(&[0.05], &[]), None, 0.1).unwrap();
        let out = s.push(packet(&[0.09, 0.12], &[]), None, 0.2).unwrap();
        assert_eq!(s.late_events(), 1);
        assert_eq!(out[0].slice.events.t, vec![0.12]);
    }

    #[test]
    fn bad_input_is_refused() {
        for window_s in [0.0, 1e-9, 1e20, f64::NAN, -0.03] {
            let e = Slicer::new(SlicerParams {
                window_s,
                ..Default::default()
            })
            .unwrap_err()
            .to_string();
            assert!(e.contains("window_ms 0.1..=60000"), "{e}");
        }
        for imu_hold_s in [-0.001, f64::NAN, 1e9] {
            let e = Slicer::new(SlicerParams {
                imu_hold_s,
                ..Default::default()
            })
            .unwrap_err()
            .to_string();
            assert!(e.contains("imu_hold_ms must be within 0..=60000 ms"), "{e}");
        }
        for window_s in [MIN_WINDOW_S, MAX_WINDOW_S] {
            assert!(
                Slicer::new(SlicerParams {
                    window_s,
                    ..Default::default()
                })
                .is_ok()
            );
        }
        let mut s = Slicer::new(SlicerParams::default()).unwrap();
        let mut p = packet(&[0.0], &[]);
        p.events.x.push(3);
        assert_eq!(s.push(p, None, 0.1), Err(SlicerError::Columns));
        let t = Truth {
            event_object: vec![0, 0],
            ..Default::default()
        };
        assert!(matches!(
            s.push(packet(&[0.0], &[]), Some(t), 0.1),
            Err(SlicerError::TruthLength { .. })
        ));
    }
}
