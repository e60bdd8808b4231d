//! Per-event normal flow from events by local plane fits (Benosman et al. 2014, constants from
//! METHOD_NOTES §2), and a scorer against true optical flow.
//!
//! - [`PlaneFitEstimator`]: keeps a surface of active events per polarity (latest timestamp per
//!   pixel, seconds) across slices; for every event, in time order, it updates the surface and
//!   fits the plane `t = gx dx + gy dy + c` to the same-polarity neighbours of a `(2 r + 1)^2`
//!   window whose age is within `[dt_min, dt_max]`, rejecting points with a time residual above
//!   `outlier_s` and refitting. The normal flow is `(gx, gy) / (gx^2 + gy^2)` pixels per second
//!   (pointing along the motion), converted to normalized units per second with the camera
//!   Jacobian at the event's pixel ([`evseg_geometry::Camera::pixel_flow_to_normalized`]).
//!   Invalid fits have confidence 0 and flow 0.
//! - [`LearnedEstimator`]: the learned alternative (VecKM_flow style, METHOD_NOTES §2): a
//!   random-Fourier-feature encoding of each event's spatio-temporal neighbourhood within the
//!   slice and a bias-free ReLU MLP, weights from a file ([`weights`]) trained by [`train`] on
//!   simulator ground truth with the circle loss. Same output units as the plane fit.
//! - [`score`]: sign-correct rate, magnitude error, circle angle error and coverage, at object
//!   boundaries and elsewhere.

#![deny(missing_docs)]

pub mod consensus;
pub mod estimator;
pub mod fit;
pub mod learned;
pub mod mlp;
pub mod node_score;
pub mod params;
pub mod score;
pub mod train;
pub mod weights;

pub use consensus::{ConsensusParams, ConsensusStats, consensus};
pub use estimator::{EstimatorError, EstimatorStats, PixelEstimate, PlaneFitEstimator, jacobian_table};
pub use fit::{Neighbourhood, PlaneFit, PlaneRefit, fit_plane};
pub use learned::{LearnedError, LearnedEstimator, LearnedParams};
pub use node_score::{NodeScore, RunScoreError, write_run_score};
pub use params::{MAX_RADIUS, ParamsError, PlaneFitParams, WideFitParams};
pub use score::{Score, ScoreParams, Scorer};
pub use weights::{LearnedWeights, WeightsError};
