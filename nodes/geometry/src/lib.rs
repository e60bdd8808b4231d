//! Shared geometry of the method (METHOD_NOTES section 1), in one place for every stage:
//!
//! - [`camera`]: pixel <-> normalized coordinates through the lens model (radial-tangential or
//!   equidistant), and a per-pixel undistortion table for the hot loops;
//! - [`motion`]: the motion-field matrices `A(x)`, `B(x)` (translation and rotation) and the
//!   planar-scene matrix `C(x)`, with the flows they give;
//! - [`rotation`]: the camera's rotation rate over a slice as a line in time, from its gyro
//!   samples;
//! - [`lsq`]: small dense least squares (normal equations with Tikhonov regularization);
//! - [`cache`]: prefetch hints for per-pixel table lookups in per-event loops;
//! - [`assignment`]: optimal one-to-one assignment (Hungarian), for matching labels to objects
//!   (evaluator) and segments to tracks (tracker);
//! - [`rigid`]: 3-vectors, rotation matrices, quaternions and the SO(3) / SE(3) logarithms on
//!   plain arrays, for the simulator's kinematics and the evaluator's ground truth.
//!
//! Normalized coordinates: undistorted, focal length 1, camera frame x right, y down, z forward.
//! Flows in normalized coordinates per second; rotation rates in rad/s; translations in the units
//! the caller chose (m/s with depth in m, or "per unit depth").

#![warn(missing_docs)]

pub mod assignment;
pub mod cache;
pub mod camera;
pub mod cell_grid;
pub mod density;
pub mod direction;
pub mod egomotion;
#[cfg(feature = "node")]
pub mod egomotion_node;
pub mod lsq;
pub mod motion;
pub mod refine;
pub mod rigid;
pub mod rotation;
pub mod samples;
pub mod svm;
pub mod translation;

pub use camera::{Camera, TableCache, UndistortTable};
pub use cell_grid::CellGrid;
pub use density::density_weights;
pub use direction::{FlowDirection, flow_direction};
pub use egomotion::{
    EgomotionParams, clear_of_foreground, estimate_background_translation,
    estimate_background_translation_with_memory, estimate_translation, estimate_translation_with_memory,
};
pub use motion::{a_matrix, b_matrix, c_matrix, planar_flow, rotational_flow, translational_flow};
pub use refine::{
    DepthMemory, grid_regions, refine_direction, refine_direction_robust, refine_direction_with_memory,
};
pub use rotation::RotationRate;
pub use samples::{FlowSample, MIN_CONFIDENCE_RANGE, flow_samples, median_length, min_confidence_problem};
pub use svm::{SvmDirection, SvmParams, translation_direction};
pub use translation::TranslationFit;
