//! Ground truth gathered across slices.
//!
//! A slice's `Truth` holds only the masks, camera samples and object poses whose time falls in
//! that slice's window, but the mask nearest to a window, or the samples bracketing its ends,
//! may belong to a neighbouring slice. The history keeps them (validated, time-sorted) for as
//! long as a pending slice may need them.

use std::collections::BTreeMap;

use evseg_schemas::{CameraMotion, Mask, Truth};

use crate::egomotion::PoseSample;
use crate::error::EvalError;
use evseg_geometry::rigid;

/// Most recent mask-to-mask intervals kept for the mask period estimate.
const PERIOD_WINDOW: usize = 64;

/// Validated ground truth of recent slices.
#[derive(Debug, Default)]
pub struct TruthHistory {
    masks: Vec<Mask>,
    camera: Vec<CameraMotion>,
    objects: BTreeMap<u32, Vec<PoseSample>>,
    intervals: Vec<f64>,
    last_mask_t: Option<f64>,
}

fn finite3(v: [f64; 3]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn insert_sorted<T>(v: &mut Vec<T>, item: T, t: impl Fn(&T) -> f64) {
    let ti = t(&item);
    let i = v.partition_point(|x| t(x) <= ti);
    v.insert(i, item);
}

impl TruthHistory {
    /// Validates and adds the time-stamped items of slice `seq`'s truth.
    pub fn add(&mut self, seq: u64, truth: &Truth) -> Result<(), EvalError> {
        for (index, m) in truth.masks.iter().enumerate() {
            if !m.t.is_finite() {
                return Err(EvalError::BadSample {
                    seq,
                    what: "mask",
                    index,
                    reason: format!("time {}", m.t),
                });
            }
            if m.ids.len() != m.width as usize * m.height as usize {
                return Err(EvalError::MaskSize {
                    seq,
                    index,
                    t: m.t,
                    len: m.ids.len(),
                    width: m.width,
                    height: m.height,
                });
            }
        }
        let bad = |what, index, reason: String| EvalError::BadSample {
            seq,
            what,
            index,
            reason,
        };
        let mut camera = Vec::with_capacity(truth.camera.len());
        for (index, c) in truth.camera.iter().enumerate() {
            if !(c.t.is_finite() && finite3(c.position)) {
                return Err(bad("camera motion", index, "time or position not finite".into()));
            }
            let q = rigid::quat_normalize(c.orientation)
                .ok_or_else(|| bad("camera motion", index, format!("quaternion {:?}", c.orientation)))?;
            if c.linear_velocity.is_some_and(|v| !finite3(v)) {
                return Err(bad("camera motion", index, "linear velocity not finite".into()));
            }
            camera.push(CameraMotion { orientation: q, ..*c });
        }
        let mut objects = Vec::with_capacity(truth.objects.len());
        for (index, o) in truth.objects.iter().enumerate() {
            if o.id == 0 {
                return Err(bad("object pose", index, "object id 0 is the background".into()));
            }
            if !(o.t.is_finite() && finite3(o.position)) {
                return Err(bad("object pose", index, "time or position not finite".into()));
            }
            let q = rigid::quat_normalize(o.orientation)
                .ok_or_else(|| bad("object pose", index, format!("quaternion {:?}", o.orientation)))?;
            objects.push((
                o.id,
                PoseSample {
                    t: o.t,
                    position: o.position,
                    orientation: q,
                },
            ));
        }
        for m in &truth.masks {
            if let Some(last) = self.last_mask_t
                && m.t > last
            {
                self.intervals.push(m.t - last);
                if self.intervals.len() > PERIOD_WINDOW {
                    self.intervals.remove(0);
                }
            }
            self.last_mask_t = Some(self.last_mask_t.map_or(m.t, |l| l.max(m.t)));
            insert_sorted(&mut self.masks, m.clone(), |m| m.t);
        }
        for c in camera {
            insert_sorted(&mut self.camera, c, |c| c.t);
        }
        for (id, p) in objects {
            insert_sorted(self.objects.entry(id).or_default(), p, |p| p.t);
        }
        Ok(())
    }

    /// Masks, time-sorted.
    pub fn masks(&self) -> &[Mask] {
        &self.masks
    }

    /// Camera samples (unit quaternions), time-sorted.
    pub fn camera(&self) -> &[CameraMotion] {
        &self.camera
    }

    /// Poses of object `id` (unit quaternions), time-sorted.
    pub fn object_poses(&self, id: u32) -> &[PoseSample] {
        self.objects.get(&id).map_or(&[], |v| v.as_slice())
    }

    /// Mask period, seconds: the median of recent intervals between consecutive masks, or
    /// `default_s` before two masks have been seen.
    pub fn mask_period(&self, default_s: f64) -> f64 {
        if self.intervals.is_empty() {
            return default_s;
        }
        let mut v = self.intervals.clone();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    }

    /// Forgets items older than `t` seconds, keeping the last one before `t` of each kind (so a
    /// later time can still be bracketed).
    pub fn prune_before(&mut self, t: f64) {
        fn prune<T>(v: &mut Vec<T>, t: f64, time: impl Fn(&T) -> f64) {
            let n = v.partition_point(|x| time(x) < t);
            if n > 1 {
                v.drain(..n - 1);
            }
        }
        prune(&mut self.masks, t, |m| m.t);
        prune(&mut self.camera, t, |c| c.t);
        for poses in self.objects.values_mut() {
            prune(poses, t, |p| p.t);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use evseg_schemas::ObjectPose;

    fn mask(t: f64) -> Mask {
        Mask {
            t,
            width: 2,
            height: 1,
            ids: vec![0, 1],
        }
    }

    #[test]
    fn mask_period_is_the_median_interval_and_pruning_keeps_one_before() {
        let mut h = TruthHistory::default();
        assert_eq!(h.mask_period(0.5), 0.5);
        let t1 = Truth {
            masks: vec![mask(0.0), mask(0.02)],
            ..Truth::default()
        };
        // A dropout (0.06 s) does not move the median.
        let t2 = Truth {
            masks: vec![mask(0.04), mask(0.10), mask(0.12)],
            ..Truth::default()
        };
        h.add(0, &t1).unwrap();
        h.add(1, &t2).unwrap();
        assert!((h.mask_period(0.5) - 0.02).abs() < 1e-12);
        h.prune_before(0.05);
        let ts: Vec<f64> = h.masks().iter().map(|m| m.t).collect();
        assert_eq!(ts, vec![0.04, 0.10, 0.12]);
    }

    #[test]
    fn malformed_truth_is_an_error() {
        let mut h = TruthHistory::default();
        let mut m = mask(0.0);
        m.ids.pop();
        let t = Truth {
            masks: vec![m],
            ..Truth::default()
        };
        assert!(matches!(
            h.add(2, &t),
            Err(EvalError::MaskSize { seq: 2, len: 1, .. })
        ));
        let t = Truth {
            objects: vec![ObjectPose {
                id: 1,
                t: 0.0,
                position: [0.0; 3],
                orientation: [0.0; 4],
            }],
            ..Truth::default()
        };
        assert!(matches!(
            h.add(3, &t),
            Err(EvalError::BadSample { seq: 3, index: 0, .. })
        ));
        let t = Truth {
            camera: vec![CameraMotion {
                t: f64::NAN,
                orientation: [0.0, 0.0, 0.0, 1.0],
                ..CameraMotion::default()
            }],
            ..Truth::default()
        };
        assert!(h.add(4, &t).is_err());
    }
}
