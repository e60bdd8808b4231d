//! The scoring an estimator node does when its `truth` input is wired, shared by both estimator
//! binaries: each slice scored and logged, the run's score written to
//! `normal-flow-score-<node>.json` in the run folder at the end.

use std::path::{Path, PathBuf};

use evseg_schemas::{CameraInfo, Events, NormalFlow, Truth};
use serde::Serialize;

use crate::score::{Score, ScoreError, ScoreParams, Scorer};

/// Errors writing the run's score file; each names the file.
#[derive(Debug, thiserror::Error)]
pub enum RunScoreError {
    /// The report did not serialise.
    #[error("cannot encode {path}: {source}")]
    Encode {
        /// The score file.
        path: PathBuf,
        /// The serialiser's error.
        source: serde_json::Error,
    },
    /// The file could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The score file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
}

/// A node's running score against the truth; empty until the first slice with truth.
#[derive(Debug, Default)]
pub struct NodeScore {
    scorer: Option<Scorer>,
}

impl NodeScore {
    /// Scores slice `seq` (`flow` and `truth` aligned with `events`) and logs its figures;
    /// `camera_changed` restarts the scorer for the new camera (true pixel flow is converted
    /// with its Jacobian).
    pub fn add_slice(
        &mut self,
        camera: &CameraInfo,
        camera_changed: bool,
        seq: u64,
        events: &Events,
        flow: &NormalFlow,
        truth: &Truth,
    ) -> Result<(), ScoreError> {
        if self.scorer.is_none() || camera_changed {
            self.scorer = Some(Scorer::new(camera, ScoreParams::default()));
        }
        let Some(scorer) = self.scorer.as_mut() else {
            return Ok(());
        };
        let s = scorer.add_slice(events, flow, truth)?;
        tracing::info!(
            seq,
            events = s.all.events,
            coverage = s.all.coverage,
            sign_correct = s.all.sign_correct_rate,
            sign_correct_boundary = s.boundary.sign_correct_rate,
            circle_angle_deg_median = s.all.circle_angle_error_deg_median,
            "normal-flow score"
        );
        Ok(())
    }

    /// The run's score so far; `None` when no slice had truth.
    pub fn summary(&self) -> Option<Score> {
        self.scorer.as_ref().map(Scorer::summary)
    }
}

/// Writes `report` (the estimator's settings and `score`, the run's score) as pretty JSON to
/// `run_dir/normal-flow-score-<node>.json`, logs the main figures and returns the path.
pub fn write_run_score(
    run_dir: &Path,
    node: &str,
    report: &impl Serialize,
    score: &Score,
) -> Result<PathBuf, RunScoreError> {
    let path = run_dir.join(format!("normal-flow-score-{node}.json"));
    let json = serde_json::to_string_pretty(report).map_err(|source| RunScoreError::Encode {
        path: path.clone(),
        source,
    })?;
    std::fs::write(&path, json).map_err(|source| RunScoreError::Write {
        path: path.clone(),
        source,
    })?;
    let s = &score.all;
    tracing::info!(
        path = %path.display(),
        coverage = s.coverage,
        sign_correct = s.sign_correct_rate,
        circle_angle_deg_median = s.circle_angle_error_deg_median,
        "normal-flow run score written"
    );
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_truth_no_summary_and_an_unwritable_folder_is_an_error_naming_the_file() {
        assert!(NodeScore::default().summary().is_none());
        let score = Scorer::new(&CameraInfo::pinhole(4, 4, 1.0, "t"), ScoreParams::default()).summary();
        let missing = Path::new("/nonexistent-evseg-dir");
        let err = write_run_score(missing, "flow", &serde_json::json!({}), &score).unwrap_err();
        assert!(
            err.to_string()
                .contains("/nonexistent-evseg-dir/normal-flow-score-flow.json"),
            "{err}"
        );
    }
}
