//! The built-in event-camera simulator (crate `evseg-sim`) as a source, with full ground truth.

use evseg_schemas::CameraInfo;
use evseg_sim::{Simulator, preset};

use crate::{Batch, EventSource, SourceError};

/// A simulated sequence.
pub struct SyntheticSource {
    sim: Simulator,
}

impl SyntheticSource {
    /// Scene preset `scene` with `seed`, optionally cut or stretched to `seconds`.
    pub fn new(scene: &str, seed: u64, seconds: Option<f64>) -> Result<Self, SourceError> {
        let mut config = preset(scene, seed).map_err(|e| SourceError::Param(e.to_string()))?;
        if let Some(s) = seconds {
            if !(s.is_finite() && s > 0.0) {
                return Err(SourceError::Param(format!("seconds must be > 0, got {s}")));
            }
            config.duration_s = s;
        }
        let sim = Simulator::new(config).map_err(|e| SourceError::Param(e.to_string()))?;
        Ok(Self { sim })
    }
}

impl EventSource for SyntheticSource {
    fn camera(&self) -> CameraInfo {
        self.sim.camera_info()
    }

    fn next_batch(&mut self, t_end: f64) -> Result<Option<Batch>, SourceError> {
        if self.sim.is_finished() {
            return Ok(None);
        }
        let chunk = self.sim.next_chunk(t_end.min(self.sim.duration()));
        Ok(Some(Batch {
            events: chunk.events,
            imu: chunk.imu,
            truth: Some(chunk.truth),
        }))
    }

    fn has_truth(&self) -> bool {
        true
    }
}
